//! A mesh of Lagrange cells with a scalar field on its nodes: the mapping T, its Jacobian
//! and second derivatives, the world-space gradient and Hessian of the field (the paper's
//! eqs. 19–20), element validity and face adjacency.

use super::basis::{outer, BasisValues};
use super::bernstein::{control_map, ControlMap};
use super::classic::{self, Completions};
use super::search::{CellIndex, PROBE_SLACK};
use super::shape::{Kind, Shape};
use crate::error::{Error, Result};
use crate::field::particles::Attribute;
use glam::{DMat3, DVec3};
use rustc_hash::FxHashMap;
use std::borrow::Cow;
use std::sync::{Arc, OnceLock};

/// No neighbour across a face (the domain boundary).
pub(crate) const NO_NEIGHBOUR: u32 = u32::MAX;

/// Lagrange cells over shared points, with per-point arrays.
#[derive(Clone, Debug)]
pub struct FeMesh {
    pub points: Vec<DVec3>,
    /// Distinct (kind, order) shapes; cells refer to them by index.
    shapes: Vec<Shape>,
    /// Each shape's Lagrange-to-Bernstein conversion (see `bernstein.rs`).
    controls: Vec<Arc<ControlMap>>,
    cell_shape: Vec<u16>,
    /// Cell c's nodes are `connectivity[offsets[c]..offsets[c + 1]]`, in VTK order.
    offsets: Vec<usize>,
    connectivity: Vec<u32>,
    /// For cell c and face f: (neighbour cell, its face index), or NO_NEIGHBOUR.
    neighbours: Vec<[(u32, u8); 6]>,
    /// Each point's representative among the cell corners at the same place (itself
    /// unless the file repeats shared nodes per cell, as MFEM's ParaView output does).
    weld: Vec<u32>,
    /// Per cell, an axis-aligned box that contains the whole cell (see [`FeMesh::cell_box`]).
    boxes: Vec<(DVec3, DVec3)>,
    /// The union of `boxes`.
    hull: (DVec3, DVec3),
    /// Arrays given per point (the candidates for the field), completed over the points
    /// the mesh made itself (see `completions`): add one with
    /// [`FeMesh::add_point_array`], which completes it.
    pub point_data: Vec<Attribute>,
    /// The points made for VTK's serendipity cells (after the given ones), and how.
    completions: Completions,
    /// Each cell's VTK type as given, where some were linear or quadratic cells (else
    /// empty: the types are the shapes').
    given_types: Vec<u8>,
    /// Hexahedra with two collapsed edges, read as wedges: (cell, rotation), in cell order
    /// (see `classic::collapsed_to_wedge`).
    collapsed: Vec<(u32, u8)>,
    /// What error messages call the data (the file name).
    name: String,
    /// Each cell's index among the cells as given, where the vertex, line and surface
    /// cells a mesher writes beside the volume cells were left out (else empty).
    given_cells: Vec<u32>,
    /// How many cells were left out that way.
    left_out: usize,
    /// Point location, built on first need (probes, the marching baseline, and particles
    /// the walk across faces loses) and kept while the mesh is.
    index: OnceLock<CellIndex>,
}

/// Everything the particle system needs at one point of one cell.
#[derive(Clone, Copy, Debug, Default)]
pub struct Evaluation {
    /// World position T(u).
    pub x: DVec3,
    /// J = ∂x/∂u (columns ∂x/∂r, ∂x/∂s, ∂x/∂t).
    pub jacobian: DMat3,
    /// F*(u) = F(T(u)).
    pub value: f64,
    /// F*_u.
    pub grad_ref: DVec3,
    /// F_x = Kᵀ F*_u (eq. 19).
    pub grad: DVec3,
    /// F_xx (eq. 20).
    pub hessian: DMat3,
}

impl Evaluation {
    /// K = J⁻¹.
    pub fn inverse_jacobian(&self) -> DMat3 {
        self.jacobian.inverse()
    }
}

/// Reusable evaluation buffers (one per thread).
#[derive(Clone, Debug, Default)]
pub struct Scratch {
    basis: BasisValues,
    /// Control values and a row buffer for [`FeMesh::field_range`].
    control: Vec<f64>,
    row: Vec<f64>,
}

