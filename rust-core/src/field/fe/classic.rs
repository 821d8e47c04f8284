//! VTK's linear and quadratic cells read as the Lagrange cells that span the same functions.
//!
//! Most meshes people hold are made of VTK's classic cells (pyvista's `delaunay_3d` and
//! `cast_to_unstructured_grid`, solvers' and gmsh's output, ParaView's Tessellate), not of
//! its Lagrange cells. Each classic cell below interpolates with a space the Lagrange cell
//! of some order spans as well:
//!
//! - tetra, voxel, hexahedron, wedge: order 1, the same nodes in the voxel's other order;
//! - quadratic tetra, triquadratic hexahedron, biquadratic-quadratic wedge: order 2;
//! - quadratic-linear wedge: order 2 on the triangle, 1 along t;
//! - quadratic hexahedron (20 nodes) and quadratic wedge (15): serendipity cells, whose
//!   functions are a subspace of the order-2 Lagrange cell's. The Lagrange cell's missing
//!   face and body nodes are made here, each the serendipity interpolant at that node (a
//!   weighted sum of the cell's nodes, kept in [`Completions`]), so geometry and every point
//!   array interpolate exactly as VTK interpolates the classic cell.
//!
//! Nodes are matched by their parametric coordinates (VTK's `GetParametricCoords`, kept
//! below in halves, checked against VTK's own in the tests), never by a hand-made
//! permutation, so one table per type is all a type needs.

use super::shape::{Kind, Shape};
use glam::{DMat3, DVec3};
use rustc_hash::FxHashMap;
use std::sync::OnceLock;

/// One classic VTK cell type and the Lagrange shape that spans its functions.
struct Classic {
    vtk: u8,
    name: &'static str,
    kind: Kind,
    order: [usize; 3],
    /// Parametric coordinates of the nodes in VTK order, times two (0, 1 or 2): the
    /// first `count` of a table that types whose nodes begin alike share.
    nodes: &'static [[u8; 3]],
    count: usize,
}

const HEX_27: [[u8; 3]; 27] = [
    [0, 0, 0],
    [2, 0, 0],
    [2, 2, 0],
    [0, 2, 0],
    [0, 0, 2],
    [2, 0, 2],
    [2, 2, 2],
    [0, 2, 2],
    [1, 0, 0],
    [2, 1, 0],
    [1, 2, 0],
    [0, 1, 0],
    [1, 0, 2],
    [2, 1, 2],
    [1, 2, 2],
    [0, 1, 2],
    [0, 0, 1],
    [2, 0, 1],
    [2, 2, 1],
    [0, 2, 1],
    [0, 1, 1],
    [2, 1, 1],
    [1, 0, 1],
    [1, 2, 1],
    [1, 1, 0],
    [1, 1, 2],
    [1, 1, 1],
];

const VOXEL: [[u8; 3]; 8] = [
    [0, 0, 0],
    [2, 0, 0],
    [0, 2, 0],
    [2, 2, 0],
    [0, 0, 2],
    [2, 0, 2],
    [0, 2, 2],
    [2, 2, 2],
];

const TETRA_10: [[u8; 3]; 10] = [
    [0, 0, 0],
    [2, 0, 0],
    [0, 2, 0],
    [0, 0, 2],
    [1, 0, 0],
    [1, 1, 0],
    [0, 1, 0],
    [0, 0, 1],
    [1, 0, 1],
    [0, 1, 1],
];

const WEDGE_18: [[u8; 3]; 18] = [
    [0, 0, 0],
    [2, 0, 0],
    [0, 2, 0],
    [0, 0, 2],
    [2, 0, 2],
    [0, 2, 2],
    [1, 0, 0],
    [1, 1, 0],
    [0, 1, 0],
    [1, 0, 2],
    [1, 1, 2],
    [0, 1, 2],
    [0, 0, 1],
    [2, 0, 1],
    [0, 2, 1],
    [1, 0, 1],
    [1, 1, 1],
    [0, 1, 1],
];

