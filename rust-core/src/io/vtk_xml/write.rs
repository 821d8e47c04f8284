//! The `.vtp` mesh writer.

use crate::mesh::Mesh;
use std::borrow::Cow;
use std::io::Write;

/// Writes `mesh` as VTK XML PolyData with raw appended data: Points Float64, Polys as Int64
/// connectivity/offsets, Normals Float32 and every attribute Float64. Raw appended keeps the
/// file compact and the write a straight copy of the arrays; VTK and ParaView read it.
pub(crate) fn write_mesh(w: &mut dyn Write, mesh: &Mesh) -> std::io::Result<()> {
    let n = mesh.positions.len();
    let m = mesh.triangles.len();
    // (name, type, components, byte length) in the order the data is appended.
    let mut point_arrays: Vec<(&str, &str, usize, usize)> = Vec::new();
    if !mesh.normals.is_empty() {
        point_arrays.push(("Normals", "Float32", 3, n * 12));
    }
    for a in &mesh.attributes {
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
        "    <Piece NumberOfPoints=\"{n}\" NumberOfVerts=\"0\" NumberOfLines=\"0\" NumberOfStrips=\"0\" NumberOfPolys=\"{m}\">"
    )?;
    if mesh.normals.is_empty() {
        writeln!(w, "      <PointData>")?;
    } else {
        writeln!(w, "      <PointData Normals=\"Normals\">")?;
    }
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
    writeln!(w, "      <Polys>")?;
    writeln!(
        w,
        "        <DataArray type=\"Int64\" Name=\"connectivity\" format=\"appended\" offset=\"{}\"/>",
        next_offset(m * 24)
    )?;
    writeln!(
        w,
        "        <DataArray type=\"Int64\" Name=\"offsets\" format=\"appended\" offset=\"{}\"/>",
        next_offset(m * 8)
    )?;
    writeln!(w, "      </Polys>")?;
    writeln!(w, "    </Piece>")?;
    writeln!(w, "  </PolyData>")?;
    writeln!(w, "  <AppendedData encoding=\"raw\">")?;
    w.write_all(b"   _")?;

    let mut out = Chunked::new(w);
    if !mesh.normals.is_empty() {
        out.bytes(&((n * 12) as u64).to_le_bytes())?;
        for v in mesh.normals.iter().flatten() {
            out.bytes(&v.to_le_bytes())?;
        }
    }
    for a in &mesh.attributes {
        out.bytes(&((a.data.len() * 8) as u64).to_le_bytes())?;
        for v in &a.data {
            out.bytes(&v.to_le_bytes())?;
        }
    }
    out.bytes(&((n * 24) as u64).to_le_bytes())?;
    for v in mesh.positions.iter().flatten() {
        out.bytes(&v.to_le_bytes())?;
    }
    out.bytes(&((m * 24) as u64).to_le_bytes())?;
    for &i in mesh.triangles.iter().flatten() {
        out.bytes(&(i as i64).to_le_bytes())?;
    }
    out.bytes(&((m * 8) as u64).to_le_bytes())?;
    for k in 1..=m {
        out.bytes(&((3 * k) as i64).to_le_bytes())?;
    }
    out.flush()?;
    w.write_all(b"\n  </AppendedData>\n</VTKFile>\n")
}

/// Gathers small little-endian values into 64 KiB writes.
pub(super) struct Chunked<'w> {
    w: &'w mut dyn Write,
    buf: Vec<u8>,
}

impl<'w> Chunked<'w> {
    pub(super) fn new(w: &'w mut dyn Write) -> Self {
        Chunked {
            w,
            buf: Vec::with_capacity(1 << 16),
        }
    }

    pub(super) fn bytes(&mut self, b: &[u8]) -> std::io::Result<()> {
        if self.buf.len() + b.len() > self.buf.capacity() {
            self.flush()?;
        }
        self.buf.extend_from_slice(b);
        Ok(())
    }

    pub(super) fn flush(&mut self) -> std::io::Result<()> {
        self.w.write_all(&self.buf)?;
        self.buf.clear();
        Ok(())
    }
}

pub(super) fn xml_escape(s: &str) -> Cow<'_, str> {
    if !s.contains(['&', '<', '>', '"', '\'']) {
        return Cow::Borrowed(s);
    }
    let mut out = String::with_capacity(s.len() + 8);
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            c => out.push(c),
        }
    }
    Cow::Owned(out)
}