impl FeMesh {
    /// Builds a mesh from VTK-style arrays: `points`, per-cell VTK `types`, `offsets`
    /// (cell c's nodes are `connectivity[offsets[c]..offsets[c+1]]`, offsets.len() = cells + 1),
    /// optional per-cell `degrees` (VTK's HigherOrderDegrees), and per-point arrays. `name`
    /// is what error messages call the data. Lagrange cells are read as they are, VTK's
    /// linear and quadratic cells as the Lagrange cells of the same functions (see
    /// `classic.rs`), a linear hexahedron with two collapsed edges as its wedge. Checks
    /// indices, node counts and that no element is degenerate or inverted (det J of one
    /// sign at every node; see `check_elements`).
    ///
    /// Vertex, line and surface cells given beside volume cells are left out unchecked;
    /// the mesh's own cell numbering (`cell_count`, `nodes`, `shape`, `evaluate`) is then
    /// that of the volume cells alone, while messages, the samples' Element and probes
    /// count the cells as given ([`FeMesh::given_cell`]).
    pub fn new(
        name: &str,
        points: Vec<DVec3>,
        types: &[u8],
        offsets: &[usize],
        connectivity: Vec<u32>,
        degrees: Option<&[[usize; 3]]>,
        point_data: Vec<Attribute>,
    ) -> Result<FeMesh> {
        let bad = |m: String| Error::InvalidInput(format!("{name}: {m}"));
        if offsets.len() != types.len() + 1 {
            return Err(bad(format!(
                "{} cell types but {} offsets",
                types.len(),
                offsets.len().saturating_sub(1)
            )));
        }
        if types.is_empty() {
            return Err(bad("no cells".into()));
        }
        if let Some(d) = degrees {
            if d.len() != types.len() {
                return Err(bad(format!(
                    "{} HigherOrderDegrees for {} cells",
                    d.len(),
                    types.len()
                )));
            }
        }
        // Meshers write the boundary faces, edges and vertices (their physical groups)
        // beside the volume cells: leave those out, keeping each volume cell's index as
        // given for messages and the samples' Element.
        let volume = types.iter().filter(|&&t| !below_3d(t)).count();
        if volume == 0 || volume == types.len() {
            return Self::build(
                name,
                points,
                types,
                offsets,
                connectivity,
                degrees,
                point_data,
                Vec::new(),
            );
        }
        let mut kept = Vec::with_capacity(volume);
        let (mut kept_types, mut kept_offsets) = (Vec::with_capacity(volume), vec![0]);
        let mut kept_nodes = Vec::with_capacity(connectivity.len());
        let mut kept_degrees = Vec::new();
        for (c, &ty) in types.iter().enumerate() {
            if below_3d(ty) {
                continue;
            }
            let (start, end) = (offsets[c], offsets[c + 1]);
            if end < start || end > connectivity.len() {
                return Err(bad(format!(
                    "cell {c}: offsets {start}..{end} out of order or range"
                )));
            }
            kept.push(c as u32);
            kept_types.push(ty);
            kept_nodes.extend_from_slice(&connectivity[start..end]);
            kept_offsets.push(kept_nodes.len());
            if let Some(d) = degrees {
                kept_degrees.push(d[c]);
            }
        }
        let mut mesh = Self::build(
            name,
            points,
            &kept_types,
            &kept_offsets,
            kept_nodes,
            degrees.map(|_| &kept_degrees[..]),
            point_data,
            kept,
        )?;
        mesh.left_out = types.len() - volume;
        Ok(mesh)
    }

