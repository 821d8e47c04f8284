//! The paper's baseline (Sect. 2, Fig. 3e–g): marching cubes on a world-space grid over
//! high-order elements. Every grid node is numerically inverted (the cell holding it and
//! its reference point, by Newton on T) to evaluate the field; then on each cut grid edge
//! a safeguarded Newton iteration along the edge (each step another inversion) puts the
//! vertex on F = C to the tolerance. Cells, edges and triangles come from the shared
//! `mc` table and assembly. Cells with a corner outside the mesh are not contoured, so
//! a surface that reaches the mesh boundary stays open there.
//!
//! Forward evaluations (one mapping or field evaluation at one reference point) are
//! counted as the paper counts them, to compare with the particle system.

use super::field_values;
use crate::error::{Error, Result};
use crate::field::fe::{CellIndex, FeMesh, Scratch};
use crate::field::particles::Attribute;
use crate::mc::{self, case_index, linear_crossing, ActiveCell, VirtualGrid};
use crate::mesh::Mesh;
use crate::progress::Progress;
use glam::DVec3;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

/// Parameters of [`extract`].
#[derive(Clone, Debug)]
pub struct McParams {
    /// The isovalue C.
    pub iso: f64,
    /// Grid cell size, world units; 0 picks 1/40 of the mesh's bounding-box diagonal.
    pub spacing: f64,
    /// Every vertex has |F − C| ≤ tolerance (Newton along its edge).
    pub tolerance: f64,
    /// Refuse grids whose node store would need more bytes than this.
    pub memory_budget: u64,
}

impl Default for McParams {
    fn default() -> Self {
        McParams {
            iso: 0.0,
            spacing: 0.0,
            tolerance: 1e-6,
            memory_budget: crate::field::DEFAULT_MEMORY_BUDGET,
        }
    }
}

/// What a run did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct McStats {
    /// Grid cell size used.
    pub spacing: f64,
    /// Grid nodes evaluated.
    pub nodes: u64,
    /// Grid nodes found inside a cell.
    pub nodes_inside: u64,
    /// Cells the surface passes through.
    pub active_cells: u64,
    pub vertices: u64,
    pub triangles: u64,
    /// Forward evaluations: mappings during inversion plus field evaluations.
    pub evaluations: u64,
    /// Cut edges whose Newton iteration left the mesh (vertex kept at the linear guess).
    pub unresolved_edges: u64,
    /// Largest |F − C| over the vertices (resolved edges).
    pub max_residual: f64,
    /// Seconds for locating the grid nodes and for the edges.
    pub node_seconds: f64,
    pub edge_seconds: f64,
}

/// A located grid node.
#[derive(Clone, Copy, Debug)]
struct Node {
    /// Cell holding the node, or u32::MAX outside the mesh.
    cell: u32,
    u: DVec3,
    value: f64,
}

const OUTSIDE: u32 = u32::MAX;

