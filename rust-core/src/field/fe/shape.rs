//! Reference shapes of Lagrange cells and VTK's node numbering for each.
//!
//! Every basis function of a Lagrange cell is a product of univariate polynomials, one per
//! *variable*, where each variable is an affine function of the reference coordinates
//! u = (r, s, t): the hexahedron uses r, s, t (tensor-product Lagrange on equispaced nodes),
//! the tetrahedron the four barycentric coordinates (Silvester's polynomials), the wedge the
//! three barycentric coordinates of its triangle times a Lagrange polynomial in t. A node is
//! then just the degree index it picks in each variable. The node *order* is VTK 9's
//! (`vtkHigherOrderHexahedron/Tetra/Wedge::PointIndexFromIJK` and the tetrahedron's
//! recursive numbering), checked against VTK's own parametric coordinates in the tests.
//!
//! Reference domains, as in VTK: hexahedron [0,1]³; tetrahedron r, s, t ≥ 0, r + s + t ≤ 1;
//! wedge r, s ≥ 0, r + s ≤ 1, t ∈ [0,1].

use glam::DVec3;

// VTK cell types (kept out of the crate's top-level constants, which cbindgen would put
// into the C header).
const VTK_LAGRANGE_TETRAHEDRON: u8 = 71;
const VTK_LAGRANGE_HEXAHEDRON: u8 = 72;
const VTK_LAGRANGE_WEDGE: u8 = 73;

/// The three element families.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Kind {
    Hexahedron,
    Tetrahedron,
    Wedge,
}

impl Kind {
    /// The VTK cell type number.
    pub fn vtk_type(self) -> u8 {
        match self {
            Kind::Hexahedron => VTK_LAGRANGE_HEXAHEDRON,
            Kind::Tetrahedron => VTK_LAGRANGE_TETRAHEDRON,
            Kind::Wedge => VTK_LAGRANGE_WEDGE,
        }
    }

    /// The family of a VTK cell type, if it is one of ours.
    pub fn from_vtk(ty: u8) -> Option<Kind> {
        match ty {
            VTK_LAGRANGE_HEXAHEDRON => Some(Kind::Hexahedron),
            VTK_LAGRANGE_TETRAHEDRON => Some(Kind::Tetrahedron),
            VTK_LAGRANGE_WEDGE => Some(Kind::Wedge),
            _ => None,
        }
    }

