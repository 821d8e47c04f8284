//! Initial particles: in every cell whose nodal values straddle C, a small reference-space
//! lattice is scanned for sign changes along its axes and each crossing is projected onto
//! the surface. Cells are visited in parallel and their seeds joined in cell order.

use super::particle::{Particle, Surface};
use crate::field::fe::{Kind, Scratch};
use glam::DVec3;
use rayon::prelude::*;

/// Projected seeds of every cell, in cell order, with initial step `lambda`.
pub(crate) fn seeds(surface: &Surface, lambda: f64) -> Vec<Particle> {
    let mesh = surface.mesh;
    let per_cell: Vec<Vec<Particle>> = (0..mesh.cell_count())
        .into_par_iter()
        .map_init(Scratch::default, |sc, c| cell_seeds(surface, c, lambda, sc))
        .collect();
    per_cell.into_iter().flatten().collect()
}

fn cell_seeds(surface: &Surface, c: usize, lambda: f64, sc: &mut Scratch) -> Vec<Particle> {
    let mesh = surface.mesh;
    let iso = surface.iso;
    let nodes = mesh.nodes(c);
    let above = nodes
        .iter()
        .filter(|&&n| surface.values[n as usize] > iso)
        .count();
    if above == 0 || above == nodes.len() {
        return Vec::new();
    }
    let shape = mesh.shape(c);
    // The lattice holds every node of the cell (m is a multiple of the order on each
    // axis), so when the nodes straddle the isovalue some lattice edge does too and the
    // cell is never left without seeds, however small the surface inside it (a sphere
    // around the body node of one cell has no coarser lattice point inside it).
    let m = lattice_divisions(shape.order) as i32;
    let inside = |i: i32, j: i32, k: i32| -> bool {
        let ok = |v: i32| (0..=m).contains(&v);
        ok(i)
            && ok(j)
            && ok(k)
            && match shape.kind {
                Kind::Hexahedron => true,
                Kind::Tetrahedron => i + j + k <= m,
                Kind::Wedge => i + j <= m,
            }
    };
    let at = |i: i32, j: i32, k: i32| DVec3::new(i as f64, j as f64, k as f64) / m as f64;
    let side = (m + 1) as usize;
    let mut value = vec![f64::NAN; side * side * side];
    let idx = |i: i32, j: i32, k: i32| (i as usize) + side * ((j as usize) + side * (k as usize));
    for k in 0..=m {
        for j in 0..=m {
            for i in 0..=m {
                if inside(i, j, k) {
                    value[idx(i, j, k)] = surface.value(c, at(i, j, k), sc) - iso;
                }
            }
        }
    }
    let mut out = Vec::new();
    for k in 0..=m {
        for j in 0..=m {
            for i in 0..=m {
                if !inside(i, j, k) {
                    continue;
                }
                let a = value[idx(i, j, k)];
                for (di, dj, dk) in [(1, 0, 0), (0, 1, 0), (0, 0, 1)] {
                    let (i2, j2, k2) = (i + di, j + dj, k + dk);
                    if !inside(i2, j2, k2) {
                        continue;
                    }
                    let b = value[idx(i2, j2, k2)];
                    if (a < 0.0) == (b < 0.0) {
                        continue;
                    }
                    let t = a / (a - b);
                    let u = at(i, j, k).lerp(at(i2, j2, k2), t);
                    if let Some(p) = surface.project(c, u, lambda, sc) {
                        out.push(p);
                    }
                }
            }
        }
    }
    out
}

impl Surface<'_> {
    /// F* at reference point `u` of cell `c` (one forward evaluation).
    pub(crate) fn value(&self, c: usize, u: DVec3, sc: &mut Scratch) -> f64 {
        self.evaluations
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        self.mesh.value(self.values, c, u, sc)
    }
}

/// Divisions per axis of the seeding lattice: a multiple of every axis order, at least
/// max(order + 1, 3) so that curved cells are probed between their nodes.
fn lattice_divisions(order: [usize; 3]) -> usize {
    fn gcd(a: usize, b: usize) -> usize {
        if b == 0 {
            a
        } else {
            gcd(b, a % b)
        }
    }
    let lcm = order
        .iter()
        .fold(1, |l, &o| if o == 0 { l } else { l / gcd(l, o) * o });
    let want = (order.iter().max().copied().unwrap_or(1) + 1).max(3);
    lcm * want.div_ceil(lcm)
}