/// Extracts the isosurface `params.iso` of the point array `field` by marching cubes with
/// numerical inversion and Newton along the edges. Normals point down the gradient (the
/// winding of the shared case table); the vertex array "Element" names the cell of each
/// vertex.
pub fn extract(
    mesh: &FeMesh,
    field: &str,
    params: &McParams,
    progress: &mut Progress,
) -> Result<(Mesh, McStats)> {
    let values = field_values(mesh, field)?;
    let values = &*values;
    if !params.iso.is_finite() {
        return Err(bad("iso", "must be finite"));
    }
    if !(params.tolerance > 0.0 && params.tolerance.is_finite()) {
        return Err(bad("tolerance", "must be positive"));
    }
    if !(params.spacing >= 0.0 && params.spacing.is_finite()) {
        return Err(bad(
            "spacing",
            "must be ≥ 0 (0 picks 1/40 of the mesh's diagonal)",
        ));
    }
    let (lo, hi) = mesh.bounds();
    let spacing = if params.spacing > 0.0 {
        params.spacing
    } else {
        (hi - lo).length() / 40.0
    };
    let grid = VirtualGrid::covering(lo, hi, spacing, "spacing")?;
    let dims = grid.cells.map(|c| c as usize + 1);
    let count = dims.iter().map(|&n| n as u128).product::<u128>();
    let needed = count * std::mem::size_of::<Node>() as u128;
    if needed > params.memory_budget as u128 {
        return Err(Error::OverBudget {
            what: format!(
                "a marching-cubes grid of {}×{}×{} nodes (spacing {spacing:.3e})",
                dims[0], dims[1], dims[2]
            ),
            needed_bytes: needed.min(u64::MAX as u128) as u64,
            budget_bytes: params.memory_budget,
        });
    }
    let mut stats = McStats {
        spacing,
        nodes: count as u64,
        ..McStats::default()
    };
    let evaluations = AtomicU64::new(0);
    let index = mesh.index();

    // 1. Locate and evaluate every node; a row runs in x order, each node hinted by the
    // one before, so results do not depend on the thread count.
    let t = Instant::now();
    progress.phase("locating grid nodes", 0.0, 0.8)?;
    let outside = Node {
        cell: OUTSIDE,
        u: DVec3::ZERO,
        value: 0.0,
    };
    let mut nodes = vec![outside; count as usize];
    let slice = dims[0] * dims[1];
    for (z, chunk) in nodes.chunks_mut(slice).enumerate() {
        chunk.par_chunks_mut(dims[0]).enumerate().for_each_init(
            Scratch::default,
            |scratch, (y, row)| {
                let mut evals = 0u64;
                let mut hint = None;
                for (x, node) in row.iter_mut().enumerate() {
                    let p = grid.node_position(VirtualGrid::key(x as u32, y as u32, z as u32));
                    if let Some((c, u)) = index.locate(mesh, p, hint, scratch, &mut evals) {
                        evals += 1;
                        *node = Node {
                            cell: c as u32,
                            u,
                            value: mesh.value(values, c, u, scratch),
                        };
                        hint = Some((c, u));
                    }
                }
                evaluations.fetch_add(evals, Ordering::Relaxed);
            },
        );
        progress.report((z + 1) as f64 / dims[2] as f64)?;
    }
    stats.nodes_inside = nodes.iter().filter(|n| n.cell != OUTSIDE).count() as u64;
    stats.node_seconds = t.elapsed().as_secs_f64();
    let node_at = |key: u64| {
        let [x, y, z] = VirtualGrid::coords(key).map(|c| c as usize);
        &nodes[x + dims[0] * (y + dims[1] * z)]
    };

    // 2. Active cells: all eight corners inside the mesh and the surface between them.
    let t = Instant::now();
    progress.phase("vertices on cut edges", 0.8, 1.0)?;
    let iso = params.iso;
    let active: Vec<ActiveCell> = (0..grid.cells[2])
        .into_par_iter()
        .flat_map_iter(|z| {
            (0..grid.cells[1]).flat_map(move |y| {
                (0..grid.cells[0]).filter_map(move |x| {
                    let key = VirtualGrid::key(x, y, z);
                    let corners: [&Node; 8] =
                        std::array::from_fn(|c| node_at(VirtualGrid::corner(key, c)));
                    if corners.iter().any(|n| n.cell == OUTSIDE) {
                        return None;
                    }
                    let case = case_index(&corners.map(|n| n.value), iso);
                    (case != 0 && case != 255).then_some(ActiveCell { key, case })
                })
            })
        })
        .collect();
    stats.active_cells = active.len() as u64;

    // 3. One vertex per cut edge, by Newton along the edge; 4. the shared assembly.
    let edges = mc::cut_edges(&active);
    let target = 0.01 * params.tolerance;
    let vertices: Vec<EdgeVertex> = edges
        .par_iter()
        .map_init(Scratch::default, |scratch, &edge| {
            let n0 = mc::edge_node_axis(edge).0;
            let n1 = mc::edge_upper_node(edge);
            let ends = [n0, n1].map(|n| (grid.node_position(n), *node_at(n)));
            edge_vertex(
                mesh,
                index,
                values,
                ends,
                iso,
                target,
                params.tolerance,
                scratch,
            )
        })
        .collect();
    progress.report(1.0)?;
    let triangles = mc::triangulate(&active, &edges);
    stats.edge_seconds = t.elapsed().as_secs_f64();

    let mut out = Mesh {
        triangles,
        ..Mesh::default()
    };
    let mut element = Vec::with_capacity(vertices.len());
    let mut total = evaluations.into_inner();
    for v in &vertices {
        out.positions.push(v.x.to_array());
        out.normals
            .push((-v.grad).normalize_or_zero().as_vec3().to_array());
        element.push(mesh.given_cell(v.cell as usize) as f64);
        total += v.evaluations;
        if v.resolved {
            stats.max_residual = stats.max_residual.max(v.residual);
        } else {
            stats.unresolved_edges += 1;
        }
    }
    out.attributes.push(Attribute {
        name: "Element".into(),
        components: 1,
        data: element,
    });
    stats.evaluations = total;
    stats.vertices = out.positions.len() as u64;
    stats.triangles = out.triangles.len() as u64;
    Ok((out, stats))
}

