//! From active cells to a finished mesh: one vertex per cut edge, triangles from the case
//! table, trimming, normals and interpolated attributes. Marching Correctors and the
//! full-grid baseline both end here; they differ only in which cells are active, where
//! node values come from, and how vertices are placed.

use super::cache::NodeValues;
use super::trimming::{self, CutTarget, Untrimmed};
use super::vertices::{self, Placement};
use super::{Params, Stats};
use crate::error::Result;
use crate::field::particles::Attribute;
use crate::field::sph::SphField;
use crate::mc::{self, ActiveCell, VirtualGrid};
use crate::mesh::Mesh;
use crate::progress::{for_chunks, Progress};
use glam::DVec3;
use rayon::prelude::*;
use std::time::Instant;

pub use crate::field::sph::carried::{Carried, RESERVED};

/// Appends one isovalue's surface to the extraction's mesh, tagging its vertices with an
/// `Isovalue` array when there are several; an empty one is a warning, which says whether
/// the field never crosses the isovalue, crosses it between particles (`between`: the
/// grid's cell size, when a particle pair straddles it) but not between grid nodes, or
/// crosses it in `crossed` cells that trimming and clipping all removed.
pub fn append_surface(
    mesh: &mut Mesh,
    mut part: Mesh,
    iso: f64,
    crossed: u64,
    between: Option<f64>,
    params: &Params,
    warnings: &mut Vec<String>,
) {
    if part.triangles.is_empty() {
        warnings.push(match (crossed, between) {
            (0, Some(cell)) => crate::mesh::no_surface_on_grid(iso, cell),
            (0, None) => crate::mesh::no_surface(iso),
            _ => crate::mesh::surface_cut_away(iso, crossed),
        });
    }
    if params.isovalues.len() > 1 {
        let n = part.vertex_count();
        part.attributes
            .push(Attribute::scalar("Isovalue", vec![iso; n]));
    }
    mesh.append(part);
}

/// The edges of a surface's active cells that the surface cuts, with the samples at both
/// ends of each: all that vertex placement needs from the nodes.
pub struct CutEdges {
    /// Sorted: vertex i will sit on edge i.
    edges: Vec<u64>,
    /// Field values at both ends of each edge.
    values: Vec<[f64; 2]>,
    /// Sums of weights at both ends, for linear placement only (empty otherwise: a
    /// corrected vertex takes its own from its last sample). Left out, the list that
    /// exists beside the node cache at the extraction's peak is half as long.
    weights: Vec<[f64; 2]>,
}

/// A surface's vertices, one per cut edge, before triangulation.
pub struct PlacedVertices {
    edges: Vec<u64>,
    positions: Vec<DVec3>,
    gradients: Vec<DVec3>,
    weights: Vec<f64>,
}

/// Running sums of the vertex corrections, pooled into [`Stats`] at the end.
#[derive(Default)]
struct Corrections {
    count: f64,
    sum: f64,
    sum2: f64,
    max: f64,
}

impl Corrections {
    fn add(&mut self, p: &vertices::Placed) {
        self.count += 1.0;
        self.sum += p.correction;
        self.sum2 += p.correction * p.correction;
        self.max = self.max.max(p.correction);
    }

    /// Pools these with earlier isovalues' vertices.
    fn pool_into(&self, stats: &mut Stats) {
        let n0 = stats.corrected_vertices as f64;
        let total = n0 + self.count;
        if total > 0.0 {
            let mean0 = stats.correction_mean;
            let m2_0 = (stats.correction_stdev.powi(2) + mean0 * mean0) * n0;
            let mean = (mean0 * n0 + self.sum) / total;
            let var = ((m2_0 + self.sum2) / total - mean * mean).max(0.0);
            stats.correction_mean = mean;
            stats.correction_stdev = var.sqrt();
        }
        stats.correction_max = stats.correction_max.max(self.max);
        stats.corrected_vertices += self.count as u64;
    }
}