const CLASSIC: [Classic; 10] = [
    Classic {
        vtk: 10,
        name: "tetra",
        kind: Kind::Tetrahedron,
        order: [1; 3],
        nodes: &TETRA_10,
        count: 4,
    },
    Classic {
        vtk: 11,
        name: "voxel",
        kind: Kind::Hexahedron,
        order: [1; 3],
        nodes: &VOXEL,
        count: 8,
    },
    Classic {
        vtk: 12,
        name: "hexahedron",
        kind: Kind::Hexahedron,
        order: [1; 3],
        nodes: &HEX_27,
        count: 8,
    },
    Classic {
        vtk: 13,
        name: "wedge",
        kind: Kind::Wedge,
        order: [1; 3],
        nodes: &WEDGE_18,
        count: 6,
    },
    Classic {
        vtk: 24,
        name: "quadratic tetra",
        kind: Kind::Tetrahedron,
        order: [2; 3],
        nodes: &TETRA_10,
        count: 10,
    },
    Classic {
        vtk: 25,
        name: "quadratic hexahedron",
        kind: Kind::Hexahedron,
        order: [2; 3],
        nodes: &HEX_27,
        count: 20,
    },
    Classic {
        vtk: 26,
        name: "quadratic wedge",
        kind: Kind::Wedge,
        order: [2; 3],
        nodes: &WEDGE_18,
        count: 15,
    },
    Classic {
        vtk: 29,
        name: "triquadratic hexahedron",
        kind: Kind::Hexahedron,
        order: [2; 3],
        nodes: &HEX_27,
        count: 27,
    },
    Classic {
        vtk: 31,
        name: "quadratic-linear wedge",
        kind: Kind::Wedge,
        order: [2, 2, 1],
        nodes: &WEDGE_18,
        count: 12,
    },
    Classic {
        vtk: 32,
        name: "biquadratic-quadratic wedge",
        kind: Kind::Wedge,
        order: [2; 3],
        nodes: &WEDGE_18,
        count: 18,
    },
];

impl Classic {
    /// The VTK nodes of this type.
    fn vtk_nodes(&self) -> &'static [[u8; 3]] {
        &self.nodes[..self.count]
    }
}

/// The classic type `ty`, if it is one this module reads.
fn classic(ty: u8) -> Option<&'static Classic> {
    CLASSIC.iter().find(|c| c.vtk == ty)
}

/// The name of a VTK cell type this module reads ("quadratic hexahedron"), for messages.
pub(crate) fn name(ty: u8) -> Option<&'static str> {
    classic(ty).map(|c| c.name)
}

/// VTK's quadratic serendipity cell of `kind` (the 20-node hexahedron, the 15-node wedge):
/// its type and its nodes' parametric coordinates times two, for readers of formats that
/// number the same nodes otherwise.
pub(crate) fn serendipity(kind: Kind) -> Option<(u8, &'static [[u8; 3]])> {
    let ty = match kind {
        Kind::Hexahedron => 25,
        Kind::Wedge => 26,
        Kind::Tetrahedron => return None,
    };
    classic(ty).map(|c| (ty, c.vtk_nodes()))
}

/// Where each Lagrange node of a classic type comes from.
enum Source {
    /// The classic cell's node at this position.
    Node(usize),
    /// The serendipity interpolant at the node: weights of the classic nodes (non-zero only).
    Made(Vec<(usize, f64)>),
}

/// The Lagrange nodes of `c`, in VTK's Lagrange order, by where they come from.
fn sources(c: &Classic) -> Vec<Source> {
    let shape = Shape::new(c.kind, c.order);
    let given = c.vtk_nodes();
    (0..shape.len())
        .map(|n| {
            let u = shape.node_coords(n);
            let halves = [0, 1, 2].map(|k| (u[k] * 2.0).round() as u8);
            match given.iter().position(|&g| g == halves) {
                Some(i) => Source::Node(i),
                None => Source::Made(serendipity_weights(c.kind, given, u)),
            }
        })
        .collect()
}

/// How a classic type becomes its Lagrange cell, worked out once per type.
struct Plan {
    /// For each Lagrange node, the classic node it is (None: made).
    given_at: Vec<Option<usize>>,
    /// The made nodes: Lagrange node index, and weights of the Lagrange nodes (positions
    /// in the cell's node list) that hold the classic nodes it sums.
    made: Vec<(usize, Vec<(usize, f64)>)>,
}

/// The plan of classic type `ty` (cached: built from the shapes once per process).
fn plan(ty: u8) -> Option<&'static Plan> {
    static PLANS: OnceLock<Vec<Plan>> = OnceLock::new();
    let plans = PLANS.get_or_init(|| {
        CLASSIC
            .iter()
            .map(|c| {
                let sources = sources(c);
                let given_at: Vec<Option<usize>> = sources
                    .iter()
                    .map(|s| match s {
                        Source::Node(i) => Some(*i),
                        Source::Made(_) => None,
                    })
                    .collect();
                let position = |i: usize| given_at.iter().position(|&g| g == Some(i)).unwrap();
                let made = sources
                    .iter()
                    .enumerate()
                    .filter_map(|(n, s)| match s {
                        Source::Made(w) => {
                            Some((n, w.iter().map(|&(i, w)| (position(i), w)).collect()))
                        }
                        Source::Node(_) => None,
                    })
                    .collect();
                Plan { given_at, made }
            })
            .collect()
    });
    CLASSIC.iter().position(|c| c.vtk == ty).map(|k| &plans[k])
}

