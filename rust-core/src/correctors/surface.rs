//! From active cells to a finished mesh: one vertex per cut edge, triangles from the case
//! table, trimming, normals and interpolated attributes. Marching Correctors and the
//! full-grid baseline both end here; they differ only in which cells are active, where
//! node values come from, and how vertices are placed.

use super::cache::NodeValues;
use super::trimming::{self, CutTarget, Untrimmed};
use super::vertices::{self, Placement};
use super::{Params, Stats};
use crate::error::{Error, Result};
use crate::field::particles::{Attribute, ParticleData};
use crate::field::sph::SphField;
use crate::mc::{self, ActiveCell, VirtualGrid};
use crate::mesh::Mesh;
use crate::progress::{chunked, Progress};
use glam::DVec3;
use rayon::prelude::*;
use std::time::Instant;

/// Surface arrays the extractor writes itself.
pub const RESERVED: [&str; 2] = ["SumOfWeights", "Isovalue"];

/// Particle arrays to carry onto the surface, reordered for interpolation.
pub struct AttributeSource {
    arrays: Vec<(String, usize, Vec<f64>)>,
}

impl AttributeSource {
    /// Looks up `names` in `data`; a missing name is an error that lists what exists.
    pub fn new(field: &SphField, data: &ParticleData, names: &[String]) -> Result<Self> {
        let mut arrays = Vec::new();
        for name in names {
            if RESERVED.contains(&name.as_str()) {
                return Err(Error::InvalidParameter {
                    name: "attributes",
                    message: format!("'{name}' is the name of an array isobar computes itself; rename the particle array"),
                });
            }
            let a = data.require(name)?;
            arrays.push((
                a.name.clone(),
                a.components,
                field.to_grid_order(&a.data, a.components),
            ));
        }
        Ok(AttributeSource { arrays })
    }

    fn components(&self) -> usize {
        self.arrays.iter().map(|a| a.1).sum()
    }
}

/// Appends one isovalue's surface to the extraction's mesh, tagging its vertices with an
/// `Isovalue` array when there are several.
pub fn append_surface(mesh: &mut Mesh, mut part: Mesh, iso: f64, params: &Params) {
    if params.isovalues.len() > 1 {
        let n = part.vertex_count();
        part.attributes
            .push(Attribute::scalar("Isovalue", vec![iso; n]));
    }
    mesh.append(part);
}

/// Builds the mesh of `active` cells for `iso`, reporting within `span` of the run.
#[allow(clippy::too_many_arguments)]
pub fn build(
    field: &SphField,
    grid: &VirtualGrid,
    nodes: &impl NodeValues,
    active: &[ActiveCell],
    iso: f64,
    params: &Params,
    placement: Placement,
    attributes: &AttributeSource,
    progress: &mut Progress,
    span: (f64, f64),
    stats: &mut Stats,
) -> Result<Mesh> {
    let at = |f: f64| span.0 + (span.1 - span.0) * f;
    progress.phase("vertices", at(0.0), at(0.6))?;
    let t = Instant::now();
    let edges = mc::cut_edges(active);
    let placed = chunked(&edges, progress, |part| {
        part.par_iter()
            .map(|&e| vertices::place(grid, nodes, e, iso, placement))
            .collect()
    })?;
    let triangles = mc::triangulate(active, &edges);
    drop(edges);
    if let Placement::Corrected { .. } = placement {
        let n = placed.len() as f64;
        let (sum, sum2, max) = placed.iter().fold((0.0, 0.0, 0.0f64), |(s, s2, m), p| {
            (
                s + p.correction,
                s2 + p.correction * p.correction,
                m.max(p.correction),
            )
        });
        // Pool with earlier isovalues' vertices.
        let n0 = stats.corrected_vertices as f64;
        let total = n0 + n;
        if total > 0.0 {
            let mean0 = stats.correction_mean;
            let m2_0 = (stats.correction_stdev.powi(2) + mean0 * mean0) * n0;
            let mean = (mean0 * n0 + sum) / total;
            let var = ((m2_0 + sum2) / total - mean * mean).max(0.0);
            stats.correction_mean = mean;
            stats.correction_stdev = var.sqrt();
        }
        stats.correction_max = stats.correction_max.max(max);
        stats.corrected_vertices += placed.len() as u64;
        stats.unconverged_vertices += placed.iter().filter(|p| !p.converged).count() as u64;
        stats.field_evaluations += placed.iter().map(|p| p.evaluations as u64).sum::<u64>();
    }
    let mut surface = Untrimmed {
        positions: placed.iter().map(|p| p.position).collect(),
        gradients: placed.iter().map(|p| p.gradient).collect(),
        weights: placed.iter().map(|p| p.weight).collect(),
        triangles,
    };
    drop(placed);
    stats.timings.vertices += t.elapsed().as_secs_f64();

    progress.phase("trimming", at(0.6), at(0.7))?;
    let t = Instant::now();
    if let Some(trim) = params.trim {
        let target = match placement {
            Placement::Corrected { field, tolerance } => Some(CutTarget {
                field,
                iso,
                tolerance,
                weight_tolerance: params.tolerance * trim.vertex.abs().max(f64::MIN_POSITIVE),
            }),
            Placement::Linear => None,
        };
        let trimmed = trimming::trim(surface, trim.vertex, target);
        stats.trim_cut_points += trimmed.cut_points as u64;
        stats.field_evaluations += trimmed.evaluations;
        surface = trimmed.mesh;
        surface.compact();
    }
    stats.timings.trimming += t.elapsed().as_secs_f64();

    progress.phase("attributes", at(0.7), at(1.0))?;
    let t = Instant::now();
    let normals = if !params.normals {
        Vec::new()
    } else if let Placement::Corrected { .. } = placement {
        gradient_normals(&surface)
    } else {
        face_normals(&surface)
    };
    let mut mesh_attributes = vec![Attribute::scalar("SumOfWeights", surface.weights.clone())];
    let width = attributes.components();
    if width > 0 {
        let arrays: Vec<(&[f64], usize)> = attributes
            .arrays
            .iter()
            .map(|(_, c, d)| (d.as_slice(), *c))
            .collect();
        let values: Vec<Vec<f64>> = chunked(&surface.positions, progress, |part| {
            part.par_iter()
                .map(|&x| {
                    let mut out = vec![0.0; width];
                    field.interpolate(x, &arrays, &mut out);
                    out
                })
                .collect()
        })?;
        stats.field_evaluations += values.len() as u64;
        let mut offset = 0;
        for (name, c, _) in &attributes.arrays {
            let data = values
                .iter()
                .flat_map(|v| v[offset..offset + c].iter().copied())
                .collect();
            mesh_attributes.push(Attribute {
                name: name.clone(),
                components: *c,
                data,
            });
            offset += c;
        }
    }
    stats.timings.attributes += t.elapsed().as_secs_f64();
    Ok(Mesh {
        positions: surface.positions.iter().map(|p| p.to_array()).collect(),
        normals,
        triangles: surface.triangles,
        attributes: mesh_attributes,
    })
}

