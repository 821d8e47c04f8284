//! Free-surface trimming (paper §III-D3, Fig. 3). A triangle whose vertices all have a
//! sum of weights at or above the vertex threshold is kept, one with all below is dropped,
//! and the rest are clipped where the sum of weights equals the threshold; a clipped quad
//! becomes two triangles. Cut points are shared by the two triangles on either side of a
//! mesh edge, so the trimmed boundary is a clean edge loop, and in quality mode each cut
//! point is moved onto both level sets at once: F = iso and S = threshold.

use crate::field::sph::SphField;
use glam::DVec3;
use rayon::prelude::*;

/// A mesh before trimming: positions with their sums of weights and gradients.
pub struct Untrimmed {
    pub positions: Vec<DVec3>,
    pub gradients: Vec<DVec3>,
    pub weights: Vec<f64>,
    pub triangles: Vec<[u32; 3]>,
}

/// A trimmed mesh (unused vertices not yet removed: see [`Untrimmed::compact`]).
pub struct Trimmed {
    pub mesh: Untrimmed,
    pub cut_points: usize,
    pub evaluations: u64,
}

/// Where cut points go in quality mode.
pub struct CutTarget<'a> {
    pub field: &'a SphField,
    pub iso: f64,
    /// Absolute tolerance on |F − iso|.
    pub tolerance: f64,
    /// Absolute tolerance on |S − threshold|.
    pub weight_tolerance: f64,
}

/// Clips `input` at sum of weights = `threshold`.
pub fn trim(input: Untrimmed, threshold: f64, target: Option<CutTarget>) -> Trimmed {
    let kept = |v: u32| input.weights[v as usize] >= threshold;
    // Mesh edges crossing the threshold, each once, as (kept vertex, dropped vertex).
    let mut cut_edges: Vec<(u32, u32)> = input
        .triangles
        .par_iter()
        .flat_map_iter(|t| {
            (0..3).filter_map(move |k| {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                match (kept(a), kept(b)) {
                    (true, false) => Some((a, b)),
                    (false, true) => Some((b, a)),
                    _ => None,
                }
            })
        })
        .collect();
    cut_edges.par_sort_unstable();
    cut_edges.dedup();

    let n_old = input.positions.len() as u32;
    let placed: Vec<(DVec3, DVec3, f64, u32)> = cut_edges
        .par_iter()
        .map(|&(a, b)| {
            let (wa, wb) = (input.weights[a as usize], input.weights[b as usize]);
            let s = ((wa - threshold) / (wa - wb)).clamp(0.0, 1.0);
            let (pa, pb) = (input.positions[a as usize], input.positions[b as usize]);
            let x = pa + (pb - pa) * s;
            match &target {
                None => {
                    let g = input.gradients[a as usize].lerp(input.gradients[b as usize], s);
                    (x, g, threshold, 0)
                }
                Some(t) => onto_both_level_sets(t, x, threshold, pa.distance(pb)),
            }
        })
        .collect();
    let cut_index = |a: u32, b: u32| {
        let key = if kept(a) { (a, b) } else { (b, a) };
        n_old + cut_edges.binary_search(&key).expect("cut edge listed") as u32
    };

    // Clip each triangle: walk its edges, keep kept vertices, insert cut points.
    let triangles: Vec<[u32; 3]> = input
        .triangles
        .par_iter()
        .flat_map_iter(|t| {
            let mut poly = [0u32; 4];
            let mut n = 0;
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                if kept(a) {
                    poly[n] = a;
                    n += 1;
                }
                if kept(a) != kept(b) {
                    poly[n] = cut_index(a, b);
                    n += 1;
                }
            }
            (1..n.saturating_sub(1)).map(move |i| [poly[0], poly[i], poly[i + 1]])
        })
        .collect();

    let evaluations = placed.iter().map(|p| p.3 as u64).sum();
    let cut_points = placed.len();
    let mut positions = input.positions;
    let mut gradients = input.gradients;
    let mut weights = input.weights;
    for (x, g, w, _) in placed {
        positions.push(x);
        gradients.push(g);
        weights.push(w);
    }
    Trimmed {
        mesh: Untrimmed {
            positions,
            gradients,
            weights,
            triangles,
        },
        cut_points,
        evaluations,
    }
}

/// Gauss–Newton on the two equations F(x) = iso, S(x) = threshold from `x`, taking the
/// least-norm step each time so the point stays close to where it started.
fn onto_both_level_sets(
    t: &CutTarget,
    mut x: DVec3,
    threshold: f64,
    edge_length: f64,
) -> (DVec3, DVec3, f64, u32) {
    let start = x;
    let mut evals = 0;
    let mut s = t.field.sample(x);
    evals += 1;
    for _ in 0..30 {
        let r = [s.value - t.iso, s.weight - threshold];
        if r[0].abs() <= t.tolerance && r[1].abs() <= t.weight_tolerance {
            break;
        }
        let (g, h) = (s.gradient, s.weight_gradient);
        let (a, b, d) = (g.dot(g), g.dot(h), h.dot(h));
        let det = a * d - b * b;
        let step = if det > 1e-12 * a * d && det.is_finite() {
            let y0 = (d * r[0] - b * r[1]) / det;
            let y1 = (a * r[1] - b * r[0]) / det;
            g * y0 + h * y1
        } else if a > 0.0 {
            g * (r[0] / a)
        } else {
            break;
        };
        let candidate = x - step;
        if !candidate.is_finite() || candidate.distance(start) > edge_length {
            break;
        }
        x = candidate;
        s = t.field.sample(x);
        evals += 1;
    }
    (x, s.gradient, s.weight, evals)
}

impl Untrimmed {
    /// Drops vertices no triangle uses, keeping the order of the rest.
    pub fn compact(&mut self) {
        let mut remap = vec![u32::MAX; self.positions.len()];
        for t in &self.triangles {
            for &v in t {
                remap[v as usize] = 0;
            }
        }
        let mut next = 0u32;
        for r in remap.iter_mut() {
            if *r == 0 {
                *r = next;
                next += 1;
            }
        }
        let keep = |i: &usize| remap[*i] != u32::MAX;
        self.positions = (0..self.positions.len())
            .filter(keep)
            .map(|i| self.positions[i])
            .collect();
        self.gradients = (0..self.gradients.len())
            .filter(keep)
            .map(|i| self.gradients[i])
            .collect();
        self.weights = (0..self.weights.len())
            .filter(keep)
            .map(|i| self.weights[i])
            .collect();
        for t in &mut self.triangles {
            *t = t.map(|v| remap[v as usize]);
        }
    }
}