/// The weights of the serendipity interpolant of a 20-node hexahedron or a 15-node wedge
/// at reference point `u`: the standard shape functions, written over the nodes'
/// parametric coordinates so that they follow the table's order.
fn serendipity_weights(kind: Kind, nodes: &[[u8; 3]], u: DVec3) -> Vec<(usize, f64)> {
    let weight = |g: [u8; 3]| -> f64 {
        match kind {
            Kind::Hexahedron => {
                // ξ ∈ [−1, 1]³; a node at ξ_i ∈ {−1, 0, 1}.
                let x = 2.0 * u - DVec3::ONE;
                let xi = DVec3::new(g[0] as f64, g[1] as f64, g[2] as f64) - DVec3::ONE;
                match (0..3).find(|&a| xi[a] == 0.0) {
                    // A corner: ⅛ Π(1 + ξ ξ_i) (ξ·ξ_i − 2).
                    None => {
                        (0..3).map(|a| 1.0 + x[a] * xi[a]).product::<f64>() / 8.0
                            * (x.dot(xi) - 2.0)
                    }
                    // The middle of an edge along axis a: ¼ (1 − ξ_a²) Π_{b≠a} (1 + ξ_b ξ_ib).
                    Some(a) => {
                        (1.0 - x[a] * x[a])
                            * (0..3)
                                .filter(|&b| b != a)
                                .map(|b| 1.0 + x[b] * xi[b])
                                .product::<f64>()
                            / 4.0
                    }
                }
            }
            Kind::Wedge => {
                // Barycentric L on the triangle, ζ ∈ [−1, 1] along t.
                let l = [1.0 - u.x - u.y, u.x, u.y];
                let z = 2.0 * u.z - 1.0;
                let zi = g[2] as f64 - 1.0;
                // The triangle's vertices k (and l for an edge's middle) the node sits at.
                let at = match (g[0], g[1]) {
                    (0, 0) => (0, None),
                    (2, 0) => (1, None),
                    (0, 2) => (2, None),
                    (1, 0) => (0, Some(1)),
                    (1, 1) => (1, Some(2)),
                    _ => (2, Some(0)),
                };
                match (at, zi == 0.0) {
                    // A corner: ½ L_k (2 L_k − 1)(1 + ζ ζ_i) − ½ L_k (1 − ζ²).
                    ((k, None), false) => {
                        0.5 * l[k] * (2.0 * l[k] - 1.0) * (1.0 + z * zi)
                            - 0.5 * l[k] * (1.0 - z * z)
                    }
                    // The middle of a vertical edge: L_k (1 − ζ²).
                    ((k, None), true) => l[k] * (1.0 - z * z),
                    // The middle of a triangle's edge: 2 L_k L_l (1 + ζ ζ_i).
                    ((k, Some(m)), _) => 2.0 * l[k] * l[m] * (1.0 + z * zi),
                }
            }
            Kind::Tetrahedron => unreachable!("every quadratic tetra node is a Lagrange node"),
        }
    };
    let w: Vec<(usize, f64)> = nodes
        .iter()
        .enumerate()
        .map(|(i, &g)| (i, weight(g)))
        .filter(|&(_, w)| w != 0.0)
        .collect();
    debug_assert!((w.iter().map(|p| p.1).sum::<f64>() - 1.0).abs() < 1e-12);
    w
}

/// Points the conversion made (a serendipity cell's face and body nodes), after the given
/// ones: point `given + k` is made node `m` of cell `c` for `made[k] = (c, m)`, the
/// weighted sum its type's [`Plan`] names of the cell's nodes. Every point array is
/// completed by the same sums. Eight bytes a made point, however many nodes it sums.
#[derive(Clone, Debug, Default)]
pub(crate) struct Completions {
    given: usize,
    made: Vec<(u32, u16)>,
}

impl Completions {
    /// No made points among `given`.
    pub(crate) fn none(given: usize) -> Completions {
        Completions {
            given,
            made: Vec::new(),
        }
    }

    /// The number of points the caller gave.
    pub(crate) fn given(&self) -> usize {
        self.given
    }

    /// Appends the made points' values to `data` (the given points' values, item-major),
    /// reading each cell's Lagrange nodes from `nodes` and its given VTK type from `ty`.
    pub(crate) fn complete<'a>(
        &self,
        data: &mut Vec<f64>,
        components: usize,
        nodes: impl Fn(usize) -> &'a [u32],
        ty: impl Fn(usize) -> u8,
    ) {
        debug_assert_eq!(data.len(), self.given * components);
        data.reserve(self.made.len() * components);
        // The points one cell made are listed together: its plan is looked up once.
        for run in self.made.chunk_by(|a, b| a.0 == b.0) {
            let c = run[0].0 as usize;
            let plan = plan(ty(c)).expect("made in a classic cell");
            let cell = nodes(c);
            for &(_, m) in run {
                for j in 0..components {
                    let v = plan.made[m as usize]
                        .1
                        .iter()
                        .map(|&(at, w)| w * data[cell[at] as usize * components + j])
                        .sum();
                    data.push(v);
                }
            }
        }
    }
}