    /// [`FeMesh::new`] once the cells are all volume cells, or all lower-dimensional (which
    /// is refused); `given_cells` maps each cell to its index as given (empty: the same).
    #[allow(clippy::too_many_arguments)]
    fn build(
        name: &str,
        mut points: Vec<DVec3>,
        types: &[u8],
        offsets: &[usize],
        connectivity: Vec<u32>,
        degrees: Option<&[[usize; 3]]>,
        mut point_data: Vec<Attribute>,
        given_cells: Vec<u32>,
    ) -> Result<FeMesh> {
        let bad = |m: String| Error::InvalidInput(format!("{name}: {m}"));
        // Messages name a cell by its index as given.
        let id = |c: usize| given_cells.get(c).map_or(c, |&g| g as usize);
        if let Some(p) = points.iter().position(|p| !p.is_finite()) {
            return Err(bad(format!("point {p} has a non-finite coordinate")));
        }
        for a in &point_data {
            if a.data.len() != points.len() * a.components {
                return Err(bad(format!(
                    "point array '{}' has {} values for {} points",
                    a.name,
                    a.data.len(),
                    points.len()
                )));
            }
        }
        let converted =
            classic::to_lagrange(types, offsets, &connectivity, degrees, &mut points, &id)
                .map_err(bad)?;
        let given_types = match converted {
            Some(_) => types.to_vec(),
            None => Vec::new(),
        };
        // The caller's types and degrees are borrowed where no cell was converted.
        let (types, offsets, connectivity, degrees, completions, collapsed) = match converted {
            Some((cells, completions)) => (
                Cow::Owned(cells.types),
                cells.offsets,
                cells.connectivity,
                Some(Cow::Owned(cells.degrees)),
                completions,
                cells.collapsed,
            ),
            None => (
                Cow::Borrowed(types),
                offsets.to_vec(),
                connectivity,
                degrees.map(Cow::Borrowed),
                Completions::none(points.len()),
                Vec::new(),
            ),
        };
        let degrees = degrees.as_deref();
        let mut shapes: Vec<Shape> = Vec::new();
        let mut cell_shape = Vec::with_capacity(types.len());
        for (c, &ty) in types.iter().enumerate() {
            let g = id(c);
            let kind = Kind::from_vtk(ty).ok_or_else(|| {
                bad(format!(
                    "cell {g} has VTK type {ty}{}, which isobar does not read: it reads \
                     Lagrange hexahedra, tetrahedra and wedges (72, 71, 73), and tetra, voxel, \
                     hexahedron, wedge and their quadratic forms (10–13, 24–26, 29, 31, 32){}",
                    unread_name(ty),
                    if below_3d(ty) {
                        "; the mesh holds no volume cell (beside volume cells, the boundary \
                         faces, edges and vertices a mesher writes are left out)"
                    } else {
                        ""
                    }
                ))
            })?;
            let (start, end) = (offsets[c], offsets[c + 1]);
            if end < start || end > connectivity.len() {
                return Err(bad(format!(
                    "cell {g}: offsets {start}..{end} out of order or range"
                )));
            }
            let n = end - start;
            let order = match degrees.map(|d| d[c]) {
                Some(d) if d.iter().all(|&x| x > 0) => {
                    let o = match kind {
                        Kind::Hexahedron => d,
                        Kind::Tetrahedron => [d[0]; 3],
                        Kind::Wedge => [d[0], d[0], d[2]],
                    };
                    if kind.node_count(o) != n {
                        return Err(bad(format!(
                            "cell {g} ({}): HigherOrderDegrees {:?} need {} nodes, the cell has {n}",
                            kind.name(),
                            d,
                            kind.node_count(o)
                        )));
                    }
                    o
                }
                _ => {
                    let p = kind.order_from_count(n).ok_or_else(|| {
                        bad(format!(
                            "cell {g} ({}) has {n} nodes, which matches no order",
                            kind.name()
                        ))
                    })?;
                    [p; 3]
                }
            };
            if order.iter().any(|&o| o > 16) {
                return Err(bad(format!(
                    "cell {g}: order {order:?} is above the supported 16"
                )));
            }
            let s = match shapes
                .iter()
                .position(|s| s.kind == kind && s.order == order)
            {
                Some(s) => s,
                None => {
                    shapes.push(Shape::new(kind, order));
                    shapes.len() - 1
                }
            };
            cell_shape.push(s as u16);
            if let Some(&bad_node) = connectivity[start..end]
                .iter()
                .find(|&&i| i as usize >= points.len())
            {
                return Err(bad(format!(
                    "cell {g} refers to point {bad_node}, but there are {} points",
                    points.len()
                )));
            }
        }
        let mut mesh = FeMesh {
            points,
            controls: shapes.iter().map(control_map).collect(),
            shapes,
            cell_shape,
            offsets,
            connectivity,
            neighbours: Vec::new(),
            weld: Vec::new(),
            boxes: Vec::new(),
            hull: (DVec3::ZERO, DVec3::ZERO),
            point_data: Vec::new(),
            completions,
            given_types,
            collapsed,
            name: name.to_string(),
            given_cells,
            left_out: 0,
            index: OnceLock::new(),
        };
        for a in &mut point_data {
            mesh.complete(&mut a.data, a.components);
        }
        mesh.point_data = point_data;
        mesh.check_elements(name)?;
        mesh.boxes = mesh.cell_boxes();
        mesh.hull = mesh
            .boxes
            .iter()
            .fold(mesh.boxes[0], |(l, h), b| (l.min(b.0), h.max(b.1)));
        mesh.weld = mesh.weld_corners();
        mesh.neighbours = mesh.face_adjacency();
        Ok(mesh)
    }

