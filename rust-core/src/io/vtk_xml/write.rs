//! The `.vtp` mesh writer.

use crate::mesh::Mesh;
use std::borrow::Cow;
use std::io::Write;

/// Writes `mesh` as VTK XML PolyData with raw appended data: Points Float64, Polys as Int64
/// connectivity/offsets, Normals Float32 and every attribute Float64. Raw appended keeps the
/// file compact and the write a straight copy of the arrays; VTK and ParaView read it.
pub(crate) fn write_mesh(w: &mut dyn Write, mesh: &Mesh) -> std::io::Result<()> {
    let m = mesh.triangles.len();
    let mut point_data = Vec::new();
    if !mesh.normals.is_empty() {
        point_data.push(Array::new(
            "Normals",
            3,
            Values::F32(mesh.normals.as_flattened()),
        ));
    }
    for a in &mesh.attributes {
        point_data.push(Array::new(&a.name, a.components, Values::F64(&a.data)));
    }
    let triangles = mesh.triangles.as_flattened();
    write_polydata(
        w,
        &PolyData {
            points: mesh.positions.as_flattened(),
            point_data,
            active: if mesh.normals.is_empty() {
                ""
            } else {
                " Normals=\"Normals\""
            },
            cells: Cells {
                kind: "Polys",
                count: m,
                connectivity: Values::I64(&|k| triangles[k] as i64, 3 * m),
                offsets: Values::I64(&|k| 3 * (k as i64 + 1), m),
            },
        },
    )
}

/// Values of one appended array, written as little-endian bytes.
pub(super) enum Values<'a> {
    F32(&'a [f32]),
    F64(&'a [f64]),
    /// `len` values computed from their index (cell connectivity and offsets).
    I64(&'a dyn Fn(usize) -> i64, usize),
}

impl Values<'_> {
    fn vtk_type(&self) -> &'static str {
        match self {
            Values::F32(_) => "Float32",
            Values::F64(_) => "Float64",
            Values::I64(..) => "Int64",
        }
    }

    fn byte_len(&self) -> usize {
        match self {
            Values::F32(v) => v.len() * 4,
            Values::F64(v) => v.len() * 8,
            Values::I64(_, len) => len * 8,
        }
    }

    fn append(&self, out: &mut Chunked) -> std::io::Result<()> {
        out.bytes(&(self.byte_len() as u64).to_le_bytes())?;
        match self {
            Values::F32(v) => v.iter().try_for_each(|x| out.bytes(&x.to_le_bytes())),
            Values::F64(v) => v.iter().try_for_each(|x| out.bytes(&x.to_le_bytes())),
            Values::I64(f, len) => (0..*len).try_for_each(|k| out.bytes(&f(k).to_le_bytes())),
        }
    }
}

/// A named point-data array.
pub(super) struct Array<'a> {
    name: &'a str,
    components: usize,
    values: Values<'a>,
}

impl<'a> Array<'a> {
    pub(super) fn new(name: &'a str, components: usize, values: Values<'a>) -> Self {
        Array {
            name,
            components,
            values,
        }
    }
}

/// One cell block of a PolyData piece: "Verts" or "Polys".
pub(super) struct Cells<'a> {
    pub(super) kind: &'static str,
    pub(super) count: usize,
    pub(super) connectivity: Values<'a>,
    pub(super) offsets: Values<'a>,
}

/// Everything one PolyData piece holds.
pub(super) struct PolyData<'a> {
    /// x, y, z of each point.
    pub(super) points: &'a [f64],
    pub(super) point_data: Vec<Array<'a>>,
    /// Attributes of `<PointData>` naming the active arrays (` Normals="Normals"` ...).
    pub(super) active: &'a str,
    pub(super) cells: Cells<'a>,
}

/// Writes one PolyData piece with raw appended data: the header's offsets and the data
/// that follows come from the same list, in the same order, so they cannot disagree.
pub(super) fn write_polydata(w: &mut dyn Write, pd: &PolyData) -> std::io::Result<()> {
    let n = pd.points.len() / 3;
    let cells = &pd.cells;
    let count = |kind: &str| if cells.kind == kind { cells.count } else { 0 };
    let mut offset = 0usize;
    let mut next_offset = |values: &Values| {
        let at = offset;
        offset += 8 + values.byte_len();
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
        "    <Piece NumberOfPoints=\"{n}\" NumberOfVerts=\"{}\" NumberOfLines=\"0\" NumberOfStrips=\"0\" NumberOfPolys=\"{}\">",
        count("Verts"),
        count("Polys")
    )?;
    writeln!(w, "      <PointData{}>", pd.active)?;
    for a in &pd.point_data {
        writeln!(
            w,
            "        <DataArray type=\"{}\" Name=\"{}\" NumberOfComponents=\"{}\" format=\"appended\" offset=\"{}\"/>",
            a.values.vtk_type(),
            xml_escape(a.name),
            a.components,
            next_offset(&a.values)
        )?;
    }
    writeln!(w, "      </PointData>")?;
    let points = Values::F64(pd.points);
    writeln!(w, "      <Points>")?;
    writeln!(
        w,
        "        <DataArray type=\"Float64\" Name=\"Points\" NumberOfComponents=\"3\" format=\"appended\" offset=\"{}\"/>",
        next_offset(&points)
    )?;
    writeln!(w, "      </Points>")?;
    writeln!(w, "      <{}>", cells.kind)?;
    for (name, values) in [
        ("connectivity", &cells.connectivity),
        ("offsets", &cells.offsets),
    ] {
        writeln!(
            w,
            "        <DataArray type=\"Int64\" Name=\"{name}\" format=\"appended\" offset=\"{}\"/>",
            next_offset(values)
        )?;
    }
    writeln!(w, "      </{}>", cells.kind)?;
    writeln!(w, "    </Piece>")?;
    writeln!(w, "  </PolyData>")?;
    writeln!(w, "  <AppendedData encoding=\"raw\">")?;
    w.write_all(b"   _")?;
    let mut out = Chunked::new(w);
    for a in &pd.point_data {
        a.values.append(&mut out)?;
    }
    points.append(&mut out)?;
    cells.connectivity.append(&mut out)?;
    cells.offsets.append(&mut out)?;
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
