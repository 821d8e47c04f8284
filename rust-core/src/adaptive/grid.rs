//! The coarse grid of the 3-level scheme and its cell levels: particle registration
//! (Algorithm 1, step 1), splitting by the splash criterion (step 2) and level adjustment
//! (step 3) so that cells sharing a face differ by at most one level.
//!
//! A level-1 cell is one marching-cubes cell; a level-2 cell is tessellated 2×2×2 and a
//! level-3 cell 4×4×4. All three tessellations sit on one finest lattice whose cell is a
//! quarter of a coarse cell, so every grid vertex of every level is a finest-lattice node.

use crate::error::{Error, Result};
use crate::progress::{collect_ranges, for_ranges, Progress};
use glam::DVec3;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU32, Ordering};

/// Finest-lattice cells per coarse cell along an axis.
pub(crate) const FINE_PER_COARSE: u32 = 4;

/// Sub-cells per axis of a cell of `level` (1, 2 or 4).
pub const fn subdivisions(level: u8) -> u32 {
    1 << (level - 1)
}

/// A box of coarse cells on a lattice of finest cells of size `fine`, first node at
/// `origin`. Positions are computed from integer lattice coordinates only, so a node has
/// one position bit for bit whichever cell or level asks for it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoarseGrid {
    pub origin: DVec3,
    /// Size of a finest (level-3) cell; coarse cells are `FINE_PER_COARSE` times larger.
    pub fine: f64,
    /// Coarse cells per axis.
    pub cells: [u32; 3],
}

impl CoarseGrid {
    /// The grid whose coarse cells cover `lo..hi` with finest cells of size `fine`.
    pub fn covering(lo: DVec3, hi: DVec3, fine: f64) -> Result<Self> {
        if !(fine > 0.0 && fine.is_finite()) {
            return Err(Error::InvalidParameter {
                name: "grid_factor",
                message: format!("the finest cell size must be positive, got {fine}"),
            });
        }
        if !(lo.is_finite() && hi.is_finite()) {
            return Err(Error::InvalidInput(format!(
                "the data's bounds are not finite: {lo} to {hi}"
            )));
        }
        let coarse = fine * FINE_PER_COARSE as f64;
        let mut cells = [0u32; 3];
        for a in 0..3 {
            let n = ((hi[a] - lo[a]) / coarse).ceil().max(1.0);
            // Finest nodes per axis must fit the 20-bit keys of `mc::VirtualGrid`.
            let max = (crate::mc::MAX_NODES_PER_AXIS - 1) / FINE_PER_COARSE as u64;
            if n > max as f64 {
                return Err(Error::InvalidParameter {
                    name: "grid_factor",
                    message: format!(
                        "the adaptive grid would need {n:.0} coarse cells along axis {a}; at most {max} are supported — raise the grid factor"
                    ),
                });
            }
            cells[a] = n as u32;
        }
        Ok(CoarseGrid {
            origin: lo,
            fine,
            cells,
        })
    }

    /// Number of coarse cells.
    pub fn cell_count(&self) -> usize {
        self.cells.iter().map(|&c| c as usize).product()
    }

    /// Linear index of coarse cell (x, y, z).
    #[inline]
    pub fn index(&self, c: [u32; 3]) -> usize {
        c[0] as usize
            + self.cells[0] as usize * (c[1] as usize + self.cells[1] as usize * c[2] as usize)
    }