    /// The number of points the mesh was given (the points it made for serendipity cells
    /// come after them, and hosts never see them).
    pub fn given_points(&self) -> usize {
        self.completions.given()
    }

    /// Adds (or replaces) a point array given at the [`FeMesh::given_points`] points,
    /// completed over the points the mesh made.
    pub fn add_point_array(&mut self, mut array: Attribute) -> Result<()> {
        let given = self.given_points();
        if array.components == 0 || array.data.len() != given * array.components {
            return Err(Error::InvalidInput(format!(
                "{}: point array '{}' has {} values for {given} points × {} components",
                self.name,
                array.name,
                array.data.len(),
                array.components
            )));
        }
        self.complete(&mut array.data, array.components);
        self.point_data.retain(|a| a.name != array.name);
        self.point_data.push(array);
        Ok(())
    }

    /// Appends to `data` (values at the given points) those at the points the mesh made.
    fn complete(&self, data: &mut Vec<f64>, components: usize) {
        self.completions
            .complete(data, components, |c| self.nodes(c), |c| self.given_types[c]);
    }

    /// What error messages call the data (the file it was read from).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Number of cells.
    pub fn cell_count(&self) -> usize {
        self.cell_shape.len()
    }

    /// The mesh's point location, built the first time it is asked for.
    pub fn index(&self) -> &CellIndex {
        self.index.get_or_init(|| CellIndex::new(self))
    }

    /// Whether point `p` is a node of some cell (of the volume cells: points only the
    /// left-out cells use, or none, are not).
    pub fn used_points(&self) -> Vec<bool> {
        let mut used = vec![false; self.points.len()];
        for &n in &self.connectivity {
            used[n as usize] = true;
        }
        used
    }

    /// Cell `c`'s index among the cells as given (which may hold vertex, line and surface
    /// cells the mesh left out): what messages and the samples' Element call it.
    pub fn given_cell(&self, c: usize) -> usize {
        self.given_cells.get(c).map_or(c, |&g| g as usize)
    }

    /// A warning that says which cells were left out, if any were (without the mesh's
    /// name: hosts and the CLI say which data a warning is about).
    pub fn left_out_warning(&self) -> Option<String> {
        (self.left_out > 0).then(|| {
            format!(
                "{} vertex, line and surface cell(s) left out (the boundary groups a mesher \
                 writes beside the volume); the {} volume cells are sampled",
                self.left_out,
                self.cell_count()
            )
        })
    }

    /// The shape of cell `c`.
    pub fn shape(&self, c: usize) -> &Shape {
        &self.shapes[self.cell_shape[c] as usize]
    }

    /// The coordinates of reference point `u` of cell `c` in the cell as the caller gave
    /// it: `u` itself, except in a collapsed hexahedron read as a wedge, where they are the
    /// hexahedron's parametric coordinates (what VTK's own cell takes).
    pub fn given_reference(&self, c: usize, u: DVec3) -> DVec3 {
        match self
            .collapsed
            .binary_search_by_key(&(c as u32), |&(cell, _)| cell)
        {
            Ok(k) => classic::collapsed_reference(self.collapsed[k].1, u),
            Err(_) => u,
        }
    }

    /// Node (point) indices of cell `c` in VTK order.
    pub fn nodes(&self, c: usize) -> &[u32] {
        &self.connectivity[self.offsets[c]..self.offsets[c + 1]]
    }

