//! PLY (Stanford polygon files): particles and meshes in, binary little-endian meshes out.
//!
//! One reader serves both uses: it parses the header, then reads the elements in order (a
//! binary element with lists can only be stepped over by reading its rows), keeping the
//! ones the caller needs.

use super::numeric::{byte_len, parse_number, show, Endian, Scalar, Tokens};
use crate::error::{Error, Result};
use crate::field::particles::{Attribute, ParticleData};
use crate::mesh::Mesh;
use std::io::Write;

/// Reads the `vertex` element: x, y, z become positions and every other scalar vertex
/// property becomes a scalar attribute of the same name (list properties are skipped).
pub(crate) fn read_particles(bytes: &[u8], name: &str) -> Result<ParticleData> {
    let ply = Ply::parse(bytes, name)?;
    let columns = ply.read_elements(&["vertex"])?.remove(0);
    let positions = xyz(&columns, "", name)?;
    let attributes = columns
        .into_iter()
        .filter(|c| c.starts.is_none() && !matches!(c.name.as_str(), "x" | "y" | "z"))
        .map(|c| Attribute::scalar(c.name, c.values))
        .collect();
    Ok(ParticleData {
        positions: positions.into_iter().map(glam::DVec3::from_array).collect(),
        attributes,
        ..Default::default()
    })
}

/// Reads a polygon mesh: vertex x/y/z, nx/ny/nz as normals, `name_x/_y/_z` triples as
/// 3-component attributes (as [`write_mesh`] writes them), other scalars as scalar attributes,
/// and the face `vertex_indices` lists split into triangle fans.
pub(crate) fn read_mesh(bytes: &[u8], name: &str) -> Result<Mesh> {
    let ply = Ply::parse(bytes, name)?;
    let has_faces = ply.elements.iter().any(|e| e.name == "face");
    let wanted: &[&str] = if has_faces {
        &["vertex", "face"]
    } else {
        &["vertex"]
    };
    let mut data = ply.read_elements(wanted)?;
    let faces = if has_faces { data.pop() } else { None };
    let vertices = data.remove(0);
    let positions = xyz(&vertices, "", name)?;
    let n = positions.len();
    let normals = match xyz(&vertices, "n", name) {
        Ok(normals) => normals.into_iter().map(|v| v.map(|c| c as f32)).collect(),
        Err(_) => Vec::new(),
    };

    let scalars: Vec<&Column> = vertices
        .iter()
        .filter(|c| c.starts.is_none())
        .filter(|c| !matches!(c.name.as_str(), "x" | "y" | "z"))
        .filter(|c| normals.is_empty() || !matches!(c.name.as_str(), "nx" | "ny" | "nz"))
        .collect();
    let find = |n: &str| scalars.iter().find(|c| c.name == n);
    let mut attributes = Vec::new();
    for c in &scalars {
        if let Some(base) = c.name.strip_suffix("_x") {
            if let (Some(y), Some(z)) = (find(&format!("{base}_y")), find(&format!("{base}_z"))) {
                let data = (0..n)
                    .flat_map(|i| [c.values[i], y.values[i], z.values[i]])
                    .collect();
                attributes.push(Attribute {
                    name: base.to_string(),
                    components: 3,
                    data,
                });
                continue;
            }
        }
        let is_vector_part = ["_y", "_z"].iter().any(|s| {
            c.name.strip_suffix(s).is_some_and(|base| {
                find(&format!("{base}_x")).is_some()
                    && find(&format!("{base}_y")).is_some()
                    && find(&format!("{base}_z")).is_some()
            })
        });
        if !is_vector_part {
            attributes.push(Attribute::scalar(c.name.clone(), c.values.clone()));
        }
    }

    let mut triangles = Vec::new();
    if let Some(faces) = faces {
        let list = faces
            .iter()
            .find(|c| {
                c.starts.is_some() && matches!(c.name.as_str(), "vertex_indices" | "vertex_index")
            })
            .ok_or_else(|| Error::format(name, "the face element has no vertex_indices list"))?;
        let starts = list.starts.as_deref().unwrap_or(&[]);
        for (f, w) in starts.windows(2).enumerate() {
            let poly = &list.values[w[0]..w[1]];
            let index = |v: f64| -> Result<u32> {
                if v >= 0.0 && (v as usize) < n && v.fract() == 0.0 {
                    Ok(v as u32)
                } else {
                    Err(Error::format(
                        name,
                        format!("face {f} refers to vertex {v}, but there are {n} vertices"),
                    ))
                }
            };
            for j in 1..poly.len().saturating_sub(1) {
                triangles.push([index(poly[0])?, index(poly[j])?, index(poly[j + 1])?]);
            }
        }
    }
    Ok(Mesh {
        positions,
        normals,
        triangles,
        attributes,
    })
}

