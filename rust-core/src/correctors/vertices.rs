//! Vertex placement on cut grid edges (paper §III-D2): linear interpolation for previews,
//! and the correction step — Newton along the edge with the directional derivative,
//! falling back to bisection whenever Newton would leave the bracket — until
//! |F(v) − iso| <= tolerance. The first step goes to the root of the cubic that matches
//! the two node values and the first sample's value and slope, not to the tangent's.

use crate::field::sph::{Sample, SphField};
use crate::mc::{edge_node_axis, linear_crossing, VirtualGrid};
use glam::DVec3;

/// A vertex on a grid edge.
#[derive(Clone, Copy, Debug, Default)]
pub struct Placed {
    pub position: DVec3,
    /// Field gradient at the vertex (zero in preview mode).
    pub gradient: DVec3,
    /// Sum of weights at the vertex.
    pub weight: f64,
    /// Distance from the linear-interpolation point (0 in preview mode).
    pub correction: f64,
    /// Field evaluations spent on this vertex.
    pub evaluations: u32,
    /// Whether the final point meets the tolerance.
    pub converged: bool,
}

/// How vertices are placed.
#[derive(Clone, Copy, Debug)]
pub enum Placement<'a> {
    /// Linear interpolation of node values.
    Linear,
    /// Newton-corrected to |F − iso| <= `tolerance` (absolute).
    Corrected { field: &'a SphField, tolerance: f64 },
}

/// Places the vertex of edge `edge`, whose end nodes have the field values `values`
/// and (for linear placement, which interpolates them) the sums of weights `weights`,
/// for isovalue `iso`.
pub fn place(
    grid: &VirtualGrid,
    edge: u64,
    values: [f64; 2],
    weights: Option<[f64; 2]>,
    iso: f64,
    placement: Placement,
) -> Placed {
    let (n0, axis) = edge_node_axis(edge);
    let [f0, f1] = values;
    let x0 = grid.node_position(n0);
    let mut dir = DVec3::ZERO;
    dir[axis] = grid.cell_size;
    let t_lin = linear_crossing(f0, f1, iso);
    let (field, tolerance) = match placement {
        Placement::Linear => {
            let [w0, w1] = weights.expect("linear placement interpolates the ends' weights");
            return Placed {
                position: x0 + dir * t_lin,
                weight: w0 + (w1 - w0) * t_lin,
                converged: true,
                ..Placed::default()
            };
        }
        Placement::Corrected { field, tolerance } => (field, tolerance),
    };
    // Bracket [lo, hi] in edge parameter; r0 is the residual's sign at lo.
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    let lo_above = f0 > iso;
    let mut t = t_lin;
    let mut best: Option<(f64, f64, Sample)> = None;
    let mut evaluations = 0u32;
    for _ in 0..64 {
        let s = field.sample(x0 + dir * t);
        evaluations += 1;
        let r = s.value - iso;
        if best.as_ref().is_none_or(|(_, br, _)| r.abs() < br.abs()) {
            best = Some((t, r, s));
        }
        if r.abs() <= tolerance {
            break;
        }
        if (s.value > iso) == lo_above {
            lo = t;
        } else {
            hi = t;
        }
        if hi - lo <= 1e-15 {
            break;
        }
        let slope = s.gradient[axis] * grid.cell_size;
        let newton = t - r / slope;
        let guess = if evaluations == 1 {
            // The first sample's value and slope with the two node values fix a cubic
            // along the edge whose root is far closer than Newton's tangent: most
            // vertices then converge at the second sample instead of the third.
            cubic_root(f0 - iso, f1 - iso, t, r, slope, lo, hi).unwrap_or(newton)
        } else {
            newton
        };
        t = if slope != 0.0 && guess > lo && guess < hi {
            guess
        } else {
            0.5 * (lo + hi)
        };
    }
    let (t, r, s) = best.expect("at least one evaluation");
    Placed {
        position: x0 + dir * t,
        gradient: s.gradient,
        weight: s.weight,
        correction: (t - t_lin).abs() * grid.cell_size,
        evaluations,
        converged: r.abs() <= tolerance,
    }
}

/// The root in (lo, hi) of the cubic p with p(0) = g0, p(1) = g1, p(s) = r and
/// p'(s) = slope, if the fit is well posed and its Newton iteration stays in the bracket.
fn cubic_root(g0: f64, g1: f64, s: f64, r: f64, slope: f64, lo: f64, hi: f64) -> Option<f64> {
    // p(t) = g0 + (g1 − g0) t + t (t − 1) (α + β t): the ends hold by construction.
    let q = s * (s - 1.0);
    if q.abs() < 1e-6 {
        return None;
    }
    let m = (r - g0 - (g1 - g0) * s) / q;
    let beta = (slope - (g1 - g0) - (2.0 * s - 1.0) * m) / q;
    let alpha = m - beta * s;
    let p = |t: f64| g0 + (g1 - g0) * t + t * (t - 1.0) * (alpha + beta * t);
    let dp = |t: f64| (g1 - g0) + (2.0 * t - 1.0) * (alpha + beta * t) + t * (t - 1.0) * beta;
    // Newton on the polynomial, run to the last bits: a guess cut short at a looser
    // threshold would be a discontinuous function of the data, and two lattices equal
    // to rounding would then place the same vertex visibly apart.
    let mut t = s;
    for _ in 0..16 {
        let d = dp(t);
        if d == 0.0 || !d.is_finite() {
            return None;
        }
        let next = t - p(t) / d;
        if !(next > lo && next < hi) {
            return None;
        }
        if (next - t).abs() <= 4.0 * f64::EPSILON {
            return Some(next);
        }
        t = next;
    }
    Some(t)
}

#[cfg(test)]
mod tests {
    use super::cubic_root;

    #[test]
    fn cubic_root_is_exact_for_a_cubic() {
        // p(t) = (t − 0.3)(t + 0.5)(t − 2): one root in (0, 1).
        let p = |t: f64| (t - 0.3) * (t + 0.5) * (t - 2.0);
        let dp = |t: f64| (t + 0.5) * (t - 2.0) + (t - 0.3) * (t - 2.0) + (t - 0.3) * (t + 0.5);
        for s in [0.1, 0.25, 0.6, 0.9] {
            let root = cubic_root(p(0.0), p(1.0), s, p(s), dp(s), 0.0, 1.0).unwrap();
            assert!((root - 0.3).abs() < 1e-12, "s = {s}: {root}");
        }
        // Too close to an end to fit: refused, the caller takes Newton's step.
        assert!(cubic_root(p(0.0), p(1.0), 1e-9, p(1e-9), dp(1e-9), 0.0, 1.0).is_none());
    }
}
