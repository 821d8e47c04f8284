//! Seed cells (paper §III-C): for every pair of particles closer than h whose raw values
//! straddle the isovalue, every virtual-grid cell the segment between them crosses.
//!
//! Raw values bound the field only where the kernels form a partition of unity. An isolated
//! particle or a small cluster has V·W(0) > 1, so its smoothed peak can exceed every raw
//! value and the paper's test would miss the component. Pairs are therefore also tested
//! with the smoothed value at each particle, one evaluation per particle per extraction.
//!
//! A free surface has no such pair across it, since the air holds no particles. So each
//! particle on the edge of the cloud (no neighbour within 1.5 h on one side of an axis) is
//! also paired with the point one support radius out on that side, where the field has
//! fallen to the empty-space value 0. Raw values instead of smoothed ones cost no kernel
//! evaluation and widen the value range near extrema, so no small component is lost.
//!
//! Nor has the wall of an empty cavity inside the fluid (a bubble): its particles have
//! neighbours on every side, along the wall. A particle with neighbours on every side but
//! none within 1.5 h and 60° of a half-axis has the field evaluated one h out along it,
//! and the segment
//! to there is seeded when the two values straddle the isovalue: one evaluation per such
//! side, which interior particles of a solver's even packing seldom have. A pocket
//! narrower than the packing can still be missed (dam_break_frame_9: a bubble 0.2 h
//! across whose nearest particles sit 0.9–1.2 h away, 28 triangles on the full grid).
//!
//! The paper adds every cell along each segment, and notes that most of them are not
//! intersected (on the Hilbert shape here, 96 % were: each costs eight node evaluations).
//! Only the stretch of the segment around the crossing of the linear interpolant of the
//! two end values is seeded here: [`WINDOW_CELLS`] cells, or the kernel's
//! [`Kernel::linear_crossing_error`] plus [`WINDOW_MARGIN`] of the segment, either side,
//! whichever is more. A lone particle (the least linear case) has its real crossing
//! within that error of the estimate at every isovalue, and one seed per component is
//! enough.
//!
//! [`Kernel::linear_crossing_error`]: crate::field::kernel::Kernel::linear_crossing_error

use crate::error::{Error, Result};
use crate::field::neighbours::NeighbourGrid;
use crate::field::sph::SphField;
use crate::mc::{radix, VirtualGrid};
use glam::DVec3;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering};

/// Least half-width, in cells, of the stretch of a segment seeded around its estimated
/// crossing.
pub(crate) const WINDOW_CELLS: f64 = 2.0;
/// Added to the kernel's linear-crossing error, as a fraction of the segment.
pub(crate) const WINDOW_MARGIN: f64 = 0.05;

/// What seeding needs that does not depend on the isovalue, built once per extraction:
/// particle positions, a neighbour grid for the pair search, the smoothed field at each
/// particle (grid-slot order).
pub struct SeedSearch {
    positions: Vec<DVec3>,
    pairs: NeighbourGrid,
    smoothed: Vec<f64>,
    /// (particle slot, probe point, field there) of every cavity probe, by slot.
    probes: Vec<(u32, DVec3, f64)>,
    /// Bytes the seed lists may take ([`seed_cells_with`] counts four copies).
    memory_budget: u64,
}

impl SeedSearch {
    /// Builds the search for `field`; costs one field evaluation per particle. The seed
    /// lists it makes stay within `memory_budget` bytes or are refused.
    pub fn new(field: &SphField, memory_budget: u64) -> Result<Self> {
        let positions: Vec<DVec3> = (0..field.len()).map(|i| field.position(i)).collect();
        let max_radius = (0..field.len())
            .map(|i| side_radius(field, i))
            .fold(0.0, f64::max);
        let pairs = NeighbourGrid::build(&positions, max_radius, 1, memory_budget)?;
        let smoothed = positions
            .par_iter()
            .map(|&x| field.value_and_weight(x).0)
            .collect();
        let probes = cavity_probes(field, &positions, &pairs);
        Ok(SeedSearch {
            positions,
            pairs,
            smoothed,
            probes,
            memory_budget,
        })
    }
}

/// A neighbour within 60° of a half-axis covers it for the cavity test: on the wall of an
/// empty cavity the neighbours lie along the wall, across the inward axis.
const CONE_COS2: f64 = 0.25;
const ALL_SIDES: u8 = 0b11_1111;