/// Cells in Lagrange form: the arrays `FeMesh::new` reads, with per-cell orders.
pub(crate) struct LagrangeCells {
    pub types: Vec<u8>,
    pub offsets: Vec<usize>,
    pub connectivity: Vec<u32>,
    /// Per cell, its orders, or zeros where the node count decides (as VTK reads a
    /// Lagrange cell without HigherOrderDegrees).
    pub degrees: Vec<[usize; 3]>,
    /// The hexahedra read as wedges, in cell order, with their rotations (see
    /// [`collapsed_to_wedge`]).
    pub collapsed: Vec<(u32, u8)>,
}

/// Rewrites the classic cells among `types` as Lagrange cells, appending the points that
/// serendipity cells lack to `points`; `None` when every cell is already a Lagrange cell
/// (or of a type nobody reads, which the caller refuses). Errors name the cell.
pub(crate) fn to_lagrange(
    types: &[u8],
    offsets: &[usize],
    connectivity: &[u32],
    degrees: Option<&[[usize; 3]]>,
    points: &mut Vec<DVec3>,
    id: &dyn Fn(usize) -> usize,
) -> Result<Option<(LagrangeCells, Completions)>, String> {
    if !types.iter().any(|&t| classic(t).is_some()) {
        return Ok(None);
    }
    let given = points.len();
    let mut cells = LagrangeCells {
        types: Vec::with_capacity(types.len()),
        offsets: Vec::with_capacity(types.len() + 1),
        connectivity: Vec::with_capacity(connectivity.len()),
        degrees: Vec::with_capacity(types.len()),
        collapsed: Vec::new(),
    };
    let mut made = Completions::none(given);
    // A face's made node by the points of that face (sorted; a hexahedron's and a wedge's
    // quadrilateral faces sum eight): made once for the two cells that share the face, so
    // their interpolants stay equal across it. Body nodes belong to one cell.
    let mut on_face: FxHashMap<[u32; 8], u32> = FxHashMap::default();
    cells.offsets.push(0);
    for (c, &ty) in types.iter().enumerate() {
        let g = id(c);
        let (start, end) = (offsets[c], offsets[c + 1]);
        if end < start || end > connectivity.len() {
            return Err(format!(
                "cell {g}: offsets {start}..{end} out of order or range"
            ));
        }
        let nodes = &connectivity[start..end];
        // Against the points the caller gave: a made point must not stand in for an
        // index out of range (the mesh checks again, against every point).
        if let Some(&p) = nodes.iter().find(|&&p| p as usize >= given) {
            return Err(format!(
                "cell {g} refers to point {p}, but there are {given} points"
            ));
        }
        let wedge;
        let (ty, nodes) = match collapsed_to_wedge(ty, nodes) {
            Some((w, rotation)) => {
                wedge = w;
                cells.collapsed.push((c as u32, rotation));
                (VTK_WEDGE, &wedge[..])
            }
            None => (ty, nodes),
        };
        let (Some(k), Some(plan)) = (classic(ty), plan(ty)) else {
            cells.types.push(ty);
            cells.connectivity.extend_from_slice(nodes);
            cells.offsets.push(cells.connectivity.len());
            cells.degrees.push(degrees.map_or([0; 3], |d| d[c]));
            continue;
        };
        let want = k.vtk_nodes().len();
        if nodes.len() != want {
            return Err(format!(
                "cell {g} (VTK {}, type {ty}) has {} nodes, not {want}",
                k.name,
                nodes.len()
            ));
        }
        let first = cells.connectivity.len();
        cells.connectivity.extend(
            plan.given_at
                .iter()
                .map(|g| g.map_or(u32::MAX, |i| nodes[i])),
        );
        for (m, (n, weights)) in plan.made.iter().enumerate() {
            let cell = &cells.connectivity[first..];
            let mut make = || -> Result<u32, String> {
                if points.len() >= u32::MAX as usize {
                    return Err(format!(
                        "cell {g}: the face and body nodes made for the serendipity cells \
                         take the points past 2^32"
                    ));
                }
                let x = weights
                    .iter()
                    .map(|&(at, w)| w * points[cell[at] as usize])
                    .sum();
                points.push(x);
                made.made.push((c as u32, m as u16));
                Ok((points.len() - 1) as u32)
            };
            let p = if weights.len() <= 8 {
                let mut key = [u32::MAX; 8];
                for (slot, &(at, _)) in key.iter_mut().zip(weights) {
                    *slot = cell[at];
                }
                key.sort_unstable();
                match on_face.get(&key) {
                    Some(&p) => p,
                    None => {
                        let p = make()?;
                        on_face.insert(key, p);
                        p
                    }
                }
            } else {
                make()?
            };
            cells.connectivity[first + n] = p;
        }
        cells.types.push(k.kind.vtk_type());
        cells.offsets.push(cells.connectivity.len());
        cells.degrees.push(k.order);
    }
    Ok(Some((cells, made)))
}

/// VTK's linear hexahedron and wedge.
const VTK_HEXAHEDRON: u8 = 12;
const VTK_WEDGE: u8 = 13;