/// Writes `mesh` as binary little-endian PLY: float x y z, nx ny nz when there are normals,
/// each attribute as float properties (`name`, or `name_x/_y/_z` for 3 components, or
/// `name_0..` otherwise), then faces as `uchar uint vertex_indices` lists.
pub(crate) fn write_mesh(w: &mut dyn Write, mesh: &Mesh) -> std::io::Result<()> {
    let n = mesh.positions.len();
    let has_normals = !mesh.normals.is_empty();
    writeln!(
        w,
        "ply\nformat binary_little_endian 1.0\ncomment written by isobar"
    )?;
    writeln!(w, "element vertex {n}")?;
    for c in ["x", "y", "z"] {
        writeln!(w, "property float {c}")?;
    }
    if has_normals {
        for c in ["nx", "ny", "nz"] {
            writeln!(w, "property float {c}")?;
        }
    }
    for a in &mesh.attributes {
        // A PLY header is whitespace-separated: a space in a name would break it.
        let base: String = a
            .name
            .chars()
            .map(|c| if c.is_whitespace() { '_' } else { c })
            .collect();
        match a.components {
            1 => writeln!(w, "property float {base}")?,
            3 => {
                for s in ["x", "y", "z"] {
                    writeln!(w, "property float {base}_{s}")?;
                }
            }
            k => {
                for i in 0..k {
                    writeln!(w, "property float {base}_{i}")?;
                }
            }
        }
    }
    writeln!(w, "element face {}", mesh.triangles.len())?;
    writeln!(w, "property list uchar uint vertex_indices\nend_header")?;

    let mut row = Vec::with_capacity(64);
    for i in 0..n {
        row.clear();
        let mut put = |v: f32| row.extend_from_slice(&v.to_le_bytes());
        mesh.positions[i].iter().for_each(|&c| put(c as f32));
        if has_normals {
            mesh.normals[i].iter().for_each(|&c| put(c));
        }
        for a in &mesh.attributes {
            a.item(i).iter().for_each(|&c| put(c as f32));
        }
        w.write_all(&row)?;
    }
    for t in &mesh.triangles {
        row.clear();
        row.push(3);
        for &i in t {
            row.extend_from_slice(&i.to_le_bytes());
        }
        w.write_all(&row)?;
    }
    Ok(())
}

/// The coordinates `{prefix}x, {prefix}y, {prefix}z` of every row.
fn xyz(columns: &[Column], prefix: &str, name: &str) -> Result<Vec<[f64; 3]>> {
    let get = |axis: &str| {
        let wanted = format!("{prefix}{axis}");
        columns
            .iter()
            .find(|c| c.starts.is_none() && c.name == wanted)
            .ok_or_else(|| {
                let have: Vec<&str> = columns.iter().map(|c| c.name.as_str()).collect();
                Error::format(
                    name,
                    format!(
                        "the vertex element has no '{wanted}' property (it has: {})",
                        have.join(", ")
                    ),
                )
            })
    };
    let (x, y, z) = (get("x")?, get("y")?, get("z")?);
    Ok(x.values
        .iter()
        .zip(&y.values)
        .zip(&z.values)
        .map(|((&x, &y), &z)| [x, y, z])
        .collect())
}

#[derive(Clone, Copy, Debug)]
enum Kind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Debug)]
struct Property {
    name: String,
    kind: Kind,
}

#[derive(Debug)]
struct Element {
    name: String,
    count: u64,
    properties: Vec<Property>,
}

/// One property's values over all rows of an element. For a list property `starts` holds
/// where each row's items begin in `values` (one more entry than rows).
struct Column {
    name: String,
    values: Vec<f64>,
    starts: Option<Vec<usize>>,
}