/// The unit vector of half-axis `bit` (2a + s: axis a, side s, 0 negative, 1 positive).
fn half_axis(bit: usize) -> DVec3 {
    let mut dir = DVec3::ZERO;
    dir[bit / 2] = if bit % 2 == 1 { 1.0 } else { -1.0 };
    dir
}

/// The cavity probes: for each particle with neighbours on every side but none within
/// 1.5 h and 60° of a half-axis, the point one h along it and the field there. They do
/// not depend on the isovalue, so they are evaluated once per extraction.
fn cavity_probes(
    field: &SphField,
    positions: &[DVec3],
    pairs: &NeighbourGrid,
) -> Vec<(u32, DVec3, f64)> {
    let order = pairs.order();
    (0..positions.len())
        .into_par_iter()
        .flat_map_iter(|i| {
            let xi = positions[i];
            let side_r2 = side_radius(field, i).powi(2);
            let (mut sides, mut cones) = (0u8, 0u8);
            pairs.for_each_candidate_range(xi, 1, |range| {
                for &j in &order[range] {
                    let d = positions[j as usize] - xi;
                    let d2 = d.length_squared();
                    if j as usize == i || d2 >= side_r2 {
                        continue;
                    }
                    for a in 0..3 {
                        let bit = match d[a] {
                            v if v > 0.0 => 2 * a + 1,
                            v if v < 0.0 => 2 * a,
                            _ => continue,
                        };
                        sides |= 1 << bit;
                        if d[a] * d[a] >= CONE_COS2 * d2 {
                            cones |= 1 << bit;
                        }
                    }
                }
            });
            (0..6)
                .filter(move |&bit| sides == ALL_SIDES && cones >> bit & 1 == 0)
                .map(move |bit| {
                    let probe = xi + half_axis(bit) * field.h_unscaled(i);
                    (i as u32, probe, field.value_and_weight(probe).0)
                })
        })
        .collect()
}

/// Pairs are searched within h (the paper).
fn pair_radius(field: &SphField, i: usize) -> f64 {
    field.h_unscaled(i).min(field.support(i))
}

/// A side counts as covered by a neighbour within 1.5 h: solvers space particles about h
/// apart, so h alone would leave the axis neighbours of an interior particle just outside
/// and mark it as free surface on every side.
pub(crate) fn side_radius(field: &SphField, i: usize) -> f64 {
    (1.5 * field.h_unscaled(i)).min(field.support(i))
}

/// Sorted, unique keys of the seed cells for `iso`.
pub fn seed_cells(
    field: &SphField,
    grid: &VirtualGrid,
    iso: f64,
    search: &SeedSearch,
) -> Result<Vec<u64>> {
    let order = search.pairs.order();
    seed_cells_with(field, grid, iso, search, |i, visit| {
        search
            .pairs
            .for_each_candidate_range(search.positions[i], 1, |range| visit(&order[range]))
    })
}

