//! NumPy arrays: `.npy` holding an (N, 3) position array, and `.npz` archives (stored or
//! deflated zip) holding positions plus per-particle arrays.
//!
//! An `.npy` file is a magic string, a version, a header length, a Python dict literal
//! (`{'descr': '<f8', 'fortran_order': False, 'shape': (N, 3), }`) and the raw data, in C
//! order or (for 1-D and 2-D arrays here) Fortran order.

use super::numeric::{byte_len, show, Endian, Scalar};
use crate::error::{Error, Result};
use crate::field::particles::{Attribute, ParticleData, Skipped};
use std::io::Read;

/// Names under which an `.npz` may store its (N, 3) positions, in order of preference.
const POSITION_NAMES: &[&str] = &["positions", "position", "points", "pos", "x"];

/// Reads an `.npy` file holding one (N, 3) array of positions.
pub(crate) fn read_npy(bytes: &[u8], name: &str) -> Result<ParticleData> {
    let array = Array::parse(bytes, name, None)?;
    Ok(ParticleData {
        positions: array.positions(name)?,
        ..Default::default()
    })
}

/// Reads an `.npy` file holding one 3-D array as a volume: shape (nz, ny, nx) in C order,
/// so x varies fastest (numpy's usual layout for `volume[z, y, x]`). Returns the node
/// counts (x, y, z), the stored element type, its byte order and the data bytes.
pub(crate) fn read_npy_volume<'a>(
    bytes: &'a [u8],
    name: &str,
) -> Result<([usize; 3], Scalar, Endian, &'a [u8])> {
    let array = Stored::parse(bytes, name, None)?;
    let [nz, ny, nx] = array.shape[..] else {
        return Err(Error::format(
            name,
            format!(
                "a volume must be a 3-D array (nz, ny, nx), this one has shape {}",
                shape_text(&array.shape)
            ),
        ));
    };
    // A 3-D array in Fortran order was refused by the parse.
    Ok((
        [nx as usize, ny as usize, nz as usize],
        array.ty,
        array.endian,
        array.data,
    ))
}