    /// The cells of the 3×3×3 block around cell `i` that lie in the grid, `i` included.
    #[inline]
    pub fn block(&self, i: usize) -> impl Iterator<Item = usize> + '_ {
        let c = self.coords(i);
        (0..27usize).filter_map(move |d| {
            let n: [i64; 3] =
                std::array::from_fn(|a| c[a] as i64 + [d % 3, d / 3 % 3, d / 9][a] as i64 - 1);
            (0..3)
                .all(|a| n[a] >= 0 && n[a] < self.cells[a] as i64)
                .then(|| self.index(n.map(|x| x as u32)))
        })
    }

    /// Coordinates of coarse cell `i`.
    #[inline]
    pub fn coords(&self, i: usize) -> [u32; 3] {
        let (nx, ny) = (self.cells[0] as usize, self.cells[1] as usize);
        [
            (i % nx) as u32,
            (i / nx % ny) as u32,
            (i / (nx * ny)) as u32,
        ]
    }

    /// The coarse cell holding `p`, if inside the grid.
    pub fn cell_of(&self, p: DVec3) -> Option<usize> {
        let mut c = [0u32; 3];
        for a in 0..3 {
            let f = self.coarse_floor(p[a] - self.origin[a]);
            if !(f >= 0.0 && f < self.cells[a] as f64) {
                return None;
            }
            c[a] = f as u32;
        }
        Some(self.index(c))
    }

    /// The coarse coordinate (not yet range-checked) of a point `d` from the origin along
    /// an axis: the one rounding of the division, then floor. [`cell_of`](Self::cell_of)
    /// and [`registration_thresholds`](Self::registration_thresholds) both call this, so
    /// the thresholds describe exactly the cells `cell_of` gives.
    #[inline]
    fn coarse_floor(&self, d: f64) -> f64 {
        (d / (self.fine * FINE_PER_COARSE as f64)).floor()
    }

    /// Per axis `a`, `t[k]` for k in 0..=cells[a]: the smallest f64 offset `d` from the
    /// origin (`p[a] - origin[a]`, as [`cell_of`](Self::cell_of) computes it) whose coarse
    /// coordinate is at least k. The coordinate is a monotone function of `d` (a rounded
    /// division and a floor), so a point lies in cell k along `a` exactly when
    /// `t[k] <= d < t[k + 1]`, and outside the grid when `d < t[0]` or `d >= t[cells]`.
    /// Found by bisection over the ordered f64 values themselves (not by arithmetic that
    /// could round differently), so they are exact by construction; they let the GPU
    /// register particles by comparisons alone (`gpu::register`).
    pub fn registration_thresholds(&self) -> [Vec<f64>; 3] {
        std::array::from_fn(|a| {
            (0..=self.cells[a])
                .map(|k| {
                    let at_least = |d: f64| self.coarse_floor(d) >= k as f64;
                    // Ordered keys of -inf and +inf: every non-NaN f64 lies between them,
                    // and +inf's coordinate is +inf >= k, so the search always ends.
                    let (mut lo, mut hi) = (order_key(f64::NEG_INFINITY), order_key(f64::INFINITY));
                    while lo < hi {
                        let mid = lo + (hi - lo) / 2;
                        if at_least(from_order_key(mid)) {
                            hi = mid;
                        } else {
                            lo = mid + 1;
                        }
                    }
                    from_order_key(lo)
                })
                .collect()
        })
    }

    /// Position of the point at `sub` in units of `fine / 2^shift`. A finest node
    /// (x, y, z) is `sub = (x, y, z) · 2^shift`; the product below is one rounding of the
    /// exact value, so every shift gives the node the same bits.
    #[inline]
    pub fn point(&self, sub: [i64; 3], shift: u32) -> DVec3 {
        let unit = self.fine / (1u64 << shift) as f64;
        self.origin + DVec3::new(sub[0] as f64, sub[1] as f64, sub[2] as f64) * unit
    }

    /// The six face neighbours' indices of cell `i` (None outside the grid), ordered
    /// (axis, side).
    pub fn face_neighbours(&self, i: usize) -> [Option<usize>; 6] {
        let c = self.coords(i);
        std::array::from_fn(|k| self.offset(c, k / 2, if k % 2 == 0 { -1 } else { 1 }))
    }

    fn offset(&self, c: [u32; 3], axis: usize, d: i64) -> Option<usize> {
        let x = c[axis] as i64 + d;
        if x < 0 || x >= self.cells[axis] as i64 {
            return None;
        }
        let mut n = c;
        n[axis] = x as u32;
        Some(self.index(n))
    }
}

/// A u64 whose unsigned order is the numeric order of non-NaN f64 values (-0 just below
/// +0): positive values keep their bits with the sign bit set, negative ones are inverted.
fn order_key(x: f64) -> u64 {
    let b = x.to_bits();
    if b >> 63 == 1 {
        !b
    } else {
        b | 1 << 63
    }
}

/// The inverse of [`order_key`].
fn from_order_key(k: u64) -> f64 {
    f64::from_bits(if k >> 63 == 1 { k & !(1 << 63) } else { !k })
}

/// Step 1: particles per coarse cell, counted with atomics as on the GPU (counts do not
/// depend on the order of the additions). Particles outside the grid are an error naming
/// the first one.
pub fn register(grid: &CoarseGrid, positions: &[DVec3]) -> Result<Vec<u32>> {
    let counts: Vec<AtomicU32> = (0..grid.cell_count()).map(|_| AtomicU32::new(0)).collect();
    let outside = positions
        .par_iter()
        .enumerate()
        .filter_map(|(i, &p)| match grid.cell_of(p) {
            Some(c) => {
                counts[c].fetch_add(1, Ordering::Relaxed);
                None
            }
            None => Some(i),
        })
        .min();
    if let Some(i) = outside {
        return Err(Error::InvalidInput(format!(
            "particle {i} at {} lies outside the adaptive grid",
            positions[i]
        )));
    }
    Ok(counts.into_iter().map(AtomicU32::into_inner).collect())
}