/// A linear hexahedron with two parallel edges of one face collapsed (the same point
/// given for corners 2 and 3 and for 6 and 7, or so under a rotation of the cell) is how
/// Abaqus, ANSYS and their converters write a wedge. It is read as that wedge, the
/// triangles being the two faces that hold one collapsed edge each: the trilinear map and
/// field of the collapsed cell are the wedge's. Returns the wedge's nodes and the rotation
/// (an index into [`hex_rotations`]) that maps the collapse onto 2 = 3, 6 = 7, whose wedge
/// is 0 1 2 4 5 6; the node order keeps the hexahedron's handedness. Coincident corners
/// given as distinct points are not read so: their values may differ.
fn collapsed_to_wedge(ty: u8, nodes: &[u32]) -> Option<([u32; 6], u8)> {
    if ty != VTK_HEXAHEDRON || nodes.len() != 8 {
        return None;
    }
    let collapsed: Vec<[usize; 2]> = HEX_EDGES
        .iter()
        .copied()
        .filter(|&[a, b]| nodes[a] == nodes[b])
        .collect();
    // Any other repetition (a diagonal, a third edge) is no wedge: the mesh's checks name
    // the degenerate cell.
    let repeated = (0..8)
        .flat_map(|a| (a + 1..8).map(move |b| (a, b)))
        .filter(|&(a, b)| nodes[a] == nodes[b])
        .count();
    if collapsed.len() != 2 || repeated != 2 {
        return None;
    }
    let has = |e: [usize; 2]| collapsed.iter().any(|&c| c == e || c == [e[1], e[0]]);
    let (k, (r, _)) = hex_rotations()
        .iter()
        .enumerate()
        .find(|(_, (r, _))| has([r[2], r[3]]) && has([r[6], r[7]]))?;
    Some(([0, 1, 2, 4, 5, 6].map(|i| nodes[r[i]]), k as u8))
}

/// The parametric coordinates in a collapsed hexahedron (see [`collapsed_to_wedge`]) of
/// the point at `u` in its wedge: on the face 0 1 2 3 with 2 = 3, the bilinear map
/// (1−ξ)(1−η)x0 + ξ(1−η)x1 + η x2 is the wedge's (1−r−s)x0 + r x1 + s x2 for r = ξ(1−η),
/// s = η, and ζ = t; then the rotation takes them to the cell as given.
pub(crate) fn collapsed_reference(rotation: u8, u: DVec3) -> DVec3 {
    let (_, m) = &hex_rotations()[rotation as usize];
    // On the collapsed edge (s = 1) every ξ is the same point.
    let xi = if u.y < 1.0 { u.x / (1.0 - u.y) } else { 0.0 };
    let half = DVec3::splat(0.5);
    *m * (DVec3::new(xi, u.y, u.z) - half) + half
}

/// The hexahedron's twelve edges by corner (VTK order).
const HEX_EDGES: [[usize; 2]; 12] = [
    [0, 1],
    [1, 2],
    [2, 3],
    [3, 0],
    [4, 5],
    [5, 6],
    [6, 7],
    [7, 4],
    [0, 4],
    [1, 5],
    [2, 6],
    [3, 7],
];

