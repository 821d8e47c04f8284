//! Basis functions of a [`Shape`] with first and second derivatives in reference
//! coordinates, evaluated as products of univariate polynomials (see `shape.rs`).

use super::shape::{Family, Kind, Shape};
use glam::{DMat3, DVec3};

/// Value, first and second derivative of a univariate polynomial at one point.
#[derive(Clone, Copy, Debug, Default)]
struct Jet {
    v: f64,
    d1: f64,
    d2: f64,
}

impl Jet {
    const ONE: Jet = Jet {
        v: 1.0,
        d1: 0.0,
        d2: 0.0,
    };

    /// This polynomial times the linear factor (a·x + b) evaluated at x.
    fn times_linear(self, a: f64, b: f64, x: f64) -> Jet {
        let g = a * x + b;
        Jet {
            v: self.v * g,
            d1: self.d1 * g + self.v * a,
            d2: self.d2 * g + 2.0 * self.d1 * a,
        }
    }
}

/// Jets of every polynomial of `family` (degree index 0..=m) at `x`.
fn family_jets(family: Family, x: f64, out: &mut Vec<Jet>) {
    out.clear();
    match family {
        Family::Lagrange(m) => {
            let mf = m as f64;
            for a in 0..=m {
                let mut j = Jet::ONE;
                for q in (0..=m).filter(|&q| q != a) {
                    // (x − q/m)/((a − q)/m) = (m x − q)/(a − q)
                    let den = a as f64 - q as f64;
                    j = j.times_linear(mf / den, -(q as f64) / den, x);
                }
                out.push(j);
            }
        }
        Family::Silvester(m) => {
            let mf = m as f64;
            let mut j = Jet::ONE;
            out.push(j);
            for q in 0..m {
                // S_{q+1} = S_q · (m x − q)/(q + 1)
                let den = (q + 1) as f64;
                j = j.times_linear(mf / den, -(q as f64) / den, x);
                out.push(j);
            }
        }
    }
}

/// Basis values, gradients and Hessians at one reference point; reusable buffers.
#[derive(Clone, Debug, Default)]
pub struct BasisValues {
    pub values: Vec<f64>,
    pub gradients: Vec<DVec3>,
    pub hessians: Vec<DMat3>,
    jets: Vec<Vec<Jet>>,
}

impl Shape {
    /// Evaluates every basis function, its gradient and its Hessian at `u` into `out`.
    pub fn evaluate(&self, u: DVec3, out: &mut BasisValues) {
        self.evaluate_to(u, 2, out)
    }

    /// Evaluates derivatives up to `order` (0: values, 1: + gradients, 2: + Hessians);
    /// the arrays of higher derivatives are left empty.
    pub fn evaluate_to(&self, u: DVec3, order: u8, out: &mut BasisValues) {
        let nv = self.variables.len();
        out.jets.resize_with(nv, Vec::new);
        for (var, jets) in self.variables.iter().zip(out.jets.iter_mut()) {
            family_jets(var.family, var.offset + var.direction.dot(u), jets);
        }
        out.values.clear();
        out.gradients.clear();
        out.hessians.clear();
        if self.kind == Kind::Hexahedron {
            self.tensor_product(order, out);
            return;
        }
        for node in &self.nodes {
            // φ = Π_m f_m(x_m(u)) with x_m affine: ∇φ = Σ_m f'_m Π_{k≠m} f_k d_m, and
            // ∇²φ = Σ_m f''_m Π_{k≠m} f_k d_m d_mᵀ + Σ_{m≠k} f'_m f'_k Π_{rest} d_m d_kᵀ.
            // Hot: every forward evaluation runs this once per node, so the products
            // "all but m" and "all but m and k" are formed over fixed arrays (nv ≤ 4).
            let mut f = [Jet::ONE; 4];
            for ((fm, jets), &degree) in f.iter_mut().zip(&out.jets).zip(node) {
                *fm = jets[degree as usize];
            }
            let value = f[0].v * f[1].v * f[2].v * f[3].v;
            out.values.push(value);
            if order == 0 {
                continue;
            }
            let but = |m: usize| -> f64 {
                let mut p = 1.0;
                for (k, j) in f.iter().enumerate() {
                    if k != m {
                        p *= j.v;
                    }
                }
                p
            };
            let mut g = DVec3::ZERO;
            for (m, (var, fm)) in self.variables.iter().zip(&f).enumerate() {
                g += var.direction * (fm.d1 * but(m));
            }
            out.gradients.push(g);
            if order == 1 {
                continue;
            }
            let mut h = DMat3::ZERO;
            for m in 0..nv {
                let dm = self.variables[m].direction;
                h += outer(dm, dm) * (f[m].d2 * but(m));
                for k in (m + 1)..nv {
                    let mut rest = 1.0;
                    for (q, j) in f.iter().enumerate() {
                        if q != m && q != k {
                            rest *= j.v;
                        }
                    }
                    let dk = self.variables[k].direction;
                    h += (outer(dm, dk) + outer(dk, dm)) * (f[m].d1 * f[k].d1 * rest);
                }
            }
            out.hessians.push(h);
        }
    }
}

impl Shape {
    /// The hexahedron's case of [`Shape::evaluate_to`]: its variables are r, s and t
    /// themselves, so φ = R(r) S(s) T(t) and every derivative is a product of three jets
    /// (a third of the general loop's work: no direction vectors, no outer products).
    fn tensor_product(&self, order: u8, out: &mut BasisValues) {
        let [r, s, t] = [&out.jets[0], &out.jets[1], &out.jets[2]];
        for node in &self.nodes {
            let (a, b, c) = (
                r[node[0] as usize],
                s[node[1] as usize],
                t[node[2] as usize],
            );
            out.values.push(a.v * b.v * c.v);
            if order == 0 {
                continue;
            }
            let (bc, ac, ab) = (b.v * c.v, a.v * c.v, a.v * b.v);
            out.gradients
                .push(DVec3::new(a.d1 * bc, b.d1 * ac, c.d1 * ab));
            if order == 1 {
                continue;
            }
            let (xy, xz, yz) = (a.d1 * b.d1 * c.v, a.d1 * c.d1 * b.v, b.d1 * c.d1 * a.v);
            out.hessians.push(DMat3::from_cols(
                DVec3::new(a.d2 * bc, xy, xz),
                DVec3::new(xy, b.d2 * ac, yz),
                DVec3::new(xz, yz, c.d2 * ab),
            ));
        }
    }
}

/// a bᵀ.
pub(crate) fn outer(a: DVec3, b: DVec3) -> DMat3 {
    DMat3::from_cols(a * b.x, a * b.y, a * b.z)
}
