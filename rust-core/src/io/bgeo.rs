//! Houdini classic binary geometry (`.bgeo`, version 5), as SPlisHSPlasH and partio write
//! particles. Gzip compression is undone by the caller (detected by magic bytes).
//!
//! Layout, all big-endian: `Bgeo`, `V`, i32 version, eight i32 counts (points, primitives,
//! point groups, primitive groups, point/vertex/primitive/detail attributes), the point
//! attribute definitions (u16 name length, name, u16 tuple size, i32 type, default values),
//! then per point x y z w as f32 followed by each attribute's tuple of 4-byte values.
//! Everything after the points (primitives, groups) says nothing about particles and is
//! not read.

use super::numeric::{byte_len, Endian, Scalar};
use crate::error::{Error, Result};
use crate::field::particles::{Attribute, ParticleData};

/// Houdini attribute types (`GB_ATTRIB_*`).
const FLOAT: i32 = 0;
const INT: i32 = 1;
const STRING: i32 = 2;
const INDEX: i32 = 4;
const VECTOR: i32 = 5;

/// One point attribute: where its tuple sits in a point record and how to read it.
struct Definition {
    name: String,
    size: usize,
    /// `None` for indexed strings, whose per-point values are only table indices.
    ty: Option<Scalar>,
    offset: usize,
}

/// Reads positions (homogeneous w dropped) and every numeric point attribute.
pub(crate) fn read(bytes: &[u8], name: &str) -> Result<ParticleData> {
    let mut r = Cursor {
        bytes,
        pos: 0,
        name,
    };
    if bytes.starts_with(b"\x7fNSJ") || bytes.starts_with(b"{") || bytes.starts_with(b"[") {
        return Err(r.err(
            "this is Houdini's JSON geometry format (Houdini 12+); only the classic binary .bgeo is supported",
        ));
    }
    if !bytes.starts_with(b"BgeoV") {
        return Err(r.err("not a Houdini .bgeo file (no 'BgeoV' magic)"));
    }
    r.pos = 5;
    let version = r.i32("the version")?;
    if version != 5 {
        return Err(r.err(format!(
            "classic bgeo version {version} is not supported (only version 5)"
        )));
    }
    let mut counts = [0i32; 8];
    for c in &mut counts {
        *c = r.i32("the header counts")?;
    }
    let [points, _prims, _point_groups, _prim_groups, point_attributes, ..] = counts;
    let (Ok(points), Ok(point_attributes)) =
        (u64::try_from(points), usize::try_from(point_attributes))
    else {
        return Err(r.err(format!(
            "negative counts in the header ({points} points, {point_attributes} attributes)"
        )));
    };

    // Each point starts with x y z w.
    let mut record = 4usize;
    let mut definitions = Vec::new();
    for k in 0..point_attributes {
        let len = r.u16("an attribute name")? as usize;
        let name_bytes = r.take(len, "an attribute name")?;
        let attr_name = String::from_utf8_lossy(name_bytes).into_owned();
        // Named in messages as shown text: a corrupt length reads binary as the name.
        let shown = super::numeric::show(name_bytes);
        let size = r.u16("an attribute size")? as usize;
        let ty = r.i32("an attribute type")?;
        let scalar = match ty {
            FLOAT | VECTOR => Some(Scalar::F32),
            INT => Some(Scalar::I32),
            INDEX => None,
            STRING => {
                return Err(r.err(format!(
                    "point attribute '{shown}' has Houdini type string, which has no per-point layout in classic bgeo"
                )))
            }
            other => {
                return Err(r.err(format!(
                    "point attribute {k} '{shown}' has unknown Houdini type {other}"
                )))
            }
        };
        if ty == INDEX {
            // The string table: i32 count, then u16-length-prefixed strings.
            let entries = r.i32("an index table")?;
            for _ in 0..entries.max(0) {
                let len = r.u16("an index table entry")? as usize;
                r.take(len, "an index table entry")?;
            }
        } else {
            // Default values, one 4-byte value per component.
            r.take(size * 4, "attribute defaults")?;
        }
        definitions.push(Definition {
            name: attr_name,
            size,
            ty: scalar,
            offset: record * 4,
        });
        record += size;
    }

    let stride = record * 4;
    let remaining = bytes.len() - r.pos;
    let need = byte_len(points, stride as u64)
        .filter(|&n| n <= remaining)
        .ok_or_else(|| {
            r.err(format!(
                "truncated: the header declares {points} points but the file ends after {}",
                remaining / stride
            ))
        })?;
    let block = &bytes[r.pos..r.pos + need];
    let n = points as usize;

    let column =
        |ty: Scalar, offset: usize| ty.decode_strided(block, n, stride, offset, Endian::Big);
    let (x, y, z) = (
        column(Scalar::F32, 0),
        column(Scalar::F32, 4),
        column(Scalar::F32, 8),
    );
    let positions = (0..n).map(|i| glam::DVec3::new(x[i], y[i], z[i])).collect();
    let attributes = definitions
        .into_iter()
        .filter_map(|d| {
            let ty = d.ty?;
            let columns: Vec<Vec<f64>> =
                (0..d.size).map(|c| column(ty, d.offset + 4 * c)).collect();
            let data = (0..n)
                .flat_map(|i| columns.iter().map(move |col| col[i]))
                .collect();
            Some(Attribute {
                name: d.name,
                components: d.size,
                data,
            })
        })
        .filter(|a| a.components > 0)
        .collect();
    Ok(ParticleData {
        positions,
        attributes,
        ..Default::default()
    })
}