/// Reads an `.npz` archive: positions from the first of [`POSITION_NAMES`] present (or from
/// three (N,) arrays `x`, `y`, `z`), and every other array whose first dimension is N as an
/// attribute ((N,) scalar, (N, k) with k components). Other arrays are ignored.
pub(crate) fn read_npz(bytes: &[u8], name: &str) -> Result<ParticleData> {
    let mut zip = zip::ZipArchive::new(std::io::Cursor::new(bytes))
        .map_err(|e| Error::format(name, format!("not a readable .npz (zip) archive: {e}")))?;
    let mut arrays: Vec<(String, Result<Array>)> = Vec::new();
    for i in 0..zip.len() {
        let mut entry = zip
            .by_index(i)
            .map_err(|e| Error::format(name, format!("archive entry {i}: {e}")))?;
        let Some(key) = entry.name().strip_suffix(".npy").map(str::to_string) else {
            continue;
        };
        let declared = entry.size();
        if entry.compressed_size() > bytes.len() as u64 {
            return Err(Error::format(
                name,
                format!(
                    "truncated: array '{key}' claims more compressed bytes than the archive holds"
                ),
            ));
        }
        // Deflate expands at most about 1032:1; a larger declared size is a corrupt entry,
        // refused before reserving memory for it.
        let bound = super::inflate_bound(entry.compressed_size() as usize) as u64;
        if declared > bound {
            return Err(Error::format(
                name,
                format!(
                    "array '{key}' claims {declared} bytes from {} compressed (corrupt archive)",
                    entry.compressed_size()
                ),
            ));
        }
        // Reserve for a plausible ratio only; the vector grows if the data really is there.
        let reserve = declared.min(entry.compressed_size().saturating_mul(16));
        let mut data = Vec::with_capacity(reserve as usize);
        entry
            .by_ref()
            .take(declared)
            .read_to_end(&mut data)
            .map_err(|e| Error::format(name, format!("array '{key}': {e}")))?;
        if (data.len() as u64) < declared {
            return Err(Error::format(
                name,
                format!(
                    "truncated: array '{key}' holds {} of its {declared} bytes",
                    data.len()
                ),
            ));
        }
        // Read to the declared size, not to the end, so the zip reader's own CRC check
        // never runs: checked here (a flipped bit in an array must not pass as data).
        if crc32fast::hash(&data) != entry.crc32() {
            return Err(Error::format(
                name,
                format!("array '{key}' fails its CRC-32 check (corrupt archive)"),
            ));
        }
        let parsed = Array::parse(&data, name, Some(&key));
        arrays.push((key, parsed));
    }

    let is_vector = |k: &str| {
        arrays
            .iter()
            .any(|(n, a)| n == k && a.as_ref().is_ok_and(|a| a.shape.len() == 1))
    };
    // x, y, z as three (N,) arrays is a common way to save coordinates too.
    let split_xyz = ["x", "y", "z"].iter().all(|k| is_vector(k));
    let position_key = POSITION_NAMES
        .iter()
        .copied()
        .filter(|&k| !(k == "x" && split_xyz))
        .find(|&k| arrays.iter().any(|(n, _)| n == k));
    let positions = if let Some(key) = position_key {
        remove(&mut arrays, key, name)?.positions(name)?
    } else if split_xyz {
        let (x, y, z) = (
            remove(&mut arrays, "x", name)?,
            remove(&mut arrays, "y", name)?,
            remove(&mut arrays, "z", name)?,
        );
        if x.shape != y.shape || x.shape != z.shape {
            return Err(Error::format(
                name,
                format!(
                    "arrays 'x', 'y', 'z' have shapes {}, {}, {}; they must match",
                    shape_text(&x.shape),
                    shape_text(&y.shape),
                    shape_text(&z.shape)
                ),
            ));
        }
        (0..x.data.len())
            .map(|i| glam::DVec3::new(x.data[i], y.data[i], z.data[i]))
            .collect()
    } else {
        let present: Vec<String> = arrays
            .iter()
            .map(|(k, a)| match a {
                Ok(a) => format!("{k} {}", shape_text(&a.shape)),
                Err(_) => format!("{k} (unreadable)"),
            })
            .collect();
        return Err(Error::format(
            name,
            format!(
                "no positions: expected an (N, 3) array named {} (the archive has: {})",
                POSITION_NAMES.join(", "),
                if present.is_empty() {
                    "nothing".into()
                } else {
                    present.join(", ")
                }
            ),
        ));
    };

    let n = positions.len() as u64;
    let mut attributes = Vec::new();
    let mut skipped = Vec::new();
    for (key, array) in arrays {
        // Arrays of another length, rank or an unsupported dtype are not per-particle data
        // (an archive may hold a time step or a box too); they are kept aside by name.
        let array = match array {
            Ok(array) => array,
            Err(e) => {
                let why = match e {
                    Error::Format { message, .. } => message,
                    other => other.to_string(),
                };
                skipped.push(Skipped { name: key, why });
                continue;
            }
        };
        let components = match array.shape[..] {
            [m] if m == n => 1,
            [m, k] if m == n && k > 0 => k as usize,
            _ => {
                let why = format!("shape {} for {n} particles", shape_text(&array.shape));
                skipped.push(Skipped { name: key, why });
                continue;
            }
        };
        attributes.push(Attribute {
            name: key,
            components,
            data: array.data,
        });
    }
    Ok(ParticleData {
        positions,
        attributes,
        skipped,
    })
}

/// Takes the entry called `key` out of the list; its parse error, if it had one, is returned.
fn remove(arrays: &mut Vec<(String, Result<Array>)>, key: &str, name: &str) -> Result<Array> {
    match arrays.iter().position(|(n, _)| n == key) {
        Some(i) => arrays.remove(i).1,
        None => Err(Error::format(name, format!("no array '{key}'"))),
    }
}

