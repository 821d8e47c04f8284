//! Bernstein (Bézier) control points of a cell's geometry, for bounding boxes that provably
//! contain the cell.
//!
//! A Lagrange cell is not inside the hull of its nodes: its basis functions go negative,
//! so a curved cell bulges past its nodes. The same polynomial mapping written in the
//! Bernstein basis, T(u) = Σ_b B_b(u) C_b, has nonnegative basis functions that sum to one
//! on the reference domain, so T(u) is a convex combination of the control points C_b and
//! the cell lies in their convex hull, hence in their bounding box.
//!
//! The Bernstein basis of a shape factors like its Lagrange basis (`shape.rs`): one factor
//! per group of variables, a Lagrange variable on its own (1-D Bernstein
//! `C(m,d) x^d (1−x)^(m−d)`) or a set of barycentric (Silvester) variables together
//! (`m!/Π d_i! Π λ_i^d_i`): the hexahedron is three 1-D factors, the tetrahedron one
//! barycentric factor, the wedge a triangle factor times a 1-D factor. Bernstein function b
//! is indexed by the same degree-index lattice point as Lagrange node b, so control point b
//! goes with node b. With M[n][b] = B_b(ξ_n) at the Lagrange nodes ξ_n, the nodes are
//! X = M C, so C = M⁻¹ X; M is the Kronecker product of the factors' matrices, so M⁻¹ is
//! too, applied one factor at a time along the "fibres" of nodes that differ only in that
//! factor's indices (the hexahedron's three 1-D inverses per axis). Each factor's inverse
//! depends only on (kind, order): it is computed once per process and shared.

use super::shape::{Family, Kind, Shape};
use rustc_hash::FxHashMap;
use std::sync::{Arc, Mutex, OnceLock};

/// One factor of the Bernstein basis: a group of variables of the shape.
#[derive(Debug)]
struct Factor {
    /// Number of lattice points (Bernstein functions) of the factor.
    size: usize,
    /// M_f⁻¹, `size × size`, row-major.
    inverse: Vec<f64>,
    /// Nodes grouped in fibres of `size`, each in the factor's lattice order: fibre k is
    /// `fibres[k * size..(k + 1) * size]`; the nodes of one fibre differ only in this
    /// factor's degree indices.
    fibres: Vec<u32>,
}

/// Lagrange-to-Bernstein conversion of one shape: see the module docs.
#[derive(Debug)]
pub(crate) struct ControlMap {
    factors: Vec<Factor>,
    /// A bound on the control points' rounding error relative to the largest node
    /// coordinate magnitude (per axis, after translating the nodes): see
    /// [`ControlMap::rounding`].
    rounding: f64,
}

/// The conversion for `shape`'s (kind, order), computed on first use.
pub(crate) fn control_map(shape: &Shape) -> Arc<ControlMap> {
    type Cache = Mutex<FxHashMap<(Kind, [usize; 3]), Arc<ControlMap>>>;
    static CACHE: OnceLock<Cache> = OnceLock::new();
    let cache = CACHE.get_or_init(Default::default);
    let key = (shape.kind, shape.order);
    // A poisoned lock only means another thread panicked while inserting; the map holds
    // complete entries only, so it is still usable.
    let mut map = cache.lock().unwrap_or_else(|e| e.into_inner());
    map.entry(key)
        .or_insert_with(|| Arc::new(ControlMap::new(shape)))
        .clone()
}

/// The value of a factor's Bernstein function with degree indices `d` (one per variable of
/// the group) at the group's variable values `x`.
fn factor_basis(degree: usize, d: &[u16], x: &[f64]) -> f64 {
    if let ([d], [x]) = (d, x) {
        // A 1-D factor: x and 1 − x are its barycentric pair.
        let d = *d as usize;
        return binomial(degree, d) * x.powi(d as i32) * (1.0 - x).powi((degree - d) as i32);
    }
    // m!/Π d_i! as a product of binomials (exact in f64 for the orders supported).
    let mut coefficient = 1.0;
    let mut rest = degree;
    let mut value = 1.0;
    for (&di, &xi) in d.iter().zip(x) {
        coefficient *= binomial(rest, di as usize);
        rest -= di as usize;
        value *= xi.powi(di as i32);
    }
    coefficient * value
}

fn binomial(n: usize, k: usize) -> f64 {
    (0..k).fold(1.0, |c, i| c * (n - i) as f64 / (i + 1) as f64)
}