/// First step of a surface: lists the edges of `active` that the surface `iso` cuts and
/// reads their end nodes, reporting the start of the "vertices" phase within `span`. This
/// is the last step that reads `nodes`: the caller may free them before
/// [`place_vertices`] and [`finish`] allocate the mesh's arrays. `complete` is the grid's
/// cells per axis when every grid cell around a cut edge of `active` is in it (nothing
/// discarded or clipped), which lets each edge be listed once ([`mc::cut_edges_complete`]).
/// The ends' sums of weights are read for `Placement::Linear` only.
pub fn cut_edges(
    nodes: &impl NodeValues,
    active: &[ActiveCell],
    complete: Option<[u32; 3]>,
    placement: Placement,
    progress: &mut Progress,
    span: (f64, f64),
    stats: &mut Stats,
) -> Result<CutEdges> {
    progress.phase("vertices", span.0, span.0 + 0.6 * (span.1 - span.0))?;
    let t = Instant::now();
    let edges = match complete {
        Some(cells) => mc::cut_edges_complete(active, cells),
        None => mc::cut_edges(active),
    };
    let ends = |e: u64| {
        [
            nodes.node(mc::edge_node_axis(e).0),
            nodes.node(mc::edge_upper_node(e)),
        ]
    };
    let (values, weights) = match placement {
        Placement::Linear => edges
            .par_iter()
            .map(|&e| {
                let [(f0, w0), (f1, w1)] = ends(e);
                ([f0, f1], [w0, w1])
            })
            .unzip(),
        Placement::Corrected { .. } => {
            let values = edges.par_iter().map(|&e| ends(e).map(|n| n.0)).collect();
            (values, Vec::new())
        }
    };
    stats.timings.vertices += t.elapsed().as_secs_f64();
    Ok(CutEdges {
        edges,
        values,
        weights,
    })
}

/// Second step: places a vertex on every cut edge.
pub fn place_vertices(
    grid: &VirtualGrid,
    cut: CutEdges,
    iso: f64,
    placement: Placement,
    progress: &mut Progress,
    stats: &mut Stats,
) -> Result<PlacedVertices> {
    let t = Instant::now();
    let CutEdges {
        edges,
        values,
        weights,
    } = cut;
    let n = edges.len();
    let mut out = PlacedVertices {
        edges: Vec::new(),
        positions: Vec::with_capacity(n),
        gradients: Vec::with_capacity(n),
        weights: Vec::with_capacity(n),
    };
    // Chunk by chunk into the surface's arrays: a list of all placements (three times the
    // bytes of a position) would sit beside them at the peak.
    let mut corrections = Corrections::default();
    for_chunks(
        &edges,
        progress,
        |first, part| {
            part.par_iter()
                .zip(&values[first..first + part.len()])
                .enumerate()
                .map(|(i, (&e, &v))| {
                    let w = weights.get(first + i).copied();
                    vertices::place(grid, e, v, w, iso, placement)
                })
                .collect::<Vec<_>>()
        },
        |placed| {
            for p in &placed {
                corrections.add(p);
                stats.unconverged_vertices += u64::from(!p.converged);
                stats.field_evaluations += u64::from(p.evaluations);
            }
            out.positions.extend(placed.iter().map(|p| p.position));
            out.gradients.extend(placed.iter().map(|p| p.gradient));
            out.weights.extend(placed.iter().map(|p| p.weight));
        },
    )?;
    if let Placement::Corrected { .. } = placement {
        corrections.pool_into(stats);
    }
    drop((values, weights));
    out.edges = edges;
    stats.timings.vertices += t.elapsed().as_secs_f64();
    Ok(out)
}

/// Last step: triangulates `active` on `vertices`, trims, and adds normals and
/// attributes, reporting within the last 40 % of `span`.
#[allow(clippy::too_many_arguments)]
pub fn finish(
    field: &SphField,
    vertices: PlacedVertices,
    active: &[ActiveCell],
    iso: f64,
    params: &Params,
    placement: Placement,
    attributes: &Carried,
    progress: &mut Progress,
    span: (f64, f64),
    stats: &mut Stats,
) -> Result<Mesh> {
    let at = |f: f64| span.0 + (span.1 - span.0) * f;
    let t = Instant::now();
    let PlacedVertices {
        edges,
        positions,
        gradients,
        weights,
    } = vertices;
    let triangles = mc::triangulate(active, &edges);
    drop(edges);
    let mut surface = Untrimmed {
        positions,
        gradients,
        weights,
        triangles,
    };
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
    // From here each array moves into the mesh as it is finished, so no array of the
    // surface exists twice.
    let Untrimmed {
        positions,
        gradients,
        weights,
        triangles,
    } = surface;
    drop(gradients);
    let mut mesh_attributes = vec![Attribute::scalar("SumOfWeights", weights)];
    let carried = attributes.onto(field, &positions, progress)?;
    if !carried.is_empty() {
        stats.field_evaluations += positions.len() as u64;
    }
    mesh_attributes.extend(carried);
    stats.timings.attributes += t.elapsed().as_secs_f64();
    Ok(Mesh {
        // Same size and alignment: collected in place, without a second buffer.
        positions: positions.into_iter().map(|p| p.to_array()).collect(),
        normals,
        triangles,
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
