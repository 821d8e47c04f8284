//! One particle: its reference-space position in a cell and what the field says there;
//! projection onto F = C (eq. 1, in reference space) and moves across cells. Where the
//! surface meets the mesh's boundary, a projection step or a move that would leave the
//! mesh is kept in its cell instead of dropped: its components along the normals of the
//! cell's faces it crosses are removed, so it slides parallel to them, and the surface is
//! sampled up to its edge.

use crate::field::fe::curvature::curvature_magnitude;
use crate::field::fe::{FeMesh, Kind, Scratch, Walk, INSIDE_SLACK};
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
    /// Whether some values are not finite (their cells are left out): "never crosses"
    /// then holds only where the field is finite.
    pub gaps: bool,
}

impl Surface<'_> {
    fn count(&self) {
        self.evaluations.fetch_add(1, Ordering::Relaxed);
    }

    /// [`FeMesh::relocate`] that finds a point the walk across faces lost (an inversion
    /// failed in a sliver, or the path crossed more faces than the walk follows, as in
    /// Delaunay meshes) by locating it in the whole mesh. `None` where the walk leaves
    /// the mesh through a boundary face of the cell it reached (the point may still be in
    /// the mesh past a re-entrant corner; it is then held in that cell). Without this, a
    /// lost point would be taken for one leaving the mesh and held too, and a held move
    /// can leave a particle's copy on it.
    pub(super) fn relocate(&self, c: usize, u: DVec3, sc: &mut Scratch) -> Option<(usize, DVec3)> {
        match self.mesh.walk(c, u, sc) {
            Walk::To(c, u) => Some((c, u)),
            Walk::Out => None,
            Walk::Lost(x) => {
                let mut evaluations = 0;
                let found = self
                    .mesh
                    .index()
                    .locate_thorough(self.mesh, x, sc, &mut evaluations);
                self.evaluations.fetch_add(evaluations, Ordering::Relaxed);
                found
            }
        }
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
        let (mut cell, mut u) = self.relocate(cell, u, sc)?;
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
            let du = newton_step(r, e.grad_ref, e.grad_ref.length_squared());
            (cell, u) = match self.relocate(cell, u + du, sc) {
                Some(next) => next,
                // The step leaves the mesh: the surface meets the mesh's boundary here,
                // and is followed parallel to the cell's faces the step would cross
                // (Newton on the field restricted to those directions) instead of being
                // lost. The faces are those of this cell, which may be inner ones where
                // the mesh is left beyond a neighbour; sliding along them still keeps
                // the point in the mesh, and a later step may cross them.
                None => {
                    let kind = self.mesh.shape(cell).kind;
                    let step = within(kind, u, |held| {
                        let g = held.along(e.grad_ref);
                        let g2 = g.length_squared();
                        (g2 > 1e-12 * e.grad_ref.length_squared()).then(|| newton_step(r, g, g2))
                    })?;
                    (cell, u + step)
                }
            };
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
        let du = p.k * dx;
        let cell = p.cell as usize;
        let (cell, u) = match self.relocate(cell, p.u + du, sc) {
            Some(next) => next,
            // A particle pushed out of the mesh slides parallel to the faces it would
            // cross.
            None => {
                let kind = self.mesh.shape(cell).kind;
                (cell, p.u + within(kind, p.u, |held| Some(held.along(du)))?)
            }
        };
        self.project(cell, u, p.lambda, sc)
    }
}

/// The Newton step −r g/|g|² (`g2` = |g|²), no longer than half a cell: a longer one is not
/// to be trusted.
fn newton_step(r: f64, g: DVec3, g2: f64) -> DVec3 {
    let du = -r * g / g2;
    let len = du.length();
    if len > 0.5 {
        du * (0.5 / len)
    } else {
        du
    }
}

/// The faces of a reference domain a step is held on: their orthonormalised inward
/// normals.
#[derive(Default)]
struct Held {
    normals: [DVec3; 3],
    count: usize,
}

impl Held {
    /// `v` without its components along the held faces' normals.
    fn along(&self, v: DVec3) -> DVec3 {
        self.normals[..self.count]
            .iter()
            .fold(v, |v, n| v - v.dot(*n) * *n)
    }

    /// Holds the step on one more face; false when its normal is already spanned.
    fn hold(&mut self, normal: DVec3) -> bool {
        let t = self.along(normal);
        if self.count == 3 || t.length_squared() < 1e-18 {
            return false;
        }
        self.normals[self.count] = t.normalize();
        self.count += 1;
        true
    }
}

/// A step from `u` that stays in the reference domain of `kind` (an active-set method):
/// `step(held)` proposes one with the held faces' normal components removed; each face the
/// proposal crosses is held in turn, until one stays inside. `None` when `step` gives up
/// or the faces leave no direction (a corner).
fn within(kind: Kind, u: DVec3, step: impl Fn(&Held) -> Option<DVec3>) -> Option<DVec3> {
    let mut held = Held::default();
    loop {
        let du = step(&held)?;
        match kind.crossed_face(u, du, INSIDE_SLACK) {
            None => return Some(du),
            Some(f) => {
                if !held.hold(kind.face_normal(f)) {
                    return None;
                }
            }
        }
    }
}