/// Step 2: the paper's splash criterion. A cell holding between 1 and `threshold`
/// particles is level 3 (isolated particles need the finest cells); all others level 1.
pub fn split(counts: &[u32], threshold: u32) -> Vec<u8> {
    counts
        .par_iter()
        .map(|&n| if n >= 1 && n <= threshold { 3 } else { 1 })
        .collect()
}

/// Raises the `rings` layers of cells around every level-3 cell (26-neighbourhood) to
/// level 3. A splash particle's kernel reaches about one coarse cell beyond its own cell
/// (support 2h = one coarse cell at the default grid factor), so its droplet surface
/// spills into those neighbours; at level 1 or 2 they would contour a sphere of one or
/// two cells' radius, far off the finest surface. 0 keeps the paper's criterion alone.
pub fn dilate(
    grid: &CoarseGrid,
    levels: &mut [u8],
    rings: u32,
    progress: &mut Progress,
) -> Result<()> {
    for _ in 0..rings {
        let now = &*levels;
        let next: Vec<u8> = collect_ranges(levels.len(), progress, |cells| {
            cells
                .into_par_iter()
                .map(|i| {
                    if grid.block(i).any(|n| now[n] == 3) {
                        3
                    } else {
                        now[i]
                    }
                })
                .collect()
        })?;
        levels.copy_from_slice(&next);
    }
    Ok(())
}

/// Step 3, extended to a fixed point: raises levels until (a) cells sharing a face differ
/// by at most one level and (b) no grid edge has its four cells alternating between two
/// levels (coarse, fine, coarse, fine). The paper's one pass gives (a) for its two-valued
/// input; (b) keeps the mesh manifold: with alternating cells, a sign change in the middle
/// of the shared edge would give two fine blobs touching along that edge. Levels only
/// rise, so this terminates; each pass reads the previous one, so it is deterministic.
///
/// A cell's requirement reads only its 3×3×3 block, so after the first pass only the
/// blocks of the cells that changed are looked at again: the same passes, the same
/// result, without sweeping every coarse cell per pass (balancing was a tenth of an
/// adaptive extraction's time).
pub fn balance(grid: &CoarseGrid, levels: &mut [u8], progress: &mut Progress) -> Result<()> {
    balance_around(grid, levels, None, progress)
}

/// [`balance`] when only the cells in `changed` have risen since the levels were last
/// balanced: the passes start from their 3×3×3 blocks instead of every cell.
pub fn rebalance(grid: &CoarseGrid, levels: &mut [u8], changed: &[usize]) -> Result<()> {
    let blocks = blocks_of(grid, changed.par_iter().copied());
    balance_around(grid, levels, Some(blocks), &mut Progress::none())
}

/// The sorted, unique cells of the 3×3×3 blocks around `cells`.
fn blocks_of(grid: &CoarseGrid, cells: impl IntoParallelIterator<Item = usize>) -> Vec<usize> {
    let mut out: Vec<usize> = cells
        .into_par_iter()
        .flat_map_iter(|i| grid.block(i))
        .collect();
    out.par_sort_unstable();
    out.dedup();
    out
}

/// The passes of [`balance`] from `dirty`, the cells to look at first (None: every
/// cell).
fn balance_around(
    grid: &CoarseGrid,
    levels: &mut [u8],
    mut dirty: Option<Vec<usize>>,
    progress: &mut Progress,
) -> Result<()> {
    // A first pass over every cell sweeps them without listing them (a list of all cells
    // would take 8 bytes a cell, more than the grid's own arrays), reporting as it goes.
    loop {
        let now = &*levels;
        let need = |i: usize| {
            let need = required_level(grid, now, i);
            (need != now[i]).then_some((i, need))
        };
        let changes: Vec<(usize, u8)> = match &dirty {
            None => collect_ranges(now.len(), progress, |cells| {
                cells.into_par_iter().filter_map(need).collect()
            })?,
            Some(cells) => cells.par_iter().filter_map(|&i| need(i)).collect(),
        };
        if changes.is_empty() {
            return Ok(());
        }
        for &(i, need) in &changes {
            levels[i] = need;
        }
        dirty = Some(blocks_of(grid, changes.par_iter().map(|&(i, _)| i)));
    }
}

