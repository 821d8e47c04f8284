//! One particle: its reference-space position in a cell and what the field says there;
//! projection onto F = C (eq. 1, in reference space) and moves across cells.

use crate::field::fe::curvature::curvature_magnitude;
use crate::field::fe::{FeMesh, Scratch};
use glam::{DMat3, DVec3};
use std::sync::atomic::{AtomicU64, Ordering};

/// A particle with the world quantities of its reference position.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Particle {
    pub cell: u32,
    pub u: DVec3,
    /// World position T(u).
    pub x: DVec3,
    /// Unit normal F_x / |F_x|.
    pub n: DVec3,
    /// K = J⁻¹ at u (maps world velocities into reference space, eq. 21).
    pub k: DMat3,
    /// Curvature magnitude D.
    pub d: f64,
    /// |F − C| after projection.
    pub residual: f64,
    /// Adaptive step λ of the gradient descent.
    pub lambda: f64,
    /// Energy at the last accepted position.
    pub energy: f64,
}

/// The surface F = C of one point array over a mesh, with evaluation counting.
pub(crate) struct Surface<'a> {
    pub mesh: &'a FeMesh,
    pub values: &'a [f64],
    pub iso: f64,
    pub tolerance: f64,
    /// Whether projections compute the curvature D (ρ > 0 scales the spacing by it).
    /// Without, D stays 0 until [`Surface::curvature`] fills it in for the output: the
    /// second derivatives cost more than the rest of an evaluation.
    pub curvature_in_projection: bool,
    /// Forward evaluations (basis + mapping at one point).
    pub evaluations: AtomicU64,
}

impl Surface<'_> {
    fn count(&self) {
        self.evaluations.fetch_add(1, Ordering::Relaxed);
    }

    /// Newton steps u ← u − (F* − C) F*_u/|F*_u|² (eq. 1 in reference coordinates, where
    /// the basis is closed-form), following the point across cells. `None` when it
    /// leaves the mesh or does not reach the tolerance.
    pub fn project(
        &self,
        cell: usize,
        u: DVec3,
        lambda: f64,
        sc: &mut Scratch,
    ) -> Option<Particle> {
        let (mut cell, mut u) = self.mesh.relocate(cell, u, sc)?;
        for _ in 0..12 {
            self.count();
            let order = if self.curvature_in_projection { 2 } else { 1 };
            let e = self.mesh.evaluate_to(self.values, cell, u, order, sc);
            let r = e.value - self.iso;
            let g2 = e.grad_ref.length_squared();
            if !r.is_finite() || g2 <= 0.0 || !g2.is_finite() {
                return None;
            }
            if r.abs() <= self.tolerance {
                let len = e.grad.length();
                return Some(Particle {
                    cell: cell as u32,
                    u,
                    x: e.x,
                    n: e.grad / len,
                    k: e.inverse_jacobian(),
                    d: if order == 2 {
                        curvature_magnitude(e.grad, e.hessian)
                    } else {
                        0.0
                    },
                    residual: r.abs(),
                    lambda,
                    energy: 0.0,
                });
            }
            let mut du = -r * e.grad_ref / g2;
            // A Newton step longer than half a cell is not to be trusted.
            let len = du.length();
            if len > 0.5 {
                du *= 0.5 / len;
            }
            (cell, u) = self.mesh.relocate(cell, u + du, sc)?;
        }
        None
    }

    /// The curvature magnitude D at particle `p` (one forward evaluation).
    pub fn curvature(&self, p: &Particle, sc: &mut Scratch) -> f64 {
        self.count();
        let e = self.mesh.evaluate(self.values, p.cell as usize, p.u, sc);
        curvature_magnitude(e.grad, e.hessian)
    }

    /// The particle moved by the world displacement `dx` (mapped to reference space by K,
    /// eq. 21) and projected back.
    pub fn moved(&self, p: &Particle, dx: DVec3, sc: &mut Scratch) -> Option<Particle> {
        self.project(p.cell as usize, p.u + p.k * dx, p.lambda, sc)
    }
}
