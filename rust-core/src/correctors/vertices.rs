//! Vertex placement on cut grid edges (paper §III-D2): linear interpolation for previews,
//! and the correction step — Newton along the edge with the directional derivative,
//! falling back to bisection whenever Newton would leave the bracket — until
//! |F(v) − iso| <= tolerance.

use super::cache::NodeValues;
use crate::field::sph::{Sample, SphField};
use crate::mc::{edge_node_axis, edge_upper_node, linear_crossing, VirtualGrid};
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

/// Places the vertex of edge `edge` for isovalue `iso`.
pub fn place(
    grid: &VirtualGrid,
    nodes: &impl NodeValues,
    edge: u64,
    iso: f64,
    placement: Placement,
) -> Placed {
    let (n0, axis) = edge_node_axis(edge);
    let n1 = edge_upper_node(edge);
    let (f0, w0) = nodes.node(n0);
    let (f1, w1) = nodes.node(n1);
    let x0 = grid.node_position(n0);
    let mut dir = DVec3::ZERO;
    dir[axis] = grid.cell_size;
    let t_lin = linear_crossing(f0, f1, iso);
    let linear = Placed {
        position: x0 + dir * t_lin,
        weight: w0 + (w1 - w0) * t_lin,
        converged: true,
        ..Placed::default()
    };
    let (field, tolerance) = match placement {
        Placement::Linear => return linear,
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
        t = if slope != 0.0 && newton > lo && newton < hi {
            newton
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