struct Ply<'a> {
    name: &'a str,
    bytes: &'a [u8],
    /// `None` for ASCII.
    binary: Option<Endian>,
    elements: Vec<Element>,
    body: usize,
}

impl<'a> Ply<'a> {
    fn err(&self, message: impl Into<String>) -> Error {
        Error::format(self.name, message)
    }

    fn parse(bytes: &'a [u8], name: &'a str) -> Result<Self> {
        let err = |m: String| Error::format(name, m);
        if !bytes.starts_with(b"ply") {
            return Err(err("not a PLY file (it does not start with 'ply')".into()));
        }
        let mut ply = Ply {
            name,
            bytes,
            binary: None,
            elements: Vec::new(),
            body: 0,
        };
        let mut pos = 0;
        let mut format_seen = false;
        loop {
            let rest = &bytes[pos..];
            let Some(end) = rest.iter().position(|&b| b == b'\n') else {
                return Err(err("truncated: the header has no end_header line".into()));
            };
            pos += end + 1;
            let line = String::from_utf8_lossy(&rest[..end]);
            let words: Vec<&str> = line.split_whitespace().collect();
            match words.first().copied() {
                Some("ply") | Some("comment") | Some("obj_info") | None => {}
                Some("format") => {
                    ply.binary = match words.get(1).copied() {
                        Some("ascii") => None,
                        Some("binary_little_endian") => Some(Endian::Little),
                        Some("binary_big_endian") => Some(Endian::Big),
                        other => {
                            return Err(err(format!(
                                "unknown PLY format '{}'",
                                show(other.unwrap_or("").as_bytes())
                            )))
                        }
                    };
                    format_seen = true;
                }
                Some("element") => {
                    let (Some(ename), Some(count)) = (
                        words.get(1),
                        words.get(2).and_then(|c| c.parse::<u64>().ok()),
                    ) else {
                        return Err(err(format!(
                            "malformed header line '{}'",
                            show(line.as_bytes())
                        )));
                    };
                    ply.elements.push(Element {
                        name: ename.to_string(),
                        count,
                        properties: Vec::new(),
                    });
                }
                Some("property") => {
                    let kind = match words.get(1).copied() {
                        Some("list") => Kind::List {
                            count: ply_type(words.get(2).copied(), &line, name)?,
                            item: ply_type(words.get(3).copied(), &line, name)?,
                        },
                        ty => Kind::Scalar(ply_type(ty, &line, name)?),
                    };
                    let pname = words.last().copied().unwrap_or("").to_string();
                    let Some(element) = ply.elements.last_mut() else {
                        return Err(err(format!(
                            "property before any element: '{}'",
                            show(line.as_bytes())
                        )));
                    };
                    element.properties.push(Property { name: pname, kind });
                }
                Some("end_header") => break,
                Some(other) => {
                    return Err(err(format!(
                        "unknown header keyword '{}'",
                        show(other.as_bytes())
                    )))
                }
            }
        }
        if !format_seen {
            return Err(err("the header has no format line".into()));
        }
        ply.body = pos;
        Ok(ply)
    }

    /// Reads every element in file order (the ones not wanted only to check that the file is
    /// complete); returns the columns of the wanted ones in the order asked.
    fn read_elements(&self, wanted: &[&str]) -> Result<Vec<Vec<Column>>> {
        let mut found: Vec<Option<Vec<Column>>> = wanted.iter().map(|_| None).collect();
        let mut pos = self.body;
        for element in &self.elements {
            let slot = wanted.iter().position(|w| *w == element.name);
            let keep = slot.is_some_and(|s| found[s].is_none());
            let columns = match self.binary {
                Some(endian) => self.binary_element(element, &mut pos, endian, keep)?,
                None => self.ascii_element(element, &mut pos, keep)?,
            };
            if let (true, Some(s)) = (keep, slot) {
                found[s] = Some(columns);
            }
        }
        found
            .into_iter()
            .zip(wanted)
            .map(|(f, w)| f.ok_or_else(|| self.err(format!("the file has no '{w}' element"))))
            .collect()
    }

    fn truncated(&self, element: &Element, rows: u64) -> Error {
        self.err(format!(
            "truncated: element '{}' declares {} rows but the file ends after {rows}",
            element.name, element.count
        ))
    }