    /// Human name for messages.
    pub fn name(self) -> &'static str {
        match self {
            Kind::Hexahedron => "Lagrange hexahedron",
            Kind::Tetrahedron => "Lagrange tetrahedron",
            Kind::Wedge => "Lagrange wedge",
        }
    }

    /// Node count for per-axis orders (hexahedron: r, s, t; wedge: triangle, t; tetrahedron: first).
    pub fn node_count(self, order: [usize; 3]) -> usize {
        let [p, q, r] = order;
        match self {
            Kind::Hexahedron => (p + 1) * (q + 1) * (r + 1),
            Kind::Tetrahedron => (p + 1) * (p + 2) * (p + 3) / 6,
            Kind::Wedge => (p + 1) * (p + 2) / 2 * (r + 1),
        }
    }

    /// The uniform order whose node count is `n`, if any (what VTK assumes without
    /// `HigherOrderDegrees`).
    pub fn order_from_count(self, n: usize) -> Option<usize> {
        (1..=64).find(|&p| self.node_count([p, p, p]) == n)
    }

    /// Corner node indices of each face, in cyclic order around the face.
    pub fn faces(self) -> &'static [&'static [usize]] {
        match self {
            Kind::Hexahedron => &[
                &[0, 3, 7, 4],
                &[1, 2, 6, 5],
                &[0, 1, 5, 4],
                &[3, 2, 6, 7],
                &[0, 1, 2, 3],
                &[4, 5, 6, 7],
            ],
            Kind::Tetrahedron => &[&[0, 1, 3], &[1, 2, 3], &[2, 0, 3], &[0, 2, 1]],
            Kind::Wedge => &[
                &[0, 1, 2],
                &[3, 4, 5],
                &[0, 1, 4, 3],
                &[1, 2, 5, 4],
                &[2, 0, 3, 5],
            ],
        }
    }

    /// Reference coordinates of the corner nodes (VTK's linear cell numbering).
    pub fn corners(self) -> &'static [[f64; 3]] {
        match self {
            Kind::Hexahedron => &[
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 1.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, 0.0, 1.0],
                [1.0, 0.0, 1.0],
                [1.0, 1.0, 1.0],
                [0.0, 1.0, 1.0],
            ],
            Kind::Tetrahedron => &[
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, 0.0, 1.0],
            ],
            Kind::Wedge => &[
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, 0.0, 1.0],
                [1.0, 0.0, 1.0],
                [0.0, 1.0, 1.0],
            ],
        }
    }

    /// The signed distances of `u` inside each face's half-space (all ≥ 0 inside),
    /// indexed like [`Kind::faces`].
    pub fn face_distances(self, u: DVec3) -> ([f64; 6], usize) {
        match self {
            Kind::Hexahedron => ([u.x, 1.0 - u.x, u.y, 1.0 - u.y, u.z, 1.0 - u.z], 6),
            Kind::Tetrahedron => ([u.y, 1.0 - u.x - u.y - u.z, u.x, u.z, 0.0, 0.0], 4),
            Kind::Wedge => ([u.z, 1.0 - u.z, u.y, 1.0 - u.x - u.y, u.x, 0.0], 5),
        }
    }

    /// The unit inward normal of face `f` (the gradient of its [`Kind::face_distances`]
    /// entry, normalised).
    pub fn face_normal(self, f: usize) -> DVec3 {
        let third = 1.0 / 3.0_f64.sqrt();
        let half = std::f64::consts::FRAC_1_SQRT_2;
        match (self, f) {
            (Kind::Hexahedron, _) => {
                let sign = if f.is_multiple_of(2) { 1.0 } else { -1.0 };
                let mut n = DVec3::ZERO;
                n[f / 2] = sign;
                n
            }
            (Kind::Tetrahedron, 0) => DVec3::Y,
            (Kind::Tetrahedron, 1) => DVec3::splat(-third),
            (Kind::Tetrahedron, 2) => DVec3::X,
            (Kind::Tetrahedron, _) => DVec3::Z,
            (Kind::Wedge, 0) => DVec3::Z,
            (Kind::Wedge, 1) => DVec3::NEG_Z,
            (Kind::Wedge, 2) => DVec3::Y,
            (Kind::Wedge, 3) => DVec3::new(-half, -half, 0.0),
            (Kind::Wedge, _) => DVec3::X,
        }
    }

    /// The first face the step from `u` to `u + du` leaves the reference domain through
    /// (by more than `slack`), if any. Faces the step does not move away from are not
    /// counted: a point held on a face may sit a rounding error outside it.
    pub fn crossed_face(self, u: DVec3, du: DVec3, slack: f64) -> Option<usize> {
        let (before, nf) = self.face_distances(u);
        let (after, _) = self.face_distances(u + du);
        (0..nf)
            .filter(|&f| after[f] < -slack && after[f] < before[f])
            .map(|f| (f, before[f].max(0.0) / (before[f].max(0.0) - after[f])))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(f, _)| f)
    }

    /// The reference centroid.
    pub fn centroid(self) -> DVec3 {
        match self {
            Kind::Hexahedron => DVec3::splat(0.5),
            Kind::Tetrahedron => DVec3::splat(0.25),
            Kind::Wedge => DVec3::new(1.0 / 3.0, 1.0 / 3.0, 0.5),
        }
    }
}

/// The univariate polynomial family of one variable.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Family {
    /// Lagrange polynomials on the equispaced nodes a/m, a = 0..=m, of [0,1].
    Lagrange(usize),
    /// Silvester's S_a(λ) = Π_{q<a} (mλ − q)/(q + 1), a = 0..=m, for barycentric λ.
    Silvester(usize),
}