/// [`seed_cells`] with each particle's neighbour candidates from `candidates(i, visit)`,
/// handed over as slices of grid slots (a neighbour-grid row, or the GPU's whole list):
/// any superset, in any order, of the particles within [`side_radius`] of particle i.
/// The exact tests here pick the pairs, so every such superset (the GPU's conservative
/// f32 search, `gpu::seeds`) gives the same seeds. Slices, not single candidates, cross
/// the `dyn` boundary, so the per-pair test stays an inlined loop.
pub fn seed_cells_with(
    field: &SphField,
    grid: &VirtualGrid,
    iso: f64,
    search: &SeedSearch,
    candidates: impl Fn(usize, &mut dyn FnMut(&[u32])) + Sync,
) -> Result<Vec<u64>> {
    let SeedSearch {
        positions,
        smoothed,
        probes,
        memory_budget,
        ..
    } = search;
    // A grid far finer than the particles puts thousands of cells on each segment, most
    // of them listed again by the neighbouring pairs. Each thread's list is deduplicated
    // whenever it has doubled, and the keys held across the lists are counted: past the
    // budget (8 bytes a key, about four copies at the peak: the lists, their
    // concatenation, the sort's buffer) the search stops and is refused.
    let most_keys = memory_budget / 32;
    let held = AtomicU64::new(0);
    // Each particle is classified twice, by its raw and by its smoothed value; a pair
    // straddles when either classification differs.
    let class = |i: usize| (field.raw_value(i) > iso) as u8 | ((smoothed[i] > iso) as u8) << 1;
    let outside = if 0.0 > iso { 3u8 } else { 0u8 };
    // End values for the crossing estimate: the smoothed ones where they straddle, else raw.
    let ends = |ci: u8, cj: u8, (si, sj): (f64, f64), (ri, rj): (f64, f64)| {
        if (ci ^ cj) & 2 != 0 {
            (si, sj)
        } else {
            (ri, rj)
        }
    };
    let fraction = field.kernel().linear_crossing_error() + WINDOW_MARGIN;
    let window = |length: f64| (WINDOW_CELLS * grid.cell_size).max(fraction * length);
    let mut seeds: Vec<u64> = (0..field.len())
        .into_par_iter()
        .fold(Seeds::default, |mut seeds, i| {
            if held.load(Ordering::Relaxed) > most_keys {
                return seeds;
            }
            let before = seeds.keys.len();
            let out = &mut seeds.keys;
            let xi = positions[i];
            let ci = class(i);
            let r2 = pair_radius(field, i).powi(2);
            let side_r2 = side_radius(field, i).powi(2);
            // Bit 2a+s: a neighbour lies on side s (0: negative, 1: positive) of axis a.
            let mut sides = 0u8;
            candidates(i, &mut |row| {
                for j in row.iter().map(|&j| j as usize) {
                    let d = positions[j] - xi;
                    let d2 = d.length_squared();
                    if j == i || d2 >= side_r2 {
                        continue;
                    }
                    for a in 0..3 {
                        if d[a] > 0.0 {
                            sides |= 1 << (2 * a + 1);
                        } else if d[a] < 0.0 {
                            sides |= 1 << (2 * a);
                        }
                    }
                    if d2 >= r2 {
                        continue;
                    }
                    let cj = class(j);
                    if j > i && cj != ci {
                        let values = ends(
                            ci,
                            cj,
                            (smoothed[i], smoothed[j]),
                            (field.raw_value(i), field.raw_value(j)),
                        );
                        let (a, b) = crossing_window(xi, positions[j], values, iso, window);
                        cells_on_segment(grid, a, b, out);
                    }
                }
            });
            if ci != outside {
                for bit in (0..6).filter(|bit| sides >> bit & 1 == 0) {
                    let far = xi + half_axis(bit) * field.support(i);
                    let values = ends(ci, outside, (smoothed[i], 0.0), (field.raw_value(i), 0.0));
                    let (a, b) = crossing_window(xi, far, values, iso, window);
                    cells_on_segment(grid, a, b, out);
                }
            }
            // The wall of a cavity (see `cavity_probes`): seeded where the field one h in
            // lies on the other side of the isovalue.
            let first = probes.partition_point(|p| (p.0 as usize) < i);
            for &(_, probe, value) in probes[first..].iter().take_while(|p| p.0 as usize == i) {
                if (value > iso) != (smoothed[i] > iso) {
                    cells_on_segment(grid, xi, probe, out);
                }
            }
            seeds.deduplicate_if_doubled();
            let after = seeds.keys.len();
            if after >= before {
                held.fetch_add((after - before) as u64, Ordering::Relaxed);
            } else {
                held.fetch_sub((before - after) as u64, Ordering::Relaxed);
            }
            seeds
        })
        .flat_map_iter(|seeds| seeds.keys)
        .collect();
    let held = held.into_inner();
    if held > most_keys {
        return Err(Error::OverBudget {
            what: format!(
                "the seed cells of a grid with cells of {} (over {held} held before stopping)",
                grid.cell_size
            ),
            needed_bytes: held.saturating_mul(32),
            budget_bytes: *memory_budget,
        });
    }
    radix::sort_unique(&mut seeds);
    Ok(seeds)
}

/// One thread's seed keys, deduplicated whenever they have doubled since the last time:
/// neighbouring pairs list the same cells again and again.
#[derive(Default)]
struct Seeds {
    keys: Vec<u64>,
    /// Length right after the last deduplication.
    distinct: usize,
}

impl Seeds {
    /// Lists shorter than this are left as they are until the final sort.
    const DEDUPLICATE_FROM: usize = 1 << 16;

    fn deduplicate_if_doubled(&mut self) {
        if self.keys.len() >= Self::DEDUPLICATE_FROM.max(2 * self.distinct) {
            self.keys.sort_unstable();
            self.keys.dedup();
            self.distinct = self.keys.len();
        }
    }
}

