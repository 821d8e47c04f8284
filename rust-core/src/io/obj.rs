//! Wavefront OBJ meshes: `v`, `vn` and `f` lines. OBJ has no per-vertex attributes, so a
//! mesh's attributes are not written.

use super::numeric::show;
use crate::error::{Error, Result};
use crate::mesh::Mesh;
use std::io::Write;

/// Writes `v` lines (f64 shortest round-trip text), `vn` lines when the mesh has normals,
/// and `f` lines with 1-based indices (`a//a` when there are normals).
pub(crate) fn write_mesh(w: &mut dyn Write, mesh: &Mesh) -> std::io::Result<()> {
    writeln!(
        w,
        "# written by isobar: {} vertices, {} triangles",
        mesh.positions.len(),
        mesh.triangles.len()
    )?;
    for [x, y, z] in &mesh.positions {
        writeln!(w, "v {x} {y} {z}")?;
    }
    for [x, y, z] in &mesh.normals {
        writeln!(w, "vn {x} {y} {z}")?;
    }
    let with_normals = !mesh.normals.is_empty();
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| i as u64 + 1);
        if with_normals {
            writeln!(w, "f {a}//{a} {b}//{b} {c}//{c}")?;
        } else {
            writeln!(w, "f {a} {b} {c}")?;
        }
    }
    Ok(())
}

/// Reads `v`, `vn` and `f` lines (polygons become triangle fans; negative indices count from
/// the end; texture indices are ignored). Normals are kept when there is one per vertex and
/// faces pair each vertex with the normal of the same index, as [`write_mesh`] writes them.
pub(crate) fn read_mesh(bytes: &[u8], name: &str) -> Result<Mesh> {
    let text = String::from_utf8_lossy(bytes);
    let mut mesh = Mesh::default();
    let mut normals: Vec<[f32; 3]> = Vec::new();
    let mut normals_match = true;
    for (line_no, line) in text.lines().enumerate() {
        let err = |m: String| Error::format(name, format!("line {}: {m}", line_no + 1));
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => {
                let c = coords(&mut words)
                    .ok_or_else(|| err(format!("bad vertex '{}'", show(line.as_bytes()))))?;
                mesh.positions.push(c);
            }
            Some("vn") => {
                let c = coords(&mut words)
                    .ok_or_else(|| err(format!("bad normal '{}'", show(line.as_bytes()))))?;
                normals.push(c.map(|v| v as f32));
            }
            Some("f") => {
                let mut poly = Vec::new();
                for corner in words {
                    let mut parts = corner.split('/');
                    let v = resolve(parts.next(), mesh.positions.len()).ok_or_else(|| {
                        err(format!("bad face corner '{}'", show(corner.as_bytes())))
                    })?;
                    let vn = parts.nth(1).filter(|s| !s.is_empty());
                    if resolve(vn, normals.len()) != Some(v) {
                        normals_match = false;
                    }
                    poly.push(v);
                }
                for j in 1..poly.len().saturating_sub(1) {
                    mesh.triangles.push([poly[0], poly[j], poly[j + 1]]);
                }
            }
            _ => {}
        }
    }
    if normals_match && normals.len() == mesh.positions.len() {
        mesh.normals = normals;
    }
    Ok(mesh)
}

fn coords<'a>(words: &mut impl Iterator<Item = &'a str>) -> Option<[f64; 3]> {
    let mut c = [0.0; 3];
    for v in &mut c {
        *v = words.next()?.parse().ok()?;
    }
    Some(c)
}

/// A 1-based (or negative, from the end) OBJ index into `len` items, as 0-based.
fn resolve(index: Option<&str>, len: usize) -> Option<u32> {
    let i: i64 = index?.parse().ok()?;
    let zero_based = if i < 0 { len as i64 + i } else { i - 1 };
    (0..len as i64)
        .contains(&zero_based)
        .then_some(zero_based as u32)
}

#[cfg(test)]
mod tests {
    use super::super::test_support::*;
    use super::super::{read_mesh as read_file, write_mesh as write_file};

    #[test]
    fn written_obj_has_one_line_per_item_and_reads_back() {
        let dir = scratch_dir("obj");
        let path = dir.join("m.obj");
        let mesh = sample_mesh();
        write_file(&path, &mesh).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        let count = |p: &str| text.lines().filter(|l| l.starts_with(p)).count();
        assert_eq!(count("v "), 4);
        assert_eq!(count("vn "), 4);
        assert_eq!(count("f "), 4);
        assert_eq!(text.lines().count(), 1 + 4 + 4 + 4);
        assert!(text.contains("f 1//1 3//3 2//2"), "{text}");
        let back = read_file(&path).unwrap();
        assert_eq!(
            back.positions, mesh.positions,
            "OBJ keeps f64 round-trip text"
        );
        assert_eq!(back.normals, mesh.normals);
        assert_eq!(back.triangles, mesh.triangles);
        assert!(back.attributes.is_empty());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn polygons_negative_indices_and_errors() {
        let m = super::read_mesh(
            b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1 -2/1 -1/1\n",
            "q.obj",
        )
        .unwrap();
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
        assert!(m.normals.is_empty());
        let e = super::read_mesh(b"v 0 0 0\nf 1 2 3\n", "bad.obj").unwrap_err();
        assert!(
            e.to_string()
                .contains("bad.obj: line 2: bad face corner '2'"),
            "{e}"
        );
    }
}
