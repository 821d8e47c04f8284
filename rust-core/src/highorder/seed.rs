//! Initial particles: in every cell whose nodal values straddle C, a small reference-space
//! lattice is scanned for sign changes along its axes (the lattice of the cell's nodes
//! when that one finds none) and each crossing is projected onto the surface. Cells are
//! visited in parallel and their seeds joined in cell order.

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
    let nodes = surface.mesh.nodes(c);
    let below = nodes
        .iter()
        .filter(|&&n| surface.values[n as usize] < surface.iso)
        .count();
    if below == 0 || below == nodes.len() {
        return Vec::new();
    }
    let order = surface.mesh.shape(c).order;
    let probe = (order.iter().max().copied().unwrap_or(1) + 1).max(3);
    let seeds = lattice_seeds(surface, c, probe, lambda, sc);
    let nodal = node_lattice(order);
    if !seeds.is_empty() || probe % nodal == 0 {
        return seeds;
    }
    // The nodes straddle C but no probe edge crosses it: a small surface around a node
    // the probe lattice misses (a sphere about the body node of one quadratic cell). The
    // node lattice holds every node, so one of its edges crosses.
    lattice_seeds(surface, c, nodal, lambda, sc)
}

/// Seeds from the sign changes of F* − C along the axes of an m-per-axis lattice of
/// reference points of cell `c`, each crossing projected onto the surface.
fn lattice_seeds(
    surface: &Surface,
    c: usize,
    m: usize,
    lambda: f64,
    sc: &mut Scratch,
) -> Vec<Particle> {
    let iso = surface.iso;
    let shape = surface.mesh.shape(c);
    let m = m as i32;
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

/// Divisions per axis of the smallest lattice that holds every node of a cell of these
/// orders (the least common multiple of the axis orders).
fn node_lattice(order: [usize; 3]) -> usize {
    fn gcd(a: usize, b: usize) -> usize {
        if b == 0 {
            a
        } else {
            gcd(b, a % b)
        }
    }
    order
        .iter()
        .fold(1, |l, &o| if o == 0 { l } else { l / gcd(l, o) * o })
}