impl ControlMap {
    fn new(shape: &Shape) -> ControlMap {
        // Group the variables: each Lagrange variable alone, consecutive barycentric
        // (Silvester) variables of the same degree together.
        let mut groups: Vec<(Vec<usize>, usize)> = Vec::new();
        for (v, var) in shape.variables.iter().enumerate() {
            match (var.family, groups.last_mut()) {
                (Family::Silvester(m), Some((vs, g)))
                    if *g == m && matches!(shape.variables[vs[0]].family, Family::Silvester(_)) =>
                {
                    vs.push(v)
                }
                (Family::Silvester(m) | Family::Lagrange(m), _) => groups.push((vec![v], m)),
            }
        }
        let n = shape.len();
        let factors: Vec<Factor> = groups
            .into_iter()
            .map(|(variables, degree)| {
                let own = |node: usize| -> Vec<u16> {
                    variables.iter().map(|&v| shape.nodes[node][v]).collect()
                };
                // The factor's lattice, in order of first appearance, and a node at each
                // lattice point (whose reference coordinates give the point).
                let mut index: FxHashMap<Vec<u16>, u32> = FxHashMap::default();
                let mut representative = Vec::new();
                let local: Vec<u32> = (0..n)
                    .map(|node| {
                        let next = index.len() as u32;
                        *index.entry(own(node)).or_insert_with(|| {
                            representative.push(node);
                            next
                        })
                    })
                    .collect();
                let size = representative.len();
                // The variable values at each lattice point, from the node coordinates the
                // basis uses (`Shape::node_coords`), so both agree on where nodes are.
                let at = |node: usize| -> Vec<f64> {
                    let u = shape.node_coords(node);
                    variables
                        .iter()
                        .map(|&v| {
                            let var = &shape.variables[v];
                            var.offset + var.direction.dot(u)
                        })
                        .collect()
                };
                let mut m = vec![0.0; size * size];
                for (a, &na) in representative.iter().enumerate() {
                    let x = at(na);
                    for (b, &nb) in representative.iter().enumerate() {
                        m[a * size + b] = factor_basis(degree, &own(nb), &x);
                    }
                }
                let inverse = invert(&m, size);
                // Fibres: nodes that agree in every other factor's indices.
                let mut fibre_of: FxHashMap<[u16; 4], usize> = FxHashMap::default();
                let mut fibres = vec![u32::MAX; n];
                for (node, &l) in local.iter().enumerate() {
                    let mut key = shape.nodes[node];
                    for &v in &variables {
                        key[v] = u16::MAX;
                    }
                    let next = fibre_of.len();
                    let k = *fibre_of.entry(key).or_insert(next);
                    fibres[k * size + l as usize] = node as u32;
                }
                // Every shape's nodes are the product of its factors' lattices.
                assert!(
                    fibre_of.len() * size == n && !fibres.contains(&u32::MAX),
                    "{:?} {:?}: nodes are not a product lattice",
                    shape.kind,
                    shape.order
                );
                Factor {
                    size,
                    inverse,
                    fibres,
                }
            })
            .collect();
        // ‖M⁻¹‖∞, the product of the factors' row-sum norms: how much the control points'
        // rounding errors can grow over the node coordinates' magnitudes.
        let norm: f64 = factors
            .iter()
            .map(|f| {
                f.inverse
                    .chunks(f.size)
                    .map(|row| row.iter().map(|x| x.abs()).sum::<f64>())
                    .fold(0.0, f64::max)
            })
            .product();
        // Applying factor f forms dot products of `size` terms, so each stage adds at most
        // γ_size = size·ε/(1 − size·ε) relative to |M_f⁻¹| |input|; over all stages the
        // error is at most γ_K |M⁻¹| |X| ≤ γ_K ‖M⁻¹‖∞ max|X| with K the sum of the sizes
        // (Higham, Accuracy and Stability of Numerical Algorithms, §3.1 and §3.5). Doubled
        // to also cover the computed inverse's own error (its residual M·M⁻¹ − I is checked
        // to be within that in the tests).
        let k: usize = factors.iter().map(|f| f.size).sum();
        let kf = k as f64 * f64::EPSILON;
        let rounding = 2.0 * norm * kf / (1.0 - kf);
        ControlMap { factors, rounding }
    }

    /// Relative bound on the rounding in [`ControlMap::control_points`]: a control point's
    /// coordinate is within `rounding() · max_n |x_n|` (same axis) of its exact value. Grows
    /// with the order as the conversion from equispaced Lagrange nodes gets ill-conditioned
    /// (‖M⁻¹‖∞ is 1 for linear cells, 3.5e3 for quartic hexahedra, 1.8e8 at order 8).
    #[cfg(test)]
    pub(crate) fn rounding(&self) -> f64 {
        self.rounding
    }

