//! Carrying a reference point across element faces (the paper's Fig. 5): a point that a
//! step moved outside its cell's reference domain is handed to the neighbour across the
//! face it left through. The first guess interpolates the shared face's corners between
//! the two cells' reference coordinates (the paper's linear interpolation); a few Newton
//! steps on the neighbour's mapping then put it on the same world point, so the field is
//! continuous across the hand-over even for curved faces.

use super::mesh::{FeMesh, Scratch};
use glam::{DMat2, DVec2, DVec3};

/// Slack on the reference domain: points this far outside still count as inside.
pub(crate) const INSIDE_SLACK: f64 = 1e-9;

/// Where [`FeMesh::walk`] took a point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Walk {
    /// Into this cell, at this reference point.
    To(usize, DVec3),
    /// Out of the mesh, through a boundary face.
    Out,
    /// Nowhere it could follow; the point is at this world position.
    Lost(DVec3),
}

impl FeMesh {
    /// The cell whose reference domain holds the point `u` of cell `c` (extended past its
    /// faces if `u` is outside), and the reference point there. `None` when the point
    /// leaves the mesh through a boundary face or cannot be followed.
    pub fn relocate(&self, c: usize, u: DVec3, scratch: &mut Scratch) -> Option<(usize, DVec3)> {
        match self.walk(c, u, scratch) {
            Walk::To(c, u) => Some((c, u)),
            Walk::Out | Walk::Lost(_) => None,
        }
    }

    /// [`FeMesh::relocate`] that says why it found no cell: the point left the mesh
    /// through a boundary face, or the walk lost it (a Newton inversion failed in a
    /// sliver, or more face crossings than it follows) at world point x.
    pub fn walk(&self, c: usize, u: DVec3, scratch: &mut Scratch) -> Walk {
        let (mut cell, start) = (c, u);
        let mut u = u;
        let mut world: Option<DVec3> = None;
        for _hop in 0..8 {
            let kind = self.shape(cell).kind;
            let (d, nf) = kind.face_distances(u);
            let Some((f, depth)) = d[..nf]
                .iter()
                .copied()
                .enumerate()
                .min_by(|a, b| a.1.total_cmp(&b.1))
            else {
                return Walk::Out;
            };
            if depth >= -INSIDE_SLACK {
                return Walk::To(cell, u);
            }
            let x = *world.get_or_insert_with(|| self.map(cell, u, scratch).0);
            let Some((next, g)) = self.neighbour(cell, f) else {
                return Walk::Out;
            };
            let guess = self.face_guess(cell, f, u, next, g, -depth);
            match self.invert(next, x, guess, scratch) {
                Some(v) => u = v,
                None => return Walk::Lost(x),
            }
            cell = next;
        }
        // Every hop that did not return has set `world`: the point as first given.
        Walk::Lost(world.unwrap_or_else(|| self.map(c, start, scratch).0))
    }

    /// Newton's method on T_c(u) = x from `guess`.
    pub fn invert(&self, c: usize, x: DVec3, guess: DVec3, scratch: &mut Scratch) -> Option<DVec3> {
        let mut evaluations = 0;
        self.invert_counted(c, x, guess, f64::INFINITY, scratch, &mut evaluations)
    }

    /// [`FeMesh::invert`] that adds its forward evaluations (mappings) to `evaluations`
    /// and gives up once an iterate lies further than `give_up` outside the reference
    /// domain (x is then in another cell; saves iterations when searching).
    pub fn invert_counted(
        &self,
        c: usize,
        x: DVec3,
        guess: DVec3,
        give_up: f64,
        scratch: &mut Scratch,
        evaluations: &mut u64,
    ) -> Option<DVec3> {
        let mut u = guess;
        let kind = self.shape(c).kind;
        for _ in 0..30 {
            if give_up.is_finite() {
                let (d, nf) = kind.face_distances(u);
                if d[..nf].iter().any(|&d| d < -give_up) {
                    return None;
                }
            }
            *evaluations += 1;
            let (y, j) = self.map(c, u, scratch);
            let det = j.determinant();
            if det == 0.0 || !det.is_finite() {
                return None;
            }
            let mut du = j.inverse() * (x - y);
            // Damped: the mapping is only trusted near the cell.
            let len = du.length();
            if len > 0.5 {
                du *= 0.5 / len;
            }
            u += du;
            if len < 1e-13 {
                return Some(u);
            }
        }
        None
    }

    /// The paper's linear interpolation: `u` (outside face `f` of `c` by `depth`) in the
    /// neighbour `n`'s reference coordinates, through the corners of the shared face.
    fn face_guess(&self, c: usize, f: usize, u: DVec3, n: usize, g: usize, depth: f64) -> DVec3 {
        let (kc, kn) = (self.shape(c).kind, self.shape(n).kind);
        let fc = kc.faces()[f];
        let fnb = kn.faces()[g];
        let (nc, nn) = (self.nodes(c), self.nodes(n));
        let rc: Vec<DVec3> = fc.iter().map(|&i| DVec3::from(kc.corners()[i])).collect();
        let rn: Vec<DVec3> = fc
            .iter()
            .map(|&i| {
                let id = self.welded(nc[i]);
                let j = fnb
                    .iter()
                    .copied()
                    .find(|&j| self.welded(nn[j]) == id)
                    .unwrap_or(fnb[0]);
                DVec3::from(kn.corners()[j])
            })
            .collect();
        let last = rc.len() - 1;
        let (e1, e2) = (rc[1] - rc[0], rc[last] - rc[0]);
        // Least-squares face parameters (a, b) of u − rc0 ≈ a e1 + b e2.
        let m = DMat2::from_cols_array(&[e1.dot(e1), e1.dot(e2), e1.dot(e2), e2.dot(e2)]);
        let rhs = DVec2::new((u - rc[0]).dot(e1), (u - rc[0]).dot(e2));
        let ab = m.inverse() * rhs;
        let (a, b) = (ab.x.clamp(0.0, 1.0), ab.y.clamp(0.0, 1.0));
        let on_face = if rc.len() == 3 {
            let (a, b) = if a + b > 1.0 {
                (a / (a + b), b / (a + b))
            } else {
                (a, b)
            };
            rn[0] * (1.0 - a - b) + rn[1] * a + rn[2] * b
        } else {
            rn[0] * ((1.0 - a) * (1.0 - b))
                + rn[1] * (a * (1.0 - b))
                + rn[2] * (a * b)
                + rn[3] * ((1.0 - a) * b)
        };
        let inward = (kn.centroid() - on_face).normalize_or_zero();
        on_face + inward * depth
    }
}