    /// An axis-aligned box that contains every cell: the union of the [`FeMesh::cell_box`]es.
    /// Larger than the nodes' box where curved cells bulge past their nodes (Lagrange cells
    /// are not inside their nodes' hull), so a grid over it reaches every cell.
    pub fn bounds(&self) -> (DVec3, DVec3) {
        self.hull
    }

    /// An axis-aligned box that provably contains cell `c`: the box of the control points
    /// of its mapping in Bernstein form (the cell is in their convex hull; see
    /// `bernstein.rs`), widened for rounding.
    pub fn cell_box(&self, c: usize) -> (DVec3, DVec3) {
        self.boxes[c]
    }

    /// An interval that provably holds the point array `values` over cell `c`: its
    /// Bernstein coefficients' range (the field is their convex combination, as the cell's
    /// points are of its control points; see `bernstein.rs`), widened for rounding. The
    /// nodal values alone do not bound it: a quadratic cell's field dips between nodes.
    pub fn field_range(&self, values: &[f64], c: usize, scratch: &mut Scratch) -> (f64, f64) {
        let map = &self.controls[self.cell_shape[c] as usize];
        let nodes = self.nodes(c).iter().map(|&n| values[n as usize]);
        let (lo, hi, slack) = map.control_range(nodes, &mut scratch.control, &mut scratch.row);
        (lo - slack, hi + slack)
    }

    /// [`FeMesh::cell_box`] of every cell.
    fn cell_boxes(&self) -> Vec<(DVec3, DVec3)> {
        let (mut x, mut row) = (Vec::new(), Vec::new());
        (0..self.cell_count())
            .map(|c| {
                let map = &self.controls[self.cell_shape[c] as usize];
                let nodes = self.nodes(c).iter().map(|&n| self.points[n as usize]);
                let (lo, hi, slack) = map.control_range(nodes, &mut x, &mut row);
                // More slack, so the box holds every point the search accepts in this cell:
                // - the search takes points up to PROBE_SLACK (δ = 1e-8) outside the
                //   reference domain (on the mesh boundary, surface points lie a rounding
                //   error outside their cell). A Bézier polynomial's derivative along a
                //   reference direction (r, s, t, or one barycentric coordinate against
                //   another) is p times a Bézier polynomial of control point differences,
                //   so at most p (hi − lo) per axis; such a point is within δ of the domain
                //   along each of three directions, so within 3 p δ (hi − lo) of the box to
                //   first order: doubled for the δ² terms (1.8e-7 of the side for cubics);
                // - 1e-9 of the largest side, for the rounding of the mapping itself where a
                //   flat cell's thin side makes the rest vanish.
                let shape = &self.shapes[self.cell_shape[c] as usize];
                let order = shape.order.into_iter().max().unwrap_or(1) as f64;
                let pad = slack
                    + (hi - lo) * (6.0 * order * PROBE_SLACK)
                    + DVec3::splat(1e-9 * (hi - lo).max_element());
                (lo - pad, hi + pad)
            })
            .collect()
    }

    /// (neighbour cell, its face) across face `f` of cell `c`, if any.
    pub fn neighbour(&self, c: usize, f: usize) -> Option<(usize, usize)> {
        let (n, g) = self.neighbours[c][f];
        (n != NO_NEIGHBOUR).then_some((n as usize, g as usize))
    }

    /// World position and Jacobian of cell `c` at reference point `u`.
    pub fn map(&self, c: usize, u: DVec3, scratch: &mut Scratch) -> (DVec3, DMat3) {
        self.shape(c).evaluate_to(u, 1, &mut scratch.basis);
        let b = &scratch.basis;
        let mut x = DVec3::ZERO;
        let mut j = DMat3::ZERO;
        for (k, &n) in self.nodes(c).iter().enumerate() {
            let p = self.points[n as usize];
            x += p * b.values[k];
            j += outer(p, b.gradients[k]);
        }
        (x, j)
    }

    /// F* of the point array `values` in cell `c` at `u` (no derivatives).
    pub fn value(&self, values: &[f64], c: usize, u: DVec3, scratch: &mut Scratch) -> f64 {
        self.shape(c).evaluate_to(u, 0, &mut scratch.basis);
        self.nodes(c)
            .iter()
            .zip(&scratch.basis.values)
            .map(|(&n, &phi)| values[n as usize] * phi)
            .sum()
    }

