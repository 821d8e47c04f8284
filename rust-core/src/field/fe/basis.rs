//! Basis functions of a [`Shape`] with first and second derivatives in reference
//! coordinates, evaluated as products of univariate polynomials (see `shape.rs`).

use super::shape::{Family, Shape};
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
        for node in &self.nodes {
            // φ = Π_m f_m(x_m(u)) with x_m affine: ∇φ = Σ_m f'_m Π_{k≠m} f_k d_m, and
            // ∇²φ = Σ_m f''_m Π_{k≠m} f_k d_m d_mᵀ + Σ_{m≠k} f'_m f'_k Π_{rest} d_m d_kᵀ.
            let f: [Jet; 4] = std::array::from_fn(|m| {
                if m < nv {
                    out.jets[m][node[m] as usize]
                } else {
                    Jet::ONE
                }
            });
            let prod_except = |skip: &[usize]| -> f64 {
                (0..nv)
                    .filter(|k| !skip.contains(k))
                    .map(|k| f[k].v)
                    .product()
            };
            let mut value = 1.0;
            for j in f.iter().take(nv) {
                value *= j.v;
            }
            out.values.push(value);
            if order == 0 {
                continue;
            }
            if order == 1 {
                let g: DVec3 = self
                    .variables
                    .iter()
                    .zip(&f)
                    .enumerate()
                    .map(|(m, (var, fm))| var.direction * (fm.d1 * prod_except(&[m])))
                    .sum();
                out.gradients.push(g);
                continue;
            }
            let mut g = DVec3::ZERO;
            let mut h = DMat3::ZERO;
            for m in 0..nv {
                let dm = self.variables[m].direction;
                let rest = prod_except(&[m]);
                g += dm * (f[m].d1 * rest);
                h += outer(dm, dm) * (f[m].d2 * rest);
                for k in (m + 1)..nv {
                    let dk = self.variables[k].direction;
                    let c = f[m].d1 * f[k].d1 * prod_except(&[m, k]);
                    h += (outer(dm, dk) + outer(dk, dm)) * c;
                }
            }
            out.gradients.push(g);
            out.hessians.push(h);
        }
    }
}

/// a bᵀ.
pub(crate) fn outer(a: DVec3, b: DVec3) -> DMat3 {
    DMat3::from_cols(a * b.x, a * b.y, a * b.z)
}
