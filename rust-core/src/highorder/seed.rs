//! Initial particles: in every cell the field may cross C, a small reference-space
//! lattice is scanned for sign changes along its axes (the lattice of the cell's nodes
//! when that one finds none) and each crossing is projected onto the surface. Cells are
//! visited in parallel and their seeds joined in cell order.
//!
//! A cell may cross C when its nodal values straddle it, or, with every node on one side,
//! when the field's Bernstein coefficients do (a sphere's cap through a face, between the
//! nodes). Such a cell with no lattice crossing is searched by projecting its lattice point
//! nearest in value; a cell whose coefficients lie on one side provably holds no surface.

use super::particle::{Particle, Surface};
use crate::field::fe::{Kind, Scratch};
use glam::DVec3;
use rayon::prelude::*;

/// The seeds, and where the surface may be.
pub(crate) struct Seeds {
    /// Projected seeds of every cell, in cell order.
    pub particles: Vec<Particle>,
    /// How many cells the field may cross (0 proves that it never crosses C).
    pub cells: usize,
    /// The largest side of the box of those cells: the surface's extent, where the seeds
    /// may be bunched in a corner of it.
    pub extent: f64,
}

/// The seeds of every cell, with initial step `lambda`.
pub(crate) fn seeds(surface: &Surface, lambda: f64) -> Seeds {
    let mesh = surface.mesh;
    let per_cell: Vec<(usize, Vec<Particle>)> = (0..mesh.cell_count())
        .into_par_iter()
        .map_init(Scratch::default, |sc, c| {
            Some((c, cell_seeds(surface, c, lambda, sc)?))
        })
        .flatten()
        .collect();
    let (lo, hi) = per_cell.iter().fold(
        (DVec3::INFINITY, DVec3::NEG_INFINITY),
        |(lo, hi), &(c, _)| {
            let (a, b) = mesh.cell_box(c);
            (lo.min(a), hi.max(b))
        },
    );
    Seeds {
        cells: per_cell.len(),
        extent: if per_cell.is_empty() {
            0.0
        } else {
            (hi - lo).max_element()
        },
        particles: per_cell.into_iter().flat_map(|(_, s)| s).collect(),
    }
}

/// The seeds of cell `c`; `None` when the field provably does not cross C in it.
fn cell_seeds(surface: &Surface, c: usize, lambda: f64, sc: &mut Scratch) -> Option<Vec<Particle>> {
    let nodes = surface.mesh.nodes(c);
    // A cell touching a non-finite value (a masked region) holds no surface; its field
    // is NaN throughout, so nothing moves into it either.
    if nodes
        .iter()
        .any(|&n| !surface.values[n as usize].is_finite())
    {
        return None;
    }
    let below = nodes
        .iter()
        .filter(|&&n| surface.values[n as usize] < surface.iso)
        .count();
    let straddles = below != 0 && below != nodes.len();
    if !straddles {
        let (lo, hi) = surface.mesh.field_range(surface.values, c, sc);
        if !(lo < surface.iso && surface.iso <= hi) {
            return None;
        }
    }
    let order = surface.mesh.shape(c).order;
    let probe = (order.iter().max().copied().unwrap_or(1) + 1).max(3);
    let (seeds, nearest) = lattice_seeds(surface, c, probe, lambda, sc);
    if !seeds.is_empty() {
        return Some(seeds);
    }
    if !straddles {
        // Every lattice point on one side: Newton from the one nearest in value walks
        // towards C (held on the boundary faces it meets) and finds the surface if the
        // field reaches C there. The coefficients' range may be wider than the field's,
        // so finding none is no error.
        return Some(
            surface
                .project(c, nearest, lambda, sc)
                .into_iter()
                .collect(),
        );
    }
    let nodal = node_lattice(order);
    if probe % nodal == 0 {
        return Some(seeds);
    }
    // The nodes straddle C but no probe edge crosses it: a small surface around a node
    // the probe lattice misses (a sphere about the body node of one quadratic cell). The
    // node lattice holds every node, so one of its edges crosses.
    Some(lattice_seeds(surface, c, nodal, lambda, sc).0)
}

/// Seeds from the sign changes of F* − C along the axes of an m-per-axis lattice of
/// reference points of cell `c`, each crossing projected onto the surface, and the
/// lattice point where |F* − C| is least.
fn lattice_seeds(
    surface: &Surface,
    c: usize,
    m: usize,
    lambda: f64,
    sc: &mut Scratch,
) -> (Vec<Particle>, DVec3) {
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
    let nearest = value
        .iter()
        .enumerate()
        .filter(|(_, v)| !v.is_nan())
        .min_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
        .map(|(n, _)| {
            let n = n as i32;
            let side = side as i32;
            at(n % side, (n / side) % side, n / (side * side))
        })
        .unwrap_or_else(|| shape.kind.centroid());
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
    (out, nearest)
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