    /// T, J, F*, F*_u, F_x and F_xx of the point array `values` in cell `c` at `u`.
    pub fn evaluate(
        &self,
        values: &[f64],
        c: usize,
        u: DVec3,
        scratch: &mut Scratch,
    ) -> Evaluation {
        self.evaluate_to(values, c, u, 2, scratch)
    }

    /// [`FeMesh::evaluate`] with derivatives of the field up to `order`: 1 leaves F_xx zero
    /// and skips the second derivatives of the basis and of T, which cost more than the
    /// rest of an evaluation (Newton steps and edge searches need only F and F_x).
    pub fn evaluate_to(
        &self,
        values: &[f64],
        c: usize,
        u: DVec3,
        order: u8,
        scratch: &mut Scratch,
    ) -> Evaluation {
        let order = order.clamp(1, 2);
        self.shape(c).evaluate_to(u, order, &mut scratch.basis);
        let b = &scratch.basis;
        let nodes = self.nodes(c);
        let mut x = DVec3::ZERO;
        let mut jac = DMat3::ZERO;
        let mut f = 0.0;
        let mut fu = DVec3::ZERO;
        for (k, &n) in nodes.iter().enumerate() {
            let p = self.points[n as usize];
            let v = values[n as usize];
            let (phi, g) = (b.values[k], b.gradients[k]);
            x += p * phi;
            jac += outer(p, g);
            f += v * phi;
            fu += g * v;
        }
        let k = jac.inverse();
        let grad = k.transpose() * fu;
        let mut hessian = DMat3::ZERO;
        if order == 2 {
            // Hessians of the three world coordinates with respect to u (J's derivatives).
            let mut hx = [DMat3::ZERO; 3];
            let mut fuu = DMat3::ZERO;
            for (h, &n) in b.hessians.iter().zip(nodes) {
                let p = self.points[n as usize];
                hx[0] += *h * p.x;
                hx[1] += *h * p.y;
                hx[2] += *h * p.z;
                fuu += *h * values[n as usize];
            }
            // F_xx = Kᵀ (F*_uu − Σ_m (F_x)_m ∂²x_m/∂u²) K (eq. 20 written out).
            let m = fuu - hx[0] * grad.x - hx[1] * grad.y - hx[2] * grad.z;
            hessian = k.transpose() * m * k;
        }
        Evaluation {
            x,
            jacobian: jac,
            value: f,
            grad_ref: fu,
            grad,
            hessian,
        }
    }