fn bad(name: &'static str, message: &str) -> Error {
    Error::InvalidParameter {
        name,
        message: message.into(),
    }
}

/// A vertex on a cut edge.
struct EdgeVertex {
    x: DVec3,
    grad: DVec3,
    cell: u32,
    residual: f64,
    resolved: bool,
    evaluations: u64,
}

/// Newton along the edge from `ends[0]` to `ends[1]` (values on opposite sides of `iso`),
/// kept inside the shrinking bracket, bisecting when a step would leave it. Each step
/// locates the point (inverting T from the previous reference point) and evaluates F.
/// Newton aims at `target`; the vertex counts as resolved when within `tolerance`.
#[allow(clippy::too_many_arguments)]
fn edge_vertex(
    mesh: &FeMesh,
    index: &CellIndex,
    values: &[f64],
    ends: [(DVec3, Node); 2],
    iso: f64,
    target: f64,
    tolerance: f64,
    scratch: &mut Scratch,
) -> EdgeVertex {
    let (a, b) = (ends[0].0, ends[1].0);
    let d = b - a;
    let f0 = ends[0].1.value - iso;
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    let mut t = linear_crossing(ends[0].1.value, ends[1].1.value, iso);
    let near = if t < 0.5 { ends[0].1 } else { ends[1].1 };
    let mut hint = (near.cell as usize, near.u);
    let mut evaluations = 0u64;
    let mut best: Option<EdgeVertex> = None;
    for _ in 0..80 {
        let x = a + d * t;
        let Some((c, u)) = index.locate(mesh, x, Some(hint), scratch, &mut evaluations) else {
            break;
        };
        evaluations += 1;
        let e = mesh.evaluate_to(values, c, u, 1, scratch);
        let g = e.value - iso;
        let v = EdgeVertex {
            x,
            grad: e.grad,
            cell: c as u32,
            residual: g.abs(),
            resolved: false,
            evaluations: 0,
        };
        let done = v.residual <= target;
        if best.as_ref().is_none_or(|b| v.residual < b.residual) {
            best = Some(v);
        }
        if done || hi - lo < 1e-15 {
            break;
        }
        if (g > 0.0) == (f0 > 0.0) {
            lo = t;
        } else {
            hi = t;
        }
        let slope = e.grad.dot(d);
        let next = t - g / slope;
        t = if next > lo && next < hi {
            next
        } else {
            0.5 * (lo + hi)
        };
        hint = (c, u);
    }
    let mut v = best.unwrap_or_else(|| {
        // The edge leaves the mesh between its two nodes: keep the linear guess.
        let t = linear_crossing(ends[0].1.value, ends[1].1.value, iso);
        EdgeVertex {
            x: a + d * t,
            grad: DVec3::ZERO,
            cell: near.cell,
            residual: f64::INFINITY,
            resolved: false,
            evaluations: 0,
        }
    });
    // Only a vertex on the level set to the tolerance counts as resolved: Newton can run
    // out of steps or bracket without getting there.
    v.resolved = v.residual <= tolerance;
    v.evaluations = evaluations;
    v
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::highorder::tests::{
        grid_mesh, teardrop_field, teardrop_map, TEAR_A, TEAR_B, TEAR_R,
    };

    fn teardrop() -> FeMesh {
        grid_mesh(2, 2, teardrop_map, |y| y.length_squared())
    }

    /// |F − C| at each vertex by an independent evaluation: locate from scratch (no hint),
    /// evaluate the field there.
    fn independent_residuals(mesh: &FeMesh, m: &Mesh, iso: f64) -> Vec<f64> {
        let index = CellIndex::new(mesh);
        let values = &mesh.point_data[0].data;
        let mut scratch = Scratch::default();
        m.positions
            .iter()
            .map(|&x| {
                let (c, u) = index
                    .locate(mesh, DVec3::from(x), None, &mut scratch, &mut 0)
                    .expect("every vertex lies inside the mesh");
                (mesh.value(values, c, u, &mut scratch) - iso).abs()
            })
            .collect()
    }

    #[test]
    fn teardrop_vertices_lie_on_the_level_set_and_the_surface_is_closed() {
        let mesh = teardrop();
        let iso = TEAR_R * TEAR_R;
        let params = McParams {
            iso,
            spacing: 0.08,
            ..McParams::default()
        };
        let (m, stats) = extract(&mesh, "f", &params, &mut Progress::none()).unwrap();
        eprintln!("teardrop mc: {stats:?}");
        assert!(m.vertex_count() > 100, "{stats:?}");
        assert_eq!(stats.unresolved_edges, 0);
        assert!(m.topology().is_watertight_oriented(), "{:?}", m.topology());
        assert_eq!(m.components(), 1);
        for (i, r) in independent_residuals(&mesh, &m, iso).iter().enumerate() {
            assert!(*r <= 1e-6, "vertex {i}: |F − C| = {r}");
        }
        for (i, x) in m.positions.iter().enumerate() {
            let f = teardrop_field(DVec3::from(*x));
            assert!(
                f.abs() <= 1e-6,
                "vertex {i} at {x:?}: analytic |F − C| = {f}"
            );
        }
        // Enclosed volume against the analytic ∫ det J over the reference ball:
        // ∫ (a + b z)² = a² 4πR³/3 + b² 4πR⁵/15; normals point into the teardrop (down
        // the gradient), so the signed volume is negative.
        let r = TEAR_R;
        let exact = TEAR_A * TEAR_A * 4.0 * std::f64::consts::PI * r.powi(3) / 3.0
            + TEAR_B * TEAR_B * 4.0 * std::f64::consts::PI * r.powi(5) / 15.0;
        let v = -m.signed_volume();
        assert!((v - exact).abs() < 0.02 * exact, "volume {v} vs {exact}");
        // Normals: unit, down the analytic gradient.
        for (x, n) in m.positions.iter().zip(&m.normals) {
            let x = DVec3::from(*x);
            let h = 1e-6;
            let g = DVec3::new(
                teardrop_field(x + DVec3::X * h) - teardrop_field(x - DVec3::X * h),
                teardrop_field(x + DVec3::Y * h) - teardrop_field(x - DVec3::Y * h),
                teardrop_field(x + DVec3::Z * h) - teardrop_field(x - DVec3::Z * h),
            );
            assert!(glam::Vec3::from(*n).as_dvec3().dot(g.normalize()) < -0.999);
        }
    }

    #[test]
    fn same_output_for_any_thread_count() {
        let mesh = teardrop();
        let params = McParams {
            iso: 0.5,
            spacing: 0.15,
            ..McParams::default()
        };
        let run = || extract(&mesh, "f", &params, &mut Progress::none()).unwrap();
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap()
            .install(run);
        let many = rayon::ThreadPoolBuilder::new()
            .num_threads(3)
            .build()
            .unwrap()
            .install(run);
        assert_eq!(one.0, many.0);
        assert_eq!(one.1.evaluations, many.1.evaluations);
    }

    #[test]
    fn bad_parameters_and_budget_are_refused() {
        let mesh = teardrop();
        let over = McParams {
            spacing: 1e-4,
            ..McParams::default()
        };
        let e = extract(&mesh, "f", &over, &mut Progress::none()).unwrap_err();
        assert!(matches!(e, Error::OverBudget { .. }), "{e}");
        let nan = McParams {
            iso: f64::NAN,
            ..McParams::default()
        };
        assert!(extract(&mesh, "f", &nan, &mut Progress::none()).is_err());
        // A negative spacing used to pick the default silently; a spacing too fine for
        // the grid named the SPH grid factor.
        for spacing in [-1.0, 1e-9] {
            let p = McParams {
                spacing,
                ..McParams::default()
            };
            let e = extract(&mesh, "f", &p, &mut Progress::none()).unwrap_err();
            assert!(
                matches!(
                    e,
                    Error::InvalidParameter {
                        name: "spacing",
                        ..
                    }
                ) && !e.to_string().contains("grid factor")
                    && (spacing < 0.0 || e.to_string().contains("raise the spacing")),
                "{e}"
            );
        }
        let e = extract(&mesh, "nope", &McParams::default(), &mut Progress::none()).unwrap_err();
        let e = e.to_string();
        assert!(
            e.contains("grid: no point array named 'nope'") && e.contains("point arrays: f"),
            "{e}"
        );
    }
}
