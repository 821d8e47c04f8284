//! Error-driven refinement, added to the paper's splash criterion (which counts particles
//! and never looks at the surface). For each coarse cell at or next to the surface, the
//! field is sampled at the nodes the next level would add (edge midpoints, face and cell
//! centres of the cell's current sub-cells) and compared with the trilinear interpolant of
//! the current level's node values; the difference, turned into a distance with the
//! field's gradient (|F − F_lin| / |∇F|), estimates how far the current level's surface
//! lies from the next one's. A cell whose estimate exceeds `max_error` finest cells is
//! raised one level, 1 → 2 and then 2 → 3, with `grid::balance` between the rounds and
//! after them.
//!
//! Every cell's decision reads only the field and the levels as they were before the
//! pass, so the result does not depend on the thread count. The GPU back end takes its
//! levels from the same function, its samples evaluated here on the CPU.

use super::grid::{self, subdivisions, CoarseGrid, FINE_PER_COARSE};
use crate::field::ScalarField;
use glam::DVec3;
use rayon::prelude::*;

/// What the criteria did: cells the error criterion raised 1 → 2 and 2 → 3, cells the
/// hidden-surface rule raised ([`hidden_surfaces`]), and the field evaluations (with
/// gradient for the error criterion) both took.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Refined {
    pub raised: [u64; 2],
    pub hidden: u64,
    pub evaluations: u64,
}

/// The hidden-surface rule. A cell contours its sub-cells from their corner values, so a
/// closed piece of level set that lies strictly inside one sub-cell (a droplet between
/// the corners, or a bubble) is invisible to it, and to the error criterion as well when
/// the next level's samples miss it too. The field's extremum of such a piece sits near
/// the particles that make it, so the field at each particle is the witness: a particle
/// whose value lies on the other side of `iso` from every corner of the sub-cell holding
/// it at level L is hidden at level L.
///
/// Each particle asks for the lowest level whose sub-cell holding it has a node on its
/// side (level 1: the coarse cell's corners; level 2: the corners of its half-size
/// sub-cell; 3 if neither). Nodes nest across levels (every level-L node is a node of
/// level L + 1), so once the cell is at that level or above, its contouring has a node on
/// the particle's side within one level-L sub-cell of it and the piece gets a surface.
/// The level asked for does not depend on the cell's current level, so the rule reads
/// nothing but the field and the particles (any order, any thread count, both back
/// ends) and only raises levels; a cell already at level 2 is compared on its level-2
/// sub-cell, which the ask already includes. Balancing runs after it (in [`refine`] and
/// in `levels_from_counts`). One field evaluation per particle in a cell below level 3,
/// plus the corner values of the cells those particles lie in.
pub fn hidden_surfaces<F: ScalarField + ?Sized>(
    field: &F,
    grid: &CoarseGrid,
    positions: &[DVec3],
    levels: &mut [u8],
    iso: f64,
) -> Refined {
    // (cell, particle position, field there) for every particle whose cell can still rise.
    let mut at: Vec<(usize, DVec3, f64)> = positions
        .par_iter()
        .filter_map(|&p| {
            let i = grid.cell_of(p)?;
            (levels[i] < 3).then(|| (i, p, field.value(p)))
        })
        .collect();
    let mut out = Refined {
        evaluations: at.len() as u64,
        ..Refined::default()
    };
    // Stable: within a cell the particles keep their order, so the lazily evaluated
    // nodes (and the evaluation count) do not depend on the thread count.
    at.par_sort_by_key(|a| a.0);
    let groups: Vec<&[(usize, DVec3, f64)]> = at.chunk_by(|a, b| a.0 == b.0).collect();
    const N: usize = FINE_PER_COARSE as usize + 1;
    let asks: Vec<(usize, u8, u64)> = groups
        .par_iter()
        .map(|g| {
            let i = g[0].0;
            let base = grid.coords(i).map(|x| (x * FINE_PER_COARSE) as i64);
            let origin = grid.point(base, 0);
            // The cell's finest-lattice node values, evaluated when first needed (NaN:
            // not yet), at the same lattice points the levels contour.
            let mut nodes = [f64::NAN; N * N * N];
            let mut evaluations = 0u64;
            let mut value = |l: [usize; 3]| {
                let v = &mut nodes[l[0] + N * (l[1] + N * l[2])];
                if v.is_nan() {
                    let sub = std::array::from_fn(|a| base[a] + l[a] as i64);
                    *v = field.value(grid.point(sub, 0));
                    evaluations += 1;
                }
                *v
            };
            let mut need = 1u8;
            for &(_, p, f) in g.iter() {
                let side = f > iso;
                // The particle's position in finest cells from the cell's first node.
                let local = (p - origin) / grid.fine;
                let mut ask = 3;
                for level in 1..=2u8 {
                    let step = (FINE_PER_COARSE / subdivisions(level)) as usize;
                    let lo: [usize; 3] = std::array::from_fn(|a| {
                        let k = (local[a] / step as f64).floor().max(0.0) as usize;
                        k.min(subdivisions(level) as usize - 1) * step
                    });
                    let seen = (0..8).any(|v| {
                        let n = [v & 1, v >> 1 & 1, v >> 2 & 1];
                        let l = std::array::from_fn(|a| lo[a] + n[a] * step);
                        (value(l) > iso) == side
                    });
                    if seen {
                        ask = level;
                        break;
                    }
                }
                need = need.max(ask);
                if need == 3 {
                    break;
                }
            }
            (i, need, evaluations)
        })
        .collect();
    for (i, need, evaluations) in asks {
        out.evaluations += evaluations;
        if need > levels[i] {
            levels[i] = need;
            out.hidden += 1;
        }
    }
    out
}