/// The level cell `i` must at least have given its neighbours' current levels.
fn required_level(grid: &CoarseGrid, levels: &[u8], i: usize) -> u8 {
    let mut need = levels[i];
    if need == 3 {
        return need;
    }
    let c = grid.coords(i);
    let stride = [
        1,
        grid.cells[0] as isize,
        grid.cells[0] as isize * grid.cells[1] as isize,
    ];
    // Index offset of the neighbour one cell along `axis` by `d`, if inside the grid
    // (offsets rather than coordinates: this runs for every coarse cell, more than once).
    let step = |axis: usize, d: i64| -> Option<isize> {
        let x = c[axis] as i64 + d;
        (x >= 0 && x < grid.cells[axis] as i64).then_some(d as isize * stride[axis])
    };
    let at = |o: isize| levels[(i as isize + o) as usize];
    for axis in 0..3 {
        for d in [-1, 1] {
            if let Some(o) = step(axis, d) {
                need = need.max(at(o).saturating_sub(1));
            }
        }
    }
    // The four cells around each of the cell's 12 edges: i, i + b, i + b + d, i + d.
    for axis in 0..3 {
        let (b, d) = ((axis + 1) % 3, (axis + 2) % 3);
        for (sb, sd) in [(-1i64, -1i64), (-1, 1), (1, -1), (1, 1)] {
            if let (Some(ob), Some(od)) = (step(b, sb), step(d, sd)) {
                let (l0, l1, l2, l3) = (levels[i], at(ob), at(ob + od), at(od));
                if l0 == l2 && l1 == l3 && l1 > l0 {
                    need = need.max(l1);
                }
            }
        }
    }
    need
}

