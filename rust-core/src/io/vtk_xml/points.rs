//! The `.vtp` writer for oriented point samples: Verts, Normals, Radius and every array.

use super::write::{xml_escape, Chunked};
use crate::samples::PointSamples;
use std::io::Write;

/// Writes `samples` as VTK XML PolyData with one vertex cell per point (raw appended):
/// Points Float64, PointData Normals (Float32, marked as the normals), Radius (Float64)
/// and every attribute (Float64). ParaView shows it as point gaussians scaled by Radius.
pub(crate) fn write_points(w: &mut dyn Write, samples: &PointSamples) -> std::io::Result<()> {
    let n = samples.len();
    let mut point_arrays: Vec<(&str, &str, usize, usize)> = vec![
        ("Normals", "Float32", 3, n * 12),
        ("Radius", "Float64", 1, n * 8),
    ];
    for a in &samples.attributes {
        point_arrays.push((&a.name, "Float64", a.components, a.data.len() * 8));
    }
    let mut offset = 0usize;
    let mut next_offset = |len: usize| {
        let at = offset;
        offset += 8 + len;
        at
    };
    writeln!(w, "<?xml version=\"1.0\"?>")?;
    writeln!(
        w,
        "<VTKFile type=\"PolyData\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">"
    )?;
    writeln!(w, "  <PolyData>")?;
    writeln!(
        w,
        "    <Piece NumberOfPoints=\"{n}\" NumberOfVerts=\"{n}\" NumberOfLines=\"0\" NumberOfStrips=\"0\" NumberOfPolys=\"0\">"
    )?;
    writeln!(
        w,
        "      <PointData Normals=\"Normals\" Scalars=\"Radius\">"
    )?;
    for &(name, ty, comps, len) in &point_arrays {
        writeln!(
            w,
            "        <DataArray type=\"{ty}\" Name=\"{}\" NumberOfComponents=\"{comps}\" format=\"appended\" offset=\"{}\"/>",
            xml_escape(name),
            next_offset(len)
        )?;
    }
    writeln!(w, "      </PointData>")?;
    writeln!(w, "      <Points>")?;
    writeln!(
        w,
        "        <DataArray type=\"Float64\" Name=\"Points\" NumberOfComponents=\"3\" format=\"appended\" offset=\"{}\"/>",
        next_offset(n * 24)
    )?;
    writeln!(w, "      </Points>")?;
    writeln!(w, "      <Verts>")?;
    for name in ["connectivity", "offsets"] {
        writeln!(
            w,
            "        <DataArray type=\"Int64\" Name=\"{name}\" format=\"appended\" offset=\"{}\"/>",
            next_offset(n * 8)
        )?;
    }
    writeln!(w, "      </Verts>")?;
    writeln!(w, "    </Piece>")?;
    writeln!(w, "  </PolyData>")?;
    writeln!(w, "  <AppendedData encoding=\"raw\">")?;
    w.write_all(b"   _")?;
    let mut out = Chunked::new(w);
    out.bytes(&((n * 12) as u64).to_le_bytes())?;
    for v in samples.normals.iter().flatten() {
        out.bytes(&v.to_le_bytes())?;
    }
    let mut f64s = |values: &mut dyn Iterator<Item = f64>, len: usize| -> std::io::Result<()> {
        out.bytes(&((len * 8) as u64).to_le_bytes())?;
        for v in values {
            out.bytes(&v.to_le_bytes())?;
        }
        Ok(())
    };
    f64s(&mut samples.radii.iter().copied(), n)?;
    for a in &samples.attributes {
        f64s(&mut a.data.iter().copied(), a.data.len())?;
    }
    f64s(&mut samples.positions.iter().flatten().copied(), 3 * n)?;
    out.bytes(&((n * 8) as u64).to_le_bytes())?;
    for k in 0..n {
        out.bytes(&(k as i64).to_le_bytes())?;
    }
    out.bytes(&((n * 8) as u64).to_le_bytes())?;
    for k in 1..=n {
        out.bytes(&(k as i64).to_le_bytes())?;
    }
    out.flush()?;
    w.write_all(b"\n  </AppendedData>\n</VTKFile>\n")
}