/// Raises cells of `levels` (after splitting and dilation; balanced on return) where the
/// next level's samples are more than `max_error` finest cells off the current level's
/// interpolant near the surface. `counts` are the particles per coarse cell (a cell
/// holding particles but no corner inside the fluid may hide a droplet between its
/// corners). `max_error` ≤ 0 leaves the levels as they are.
pub fn refine<F: ScalarField + ?Sized>(
    field: &F,
    grid: &CoarseGrid,
    counts: &[u32],
    levels: &mut [u8],
    iso: f64,
    max_error: f64,
) -> Refined {
    let mut out = Refined::default();
    if max_error <= 0.0 {
        return out;
    }
    let tolerance = max_error * grid.fine;
    let corners = corner_values(field, grid);
    let node = |c: [u32; 3]| {
        c[0] as usize
            + (grid.cells[0] as usize + 1)
                * (c[1] as usize + (grid.cells[1] as usize + 1) * c[2] as usize)
    };
    // Sign of each cell's corners: bit 0 some corner inside, bit 1 some corner outside.
    let signs: Vec<u8> = (0..levels.len())
        .into_par_iter()
        .map(|i| {
            let c = grid.coords(i);
            (0..8).fold(0u8, |s, v| {
                let n = [c[0] + (v & 1), c[1] + (v >> 1 & 1), c[2] + (v >> 2 & 1)];
                s | if corners[node(n)] > iso { 1 } else { 2 }
            })
        })
        .collect();
    let crossed = |i: usize| signs[i] == 3;
    // Candidates: cells the surface crosses or touches (a corner sign change in
    // the cell or one of its 26 neighbours), and cells holding particles with no corner
    // inside (a droplet that may fall between the corners).
    let candidate = |i: usize| {
        let c = grid.coords(i);
        if counts[i] > 0 && signs[i] & 1 == 0 {
            return true;
        }
        (0..27).any(|d| {
            let n: [i64; 3] =
                std::array::from_fn(|a| c[a] as i64 + [d % 3, d / 3 % 3, d / 9][a] as i64 - 1);
            (0..3).all(|a| n[a] >= 0 && n[a] < grid.cells[a] as i64)
                && crossed(grid.index(n.map(|x| x as u32)))
        })
    };
    let corner_list = |c: [u32; 3]| -> Vec<f64> {
        (0..8)
            .map(|v| corners[node([c[0] + (v & 1), c[1] + (v >> 1 & 1), c[2] + (v >> 2 & 1)])])
            .collect()
    };
    // 1 → 2 on every level-1 candidate.
    let tested: Vec<(usize, bool)> = (0..levels.len())
        .into_par_iter()
        .filter(|&i| levels[i] == 1 && candidate(i))
        .map(|i| {
            let c = grid.coords(i);
            let (_, error) = next_level_error(field, grid, c, 1, &corner_list(c), iso);
            (i, error > tolerance)
        })
        .collect();
    out.evaluations += corners.len() as u64 + tested.len() as u64 * 19;
    for &(i, raise) in &tested {
        if raise {
            levels[i] = 2;
            out.raised[0] += 1;
        }
    }
    // 2 → 3 on every level-2 candidate, from its level-2 values. Balancing raises more
    // cells to level 2 around level-3 ones (splash cells or cells raised here), whose
    // surface the test has not seen: repeat on those until none is new. Each round
    // reads the levels as the previous one left them, so the rounds are deterministic.
    let mut seen = vec![false; levels.len()];
    loop {
        grid::balance(grid, levels);
        let fresh: Vec<usize> = (0..levels.len())
            .into_par_iter()
            .filter(|&i| levels[i] == 2 && !seen[i] && candidate(i))
            .collect();
        if fresh.is_empty() {
            return out;
        }
        let raise: Vec<usize> = fresh
            .par_iter()
            .filter_map(|&i| {
                let c = grid.coords(i);
                let (two, _) = next_level_error(field, grid, c, 1, &corner_list(c), iso);
                let (_, error) = next_level_error(field, grid, c, 2, &two, iso);
                (error > tolerance).then_some(i)
            })
            .collect();
        out.evaluations += fresh.len() as u64 * (19 + 98);
        for &i in &fresh {
            seen[i] = true;
        }
        out.raised[1] += raise.len() as u64;
        for i in raise {
            levels[i] = 3;
        }
    }
}