/// The part of segment p–q within `window` of where the linear interpolant of its end
/// values `(vp, vq)` crosses `iso`; the whole segment if they do not straddle it.
fn crossing_window(
    p: DVec3,
    q: DVec3,
    (vp, vq): (f64, f64),
    iso: f64,
    window: impl Fn(f64) -> f64,
) -> (DVec3, DVec3) {
    let length = p.distance(q);
    let window = window(length);
    if (vp > iso) == (vq > iso) || length <= 2.0 * window {
        return (p, q);
    }
    let t = ((vp - iso) / (vp - vq)).clamp(0.0, 1.0);
    let dt = window / length;
    (p.lerp(q, (t - dt).max(0.0)), p.lerp(q, (t + dt).min(1.0)))
}

/// Appends the keys of the grid cells that the segment p–q passes through (3D DDA,
/// Amanatides & Woo); cells outside the grid are skipped.
pub fn cells_on_segment(grid: &VirtualGrid, p: DVec3, q: DVec3, out: &mut Vec<u64>) {
    let u = grid.to_grid(p);
    let v = grid.to_grid(q);
    let d = v - u;
    let mut cell = [u.x.floor() as i64, u.y.floor() as i64, u.z.floor() as i64];
    let last = [v.x.floor() as i64, v.y.floor() as i64, v.z.floor() as i64];
    let mut step = [0i64; 3];
    let mut t_max = [f64::INFINITY; 3];
    let mut t_delta = [f64::INFINITY; 3];
    for a in 0..3 {
        if d[a] > 0.0 {
            step[a] = 1;
            t_max[a] = ((cell[a] + 1) as f64 - u[a]) / d[a];
            t_delta[a] = 1.0 / d[a];
        } else if d[a] < 0.0 {
            step[a] = -1;
            t_max[a] = (cell[a] as f64 - u[a]) / d[a];
            t_delta[a] = -1.0 / d[a];
        }
    }
    let max_steps = (0..3).map(|a| (last[a] - cell[a]).abs()).sum::<i64>() + 1;
    for _ in 0..=max_steps {
        if (0..3).all(|a| cell[a] >= 0 && cell[a] < grid.cells[a] as i64) {
            out.push(VirtualGrid::key(
                cell[0] as u32,
                cell[1] as u32,
                cell[2] as u32,
            ));
        }
        if cell == last {
            break;
        }
        let a = if t_max[0] <= t_max[1] && t_max[0] <= t_max[2] {
            0
        } else if t_max[1] <= t_max[2] {
            1
        } else {
            2
        };
        if t_max[a] > 1.0 {
            break;
        }
        cell[a] += step[a];
        t_max[a] += t_delta[a];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segment_cells_are_connected_and_cover_both_ends() {
        let grid =
            VirtualGrid::covering(DVec3::ZERO, DVec3::splat(10.0), 1.0, "grid_factor").unwrap();
        let mut unit = crate::test_rng::unit(7);
        let mut rnd = || unit() * 10.0;
        for _ in 0..500 {
            let p = DVec3::new(rnd(), rnd(), rnd());
            let q = DVec3::new(rnd(), rnd(), rnd());
            let mut out = Vec::new();
            cells_on_segment(&grid, p, q, &mut out);
            let first = grid.cell_of(p).unwrap();
            let last = grid.cell_of(q).unwrap();
            assert_eq!(out[0], VirtualGrid::key(first[0], first[1], first[2]));
            assert_eq!(
                *out.last().unwrap(),
                VirtualGrid::key(last[0], last[1], last[2])
            );
            for w in out.windows(2) {
                let (a, b) = (VirtualGrid::coords(w[0]), VirtualGrid::coords(w[1]));
                let dist: i64 = (0..3).map(|k| (a[k] as i64 - b[k] as i64).abs()).sum();
                assert_eq!(dist, 1, "face-adjacent steps only");
            }
            // Every cell the segment passes through appears: sample the segment densely.
            for k in 0..=1000 {
                let x = p + (q - p) * (k as f64 / 1000.0);
                let c = grid.cell_of(x).unwrap();
                let key = VirtualGrid::key(c[0], c[1], c[2]);
                let near_boundary = (0..3).any(|a| (x[a] - x[a].round()).abs() < 1e-9);
                assert!(near_boundary || out.contains(&key), "missed cell {c:?}");
            }
        }
    }
}