/// Checks a caller's level map: one entry per coarse cell, levels 1..=3, face neighbours
/// at most one level apart and no alternating edge (see [`balance`]).
pub fn check_levels(grid: &CoarseGrid, levels: &[u8], progress: &mut Progress) -> Result<()> {
    if levels.len() != grid.cell_count() {
        return Err(Error::InvalidInput(format!(
            "the level map has {} entries for {} coarse cells",
            levels.len(),
            grid.cell_count()
        )));
    }
    if let Some(i) = levels.iter().position(|&l| !(1..=3).contains(&l)) {
        return Err(Error::InvalidInput(format!(
            "coarse cell {i} has level {}, levels are 1, 2 or 3",
            levels[i]
        )));
    }
    // In ranges with a report after each: tens of millions of cells take a second.
    let mut first_bad = None;
    for_ranges(
        levels.len(),
        progress,
        |range| {
            range
                .into_par_iter()
                .find_first(|&i| required_level(grid, levels, i) != levels[i])
        },
        |bad| first_bad = first_bad.or(bad),
    )?;
    if let Some(i) = first_bad {
        return Err(Error::InvalidInput(format!(
            "coarse cell {i} (level {}) needs level {} next to its neighbours",
            levels[i],
            required_level(grid, levels, i)
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(n: u32) -> CoarseGrid {
        CoarseGrid {
            origin: DVec3::ZERO,
            fine: 0.25,
            cells: [n; 3],
        }
    }

    #[test]
    fn registration_counts_every_particle_once() {
        let g = grid(4);
        let pts = vec![
            DVec3::new(0.5, 0.5, 0.5),
            DVec3::new(0.6, 0.5, 0.5),
            DVec3::new(3.5, 0.5, 2.5),
        ];
        let counts = register(&g, &pts).unwrap();
        assert_eq!(counts.iter().sum::<u32>(), 3);
        assert_eq!(counts[0], 2);
        assert_eq!(counts[g.index([3, 0, 2])], 1);
        let err = register(&g, &[DVec3::new(9.0, 0.0, 0.0)]).unwrap_err();
        assert!(err.to_string().contains("particle 0"), "{err}");
    }

    /// The thresholds are the exact boundaries of `cell_of`: each is the first f64 of
    /// its coordinate, and classifying points by them (as the GPU does, with exact
    /// comparisons) gives `cell_of`'s cell for points on, next to and between faces.
    #[test]
    fn registration_thresholds_are_the_exact_cell_boundaries() {
        let mut rand = crate::test_rng::unit(3);
        for g in [
            grid(4),
            CoarseGrid {
                origin: DVec3::new(-0.3, 1.0 / 3.0, -1e-9),
                fine: 0.1 / 3.0,
                cells: [7, 3, 5],
            },
        ] {
            let t = g.registration_thresholds();
            for (a, ta) in t.iter().enumerate() {
                assert_eq!(ta.len(), g.cells[a] as usize + 1);
                for (k, &x) in ta.iter().enumerate() {
                    assert!(g.coarse_floor(x) >= k as f64, "axis {a} k {k}");
                    assert!(g.coarse_floor(x.next_down()) < k as f64, "axis {a} k {k}");
                }
            }
            let by_thresholds = |p: DVec3| -> Option<usize> {
                let mut c = [0u32; 3];
                for a in 0..3 {
                    let d = p[a] - g.origin[a];
                    let below = t[a].iter().filter(|&&x| x <= d).count();
                    if below == 0 || below > g.cells[a] as usize {
                        return None;
                    }
                    c[a] = below as u32 - 1;
                }
                Some(g.index(c))
            };
            let mut points = Vec::new();
            for k in 0..=g.cells[0] {
                let on = g.origin.x + t[0][k as usize];
                for x in [on, on.next_up(), on.next_down(), on.next_up().next_up()] {
                    points.push(DVec3::new(x, g.origin.y + t[1][1], g.origin.z + t[2][2]));
                }
            }
            for _ in 0..2000 {
                let u = DVec3::new(rand(), rand(), rand()) * 1.2 - 0.1;
                let size = DVec3::from(g.cells.map(|c| c as f64)) * g.fine * 4.0;
                points.push(g.origin + u * size);
            }
            for p in points {
                assert_eq!(by_thresholds(p), g.cell_of(p), "{p}");
            }
        }
    }

    #[test]
    fn splitting_and_balancing_follow_fig2() {
        let g = grid(5);
        let mut counts = vec![0u32; g.cell_count()];
        counts[g.index([2, 2, 2])] = 1; // an isolated particle
        counts[g.index([0, 0, 0])] = 7; // bulk fluid
        let mut levels = split(&counts, 1);
        assert_eq!(levels[g.index([2, 2, 2])], 3);
        assert_eq!(levels[g.index([0, 0, 0])], 1);
        balance(&g, &mut levels, &mut Progress::none()).unwrap();
        for n in g.face_neighbours(g.index([2, 2, 2])).into_iter().flatten() {
            assert_eq!(levels[n], 2);
        }
        assert_eq!(
            levels[g.index([1, 1, 2])],
            1,
            "edge neighbours may stay coarse"
        );
        check_levels(&g, &levels, &mut Progress::none()).unwrap();
        // Two diagonal splash cells around one edge: the edge alternates 3,2,3,2 and the
        // level-2 cells between them rise to 3.
        let mut counts = vec![0u32; g.cell_count()];
        counts[g.index([2, 2, 2])] = 1;
        counts[g.index([3, 3, 2])] = 1;
        let mut levels = split(&counts, 1);
        balance(&g, &mut levels, &mut Progress::none()).unwrap();
        assert_eq!(levels[g.index([3, 2, 2])], 3);
        assert_eq!(levels[g.index([2, 3, 2])], 3);
        check_levels(&g, &levels, &mut Progress::none()).unwrap();
        let mut bad = levels.clone();
        bad[g.index([0, 0, 0])] = 3;
        assert!(check_levels(&g, &bad, &mut Progress::none()).is_err());
    }

    /// Balancing only the blocks of changed cells reaches the same fixed point as
    /// sweeping every cell each pass, which is (a) and (b) of [`balance`] and raises no
    /// cell that did not need it, on random maps of all three levels.
    #[test]
    fn balancing_the_changed_blocks_equals_sweeping_every_cell() {
        let g = CoarseGrid {
            origin: DVec3::ZERO,
            fine: 0.25,
            cells: [13, 9, 11],
        };
        let mut next = crate::test_rng::unit(17);
        for density in [0.01, 0.05, 0.2] {
            let start: Vec<u8> = (0..g.cell_count())
                .map(|_| match next() {
                    x if x < density => 3,
                    x if x < 2.0 * density => 2,
                    _ => 1,
                })
                .collect();
            let mut swept = start.clone();
            loop {
                let pass: Vec<u8> = (0..swept.len())
                    .map(|i| required_level(&g, &swept, i))
                    .collect();
                if pass == swept {
                    break;
                }
                swept = pass;
            }
            let mut levels = start.clone();
            balance(&g, &mut levels, &mut Progress::none()).unwrap();
            assert_eq!(levels, swept, "density {density}");
            check_levels(&g, &levels, &mut Progress::none()).unwrap();
            assert!(levels.iter().zip(&start).all(|(a, b)| a >= b));
            assert!(levels != start, "density {density}: nothing to balance");
        }
    }
}