/// A variable c + d·u of the reference coordinates with its polynomial family.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Variable {
    pub(crate) offset: f64,
    pub(crate) direction: DVec3,
    pub(crate) family: Family,
}

/// One element type at given orders: its variables, and for each node in VTK order the
/// degree index it takes in each variable.
#[derive(Clone, Debug)]
pub struct Shape {
    pub kind: Kind,
    /// Per-axis orders as given (hexahedron r, s, t; wedge triangle, triangle, t).
    pub order: [usize; 3],
    pub(crate) variables: Vec<Variable>,
    /// `nodes[n][m]`: degree index of node n in variable m.
    pub(crate) nodes: Vec<[u16; 4]>,
}

impl Shape {
    /// The shape of `kind` at `order` (per axis for hexahedra, [p, p, q] for wedges).
    pub fn new(kind: Kind, order: [usize; 3]) -> Shape {
        let r = DVec3::X;
        let s = DVec3::Y;
        let t = DVec3::Z;
        let var = |offset, direction, family| Variable {
            offset,
            direction,
            family,
        };
        let (variables, nodes) = match kind {
            Kind::Hexahedron => {
                let [p, q, w] = order;
                let vars = vec![
                    var(0.0, r, Family::Lagrange(p)),
                    var(0.0, s, Family::Lagrange(q)),
                    var(0.0, t, Family::Lagrange(w)),
                ];
                (vars, hex_nodes(order))
            }
            Kind::Tetrahedron => {
                let p = order[0];
                let vars = vec![
                    var(1.0, -(r + s + t), Family::Silvester(p)),
                    var(0.0, r, Family::Silvester(p)),
                    var(0.0, s, Family::Silvester(p)),
                    var(0.0, t, Family::Silvester(p)),
                ];
                (vars, tet_nodes(p))
            }
            Kind::Wedge => {
                let (p, q) = (order[0], order[2]);
                let vars = vec![
                    var(1.0, -(r + s), Family::Silvester(p)),
                    var(0.0, r, Family::Silvester(p)),
                    var(0.0, s, Family::Silvester(p)),
                    var(0.0, t, Family::Lagrange(q)),
                ];
                (vars, wedge_nodes(p, q))
            }
        };
        Shape {
            kind,
            order,
            variables,
            nodes,
        }
    }

    /// Number of nodes.
    pub fn len(&self) -> usize {
        self.nodes.len()
    }

    /// Always false (every shape has nodes); for clippy's `len` convention.
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// Reference coordinates of node `n`.
    pub fn node_coords(&self, n: usize) -> DVec3 {
        let d = self.nodes[n];
        let frac = |k: usize, m: usize| d[k] as f64 / m as f64;
        match self.kind {
            Kind::Hexahedron => DVec3::new(
                frac(0, self.order[0]),
                frac(1, self.order[1]),
                frac(2, self.order[2]),
            ),
            Kind::Tetrahedron => {
                let p = self.order[0];
                DVec3::new(frac(1, p), frac(2, p), frac(3, p))
            }
            Kind::Wedge => DVec3::new(
                frac(1, self.order[0]),
                frac(2, self.order[0]),
                frac(3, self.order[2]),
            ),
        }
    }
}

/// Hexahedron nodes in VTK 9 order (vtkHigherOrderHexahedron::PointIndexFromIJK).
fn hex_nodes(order: [usize; 3]) -> Vec<[u16; 4]> {
    let [p, q, r] = order;
    let mut out = vec![[0u16; 4]; (p + 1) * (q + 1) * (r + 1)];
    for k in 0..=r {
        for j in 0..=q {
            for i in 0..=p {
                out[hex_index(i, j, k, order)] = [i as u16, j as u16, k as u16, 0];
            }
        }
    }
    out
}