    fn binary_element(
        &self,
        element: &Element,
        pos: &mut usize,
        endian: Endian,
        keep: bool,
    ) -> Result<Vec<Column>> {
        let remaining = self.bytes.len() - *pos;
        let fixed: Option<usize> = element
            .properties
            .iter()
            .map(|p| match p.kind {
                Kind::Scalar(t) => Some(t.size()),
                Kind::List { .. } => None,
            })
            .sum();
        if let Some(row) = fixed {
            // Fixed-size rows: check the whole block, then decode column by column.
            let need = byte_len(element.count, row as u64)
                .filter(|&n| n <= remaining)
                .ok_or_else(|| self.truncated(element, (remaining / row.max(1)) as u64))?;
            let block = &self.bytes[*pos..*pos + need];
            *pos += need;
            let count = element.count as usize;
            let mut columns = Vec::new();
            let mut offset = 0;
            for p in &element.properties {
                if let Kind::Scalar(t) = p.kind {
                    if keep {
                        columns.push(Column {
                            name: p.name.clone(),
                            values: t.decode_strided(block, count, row, offset, endian),
                            starts: None,
                        });
                    }
                    offset += t.size();
                }
            }
            return Ok(columns);
        }
        // Rows with lists: every row takes at least its scalars and list counts.
        let min_row: usize = element
            .properties
            .iter()
            .map(|p| match p.kind {
                Kind::Scalar(t) => t.size(),
                Kind::List { count, .. } => count.size(),
            })
            .sum();
        if byte_len(element.count, min_row as u64).is_none_or(|n| n > remaining) {
            return Err(self.truncated(element, (remaining / min_row.max(1)) as u64));
        }
        let count = element.count as usize;
        let mut columns = self.empty_columns(element, count, keep);
        for row in 0..count {
            for (p, column) in element.properties.iter().zip(columns.iter_mut()) {
                let short = || self.truncated(element, row as u64);
                match p.kind {
                    Kind::Scalar(t) => {
                        let b = self.bytes.get(*pos..*pos + t.size()).ok_or_else(short)?;
                        *pos += t.size();
                        if keep {
                            column.values.push(t.read_one(b, endian));
                        }
                    }
                    Kind::List { count: ct, item } => {
                        let b = self.bytes.get(*pos..*pos + ct.size()).ok_or_else(short)?;
                        *pos += ct.size();
                        let k = list_len(ct.read_one(b, endian)).ok_or_else(|| {
                            self.err(format!(
                                "element '{}' row {row}: invalid list length",
                                element.name
                            ))
                        })?;
                        let len = k.checked_mul(item.size()).ok_or_else(short)?;
                        let b = self.bytes.get(*pos..*pos + len).ok_or_else(short)?;
                        *pos += len;
                        if keep {
                            item.decode_into(b, endian, &mut column.values);
                            if let Some(s) = column.starts.as_mut() {
                                s.push(column.values.len());
                            }
                        }
                    }
                }
            }
        }
        Ok(if keep { columns } else { Vec::new() })
    }

    fn ascii_element(&self, element: &Element, pos: &mut usize, keep: bool) -> Result<Vec<Column>> {
        let remaining = self.bytes.len() - *pos;
        let props = element.properties.len().max(1) as u64;
        // Every ASCII value takes at least two bytes.
        if element.count.saturating_mul(props) > remaining as u64 / 2 + 1 {
            return Err(self.truncated(element, 0));
        }
        let count = element.count as usize;
        let mut columns = self.empty_columns(element, count, keep);
        let mut tokens = Tokens {
            bytes: self.bytes,
            pos: *pos,
        };
        let mut number = |row: usize| -> Result<f64> {
            let t = tokens
                .next_token()
                .ok_or_else(|| self.truncated(element, row as u64))?;
            parse_number(t).ok_or_else(|| {
                self.err(format!(
                    "element '{}' row {row}: '{}' is not a number",
                    element.name,
                    show(t)
                ))
            })
        };
        for row in 0..count {
            for (p, column) in element.properties.iter().zip(columns.iter_mut()) {
                match p.kind {
                    Kind::Scalar(ty) => {
                        let v = number(row)?;
                        if keep {
                            column.values.push(ty.narrow(v));
                        }
                    }
                    Kind::List { item, .. } => {
                        let k = list_len(number(row)?).ok_or_else(|| {
                            self.err(format!(
                                "element '{}' row {row}: invalid list length",
                                element.name
                            ))
                        })?;
                        for _ in 0..k {
                            let v = number(row)?;
                            if keep {
                                column.values.push(item.narrow(v));
                            }
                        }
                        if let Some(s) = column.starts.as_mut() {
                            s.push(column.values.len());
                        }
                    }
                }
            }
        }
        *pos = tokens.pos;
        Ok(if keep { columns } else { Vec::new() })
    }