struct Cursor<'a> {
    bytes: &'a [u8],
    pos: usize,
    name: &'a str,
}

impl<'a> Cursor<'a> {
    fn err(&self, message: impl Into<String>) -> Error {
        Error::format(self.name, message)
    }

    fn take(&mut self, len: usize, what: &str) -> Result<&'a [u8]> {
        let bytes = self.bytes;
        let slice = self
            .pos
            .checked_add(len)
            .and_then(|end| bytes.get(self.pos..end))
            .ok_or_else(|| {
                self.err(format!(
                    "truncated: the file ends in {what} (at byte {})",
                    self.pos
                ))
            })?;
        self.pos += len;
        Ok(slice)
    }

    fn i32(&mut self, what: &str) -> Result<i32> {
        let b = self.take(4, what)?;
        Ok(i32::from_be_bytes([b[0], b[1], b[2], b[3]]))
    }

    fn u16(&mut self, what: &str) -> Result<u16> {
        let b = self.take(2, what)?;
        Ok(u16::from_be_bytes([b[0], b[1]]))
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_support::*;
    use super::super::{read_particles, read_particles_from_bytes};
    use super::*;

    /// A classic bgeo with `n` points, an int id, a float density and a 3-vector velocity.
    fn sample(n: usize) -> Vec<u8> {
        let mut b = b"BgeoV".to_vec();
        for v in [5i32, n as i32, 0, 0, 0, 3, 0, 0, 0] {
            b.extend_from_slice(&v.to_be_bytes());
        }
        for (name, size, ty) in [("id", 1u16, INT), ("density", 1, FLOAT), ("v", 3, VECTOR)] {
            b.extend_from_slice(&(name.len() as u16).to_be_bytes());
            b.extend_from_slice(name.as_bytes());
            b.extend_from_slice(&size.to_be_bytes());
            b.extend_from_slice(&ty.to_be_bytes());
            b.extend(std::iter::repeat_n(0u8, 4 * size as usize));
        }
        for i in 0..n {
            for v in [i as f32, 2.0 * i as f32, -1.0, 1.0] {
                b.extend_from_slice(&v.to_be_bytes());
            }
            b.extend_from_slice(&(i as i32 + 100).to_be_bytes());
            b.extend_from_slice(&1000.5f32.to_be_bytes());
            for v in [0.5f32, i as f32, 3.0] {
                b.extend_from_slice(&v.to_be_bytes());
            }
        }
        b.extend_from_slice(b"beginExtra\0\xff");
        b
    }

    #[test]
    fn reads_positions_and_attributes() {
        let p = read(&sample(3), "s.bgeo").unwrap();
        assert_eq!(p.len(), 3);
        assert_eq!(p.positions[2].to_array(), [2.0, 4.0, -1.0]);
        assert_eq!(p.require("id").unwrap().data, vec![100.0, 101.0, 102.0]);
        assert_eq!(p.require("density").unwrap().data, vec![1000.5; 3]);
        let v = p.require("v").unwrap();
        assert_eq!(v.components, 3);
        assert_eq!(v.item(1), &[0.5, 1.0, 3.0]);
    }

    #[test]
    fn shared_frames_and_their_truncations() {
        let path = shared_data_dir().join("dam_break_frame_9_6859_particles.bgeo");
        let p = read_particles(&path).unwrap();
        assert_eq!(p.len(), 6859);
        let names: Vec<&str> = p.attributes.iter().map(|a| a.name.as_str()).collect();
        assert_eq!(names, ["id", "density", "velocity"]);
        assert_eq!(p.require("velocity").unwrap().components, 3);
        for (path, n) in shared_data_files() {
            if path.extension().unwrap() != "bgeo" {
                continue;
            }
            let gz = std::fs::read(&path).unwrap();
            let name = path.file_name().unwrap().to_string_lossy();
            // cuts of the gzip stream, and of the plain bgeo inside it
            assert_truncations_fail(&gz, "bgeo", &name, n);
            let mut plain = Vec::new();
            std::io::Read::read_to_end(&mut flate2::read::GzDecoder::new(&gz[..]), &mut plain)
                .unwrap();
            assert_truncations_fail(&plain, "bgeo", &name, n);
            assert_no_cut_panics(&plain, "bgeo", &name);
            let e =
                read_particles_from_bytes(&plain[..plain.len() / 2], "bgeo", &name).unwrap_err();
            assert!(
                e.to_string()
                    .contains(&format!("truncated: the header declares {n} points")),
                "{e}"
            );
        }
    }

    #[test]
    fn absurd_counts_and_wrong_magic() {
        let mut b = sample(2);
        b[9..13].copy_from_slice(&i32::MAX.to_be_bytes());
        let e = read(&b, "big.bgeo").unwrap_err().to_string();
        assert!(e.contains("declares 2147483647 points"), "{e}");
        b[9..13].copy_from_slice(&(-5i32).to_be_bytes());
        assert!(read(&b, "neg.bgeo")
            .unwrap_err()
            .to_string()
            .contains("negative"));
        let e = read(b"PGEOV....", "x.bgeo").unwrap_err().to_string();
        assert!(e.contains("not a Houdini .bgeo"), "{e}");
        let e = read(b"\x7fNSJb...", "j.bgeo").unwrap_err().to_string();
        assert!(e.contains("JSON"), "{e}");
    }
}