fn hex_index(i: usize, j: usize, k: usize, o: [usize; 3]) -> usize {
    let ib = i == 0 || i == o[0];
    let jb = j == 0 || j == o[1];
    let kb = k == 0 || k == o[2];
    let nb = ib as usize + jb as usize + kb as usize;
    let (a, b, c) = (o[0] - 1, o[1] - 1, o[2] - 1);
    if nb == 3 {
        let base = match (i > 0, j > 0) {
            (false, false) => 0,
            (true, false) => 1,
            (true, true) => 2,
            (false, true) => 3,
        };
        return base + if k > 0 { 4 } else { 0 };
    }
    let mut off = 8;
    if nb == 2 {
        if !ib {
            return off
                + (i - 1)
                + if j > 0 { a + b } else { 0 }
                + if k > 0 { 2 * (a + b) } else { 0 };
        }
        if !jb {
            return off
                + (j - 1)
                + if i > 0 { a } else { 2 * a + b }
                + if k > 0 { 2 * (a + b) } else { 0 };
        }
        off += 4 * (a + b);
        // k-edges at corners 0, 1, 2, 3 (VTK's linear hexahedron edges 8–11).
        let corner = match (i > 0, j > 0) {
            (false, false) => 0,
            (true, false) => 1,
            (true, true) => 2,
            (false, true) => 3,
        };
        return off + (k - 1) + c * corner;
    }
    off += 4 * (a + b + c);
    if nb == 1 {
        if ib {
            return off + (j - 1) + b * (k - 1) + if i > 0 { b * c } else { 0 };
        }
        off += 2 * b * c;
        if jb {
            return off + (i - 1) + a * (k - 1) + if j > 0 { c * a } else { 0 };
        }
        off += 2 * c * a;
        return off + (i - 1) + a * (j - 1) + if k > 0 { a * b } else { 0 };
    }
    off += 2 * (b * c + c * a + a * b);
    off + (i - 1) + a * ((j - 1) + b * (k - 1))
}

/// Barycentric lattice points of a triangle of order `n` on the corners `v` (each a
/// barycentric index vector), VTK's recursive order: corners, edges v0→v1, v1→v2, v2→v0,
/// then the interior as a triangle of order n − 3.
fn triangle_points(n: usize, v: [[usize; 4]; 3], out: &mut Vec<[usize; 4]>) {
    // `v[m]` holds the unit barycentric direction of corner m; points are offsets + n·corner.
    fn rec(n: isize, base: [usize; 4], v: [[usize; 4]; 3], out: &mut Vec<[usize; 4]>) {
        let at = |w: [usize; 3]| -> [usize; 4] {
            let mut p = base;
            for (m, &wm) in w.iter().enumerate() {
                for (x, &d) in p.iter_mut().zip(&v[m]) {
                    *x += wm * d;
                }
            }
            p
        };
        if n < 0 {
            return;
        }
        let n = n as usize;
        if n == 0 {
            out.push(at([0, 0, 0]));
            return;
        }
        out.push(at([n, 0, 0]));
        out.push(at([0, n, 0]));
        out.push(at([0, 0, n]));
        for (a, b) in [(0, 1), (1, 2), (2, 0)] {
            for q in 1..n {
                let mut w = [0; 3];
                w[a] = n - q;
                w[b] = q;
                out.push(at(w));
            }
        }
        let mut inner = base;
        for c in &v {
            for (x, &d) in inner.iter_mut().zip(c) {
                *x += d;
            }
        }
        rec(n as isize - 3, inner, v, out);
    }
    rec(n as isize, [0; 4], v, out);
}

