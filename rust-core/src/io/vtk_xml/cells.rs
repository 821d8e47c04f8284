//! `.vtu` UnstructuredGrid files with Lagrange cells (VTK types 71, 72, 73), or linear and
//! quadratic ones that `FeMesh` reads as Lagrange cells, into an [`FeMesh`]: points, cells,
//! `HigherOrderDegrees` cell data if present, point arrays.

use super::document::{DataArray, Document, Piece};
use crate::error::{Error, Result};
use crate::field::fe::{FeMesh, Kind};
use crate::field::particles::Attribute;
use glam::DVec3;

/// Reads every piece of a VTU (pieces are concatenated; point arrays missing from some
/// piece are dropped) and builds the mesh, which checks every cell.
pub(crate) fn read_fe_mesh(bytes: &[u8], name: &str) -> Result<FeMesh> {
    let doc = Document::parse(bytes, name)?;
    if doc.kind != "UnstructuredGrid" {
        return Err(Error::format(
            name,
            format!(
                "finite elements must be a VTK UnstructuredGrid (.vtu), this file holds {}",
                doc.kind
            ),
        ));
    }
    // Files older than version 2.2 use VTK 8's hexahedron numbering (edges 10 and 11 swapped).
    let legacy_hex = doc.version.as_deref().is_some_and(|v| {
        let mut it = v.split('.').map(|x| x.parse::<u32>().unwrap_or(0));
        let (major, minor) = (it.next().unwrap_or(0), it.next().unwrap_or(0));
        (major, minor) < (2, 2)
    });
    let mut points: Vec<DVec3> = Vec::new();
    let mut types: Vec<u8> = Vec::new();
    let mut offsets: Vec<usize> = vec![0];
    let mut connectivity: Vec<u32> = Vec::new();
    let mut degrees: Vec<[usize; 3]> = Vec::new();
    let mut any_degrees = false;
    let mut point_data: Vec<Attribute> = Vec::new();
    for (k, piece) in doc.pieces.iter().enumerate() {
        let base = points.len();
        let flat = doc.points(piece)?;
        points.extend(flat.chunks_exact(3).map(|c| DVec3::new(c[0], c[1], c[2])));
        let (ty, offs, conn) = cell_arrays(&doc, piece, name)?;
        let cell_base = types.len();
        let mut start = 0usize;
        for (c, (&t, &end)) in ty.iter().zip(&offs).enumerate() {
            let cell = cell_base + c;
            let t = integer(t, u8::MAX as usize).ok_or_else(|| {
                Error::format(name, format!("cell {cell} has the invalid type {t}"))
            })?;
            let end = integer(end, conn.len())
                .filter(|&e| e >= start)
                .ok_or_else(|| {
                    Error::format(
                        name,
                        format!("cell {cell}: offset {end} out of order or range"),
                    )
                })?;
            for &v in &conn[start..end] {
                let i = integer(v, piece.points.saturating_sub(1)).ok_or_else(|| {
                    Error::format(
                        name,
                        format!(
                            "cell {cell} refers to point {v}, but the piece has {}",
                            piece.points
                        ),
                    )
                })?;
                connectivity.push((base + i) as u32);
            }
            types.push(t as u8);
            offsets.push(connectivity.len());
            start = end;
        }
        let deg = piece
            .arrays
            .iter()
            .find(|a| a.section == "CellData" && a.name == "HigherOrderDegrees" && a.ty.is_some());
        match deg {
            Some(a) if a.components == 3 => {
                any_degrees = true;
                let d = doc.values(a, piece.cells)?;
                degrees.extend(
                    d.chunks_exact(3)
                        .map(|c| [0, 1, 2].map(|k| c[k].max(0.0) as usize)),
                );
            }
            _ => degrees.extend(std::iter::repeat_n([0; 3], piece.cells)),
        }
        let arrays = point_arrays(&doc, piece)?;
        point_data = if k == 0 {
            arrays
        } else {
            super::join_attributes(point_data, arrays, drop)
        };
    }
    if legacy_hex {
        swap_legacy_hex_edges(&types, &offsets, &mut connectivity, &degrees);
    }
    FeMesh::new(
        name,
        points,
        &types,
        &offsets,
        connectivity,
        any_degrees.then_some(degrees.as_slice()),
        point_data,
    )
}

/// types, offsets (ends) and connectivity of a piece, as numbers.
fn cell_arrays(
    doc: &Document,
    piece: &Piece,
    name: &str,
) -> Result<(Vec<f64>, Vec<f64>, Vec<f64>)> {
    let find = |n: &str| -> Result<&DataArray> {
        piece
            .arrays
            .iter()
            .find(|a| a.section == "Cells" && a.name == n && a.ty.is_some())
            .ok_or_else(|| Error::format(name, format!("the piece's Cells have no '{n}' array")))
    };
    let types = doc.values(find("types")?, piece.cells)?;
    let offsets = doc.values(find("offsets")?, piece.cells)?;
    let total = offsets.last().copied().unwrap_or(0.0);
    let total = integer(total, usize::MAX >> 8).ok_or_else(|| {
        Error::format(
            name,
            format!("Cells offsets end in the invalid value {total}"),
        )
    })?;
    let connectivity = doc.values(find("connectivity")?, total)?;
    Ok((types, offsets, connectivity))
}

fn point_arrays(doc: &Document, piece: &Piece) -> Result<Vec<Attribute>> {
    piece
        .arrays
        .iter()
        .filter(|a| a.section == "PointData" && a.ty.is_some())
        .map(|a| {
            Ok(Attribute {
                name: a.name.clone(),
                components: a.components,
                data: doc.values(a, piece.points)?,
            })
        })
        .collect()
}

/// `v` as an index in 0..=max, if it is one.
fn integer(v: f64, max: usize) -> Option<usize> {
    (v >= 0.0 && v.fract() == 0.0 && v <= max as f64).then_some(v as usize)
}

/// VTK 8 numbered the nodes of the hexahedron's k-edges at corners 2 and 3 the other way
/// round; VTK's own reader swaps them for files before version 2.2.
fn swap_legacy_hex_edges(
    types: &[u8],
    offsets: &[usize],
    conn: &mut [u32],
    degrees: &[[usize; 3]],
) {
    for (c, &t) in types.iter().enumerate() {
        if Kind::from_vtk(t) != Some(Kind::Hexahedron) {
            continue;
        }
        let n = offsets[c + 1] - offsets[c];
        let o = match degrees.get(c) {
            Some(&d) if d.iter().all(|&x| x > 0) && Kind::Hexahedron.node_count(d) == n => d,
            _ => match Kind::Hexahedron.order_from_count(n) {
                Some(p) => [p; 3],
                None => continue,
            },
        };
        let len = o[2] - 1;
        if len == 0 {
            continue;
        }
        let first = offsets[c] + 8 + 4 * (o[0] - 1) + 4 * (o[1] - 1) + 2 * len;
        let (a, b) = conn[first..first + 2 * len].split_at_mut(len);
        a.swap_with_slice(b);
    }
}