    /// Fails naming the first cell whose Jacobian determinant is not of one sign at its
    /// nodes and centroid (inverted in part, flat or collapsed). A cell whose determinant is
    /// negative throughout is mirrored: its node order has the other handedness, which
    /// nothing here depends on (normals come from the field's gradient), so a mesh whose
    /// cells are all mirrored is read (pyvista's `load_tetbeam`, a grid with a decreasing
    /// axis). One with both orientations is refused: a cell turned inside out among
    /// upright ones is how a bad mesh motion or a wrong node order shows.
    fn check_elements(&self, name: &str) -> Result<()> {
        // The probe points and the basis gradients there depend only on the shape: evaluate
        // them once per shape, so each cell costs only its J = Σ_k x_k ⊗ ∇φ_k sums.
        let mut basis = BasisValues::default();
        let probes: Vec<Vec<(DVec3, Vec<DVec3>)>> = self
            .shapes
            .iter()
            .map(|shape| {
                (0..shape.len())
                    .map(|n| shape.node_coords(n))
                    .chain(std::iter::once(shape.kind.centroid()))
                    .map(|u| {
                        shape.evaluate_to(u, 1, &mut basis);
                        (u, basis.gradients.clone())
                    })
                    .collect()
            })
            .collect();
        let inverted = |c: usize, det: f64, u: DVec3, why: &str| {
            // Some writers (older meshio versions, some solvers) order a wedge's triangles
            // the other way round from VTK 9.
            let hint = if self.shape(c).kind == Kind::Wedge {
                "; a wedge written for VTK's older orientation has each triangle's corners \
                 the other way round (swap its second and third corners)"
            } else {
                ""
            };
            Error::InvalidInput(format!(
                "{name}: cell {} ({}) is inverted: det J = {det:.3e} at reference point \
                 ({:.3}, {:.3}, {:.3}){why}{hint}",
                self.given_cell(c),
                self.described(c),
                u.x,
                u.y,
                u.z
            ))
        };
        // The first mirrored and the first upright cell (with its first probe), and how
        // many of each: where both are found, the fewer are the wrong ones.
        let mut mirrored: Option<(usize, f64, DVec3)> = None;
        let mut upright: Option<(usize, f64, DVec3)> = None;
        let (mut mirrored_count, mut upright_count) = (0usize, 0usize);
        let mut dets = Vec::new();
        for c in 0..self.cell_count() {
            let shape = self.shape(c);
            let nodes = self.nodes(c);
            // Scale-free test: det J relative to the cube of the cell's extent.
            let first = self.points[nodes[0] as usize];
            let (lo, hi) = nodes.iter().fold((first, first), |(a, b), &n| {
                let p = self.points[n as usize];
                (a.min(p), b.max(p))
            });
            let size = (hi - lo).max_element();
            let floor = 1e-12 * size * size * size;
            let what = self.described(c);
            let g = self.given_cell(c);
            // Two corners at one place (a collapsed edge, or the same point given twice)
            // make det J vanish along it; say so rather than report the sign it rounds to.
            let corners = shape.kind.corners().len();
            for a in 0..corners {
                for b in a + 1..corners {
                    let (pa, pb) = (nodes[a] as usize, nodes[b] as usize);
                    if self.points[pa].distance(self.points[pb]) <= 1e-12 * size {
                        return Err(Error::InvalidInput(format!(
                            "{name}: cell {g} ({what}) is degenerate: its corners {a} and {b} \
                             (points {pa} and {pb}) are at the same place"
                        )));
                    }
                }
            }
            dets.clear();
            dets.extend(
                probes[self.cell_shape[c] as usize]
                    .iter()
                    .map(|(u, gradients)| {
                        // Summed in node order, as `map` does, so det J is the same to the bit.
                        let j = nodes
                            .iter()
                            .zip(gradients)
                            .fold(DMat3::ZERO, |j, (&n, &g)| {
                                j + outer(self.points[n as usize], g)
                            });
                        (j.determinant(), *u)
                    }),
            );
            if dets.iter().all(|&(det, _)| det < -floor) {
                mirrored.get_or_insert((c, dets[0].0, dets[0].1));
                mirrored_count += 1;
                continue;
            }
            if dets.iter().all(|&(det, _)| det > floor) {
                upright.get_or_insert((c, dets[0].0, dets[0].1));
                upright_count += 1;
                continue;
            }
            let (&(det, u), low, high) = (
                dets.iter()
                    .find(|&&(det, _)| det.abs() <= floor || det.is_nan())
                    .unwrap_or(&dets[0]),
                dets.iter().map(|d| d.0).fold(f64::INFINITY, f64::min),
                dets.iter().map(|d| d.0).fold(f64::NEG_INFINITY, f64::max),
            );
            if det.abs() > floor {
                // Both signs: the cell folds over itself.
                let why = format!(" (det J runs from {low:.3e} to {high:.3e} over the cell)");
                return Err(inverted(
                    c,
                    low,
                    dets.iter().find(|d| d.0 == low).map_or(u, |d| d.1),
                    &why,
                ));
            }
            return Err(Error::InvalidInput(format!(
                "{name}: cell {g} ({what}) is degenerate: det J = {det:.3e} at reference point \
                 ({:.3}, {:.3}, {:.3})",
                u.x, u.y, u.z
            )));
        }
        if let (Some(m), Some(up)) = (mirrored, upright) {
            let ((c, det, u), other, orientation) = if mirrored_count <= upright_count {
                (m, up.0, "mirrored throughout")
            } else {
                (up, m.0, "upright where the other cells are mirrored")
            };
            let other = self.given_cell(other);
            let why = format!(
                ", {orientation}, while cell {other} is not (a mesh mirrored as a whole is \
                 read, one with both orientations is not)"
            );
            return Err(inverted(c, det, u, &why));
        }
        Ok(())
    }