/// Tetrahedron nodes in VTK order: corners, edges, faces (each a recursive triangle),
/// interior (a tetrahedron of order n − 4, recursively).
fn tet_nodes(n: usize) -> Vec<[u16; 4]> {
    const E: [[usize; 4]; 4] = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]];
    fn rec(n: isize, base: [usize; 4], out: &mut Vec<[usize; 4]>) {
        if n < 0 {
            return;
        }
        let n = n as usize;
        let add = |w: [usize; 4]| -> [usize; 4] { std::array::from_fn(|m| base[m] + w[m]) };
        if n == 0 {
            out.push(base);
            return;
        }
        for e in E {
            out.push(add(e.map(|x| x * n)));
        }
        for (a, b) in [(0, 1), (1, 2), (2, 0), (0, 3), (1, 3), (2, 3)] {
            for q in 1..n {
                let mut w = [0; 4];
                w[a] = n - q;
                w[b] = q;
                out.push(add(w));
            }
        }
        if n >= 3 {
            // VTK numbers face interiors from these corners (faces 1 and 2 start elsewhere
            // than the linear tetrahedron's face list).
            for f in [[0, 1, 3], [2, 3, 1], [0, 3, 2], [0, 2, 1]] {
                let mut face = Vec::new();
                // Interior of the face: a triangle of order n − 3 shifted one step in from
                // each of its corners.
                let corners = [E[f[0]], E[f[1]], E[f[2]]];
                triangle_points(n - 3, corners, &mut face);
                for p in face {
                    let mut w = p;
                    for c in &corners {
                        for (x, &d) in w.iter_mut().zip(c) {
                            *x += d;
                        }
                    }
                    out.push(add(w));
                }
            }
        }
        rec(n as isize - 4, add([1, 1, 1, 1]), out);
    }
    let mut pts = Vec::new();
    rec(n as isize, [0; 4], &mut pts);
    pts.into_iter().map(|p| p.map(|x| x as u16)).collect()
}

/// Wedge nodes in VTK 9 order (vtkHigherOrderWedge::PointIndexFromIJK): degree indices
/// (triangle barycentric λ0, r index i, s index j, t index k).
fn wedge_nodes(n: usize, q: usize) -> Vec<[u16; 4]> {
    let m1 = n - 1;
    let q1 = q - 1;
    // Interior points of the triangle, row by row (j outer, i fastest).
    let tri_interior: Vec<(usize, usize)> = (1..n)
        .flat_map(|j| (1..n).filter(move |&i| i + j < n).map(move |i| (i, j)))
        .collect();
    let ntf = tri_interior.len();
    let tri_off = |i: usize, j: usize| tri_interior.iter().position(|&p| p == (i, j)).unwrap();
    let mut out = vec![[0u16; 4]; Kind::Wedge.node_count([n, n, q])];
    for k in 0..=q {
        for j in 0..=n {
            for i in 0..=(n - j) {
                let ib = i == 0;
                let jb = j == 0;
                let ijb = i + j == n;
                let kb = k == 0 || k == q;
                let nb = ib as usize + jb as usize + ijb as usize + kb as usize;
                let corner = if ib && jb {
                    0
                } else if jb && ijb {
                    1
                } else {
                    2
                };
                let idx = if nb == 3 {
                    corner + if k > 0 { 3 } else { 0 }
                } else if nb == 2 && !kb {
                    6 + 6 * m1 + (k - 1) + corner * q1
                } else if nb == 2 {
                    let off = 6 + if k == q { 3 * m1 } else { 0 };
                    if jb {
                        off + i - 1
                    } else if ijb {
                        off + m1 + j - 1
                    } else {
                        off + 2 * m1 + (n - j - 1)
                    }
                } else {
                    let off = 6 + 6 * m1 + 3 * q1;
                    if nb == 1 && kb {
                        off + if k > 0 { ntf } else { 0 } + tri_off(i, j)
                    } else if nb == 1 {
                        let off = off + 2 * ntf;
                        if jb {
                            off + (i - 1) + m1 * (k - 1)
                        } else if ijb {
                            off + m1 * q1 + (n - i - 1) + m1 * (k - 1)
                        } else {
                            off + 2 * m1 * q1 + (n - j - 1) + m1 * (k - 1)
                        }
                    } else {
                        off + 2 * ntf + 3 * m1 * q1 + tri_off(i, j) + ntf * (k - 1)
                    }
                };
                out[idx] = [(n - i - j) as u16, i as u16, j as u16, k as u16];
            }
        }
    }
    out
}