/// The field at every coarse-grid node, x fastest.
fn corner_values<F: ScalarField + ?Sized>(field: &F, grid: &CoarseGrid) -> Vec<f64> {
    let n = grid.cells.map(|c| c as usize + 1);
    (0..n[0] * n[1] * n[2])
        .into_par_iter()
        .map(|v| {
            let c = [v % n[0], v / n[0] % n[1], v / (n[0] * n[1])];
            field.value(grid.point(c.map(|x| (x * FINE_PER_COARSE as usize) as i64), 0))
        })
        .collect()
}

/// The node values of coarse cell `c` at level `level + 1` ((2k+1)³, x fastest, with
/// k = subdivisions(level)), and the largest distance estimate |F − F_lin| / |∇F| over
/// the new nodes near the surface, F_lin the trilinear interpolant of `values` (the
/// (k+1)³ node values at `level`) in the sub-cell holding the node.
///
/// A node counts when it is within one current sub-cell of the surface by either value
/// (|F − iso| / |∇F| or |F_lin − iso| / |∇F|), or when F and F_lin lie on different
/// sides of `iso` (the next level would see surface the current one misses).
fn next_level_error<F: ScalarField + ?Sized>(
    field: &F,
    grid: &CoarseGrid,
    c: [u32; 3],
    level: u8,
    values: &[f64],
    iso: f64,
) -> (Vec<f64>, f64) {
    let k = subdivisions(level) as usize;
    let (n, m) = (k + 1, 2 * k + 1);
    let step = (FINE_PER_COARSE as usize / (2 * k)) as u32;
    let band = grid.fine * (2 * step) as f64;
    let mut out = vec![0.0; m * m * m];
    let mut error = 0.0f64;
    for (v, sample) in out.iter_mut().enumerate() {
        let l = [v % m, v / m % m, v / (m * m)];
        if l.iter().all(|x| x % 2 == 0) {
            *sample = values[l[0] / 2 + n * (l[1] / 2 + n * (l[2] / 2))];
            continue;
        }
        let sub: [i64; 3] =
            std::array::from_fn(|a| (c[a] * FINE_PER_COARSE + l[a] as u32 * step) as i64);
        let (f, g) = field.value_and_gradient(grid.point(sub, 0));
        *sample = f;
        // Trilinear interpolation in the current sub-cell: odd local coordinates sit at
        // its middle along that axis (weight ½ each side), even ones on its nodes.
        let mut lin = 0.0;
        for corner in 0..8usize {
            let mut w = 1.0;
            let mut at = [0usize; 3];
            for a in 0..3 {
                let hi = corner >> a & 1;
                if l[a] % 2 == 0 {
                    if hi == 1 {
                        w = 0.0;
                    }
                    at[a] = l[a] / 2;
                } else {
                    w *= 0.5;
                    at[a] = l[a] / 2 + hi;
                }
            }
            if w > 0.0 {
                lin += w * values[at[0] + n * (at[1] + n * at[2])];
            }
        }
        let gradient = g.length().max(f64::MIN_POSITIVE);
        let near = (f - iso).abs().min((lin - iso).abs()) <= band * gradient;
        if near || (f > iso) != (lin > iso) {
            error = error.max((f - lin).abs() / gradient);
        }
    }
    (out, error)
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Linear;

    impl ScalarField for Linear {
        fn value(&self, x: DVec3) -> f64 {
            0.3 - x.dot(DVec3::new(1.0, 0.5, -0.25))
        }
        fn value_and_gradient(&self, x: DVec3) -> (f64, DVec3) {
            (self.value(x), -DVec3::new(1.0, 0.5, -0.25))
        }
    }

    /// R² − |x − c|²: a sphere of radius R at iso 0, |∇F| = 2R on it.
    struct Ball(f64);

    impl ScalarField for Ball {
        fn value(&self, x: DVec3) -> f64 {
            self.0 * self.0 - (x - DVec3::splat(1.0)).length_squared()
        }
        fn value_and_gradient(&self, x: DVec3) -> (f64, DVec3) {
            (self.value(x), -2.0 * (x - DVec3::splat(1.0)))
        }
    }

    fn grid() -> CoarseGrid {
        CoarseGrid {
            origin: DVec3::ZERO,
            fine: 0.05,
            cells: [10; 3],
        }
    }

    /// The trilinear interpolant of a linear field is the field: nothing rises however
    /// small the tolerance.
    #[test]
    fn a_plane_is_never_refined() {
        let g = grid();
        let mut levels = vec![1u8; g.cell_count()];
        let r = refine(
            &Linear,
            &g,
            &vec![0; g.cell_count()],
            &mut levels,
            0.0,
            1e-9,
        );
        assert_eq!(r.raised, [0, 0]);
        assert!(levels.iter().all(|&l| l == 1));
    }

    /// On a sphere F − F_lin at an edge midpoint of a sub-cell of length L is L²/4
    /// exactly, at a face centre L²/2, at a cell centre 3L²/4; the samples counted lie
    /// within one sub-cell of the surface, where |∇F| = 2|x − c| ≥ 2(R − L). So a
    /// tolerance above 3L²/(8(R − L)) for the coarse L raises nothing, and one above it
    /// for L/2 (but below the coarse cells' centre error) raises cells to 2, none to 3.
    #[test]
    fn a_sphere_is_refined_where_the_estimate_says() {
        let g = grid();
        let coarse = 4.0 * g.fine;
        let radius = 0.45;
        let ball = Ball(radius);
        let bound = |l: f64| 3.0 * l * l / (8.0 * (radius - l));
        let none = vec![0; g.cell_count()];
        let mut levels = vec![1u8; g.cell_count()];
        let r = refine(
            &ball,
            &g,
            &none,
            &mut levels,
            0.0,
            1.01 * bound(coarse) / g.fine,
        );
        assert_eq!(r.raised, [0, 0], "above the coarse bound");
        let r = refine(
            &ball,
            &g,
            &none,
            &mut levels,
            0.0,
            1.01 * bound(coarse / 2.0) / g.fine,
        );
        assert!(r.raised[0] > 0, "{r:?}");
        assert_eq!(r.raised[1], 0, "{r:?}");
        for (i, &l) in levels.iter().enumerate() {
            if l > 1 {
                let c = g.coords(i).map(|x| x as f64 * coarse);
                let centre = DVec3::new(c[0], c[1], c[2]) + DVec3::splat(coarse / 2.0);
                let d = ((centre - DVec3::splat(1.0)).length() - radius).abs();
                assert!(d < 3.0 * coarse, "cell {i} raised {d} from the surface");
            }
        }
        let mut levels = vec![1u8; g.cell_count()];
        let r = refine(
            &ball,
            &g,
            &none,
            &mut levels,
            0.0,
            0.01 * bound(coarse) / g.fine,
        );
        assert!(r.raised[1] > 0, "{r:?}");
    }
}