/// The 24 rotations of the reference hexahedron about its centre: the corner map (corner i
/// to corner r[i]) and the matrix. Made from the signed axis permutations of determinant +1.
fn hex_rotations() -> &'static [([usize; 8], DMat3)] {
    static ROTATIONS: OnceLock<Vec<([usize; 8], DMat3)>> = OnceLock::new();
    ROTATIONS.get_or_init(|| {
        let corners = Kind::Hexahedron.corners();
        let corner = |p: DVec3| {
            corners
                .iter()
                .position(|c| DVec3::from(*c).distance(p) < 1e-9)
                .expect("a rotation maps corners to corners")
        };
        let mut out = Vec::new();
        for axes in [
            [0, 1, 2],
            [1, 2, 0],
            [2, 0, 1],
            [0, 2, 1],
            [2, 1, 0],
            [1, 0, 2],
        ] {
            for signs in 0..8 {
                let m = DMat3::from_cols_array_2d(&[0, 1, 2].map(|col| {
                    let mut v = [0.0; 3];
                    v[axes[col]] = if signs >> col & 1 == 1 { -1.0 } else { 1.0 };
                    v
                }));
                if m.determinant() < 0.0 {
                    continue;
                }
                let half = DVec3::splat(0.5);
                let map =
                    std::array::from_fn(|i| corner(m * (DVec3::from(corners[i]) - half) + half));
                out.push((map, m));
            }
        }
        out
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::fe::{FeMesh, Scratch};
    use crate::field::particles::Attribute;

    #[test]
    fn tables_are_vtks_parametric_coordinates() {
        let text = include_str!("../../../data/fe/vtk_classic_nodes.txt");
        let mut seen = 0;
        for line in text.lines().filter(|l| !l.starts_with('#')) {
            let v: Vec<f64> = line
                .split_whitespace()
                .map(|x| x.parse().unwrap())
                .collect();
            let c = classic(v[0] as u8).expect("a type classic.rs reads");
            let n = v[1] as usize;
            assert_eq!(c.vtk_nodes().len(), n, "{}", c.name);
            for (k, g) in c.vtk_nodes().iter().enumerate() {
                let vtk = [0, 1, 2].map(|a| v[2 + 3 * k + a] * 2.0);
                assert_eq!(g.map(f64::from), vtk, "{} node {k}", c.name);
            }
            seen += 1;
        }
        assert_eq!(seen, CLASSIC.len());
    }

    /// Every classic type's tables: its Lagrange shape has a node at each of the type's
    /// positions, and a made node's weights reproduce every quadratic (the serendipity
    /// space holds all of them).
    #[test]
    fn tables_fit_their_lagrange_shapes() {
        for c in &CLASSIC {
            let sources = sources(c);
            let shape = Shape::new(c.kind, c.order);
            assert_eq!(sources.len(), shape.len(), "{}", c.name);
            let mut used = vec![false; c.vtk_nodes().len()];
            for (n, s) in sources.iter().enumerate() {
                let u = shape.node_coords(n);
                match s {
                    Source::Node(i) => {
                        assert!(!std::mem::replace(&mut used[*i], true), "{}", c.name);
                    }
                    Source::Made(w) => {
                        assert!(c.vtk == 25 || c.vtk == 26, "{} made a node", c.name);
                        let at: f64 = w.iter().map(|&(i, w)| w * quadratic(reference(c, i))).sum();
                        assert!(
                            (at - quadratic(u)).abs() < 1e-13,
                            "{}: {at} vs {}",
                            c.name,
                            quadratic(u)
                        );
                    }
                }
            }
            assert!(used.iter().all(|&u| u), "{}: a VTK node is unused", c.name);
        }
    }

    fn reference(c: &Classic, i: usize) -> DVec3 {
        DVec3::from_array(c.vtk_nodes()[i].map(|h| h as f64 / 2.0))
    }

    fn quadratic(x: DVec3) -> f64 {
        1.0 + x.x - 2.0 * x.y * x.z + x.x * x.x + 0.5 * x.z * x.z - 0.7 * x.x * x.y
    }

    fn linear(x: DVec3) -> f64 {
        0.3 + x.x - 2.0 * x.y + 0.5 * x.z
    }

    /// A sheared, rotated, translated map, so no coordinate of a node equals its
    /// parametric one.
    fn affine(u: DVec3) -> DVec3 {
        DVec3::new(
            2.0 * u.x + 0.5 * u.y - 0.2 * u.z,
            1.5 * u.y - 0.3 * u.z + 0.1 * u.x,
            1.2 * u.z + 0.4 * u.x,
        ) + DVec3::new(-0.5, 0.25, 3.0)
    }

    /// Inside the reference cell of `kind`, away from its faces.
    fn inside(kind: Kind) -> Vec<DVec3> {
        let mut out = Vec::new();
        for a in [0.1, 0.3, 0.55] {
            for b in [0.15, 0.4] {
                for t in [0.05, 0.5, 0.9] {
                    let u = DVec3::new(a, b * (1.0 - a), t);
                    let ok = match kind {
                        Kind::Hexahedron | Kind::Wedge => true,
                        Kind::Tetrahedron => u.x + u.y + u.z < 1.0,
                    };
                    if ok {
                        out.push(u);
                    }
                }
            }
        }
        out
    }

    /// One cell of each classic type, its nodes the affine image of VTK's parametric
    /// coordinates and its field a function of them in the type's space (linear for the
    /// linear types, quadratic for the others, quadratic on the triangle times linear in t
    /// for the quadratic-linear wedge): the Lagrange cell made of it reproduces both at
    /// points inside, so a node put in the wrong place, or a made node's wrong weight,
    /// shows.
    #[test]
    fn classic_cells_interpolate_what_vtk_interpolates() {
        for c in &CLASSIC {
            let f = |u: DVec3| match c.order {
                [1, 1, 1] => linear(u),
                [2, 2, 1] => quadratic(u.with_z(0.0)) * (1.0 + 0.5 * u.z),
                _ => quadratic(u),
            };
            let points: Vec<DVec3> = (0..c.count).map(|i| affine(reference(c, i))).collect();
            let values: Vec<f64> = (0..c.count).map(|i| f(reference(c, i))).collect();
            let mesh = FeMesh::new(
                c.name,
                points,
                &[c.vtk],
                &[0, c.count],
                (0..c.count as u32).collect(),
                None,
                vec![Attribute::scalar("f", values)],
            )
            .unwrap_or_else(|e| panic!("{}: {e}", c.name));
            assert_eq!(mesh.given_points(), c.count, "{}", c.name);
            assert_eq!(mesh.shape(0).kind, c.kind);
            assert_eq!(mesh.shape(0).order, c.order);
            let mut sc = Scratch::default();
            let v = &mesh.point_data[0].data;
            for u in inside(c.kind) {
                let e = mesh.evaluate(v, 0, u, &mut sc);
                assert!((e.x - affine(u)).length() < 1e-12, "{} at {u}", c.name);
                assert!(
                    (e.value - f(u)).abs() < 1e-12,
                    "{} at {u}: {} vs {}",
                    c.name,
                    e.value,
                    f(u)
                );
            }
        }
    }

    /// Two 20-node hexahedra sharing a face: the face's made node is made once (one point,
    /// in both cells), the faces pair, and arrays added later are completed with it.
    #[test]
    fn a_shared_face_node_is_made_once() {
        let c = classic(25).unwrap();
        let mut points: Vec<DVec3> = (0..20).map(|i| affine(reference(c, i))).collect();
        // The second cell is the first moved by one along r: its face r = 0 is the first's
        // face r = 1. Its other nodes are new points.
        let shift = affine(DVec3::X) - affine(DVec3::ZERO);
        let mut second = Vec::new();
        for i in 0..20 {
            let g = c.vtk_nodes()[i];
            if g[0] == 0 {
                let twin = c
                    .vtk_nodes()
                    .iter()
                    .position(|h| *h == [2, g[1], g[2]])
                    .unwrap();
                second.push(twin as u32);
            } else {
                points.push(points[i] + shift);
                second.push(points.len() as u32 - 1);
            }
        }
        let given = points.len();
        let mut connectivity: Vec<u32> = (0..20).collect();
        connectivity.extend(&second);
        let mut mesh = FeMesh::new(
            "two",
            points,
            &[25, 25],
            &[0, 20, 40],
            connectivity,
            None,
            Vec::new(),
        )
        .unwrap();
        // 6 faces and a body each, less the one face they share.
        assert_eq!(mesh.points.len(), given + 2 * 7 - 1);
        assert_eq!(mesh.given_points(), given);
        // An array added later at the given points is completed like the geometry.
        let q: Vec<f64> = mesh.points[..given].iter().map(|&x| quadratic(x)).collect();
        mesh.add_point_array(Attribute::scalar("q", q)).unwrap();
        let added = &mesh.point_data[0].data;
        for (k, &x) in mesh.points.iter().enumerate() {
            assert!((added[k] - quadratic(x)).abs() < 1e-12, "point {k}");
        }
        let short = Attribute::scalar("short", vec![0.0; given - 1]);
        assert!(mesh.add_point_array(short).is_err());
        assert!(mesh.neighbour(0, 1).is_some(), "the shared face pairs");
    }

    #[test]
    fn a_classic_cell_with_the_wrong_node_count_is_named() {
        let points: Vec<DVec3> = (0..10)
            .map(|i| DVec3::new(i as f64, (i * i) as f64, 1.0))
            .collect();
        let e = FeMesh::new(
            "m",
            points,
            &[12, 24],
            &[0, 8, 17],
            (0..17).map(|i| i % 10).collect(),
            None,
            Vec::new(),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("cell 1 (VTK quadratic tetra, type 24) has 9 nodes, not 10"),
            "{e}"
        );
        let e = FeMesh::new(
            "m",
            vec![DVec3::ZERO; 5],
            &[14],
            &[0, 5],
            (0..5).collect(),
            None,
            Vec::new(),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("cell 0 has VTK type 14 (a pyramid), which isobar does not read"),
            "{e}"
        );
        assert!(!e.contains("no volume cell"), "{e}");
        // Only a triangle: nothing to sample, and the message says why.
        let e = FeMesh::new(
            "m",
            vec![DVec3::ZERO, DVec3::X, DVec3::Y],
            &[5],
            &[0, 3],
            (0..3).collect(),
            None,
            Vec::new(),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("cell 0 has VTK type 5 (a triangle)") && e.contains("no volume cell"),
            "{e}"
        );
        // A Lagrange cell beside a serendipity one may not reach the points made for it.
        let hex20 = classic(25).unwrap();
        let mut points: Vec<DVec3> = (0..20).map(|i| reference(hex20, i)).collect();
        points.push(DVec3::new(3.0, 0.0, 0.0));
        let e = FeMesh::new(
            "m",
            points,
            &[25, 71],
            &[0, 20, 24],
            (0..20).chain([20, 1, 3, 21]).collect(),
            None,
            Vec::new(),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("cell 1 refers to point 21, but there are 21 points"),
            "{e}"
        );
        // A wedge whose triangles run the other way, beside an upright one: the hint says
        // how to mend it.
        let wedge = classic(13).unwrap();
        let upright: Vec<DVec3> = (0..6).map(|i| reference(wedge, i)).collect();
        let mut flipped: Vec<DVec3> = upright.iter().map(|p| *p + DVec3::X * 2.0).collect();
        flipped.swap(1, 2);
        flipped.swap(4, 5);
        let e = FeMesh::new(
            "m",
            [upright, flipped].concat(),
            &[13, 13],
            &[0, 6, 12],
            (0..12).collect(),
            None,
            Vec::new(),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("(VTK wedge) is inverted")
                && e.contains("swap its second and third corners"),
            "{e}"
        );
        // Checks name the cell as given. A mirrored hexahedron alone is a mesh mirrored
        // as a whole, and is read; after an upright one, it is refused.
        let hex = classic(12).unwrap();
        let cube: Vec<DVec3> = (0..8).map(|i| reference(hex, i)).collect();
        let mirrored: Vec<DVec3> = cube
            .iter()
            .map(|p| p * DVec3::new(-1.0, 1.0, 1.0))
            .collect();
        let alone = FeMesh::new(
            "m",
            mirrored.clone(),
            &[12],
            &[0, 8],
            (0..8).collect(),
            None,
            Vec::new(),
        );
        assert!(alone.is_ok(), "{:?}", alone.err());
        let e = FeMesh::new(
            "m",
            [cube.clone(), mirrored].concat(),
            &[12, 12],
            &[0, 8, 16],
            (0..16).collect(),
            None,
            Vec::new(),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("cell 1 (VTK hexahedron) is inverted") && e.contains("while cell 0 is not"),
            "{e}"
        );
        let mut collapsed = cube.clone();
        collapsed[1] = collapsed[0];
        let e = FeMesh::new(
            "m",
            collapsed,
            &[12],
            &[0, 8],
            (0..8).collect(),
            None,
            Vec::new(),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("cell 0 (VTK hexahedron) is degenerate: its corners 0 and 1 (points 0 and 1) are at the same place"),
            "{e}"
        );
    }

    /// A hexahedron given with corners 2 = 3 and 6 = 7, and three other collapses of two
    /// parallel edges of one face, is read as a wedge: the mesh's map at each of its reference points is the trilinear map
    /// of the hexahedron as given at `given_reference` of that point, and a field trilinear
    /// in the hexahedron is reproduced. Mirrored, it keeps its handedness (read as a mesh
    /// mirrored as a whole); with two distinct points at one place, it stays degenerate.
    #[test]
    fn a_hexahedron_with_two_collapsed_edges_is_its_wedge() {
        let hex = classic(12).unwrap();
        let cube: Vec<DVec3> = (0..8).map(|i| reference(hex, i)).collect();
        // Bent a little, so no symmetry hides a wrong corner.
        let bend = |p: DVec3| p + DVec3::new(0.1 * p.y * p.z, 0.05 * p.x, 0.2 * p.x * p.y);
        let trilinear = |x: &[DVec3], p: DVec3| -> DVec3 {
            (0..8)
                .map(|i| {
                    let c = reference(hex, i);
                    let w = |a: f64, b: f64| if b == 1.0 { a } else { 1.0 - a };
                    x[i] * (w(p.x, c.x) * w(p.y, c.y) * w(p.z, c.z))
                })
                .sum()
        };
        for (a, b) in [
            ([2, 3], [6, 7]),
            ([1, 2], [5, 6]),
            ([4, 7], [5, 6]),
            ([0, 4], [1, 5]),
        ] {
            for mirror in [1.0, -1.0] {
                let mut x: Vec<DVec3> = cube
                    .iter()
                    .map(|&p| bend(p) * DVec3::new(mirror, 1.0, 1.0))
                    .collect();
                x[a[1]] = x[a[0]];
                x[b[1]] = x[b[0]];
                let mut conn: Vec<u32> = (0..8).collect();
                conn[a[1]] = a[0] as u32;
                conn[b[1]] = b[0] as u32;
                let f: Vec<f64> = x.iter().map(|p| linear(*p)).collect();
                let mesh = FeMesh::new(
                    "m",
                    x.clone(),
                    &[12],
                    &[0, 8],
                    conn,
                    None,
                    vec![Attribute {
                        name: "f".into(),
                        components: 1,
                        data: f,
                    }],
                )
                .unwrap_or_else(|e| panic!("{a:?} {b:?} mirror {mirror}: {e}"));
                assert_eq!(mesh.shape(0).kind, Kind::Wedge);
                let mut sc = Scratch::default();
                for u in inside(Kind::Wedge) {
                    let e = mesh.evaluate(&mesh.point_data[0].data, 0, u, &mut sc);
                    let given = mesh.given_reference(0, u);
                    let want = trilinear(&x, given);
                    assert!(
                        e.x.distance(want) < 1e-12,
                        "{a:?} {b:?} mirror {mirror} at {u}: {} vs {want}",
                        e.x
                    );
                    assert!(given.min_element() >= -1e-12 && given.max_element() <= 1.0 + 1e-12);
                    // A field linear in space is trilinear in the cell: reproduced.
                    assert!((e.value - linear(e.x)).abs() < 1e-12);
                }
            }
        }
        // Distinct points at one place: not read as a wedge.
        let mut x = cube.clone();
        x[3] = x[2];
        x[7] = x[6];
        let e = FeMesh::new("m", x, &[12], &[0, 8], (0..8).collect(), None, Vec::new())
            .unwrap_err()
            .to_string();
        assert!(e.contains("degenerate"), "{e}");
    }
}