    /// One column per property, reserved for `count` rows when kept (the caller has checked
    /// that `count` rows can fit in the file).
    fn empty_columns(&self, element: &Element, count: usize, keep: bool) -> Vec<Column> {
        element
            .properties
            .iter()
            .map(|p| Column {
                name: p.name.clone(),
                values: Vec::with_capacity(if keep { count } else { 0 }),
                starts: match p.kind {
                    Kind::List { .. } => Some(vec![0]),
                    Kind::Scalar(_) => None,
                },
            })
            .collect()
    }
}

/// A list length read as a number: must be a non-negative integer.
fn list_len(v: f64) -> Option<usize> {
    (v >= 0.0 && v.fract() == 0.0 && v < u32::MAX as f64).then_some(v as usize)
}

fn ply_type(word: Option<&str>, line: &str, name: &str) -> Result<Scalar> {
    Ok(match word.unwrap_or("") {
        "char" | "int8" => Scalar::I8,
        "uchar" | "uint8" => Scalar::U8,
        "short" | "int16" => Scalar::I16,
        "ushort" | "uint16" => Scalar::U16,
        "int" | "int32" => Scalar::I32,
        "uint" | "uint32" => Scalar::U32,
        "float" | "float32" => Scalar::F32,
        "double" | "float64" => Scalar::F64,
        other => {
            return Err(Error::format(
                name,
                format!(
                    "unknown PLY type '{}' in '{}'",
                    show(other.as_bytes()),
                    show(line.as_bytes())
                ),
            ))
        }
    })
}

#[cfg(test)]
mod tests {
    use super::super::read_particles_from_bytes;
    use super::super::test_support::*;
    use super::super::{read_mesh as read_file, write_mesh as write_file};
    use super::*;