fn shape_text(shape: &[u64]) -> String {
    match shape {
        [one] => format!("({one},)"),
        _ => format!(
            "({})",
            shape
                .iter()
                .map(u64::to_string)
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

/// One decoded array.
struct Array {
    shape: Vec<u64>,
    data: Vec<f64>,
    /// "array 'positions'" (in an .npz) or "the array" (an .npy), for messages.
    what: String,
}

/// One .npy's header and its data bytes, not yet decoded.
struct Stored<'a> {
    shape: Vec<u64>,
    ty: Scalar,
    endian: Endian,
    /// A 2-D array stored transposed.
    fortran: bool,
    data: &'a [u8],
}

impl<'a> Stored<'a> {
    /// Parses one .npy's header and finds its data; `key` is its name inside an .npz.
    fn parse(bytes: &'a [u8], name: &str, key: Option<&str>) -> Result<Stored<'a>> {
        let prefix = key.map(|k| format!("array '{k}': ")).unwrap_or_default();
        let err = |m: String| Error::format(name, format!("{prefix}{m}"));
        if !bytes.starts_with(b"\x93NUMPY") {
            return Err(err("not a .npy array (no \\x93NUMPY magic)".into()));
        }
        let (header_len, start): (usize, usize) = match bytes.get(6) {
            Some(1) if bytes.len() >= 10 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
            Some(2 | 3) if bytes.len() >= 12 => (
                u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
                12,
            ),
            Some(1..=3) => return Err(err("truncated header".into())),
            v => return Err(err(format!("unsupported .npy version {v:?}"))),
        };
        let header = bytes
            .get(start..start.saturating_add(header_len))
            .ok_or_else(|| err("truncated header".into()))?;
        let header = String::from_utf8_lossy(header);
        let descr = dict_value(&header, "descr")
            .ok_or_else(|| err(format!("no 'descr' in header {}", show(header.as_bytes()))))?;
        let fortran = dict_value(&header, "fortran_order")
            .ok_or_else(|| err("no 'fortran_order' in header".into()))?;
        let shape_text_raw =
            dict_value(&header, "shape").ok_or_else(|| err("no 'shape' in header".into()))?;
        let shape: Vec<u64> = shape_text_raw
            .trim_matches(|c| c == '(' || c == ')')
            .split(',')
            .map(str::trim)
            .filter(|s| !s.is_empty())
            .map(|s| s.trim_end_matches('L').parse::<u64>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|_| err(format!("bad shape {}", show(shape_text_raw.as_bytes()))))?;
        // numpy saves a transposed array (`np.vstack([x, y, z]).T`, the usual way to build
        // an (N, 3) array) in Fortran order; for 2-D that is just a transpose to undo.
        let fortran = fortran.starts_with("True") && shape.len() > 1;
        if fortran && shape.len() > 2 {
            return Err(err(format!(
                "shape {} is stored in Fortran order, which is supported for 1-D and 2-D arrays only; save a C-order array (numpy.ascontiguousarray)",
                shape_text(&shape)
            )));
        }
        let (ty, endian) = dtype(descr).ok_or_else(|| {
            err(format!(
                "unsupported dtype {} (supported: f4 f8 i1 i2 i4 i8 u1 u2 u4 u8 b1, either byte order)",
                show(descr.as_bytes())
            ))
        })?;
        let count = shape.iter().try_fold(1u64, |acc, &d| acc.checked_mul(d));
        let data = &bytes[start + header_len..];
        let need = count
            .and_then(|c| byte_len(c, ty.size() as u64))
            .filter(|&n| n <= data.len())
            .ok_or_else(|| {
                err(format!(
                    "truncated: shape {} needs {} bytes of {} data but the file holds {}",
                    shape_text(&shape),
                    count.map_or("too many".to_string(), |c| c
                        .saturating_mul(ty.size() as u64)
                        .to_string()),
                    descr.trim_matches('\''),
                    data.len()
                ))
            })?;
        Ok(Stored {
            shape,
            ty,
            endian,
            fortran,
            data: &data[..need],
        })
    }
}

impl Array {
    /// Parses and decodes one .npy; `key` is its name inside an .npz.
    fn parse(bytes: &[u8], name: &str, key: Option<&str>) -> Result<Array> {
        let stored = Stored::parse(bytes, name, key)?;
        let mut values = stored.ty.decode(stored.data, stored.endian);
        if stored.fortran {
            let [rows, columns] = [stored.shape[0], stored.shape[1]].map(|d| d as usize);
            values = transpose(&values, columns, rows);
        }
        Ok(Array {
            shape: stored.shape,
            data: values,
            what: key.map_or("the array".into(), |k| format!("array '{k}'")),
        })
    }

    /// The array as positions: it must be (N, 3).
    fn positions(&self, name: &str) -> Result<Vec<glam::DVec3>> {
        if !matches!(self.shape[..], [_, 3]) {
            return Err(Error::format(
                name,
                format!(
                    "{} has shape {}, expected (N, 3)",
                    self.what,
                    shape_text(&self.shape)
                ),
            ));
        }
        Ok(super::positions_from_flat(&self.data))
    }
}

/// The transpose of `data`, a row-major `rows` × `cols` matrix, as a row-major `cols` × `rows`
/// matrix (the caller has checked that `data` holds rows × cols values).
fn transpose(data: &[f64], rows: usize, cols: usize) -> Vec<f64> {
    let mut out = Vec::with_capacity(data.len());
    for j in 0..cols {
        out.extend((0..rows).map(|i| data[i * cols + j]));
    }
    out
}

/// The raw text of `key`'s value in the header's dict literal (a quoted string, a bool, or a
/// parenthesised tuple).
fn dict_value<'h>(header: &'h str, key: &str) -> Option<&'h str> {
    let at = header
        .find(&format!("'{key}'"))
        .or_else(|| header.find(&format!("\"{key}\"")))?;
    let rest = header[at + key.len() + 2..]
        .trim_start()
        .strip_prefix(':')?
        .trim_start();
    let end = match rest.chars().next()? {
        '(' => rest.find(')')? + 1,
        q @ ('\'' | '"') => rest[1..].find(q)? + 2,
        _ => rest.find([',', '}']).unwrap_or(rest.len()),
    };
    Some(rest[..end].trim())
}

/// A numpy `descr` such as `'<f8'`, `'>i4'` or `'|u1'`.
fn dtype(descr: &str) -> Option<(Scalar, Endian)> {
    let d = descr.trim_matches(|c| c == '\'' || c == '"');
    let (order, code) = match d.as_bytes().first()? {
        b'<' | b'|' | b'=' => (Endian::Little, &d[1..]),
        b'>' => (Endian::Big, &d[1..]),
        _ => (Endian::Little, d),
    };
    let ty = match code {
        "f4" => Scalar::F32,
        "f8" => Scalar::F64,
        "i1" => Scalar::I8,
        "u1" | "b1" => Scalar::U8,
        "i2" => Scalar::I16,
        "u2" => Scalar::U16,
        "i4" => Scalar::I32,
        "u4" => Scalar::U32,
        "i8" => Scalar::I64,
        "u8" => Scalar::U64,
        _ => return None,
    };
    Some((ty, order))
}

#[cfg(test)]
pub(crate) mod tests {
    use super::super::read_particles_from_bytes;
    use super::super::test_support::{assert_no_cut_panics, assert_truncations_fail};
    use std::io::Write;

    /// An .npy file, written by hand as numpy would (header padded to a multiple of 64).
    pub(crate) fn npy(descr: &str, shape: &str, fortran: bool, data: &[u8]) -> Vec<u8> {
        let mut header = format!(
            "{{'descr': '{descr}', 'fortran_order': {}, 'shape': {shape}, }}",
            if fortran { "True" } else { "False" }
        );
        while (10 + header.len() + 1) % 64 != 0 {
            header.push(' ');
        }
        header.push('\n');
        let mut out = b"\x93NUMPY\x01\x00".to_vec();
        out.extend_from_slice(&(header.len() as u16).to_le_bytes());
        out.extend_from_slice(header.as_bytes());
        out.extend_from_slice(data);
        out
    }

    fn f8(values: &[f64]) -> Vec<u8> {
        values.iter().flat_map(|v| v.to_le_bytes()).collect()
    }

    /// An .npz archive of named .npy entries.
    pub(crate) fn npz(entries: &[(&str, Vec<u8>)], deflate: bool) -> Vec<u8> {
        let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
        let method = if deflate {
            zip::CompressionMethod::Deflated
        } else {
            zip::CompressionMethod::Stored
        };
        let options = zip::write::SimpleFileOptions::default().compression_method(method);
        for (name, bytes) in entries {
            zip.start_file(format!("{name}.npy"), options).unwrap();
            zip.write_all(bytes).unwrap();
        }
        zip.finish().unwrap().into_inner()
    }

    fn sample_npz(deflate: bool) -> Vec<u8> {
        let pos = f8(&[0.0, 0.0, 0.0, 1.0, 2.0, 3.0]);
        let vel: Vec<u8> = [1.0f32, 2.0, 3.0, 4.0, 5.0, 6.0]
            .iter()
            .flat_map(|v| v.to_be_bytes())
            .collect();
        let mass: Vec<u8> = [7i32, 8].iter().flat_map(|v| v.to_le_bytes()).collect();
        npz(
            &[
                ("velocity", npy(">f4", "(2, 3)", false, &vel)),
                ("positions", npy("<f8", "(2, 3)", false, &pos)),
                ("mass", npy("<i4", "(2,)", false, &mass)),
                ("flags", npy("|u1", "(2, 2)", false, &[1, 0, 0, 1])),
                ("time", npy("<f8", "()", false, &f8(&[0.5]))),
                ("grid", npy("<f8", "(2, 2, 2)", false, &f8(&[0.0; 8]))),
                ("names", npy("<U3", "(2,)", false, &[0; 24])),
            ],
            deflate,
        )
    }

    /// A flipped bit inside a stored array is a CRC failure naming the array, not
    /// particles at altered positions.
    #[test]
    fn npz_arrays_are_checked_against_their_crc() {
        let mut bytes = sample_npz(false);
        let three = 3.0f64.to_le_bytes();
        let at = bytes.windows(8).position(|w| w == three).unwrap();
        bytes[at + 6] ^= 0x01; // 3.0 -> 3.0000000000000004-ish
        let e = read_particles_from_bytes(&bytes, "npz", "s.npz").unwrap_err();
        assert!(
            e.to_string().contains("'positions' fails its CRC-32"),
            "{e}"
        );
    }

    #[test]
    fn npz_positions_and_attributes_stored_and_deflated() {
        for deflate in [false, true] {
            let p = read_particles_from_bytes(&sample_npz(deflate), "npz", "s.npz").unwrap();
            assert_eq!(p.positions[1].to_array(), [1.0, 2.0, 3.0]);
            let names: Vec<&str> = p.attributes.iter().map(|a| a.name.as_str()).collect();
            assert_eq!(names, ["velocity", "mass", "flags"]);
            assert_eq!(p.require("velocity").unwrap().item(1), &[4.0, 5.0, 6.0]);
            assert_eq!(p.require("mass").unwrap().data, vec![7.0, 8.0]);
            assert_eq!(p.require("flags").unwrap().components, 2);
        }
    }

    /// Arrays that are not per-particle data are left out, and asking for one says why.
    #[test]
    fn arrays_left_out_say_why_when_asked_for() {
        let p = read_particles_from_bytes(&sample_npz(true), "npz", "s.npz").unwrap();
        let why = |name: &str| p.require(name).unwrap_err().to_string();
        assert!(why("time").contains("'time' is not per-particle data: shape () for 2 particles"));
        assert!(why("grid").contains("shape (2, 2, 2) for 2 particles"));
        let names = why("names");
        assert!(names.contains("unsupported dtype '<U3'"), "{names}");
        assert!(
            names.contains("usable arrays: velocity, mass, flags"),
            "{names}"
        );
        let absent = why("pressure");
        assert!(absent.contains("no array named 'pressure'"), "{absent}");
    }

    #[test]
    fn all_dtypes_decode() {
        let cases: Vec<(&str, Vec<u8>)> = vec![
            (
                "<f4",
                [1.5f32, -2.0, 3.0]
                    .iter()
                    .flat_map(|v| v.to_le_bytes())
                    .collect(),
            ),
            (
                ">f8",
                [1.5f64, -2.0, 3.0]
                    .iter()
                    .flat_map(|v| v.to_be_bytes())
                    .collect(),
            ),
            (
                "<i2",
                [1i16, -2, 3].iter().flat_map(|v| v.to_le_bytes()).collect(),
            ),
            (
                ">u2",
                [1u16, 2, 3].iter().flat_map(|v| v.to_be_bytes()).collect(),
            ),
            (
                "<i8",
                [1i64, -2, 3].iter().flat_map(|v| v.to_le_bytes()).collect(),
            ),
            (
                "<u8",
                [1u64, 2, 3].iter().flat_map(|v| v.to_le_bytes()).collect(),
            ),
            (
                "<u4",
                [1u32, 2, 3].iter().flat_map(|v| v.to_le_bytes()).collect(),
            ),
            (
                ">i4",
                [1i32, -2, 3].iter().flat_map(|v| v.to_be_bytes()).collect(),
            ),
            ("|u1", vec![1, 2, 3]),
            ("|i1", vec![1, 0xfe, 3]),
        ];
        for (descr, data) in cases {
            let p = read_particles_from_bytes(&npy(descr, "(1, 3)", false, &data), "npy", "d.npy")
                .unwrap_or_else(|e| panic!("{descr}: {e}"));
            let x = p.positions[0].to_array();
            assert_eq!(
                x[0],
                1.0 + if descr.contains('f') { 0.5 } else { 0.0 },
                "{descr}"
            );
            assert_eq!(x[1].abs(), 2.0, "{descr}");
            assert_eq!(x[2], 3.0, "{descr}");
        }
    }

    #[test]
    fn fortran_order_2d_arrays_are_transposed() {
        // [[1, 2, 3], [4, 5, 6]] stored column by column
        let f = npy("<f8", "(2, 3)", true, &f8(&[1.0, 4.0, 2.0, 5.0, 3.0, 6.0]));
        let p = read_particles_from_bytes(&f, "npy", "f.npy").unwrap();
        assert_eq!(p.positions[0].to_array(), [1.0, 2.0, 3.0]);
        assert_eq!(p.positions[1].to_array(), [4.0, 5.0, 6.0]);
        let v = npy(
            "<f4",
            "(2, 2)",
            true,
            &[1.0f32, 3.0, 2.0, 4.0]
                .iter()
                .flat_map(|v| v.to_le_bytes())
                .collect::<Vec<u8>>(),
        );
        let z = npz(&[("positions", f), ("v", v)], true);
        let p = read_particles_from_bytes(&z, "npz", "f.npz").unwrap();
        assert_eq!(p.require("v").unwrap().data, vec![1.0, 2.0, 3.0, 4.0]);
    }

    #[test]
    fn npz_with_split_coordinates() {
        let z = npz(
            &[
                ("x", npy("<f8", "(2,)", false, &f8(&[1.0, 2.0]))),
                ("y", npy("<f8", "(2,)", false, &f8(&[3.0, 4.0]))),
                ("z", npy("<f8", "(2,)", false, &f8(&[5.0, 6.0]))),
                ("rho", npy("<f8", "(2,)", false, &f8(&[9.0, 9.0]))),
            ],
            true,
        );
        let p = read_particles_from_bytes(&z, "npz", "xyz.npz").unwrap();
        assert_eq!(p.positions[1].to_array(), [2.0, 4.0, 6.0]);
        assert_eq!(p.attribute_names(), "rho");
    }

    #[test]
    fn clear_errors() {
        let bad = npz(
            &[("positions", npy("<f8", "(10, 2)", false, &f8(&[0.0; 20])))],
            false,
        );
        let e = read_particles_from_bytes(&bad, "npz", "x.npz")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("x.npz: array 'positions' has shape (10, 2), expected (N, 3)"),
            "{e}"
        );
        let f = npy("<f8", "(2, 3, 1)", true, &f8(&[0.0; 6]));
        let e = read_particles_from_bytes(&npz(&[("p", f.clone())], false), "npz", "f.npz");
        assert!(e.is_err(), "a 3-D array is no position array");
        let p = super::Array::parse(&f, "f.npy", None)
            .err()
            .unwrap()
            .to_string();
        assert!(
            p.starts_with("f.npy: shape (2, 3, 1) is stored in Fortran order"),
            "{p}"
        );
        assert!(p.contains("Fortran order"), "{p}");
        let f = npy("<f2", "(1, 3)", false, &[0; 6]);
        let e = read_particles_from_bytes(&f, "npy", "h.npy")
            .unwrap_err()
            .to_string();
        assert!(e.contains("unsupported dtype '<f2'"), "{e}");
        let none = npz(&[("other", npy("<f8", "(1,)", false, &f8(&[0.0])))], false);
        let e = read_particles_from_bytes(&none, "npz", "n.npz")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("no positions") && e.contains("other (1,)"),
            "{e}"
        );
        let e = read_particles_from_bytes(b"PK\x03\x04garbage", "npz", "g.npz").unwrap_err();
        assert!(e.to_string().starts_with("g.npz: "), "{e}");
    }

    #[test]
    fn gigantic_shape_is_refused_quickly() {
        let t = std::time::Instant::now();
        let f = npy("<f8", "(1000000000000000, 3)", false, &f8(&[0.0; 6]));
        let e = read_particles_from_bytes(&f, "npy", "g.npy")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("truncated: shape (1000000000000000, 3) needs 24000000000000000 bytes"),
            "{e}"
        );
        let f = npy("<f8", "(18446744073709551615, 3)", false, &[]);
        assert!(read_particles_from_bytes(&f, "npy", "g.npy").is_err());
        let z = npz(&[("positions", f)], true);
        assert!(read_particles_from_bytes(&z, "npz", "g.npz").is_err());
        assert!(t.elapsed().as_secs_f64() < 1.0);
    }

    #[test]
    fn truncations_fail_cleanly() {
        let f = npy("<f8", "(40, 3)", false, &f8(&[0.25; 120]));
        assert_truncations_fail(&f, "npy", "t.npy", 40);
        assert_no_cut_panics(&f, "npy", "t.npy");
        for deflate in [false, true] {
            let z = sample_npz(deflate);
            assert_truncations_fail(&z, "npz", "t.npz", 2);
            assert_no_cut_panics(&z, "npz", "t.npz");
        }
    }
}