    /// What messages call cell `c`: the VTK type it was given as.
    fn described(&self, c: usize) -> String {
        let shape = self.shape(c);
        match self.given_types.get(c).and_then(|&t| classic::name(t)) {
            Some(name) => format!("VTK {name}"),
            None => format!("{} of order {}", shape.kind.name(), shape.order[0]),
        }
    }

    /// The representative of point `p` among the corners at the same place.
    pub(crate) fn welded(&self, p: u32) -> u32 {
        self.weld[p as usize]
    }

    /// Gives corner points that coincide (within 1e-10 of the mesh's extent) one id, the
    /// first in cell order, so faces pair even where each cell has its own copy of its
    /// nodes. Only corners matter: faces are keyed by them.
    fn weld_corners(&self) -> Vec<u32> {
        let n = self.points.len();
        let mut weld: Vec<u32> = (0..n as u32).collect();
        // The nodes' box, not `bounds` (not yet known here, and the weld is about the
        // points only).
        let (lo, hi) = crate::field::neighbours::bounds(&self.points);
        let tol = 1e-10 * (hi - lo).length().max(1e-300);
        let key = |p: DVec3| ((p - lo) / tol).floor().as_i64vec3();
        let mut grid: FxHashMap<glam::I64Vec3, Vec<u32>> = FxHashMap::default();
        let mut seen = vec![false; n];
        for c in 0..self.cell_count() {
            let corners = self.shape(c).kind.corners().len();
            for &i in &self.nodes(c)[..corners] {
                if std::mem::replace(&mut seen[i as usize], true) {
                    continue;
                }
                let p = self.points[i as usize];
                let k = key(p);
                let mut rep = None;
                'search: for dz in -1..=1 {
                    for dy in -1..=1 {
                        for dx in -1..=1 {
                            let near = grid.get(&(k + glam::I64Vec3::new(dx, dy, dz)));
                            for &j in near.into_iter().flatten() {
                                if self.points[j as usize].distance(p) <= tol {
                                    rep = Some(j);
                                    break 'search;
                                }
                            }
                        }
                    }
                }
                match rep {
                    Some(j) => weld[i as usize] = j,
                    None => grid.entry(k).or_default().push(i),
                }
            }
        }
        weld
    }

    /// Pairs cell faces through their shared (welded) corner points.
    fn face_adjacency(&self) -> Vec<[(u32, u8); 6]> {
        let none = (NO_NEIGHBOUR, 0u8);
        let mut out = vec![[none; 6]; self.cell_count()];
        let mut open: FxHashMap<[u32; 4], (u32, u8)> = FxHashMap::default();
        for c in 0..self.cell_count() {
            let nodes = self.nodes(c);
            for (f, corners) in self.shape(c).kind.faces().iter().enumerate() {
                let mut key = [u32::MAX; 4];
                for (k, &i) in corners.iter().enumerate() {
                    key[k] = self.weld[nodes[i] as usize];
                }
                key.sort_unstable();
                match open.remove(&key) {
                    Some((d, g)) => {
                        out[c][f] = (d, g);
                        out[d as usize][g as usize] = (c as u32, f as u8);
                    }
                    None => {
                        open.insert(key, (c as u32, f as u8));
                    }
                }
            }
        }
        out
    }
}

/// Whether VTK type `ty` is a vertex, line or surface cell.
fn below_3d(ty: u8) -> bool {
    matches!(ty, 0..=9 | 21..=23 | 28 | 30 | 34..=36 | 60..=63 | 68..=70 | 75..=77)
}

/// " (a pyramid)" and the like for VTK cell types people meet that isobar does not read, so
/// the refusal says what the cell is.
fn unread_name(ty: u8) -> String {
    let name = match ty {
        0 => "an empty cell",
        1 | 2 => "a vertex",
        3 | 4 | 21 | 35 | 60 | 68 => "a line",
        5 | 6 | 22 | 34 | 61 | 69 => "a triangle",
        7 | 36 | 63 => "a polygon",
        8 | 9 | 23 | 28 | 30 | 62 | 70 => "a quadrilateral",
        14 | 27 | 74 => "a pyramid",
        15 | 16 => "a prism of more sides",
        33 => "a biquadratic-quadratic hexahedron",
        42 => "a polyhedron",
        75..=81 => "a Bézier cell",
        _ => return String::new(),
    };
    format!(" ({name})")
}
