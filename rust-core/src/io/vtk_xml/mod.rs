//! VTK XML files: `.vtu`/`.vtp` particles in, `.vtp` triangle meshes out and back in.
//!
//! Arrays may be `ascii`, inline `binary` (base64) or `appended` (raw or base64), each with a
//! UInt32 or UInt64 size header, optionally zlib-compressed in blocks, in either byte order.
//! The appended section of a raw file is not XML (it holds arbitrary bytes), so the file is
//! split at `<AppendedData ...>_`: the part before goes to the XML parser, the part after is
//! addressed by each array's `offset`.

mod cells;
mod document;
mod image;
mod points;
#[cfg(test)]
mod tests;
mod write;

use crate::error::{Error, Result};
use crate::field::particles::{Attribute, ParticleData, Skipped};
use crate::mesh::Mesh;
use document::Document;

pub(crate) use cells::read_fe_mesh;
pub(crate) use document::find as find_bytes;
pub(crate) use image::read_image;
pub(crate) use points::write_points;
pub(crate) use write::write_mesh;

/// Reads the points and point arrays of every piece of a VTK XML dataset (pieces are
/// concatenated; an array missing from some piece is left out, and so is an array of
/// strings or bits, each noted in `skipped`).
pub(crate) fn read_particles(bytes: &[u8], name: &str) -> Result<ParticleData> {
    let doc = Document::parse(bytes, name)?;
    let mut out = ParticleData::default();
    for (k, piece) in doc.pieces.iter().enumerate() {
        let flat = doc.points(piece)?;
        let mut attributes = Vec::new();
        for a in piece.arrays.iter().filter(|a| a.section == "PointData") {
            // Strings and bit arrays carry nothing a field can use.
            if a.ty.is_none() {
                if !out.skipped.iter().any(|s| s.name == a.name) {
                    out.skipped.push(Skipped {
                        name: a.name.clone(),
                        why: format!("its type {} is not numeric", a.type_name),
                    });
                }
                continue;
            }
            attributes.push(Attribute {
                name: a.name.clone(),
                components: a.components,
                data: doc.values(a, piece.points)?,
            });
        }
        out.positions.extend(super::positions_from_flat(&flat));
        if k == 0 {
            out.attributes = attributes;
        } else {
            let all = std::mem::take(&mut out.attributes);
            out.attributes = join_attributes(all, attributes, |a| {
                let why = format!(
                    "piece {k} has no {}-component array of that name",
                    a.components
                );
                out.skipped.push(Skipped { name: a.name, why });
            });
        }
    }
    Ok(out)
}

/// Reads a PolyData triangle mesh: Points, Polys (polygons become triangle fans), the point
/// array marked as normals (or called "Normals") as normals and every other point array as
/// an attribute.
pub(crate) fn read_mesh(bytes: &[u8], name: &str) -> Result<Mesh> {
    let doc = Document::parse(bytes, name)?;
    if doc.kind != "PolyData" {
        return Err(Error::format(
            name,
            format!("a mesh must be VTK PolyData, this file holds {}", doc.kind),
        ));
    }
    let mut mesh = Mesh::default();
    // Normals are kept only when every piece has them, as a mesh needs one per vertex.
    let mut normals_everywhere = true;
    for (k, piece) in doc.pieces.iter().enumerate() {
        let base = mesh.positions.len();
        let flat = doc.points(piece)?;
        mesh.positions
            .extend(flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]));
        let normals_name = piece.normals_name.as_deref().unwrap_or("Normals");
        let mut normals = None;
        let mut attributes = Vec::new();
        for a in piece
            .arrays
            .iter()
            .filter(|a| a.section == "PointData" && a.ty.is_some())
        {
            let data = doc.values(a, piece.points)?;
            if a.name == normals_name && a.components == 3 && normals.is_none() {
                normals = Some(data);
            } else {
                attributes.push(Attribute {
                    name: a.name.clone(),
                    components: a.components,
                    data,
                });
            }
        }
        match normals {
            Some(n) if normals_everywhere => mesh.normals.extend(
                n.chunks_exact(3)
                    .map(|c| [c[0] as f32, c[1] as f32, c[2] as f32]),
            ),
            _ => {
                normals_everywhere = false;
                mesh.normals.clear();
            }
        }
        mesh.triangles.extend(doc.polygons(piece, base)?);
        mesh.attributes = if k == 0 {
            attributes
        } else {
            join_attributes(std::mem::take(&mut mesh.attributes), attributes, drop)
        };
    }
    Ok(mesh)
}

/// Keeps the arrays of `all` that `next` also has with the same width, extended by its data;
/// the others are handed to `dropped`.
fn join_attributes(
    all: Vec<Attribute>,
    next: Vec<Attribute>,
    mut dropped: impl FnMut(Attribute),
) -> Vec<Attribute> {
    all.into_iter()
        .filter_map(|mut a| {
            let Some(b) = next
                .iter()
                .find(|b| b.name == a.name && b.components == a.components)
            else {
                dropped(a);
                return None;
            };
            a.data.extend_from_slice(&b.data);
            Some(a)
        })
        .collect()
}