    /// The range of the control points of the polynomial with the node values `nodes`
    /// (in the shape's node order: positions, or a field's values), which holds the
    /// polynomial over the cell (it is their convex combination), and a slack that covers
    /// the rounding: `(lo, hi, slack)`, per component for positions. `x` and `row` are
    /// scratch.
    pub(crate) fn control_range<T: Controlled>(
        &self,
        nodes: impl Iterator<Item = T>,
        x: &mut Vec<T>,
        row: &mut Vec<T>,
    ) -> (T, T, T) {
        x.clear();
        x.extend(nodes);
        // Relative to the first node, so rounding scales with the cell's spread, not with
        // its distance from zero (the Bernstein functions sum to one, so translating the
        // values translates the control points).
        let origin = x[0];
        for v in x.iter_mut() {
            *v = *v - origin;
        }
        let reach = x.iter().fold(T::default(), |r, &v| r.max(v.abs()));
        self.control_points(x, row);
        let (lo, hi) = x
            .iter()
            .fold((x[0], x[0]), |(a, b), &v| (a.min(v), b.max(v)));
        // The conversion's rounding and a few ulps for the translations back and forth.
        let slack = reach * self.rounding + (origin.abs() + reach) * (4.0 * f64::EPSILON);
        (origin + lo, origin + hi, slack)
    }

    /// Replaces the node values `x` (in the shape's node order: positions, or a field's
    /// values) by the control points of the same polynomial, in place; `row` is scratch.
    pub(crate) fn control_points<T: Controlled>(&self, x: &mut [T], row: &mut Vec<T>) {
        for f in &self.factors {
            for fibre in f.fibres.chunks(f.size) {
                row.clear();
                row.extend(f.inverse.chunks(f.size).map(|inv| {
                    inv.iter()
                        .zip(fibre)
                        .fold(T::default(), |acc, (&w, &n)| acc + x[n as usize] * w)
                }));
                for (&n, &c) in fibre.iter().zip(row.iter()) {
                    x[n as usize] = c;
                }
            }
        }
    }
}

/// What [`ControlMap`] converts: a field's values (`f64`) or positions (`DVec3`, each
/// component on its own).
pub(crate) trait Controlled:
    Copy
    + Default
    + std::ops::Add<Output = Self>
    + std::ops::Sub<Output = Self>
    + std::ops::Mul<f64, Output = Self>
{
    fn min(self, other: Self) -> Self;
    fn max(self, other: Self) -> Self;
    fn abs(self) -> Self;
}

impl Controlled for f64 {
    fn min(self, other: f64) -> f64 {
        f64::min(self, other)
    }
    fn max(self, other: f64) -> f64 {
        f64::max(self, other)
    }
    fn abs(self) -> f64 {
        f64::abs(self)
    }
}

impl Controlled for glam::DVec3 {
    fn min(self, other: Self) -> Self {
        glam::DVec3::min(self, other)
    }
    fn max(self, other: Self) -> Self {
        glam::DVec3::max(self, other)
    }
    fn abs(self) -> Self {
        glam::DVec3::abs(self)
    }
}

/// The inverse of the `n × n` row-major matrix `m`, by Gauss–Jordan elimination with
/// partial pivoting (M is the Bernstein collocation matrix at distinct lattice points,
/// which is nonsingular).
fn invert(m: &[f64], n: usize) -> Vec<f64> {
    let mut a = m.to_vec();
    let mut inv = vec![0.0; n * n];
    for i in 0..n {
        inv[i * n + i] = 1.0;
    }
    for col in 0..n {
        let pivot = (col..n)
            .max_by(|&r, &s| a[r * n + col].abs().total_cmp(&a[s * n + col].abs()))
            .expect("nonempty");
        if pivot != col {
            for k in 0..n {
                a.swap(pivot * n + k, col * n + k);
                inv.swap(pivot * n + k, col * n + k);
            }
        }
        let p = a[col * n + col];
        assert!(p != 0.0, "singular Bernstein collocation matrix");
        for k in 0..n {
            a[col * n + k] /= p;
            inv[col * n + k] /= p;
        }
        for r in (0..n).filter(|&r| r != col) {
            let f = a[r * n + col];
            if f != 0.0 {
                for k in 0..n {
                    a[r * n + k] -= f * a[col * n + k];
                    inv[r * n + k] -= f * inv[col * n + k];
                }
            }
        }
    }
    inv
}