/// Unit normals pointing down the field gradient (out of the region above the isovalue);
/// vertices where the gradient vanishes take their face normal.
fn gradient_normals(s: &Untrimmed) -> Vec<[f32; 3]> {
    let from_gradient: Vec<Option<[f32; 3]>> = s
        .gradients
        .par_iter()
        .map(|g| {
            let n = -*g;
            (n.length_squared() > 0.0 && n.is_finite()).then(|| n.normalize().as_vec3().to_array())
        })
        .collect();
    // Face normals are a pass over every triangle, on one thread: only for the rare
    // vertex where the gradient vanishes.
    let faces = if from_gradient.iter().any(Option::is_none) {
        face_normals(s)
    } else {
        Vec::new()
    };
    from_gradient
        .into_iter()
        .enumerate()
        .map(|(i, n)| n.unwrap_or_else(|| faces[i]))
        .collect()
}

/// Area-weighted averages of the incident triangles' normals.
fn face_normals(s: &Untrimmed) -> Vec<[f32; 3]> {
    let mut acc = vec![DVec3::ZERO; s.positions.len()];
    for t in &s.triangles {
        let [a, b, c] = t.map(|i| s.positions[i as usize]);
        let n = (b - a).cross(c - a);
        for &i in t {
            acc[i as usize] += n;
        }
    }
    acc.into_iter()
        .map(|n| n.try_normalize().unwrap_or(DVec3::Z).as_vec3().to_array())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gradient_normals_point_down_the_gradient_and_fall_back_to_faces_where_it_vanishes() {
        // Two triangles in the z = 0 plane, both facing +z.
        let positions = vec![
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(0.0, 1.0, 0.0),
            DVec3::new(1.0, 1.0, 0.0),
        ];
        let gradients = vec![
            DVec3::new(0.0, 0.0, -2.0),
            DVec3::ZERO,
            DVec3::new(f64::NAN, 0.0, 0.0),
            DVec3::new(3.0, 0.0, 4.0),
        ];
        let s = Untrimmed {
            positions,
            gradients,
            weights: vec![1.0; 4],
            triangles: vec![[0, 1, 2], [1, 3, 2]],
        };
        let n = gradient_normals(&s);
        assert_eq!(n[0], [0.0, 0.0, 1.0]);
        assert_eq!(n[1], [0.0, 0.0, 1.0], "zero gradient: the face normal");
        assert_eq!(n[2], [0.0, 0.0, 1.0], "NaN gradient: the face normal");
        assert_eq!(n[3], [-0.6, 0.0, -0.8]);
        // Where every gradient is usable no face normal is needed, and none leaks in.
        let all = Untrimmed {
            gradients: vec![DVec3::new(0.0, -1.0, 0.0); 4],
            ..s
        };
        assert!(gradient_normals(&all).iter().all(|n| *n == [0.0, 1.0, 0.0]));
    }
}