    #[test]
    fn binary_round_trip_within_f32() {
        let dir = scratch_dir("ply");
        let path = dir.join("mesh.ply");
        let mesh = sample_mesh();
        write_file(&path, &mesh).unwrap();
        let back = read_file(&path).unwrap();
        assert_eq!(back.triangles, mesh.triangles);
        assert_eq!(back.normals, mesh.normals);
        for (a, b) in back.positions.iter().zip(&mesh.positions) {
            for k in 0..3 {
                assert!(
                    (a[k] - b[k]).abs() <= 1e-7 * b[k].abs().max(1.0),
                    "{a:?} {b:?}"
                );
            }
        }
        assert_eq!(back.attributes.len(), 2);
        for (a, b) in back.attributes.iter().zip(&mesh.attributes) {
            assert_eq!((&a.name, a.components), (&b.name, b.components));
            for (x, y) in a.data.iter().zip(&b.data) {
                assert!((x - y).abs() <= 1e-7 * y.abs().max(1.0));
            }
        }
        // Read as particles every vertex property is its own scalar.
        let p = super::super::read_particles(&path).unwrap();
        assert_eq!(p.len(), 4);
        let names: Vec<&str> = p.attributes.iter().map(|a| a.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "nx",
                "ny",
                "nz",
                "SumOfWeights",
                "velocity_x",
                "velocity_y",
                "velocity_z"
            ]
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn ascii_with_lists_other_elements_and_quads() {
        let f = "ply\nformat ascii 1.0\ncomment hi\nelement material 1\nproperty list uchar float c\n\
                 element vertex 4\nproperty double x\nproperty double y\nproperty double z\nproperty list uchar int tags\nproperty float rho\n\
                 element face 1\nproperty list uchar int vertex_index\nend_header\n\
                 3 0.1 0.2 0.3\n0 0 0 0 1000\n1 0 0 2 5 6 999\n1 1 0 0 998\n0 1 0 1 7 997\n4 0 1 2 3\n";
        let p = read_particles_from_bytes(f.as_bytes(), "ply", "a.ply").unwrap();
        assert_eq!(p.len(), 4);
        assert_eq!(p.attribute_names(), "rho");
        assert_eq!(
            p.require("rho").unwrap().data,
            vec![1000.0, 999.0, 998.0, 997.0]
        );
        let m = read_mesh(f.as_bytes(), "a.ply").unwrap();
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
    }

    #[test]
    fn binary_big_endian_with_mixed_types() {
        let mut f = b"ply\r\nformat binary_big_endian 1.0\r\nelement vertex 2\r\nproperty float x\r\nproperty float y\r\nproperty float z\r\nproperty ushort id\r\nproperty uchar flag\r\nend_header\r\n".to_vec();
        for (x, id, flag) in [(1.5f32, 300u16, 1u8), (-2.0, 7, 0)] {
            for v in [x, x * 2.0, x * 3.0] {
                f.extend_from_slice(&v.to_be_bytes());
            }
            f.extend_from_slice(&id.to_be_bytes());
            f.push(flag);
        }
        let p = read_particles_from_bytes(&f, "ply", "b.ply").unwrap();
        assert_eq!(p.positions[1].to_array(), [-2.0, -4.0, -6.0]);
        assert_eq!(p.require("id").unwrap().data, vec![300.0, 7.0]);
        assert_eq!(p.require("flag").unwrap().data, vec![1.0, 0.0]);
        assert_truncations_fail(&f, "ply", "b.ply", 2);
        assert_no_cut_panics(&f, "ply", "b.ply");
    }

    #[test]
    fn truncated_and_gigantic_files_fail_quickly() {
        let mut bytes = Vec::new();
        let mut mesh = sample_mesh();
        for _ in 0..5 {
            let m = mesh.clone();
            mesh.append(m);
        }
        write_mesh(&mut bytes, &mesh).unwrap();
        let n = mesh.positions.len();
        assert_truncations_fail(&bytes, "ply", "t.ply", n);
        assert_no_cut_panics(&bytes, "ply", "t.ply");
        let e = read_mesh(&bytes[..bytes.len() - 3], "t.ply")
            .unwrap_err()
            .to_string();
        assert!(e.contains("t.ply: truncated: element 'face'"), "{e}");

        let t = std::time::Instant::now();
        for format in ["ascii", "binary_little_endian"] {
            let f = format!("ply\nformat {format} 1.0\nelement vertex 1000000000000000\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n");
            let e = read_particles_from_bytes(f.as_bytes(), "ply", "g.ply")
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("element 'vertex' declares 1000000000000000 rows"),
                "{e}"
            );
            let f = format!("ply\nformat {format} 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nelement face 100000000000000\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n");
            assert!(read_mesh(f.as_bytes(), "g.ply").is_err());
        }
        let f = b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uint int vertex_indices\nend_header\n\0\0\0\0\0\0\0\0\0\0\0\0\xff\xff\xff\xf0";
        assert!(read_mesh(f, "l.ply").is_err());
        assert!(t.elapsed().as_secs_f64() < 1.0);
    }

    #[test]
    fn header_errors_are_named() {
        let e = read_particles_from_bytes(b"solid x\n", "ply", "s.ply").unwrap_err();
        assert!(e.to_string().contains("s.ply: not a PLY file"), "{e}");
        let e = read_particles_from_bytes(
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n1\n",
            "ply",
            "s.ply",
        )
        .unwrap_err();
        assert!(e.to_string().contains("no 'y' property (it has: x)"), "{e}");
        let e = read_particles_from_bytes(
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty half x\nend_header\n",
            "ply",
            "s.ply",
        )
        .unwrap_err();
        assert!(e.to_string().contains("unknown PLY type 'half'"), "{e}");
        let e =
            read_particles_from_bytes(b"ply\nformat ascii 1.0\nelement vertex 1\n", "ply", "s.ply")
                .unwrap_err();
        assert!(e.to_string().contains("no end_header"), "{e}");
    }
}
