//! Uniform neighbour grid: particles bucketed by counting sort into cubic cells, so any
//! point's neighbours within `reach` cells lie in the (2·reach+1)³ block around it. Cells
//! are ordered x fastest, so each row of a query block is one contiguous slice of the
//! sorted particles: (2·reach+1)² range look-ups per query.
//!
//! The grid is dense over the particles' bounding box, so one stray particle far from the
//! fluid would make it huge (splashsurf's `free_particles_1000` frame needed 96 GB). Where
//! the box holds far more cells than particles, each axis is squeezed instead: every run
//! of slabs farther than `reach` cells from any particle becomes a single slab
//! ([`AxisMap`]). Distances up to `reach` cells between a query and a particle are kept,
//! so the candidates are the same; the cells follow the particles, not the box.

use crate::error::{Error, Result};
use glam::DVec3;
use rayon::prelude::*;
use std::ops::Range;

/// The most cells along an axis of the particles' bounding box.
const MAX_CELLS_PER_AXIS: u64 = 1 << 40;

/// Particles bucketed into a dense grid of cubic cells.
#[derive(Clone, Debug)]
pub struct NeighbourGrid {
    origin: DVec3,
    inv_cell: f64,
    /// Cells per axis (after squeezing).
    dims: [usize; 3],
    /// Per axis, from a cell index along the box to the grid's: None when not squeezed.
    squeeze: Option<Box<[AxisMap; 3]>>,
    /// The largest `reach` the squeeze keeps exact.
    reach: i64,
    /// Where each cell's particles lie among the sorted slots.
    cells: Cells,
    /// Original particle index of each sorted slot; within a cell, ascending.
    order: Vec<u32>,
}

impl NeighbourGrid {
    /// Buckets `positions` into cells of edge `cell_size`, for queries that look at most
    /// `reach` cells out. Refuses, before allocating, a grid whose offset table would
    /// exceed `memory_budget` bytes.
    pub fn build(
        positions: &[DVec3],
        cell_size: f64,
        reach: i64,
        memory_budget: u64,
    ) -> Result<Self> {
        if !(cell_size > 0.0 && cell_size.is_finite()) {
            return Err(Error::InvalidParameter {
                name: "neighbour cell size",
                message: format!("must be positive and finite, got {cell_size}"),
            });
        }
        if positions.len() >= u32::MAX as usize {
            return Err(Error::InvalidInput(format!(
                "{} particles is more than this build supports (2^32 - 1)",
                positions.len()
            )));
        }
        let (lo, hi) = bounds(positions);
        let mut box_dims = [0usize; 3];
        for a in 0..3 {
            let n = ((hi[a] - lo[a]) / cell_size).floor() + 1.0;
            // Past this a cell index loses the particle (f64 cell coordinates, and three
            // axes' product in 128 bits): refused, not clamped onto the last cell.
            if n.is_nan() || n > MAX_CELLS_PER_AXIS as f64 {
                // Usually one particle flung far from the rest: name the two extremes.
                let along = |i: &usize| positions[*i][a];
                let first = (0..positions.len()).min_by(|i, j| along(i).total_cmp(&along(j)));
                let last = (0..positions.len()).max_by(|i, j| along(i).total_cmp(&along(j)));
                let (first, last) = (first.unwrap_or(0), last.unwrap_or(0));
                return Err(Error::InvalidInput(format!(
                    "the particles spread over {:?}..{:?}: {n:.3e} cells of {cell_size} along \
                     axis {a}, more than the {MAX_CELLS_PER_AXIS} a neighbour grid indexes; \
                     the extremes along it are particle {first} at {:?} and particle {last} at \
                     {:?} (one flung far from the rest, or positions in mixed units?)",
                    lo.to_array(),
                    hi.to_array(),
                    positions[first].to_array(),
                    positions[last].to_array()
                )));
            }
            box_dims[a] = n as usize;
        }
        let mut grid = NeighbourGrid {
            origin: lo,
            inv_cell: 1.0 / cell_size,
            dims: box_dims,
            squeeze: None,
            reach,
            cells: Cells::Dense(Vec::new()),
            order: Vec::new(),
        };
        // Clamped: (hi - lo) / cell can round below the product used here, and a particle
        // on the upper bound would land one cell past the row's end, i.e. in the next row,
        // where no query near it looks.
        let inv_cell = grid.inv_cell;
        let box_cell = move |p: DVec3| -> [i64; 3] {
            let c = box_coords(lo, inv_cell, p);
            std::array::from_fn(|a| c[a].clamp(0, box_dims[a] as i64 - 1))
        };
        let cells = |dims: &[usize; 3]| dims.iter().map(|&d| d as u128).product::<u128>();
        // More cells than a few per particle: the box is mostly empty space.
        if cells(&box_dims) > 8 * positions.len() as u128 + (1 << 20) {
            // One axis at a time: 8 bytes a particle at most, below what either grid
            // below keeps (and the budget counts).
            let maps: [AxisMap; 3] = std::array::from_fn(|a| {
                let mut occupied: Vec<i64> =
                    positions.par_iter().map(|&p| box_cell(p)[a]).collect();
                occupied.par_sort_unstable();
                occupied.dedup();
                AxisMap::new(&occupied, reach)
            });
            // Every slab within reach of a particle on every axis: nothing to squeeze, and
            // the grid keeps the plain layout (the GPU's).
            if maps.iter().any(|m| m.runs.len() > 1) {
                grid.dims = std::array::from_fn(|a| maps[a].len as usize);
                grid.squeeze = Some(Box::new(maps));
            }
        }
        let dims = grid.dims;
        let ncells = cells(&dims);
        let n = positions.len() as u128;
        // Still far more cells than particles (particles scattered over the box on every
        // axis, as spray is) and an offset table a large share of the budget: only the
        // occupied cells are listed (a search per row of a query instead of two loads).
        let sparse = ncells > 8 * n + (1 << 20) && (ncells + 1) * 4 > memory_budget as u128 / 8;
        let needed = if sparse {
            // (key, particle) pairs, then the keys, their starts and the order.
            n * (32 + 16 + 4 + 4)
        } else {
            (ncells + 1) * 4 + n * 8
        };
        if needed > memory_budget as u128 || (!sparse && ncells >= u32::MAX as u128) {
            return Err(Error::OverBudget {
                what: format!(
                    "a neighbour grid of {}×{}×{} cells of {cell_size} (particles spread over {:?}..{:?})",
                    dims[0], dims[1], dims[2], lo.to_array(), hi.to_array()
                ),
                needed_bytes: needed.min(u64::MAX as u128) as u64,
                budget_bytes: memory_budget,
            });
        }
        if sparse {
            let mut keyed: Vec<(u128, u32)> = positions
                .par_iter()
                .enumerate()
                .map(|(i, &p)| (grid.key(grid.squeezed(box_cell(p))), i as u32))
                .collect();
            // By cell, then by particle: each cell lists its particles ascending.
            keyed.par_sort_unstable();
            let mut keys = Vec::new();
            let mut starts = Vec::new();
            for (slot, &(key, _)) in keyed.iter().enumerate() {
                if keys.last() != Some(&key) {
                    keys.push(key);
                    starts.push(slot as u32);
                }
            }
            starts.push(keyed.len() as u32);
            grid.order = keyed.into_iter().map(|(_, i)| i).collect();
            grid.cells = Cells::Sparse { keys, starts };
            return Ok(grid);
        }
        let cell_of: Vec<u32> = positions
            .par_iter()
            .map(|&p| {
                let c = grid.squeezed(box_cell(p));
                grid.linear(c[0] as usize, c[1] as usize, c[2] as usize) as u32
            })
            .collect();
        // Counting sort, in place: offsets[c] is first the end of cell c, and the scatter,
        // run backwards through the particles, moves it down to the cell's start. Each
        // cell then lists its particles ascending, which keeps every later sum in the
        // same order. (A cursor copy of the table would double it: 134 MB for the 33.6 M
        // cells of the 1.26 M-particle benchmark frame.)
        let mut offsets = vec![0u32; ncells as usize + 1];
        for &c in &cell_of {
            offsets[c as usize] += 1;
        }
        for i in 1..offsets.len() {
            offsets[i] += offsets[i - 1];
        }
        let mut order = vec![0u32; positions.len()];
        for (i, &c) in cell_of.iter().enumerate().rev() {
            offsets[c as usize] -= 1;
            order[offsets[c as usize] as usize] = i as u32;
        }
        grid.cells = Cells::Dense(offsets);
        grid.order = order;
        Ok(grid)
    }

    /// Original particle index of each sorted slot.
    pub fn order(&self) -> &[u32] {
        &self.order
    }

    /// (origin, 1 / cell size, cells per axis, slot offsets per cell plus one): the
    /// layout a GPU kernel needs to repeat [`NeighbourGrid::for_each_candidate_range`].
    /// None for a squeezed grid, whose cells are not where that arithmetic puts them.
    pub fn layout(&self) -> Option<(DVec3, f64, [usize; 3], &[u32])> {
        match (&self.squeeze, &self.cells) {
            (None, Cells::Dense(offsets)) => {
                Some((self.origin, self.inv_cell, self.dims, &offsets[..]))
            }
            _ => None,
        }
    }

    fn linear(&self, x: usize, y: usize, z: usize) -> usize {
        x + self.dims[0] * (y + self.dims[1] * z)
    }

    /// [`NeighbourGrid::linear`] in 128 bits, for a sparse grid's cell keys (its cell
    /// count may pass 2^64).
    fn key(&self, c: [i64; 3]) -> u128 {
        let [x, y, z] = c.map(|c| c as u128);
        x + self.dims[0] as u128 * (y + self.dims[1] as u128 * z)
    }

    /// Box cell coordinates to the grid's.
    #[inline]
    fn squeezed(&self, c: [i64; 3]) -> [i64; 3] {
        match &self.squeeze {
            None => c,
            Some(maps) => std::array::from_fn(|a| maps[a].map(c[a])),
        }
    }

    /// Integer cell coordinates of `p` in the grid (may lie outside it for query points).
    #[inline]
    fn cell_coords(&self, p: DVec3) -> [i64; 3] {
        self.squeezed(box_coords(self.origin, self.inv_cell, p))
    }

    /// Each sorted-slot range that may hold a particle within `reach` cell sizes of `p`:
    /// at most (2·reach+1)² contiguous ranges, z-row by y-row.
    #[inline]
    pub fn candidate_ranges(&self, p: DVec3, reach: i64) -> CandidateRanges<'_> {
        debug_assert!(
            reach <= self.reach,
            "the grid was built for reach {}",
            self.reach
        );
        let c = self.cell_coords(p);
        self.cell_block(c.map(|c| c - reach), c.map(|c| c + reach))
    }

    /// Each sorted-slot range that may hold a particle inside the box `lo..=hi`: the
    /// cells the box overlaps, z-row by y-row, so the slots come in ascending order.
    #[inline]
    pub fn ranges_in_box(&self, lo: DVec3, hi: DVec3) -> CandidateRanges<'_> {
        self.cell_block(self.cell_coords(lo), self.cell_coords(hi))
    }

    /// The ranges of the cell block `first..=last` (cell coordinates, clipped to the grid).
    #[inline]
    fn cell_block(&self, first: [i64; 3], last: [i64; 3]) -> CandidateRanges<'_> {
        let mut lo = [0usize; 3];
        let mut n = [0usize; 3];
        for a in 0..3 {
            let d = self.dims[a] as i64;
            let (l, h) = (first[a].max(0), last[a].min(d - 1));
            if l > h {
                return CandidateRanges::Empty;
            }
            lo[a] = l as usize;
            n[a] = (h - l) as usize + 1;
        }
        match &self.cells {
            Cells::Dense(offsets) => {
                let y_step = self.dims[0];
                CandidateRanges::Dense {
                    offsets,
                    rows: Rows::of_block(
                        self.linear(lo[0], lo[1], lo[2]),
                        y_step,
                        y_step * self.dims[1] - y_step * (n[1] - 1),
                        n,
                    ),
                }
            }
            Cells::Sparse { keys, starts } => {
                let y_step = self.dims[0] as u128;
                CandidateRanges::Sparse {
                    keys,
                    starts,
                    rows: Rows::of_block(
                        self.key(lo.map(|c| c as i64)),
                        y_step,
                        y_step * self.dims[1] as u128 - y_step * (n[1] as u128 - 1),
                        n,
                    ),
                }
            }
        }
    }

    /// Calls `f` with each range of [`NeighbourGrid::candidate_ranges`].
    #[inline]
    pub fn for_each_candidate_range(&self, p: DVec3, reach: i64, f: impl FnMut(Range<usize>)) {
        self.candidate_ranges(p, reach).for_each(f);
    }
}

/// One axis of a squeezed grid: runs of slabs (cell indices along the axis) farther than
/// `reach` from every occupied slab each become one slab; the other slabs keep their
/// spacing. A query slab within `reach` of an occupied one lies in the same kept run, so
/// their distance is kept; a query in a squeezed run is `reach` + 1 from the nearest
/// occupied slab, as far as it needs to be to find nothing there, as in the box.
#[derive(Clone, Debug)]
struct AxisMap {
    /// (first box slab, grid slab it maps to, whether the run is kept) of each run, in
    /// order; the first run is kept and begins at slab 0 (the lowest particle's).
    runs: Vec<(i64, i64, bool)>,
    /// Slabs along the axis after squeezing.
    len: i64,
}

impl AxisMap {
    /// The map for the `occupied` slabs (sorted, unique, from 0).
    fn new(occupied: &[i64], reach: i64) -> Self {
        let mut runs = Vec::new();
        let mut len = 0i64;
        let mut kept: Option<(i64, i64)> = None;
        let close = |(a, b): (i64, i64), runs: &mut Vec<(i64, i64, bool)>, len: &mut i64| {
            if let Some(&(start, at, _)) = runs.last() {
                let end = start + (*len - at); // one past the last run's last slab
                if a > end {
                    runs.push((end, *len, false));
                    *len += 1;
                }
            }
            runs.push((a, *len, true));
            *len += b - a + 1;
        };
        for &o in occupied {
            let (a, b) = ((o - reach).max(0), o + reach);
            kept = match kept {
                Some((ka, kb)) if a <= kb + 1 => Some((ka, kb.max(b))),
                Some(run) => {
                    close(run, &mut runs, &mut len);
                    Some((a, b))
                }
                None => Some((a, b)),
            };
        }
        if let Some(run) = kept {
            // The last run ends at the last occupied slab, the box's last.
            let last = *occupied.last().expect("occupied slabs");
            close((run.0, run.1.min(last)), &mut runs, &mut len);
        }
        AxisMap { runs, len }
    }

    /// The grid slab of box slab `i` (beyond either end, continued with unit steps).
    #[inline]
    fn map(&self, i: i64) -> i64 {
        let k = self.runs.partition_point(|r| r.0 <= i).max(1) - 1;
        let (start, at, kept) = self.runs[k];
        if kept {
            at + (i - start)
        } else {
            at
        }
    }
}

/// Where each cell's particles lie among the sorted slots.
#[derive(Clone, Debug)]
enum Cells {
    /// `offsets[c]..offsets[c+1]` are the slots of cell c, for every cell of the grid.
    Dense(Vec<u32>),
    /// The occupied cells' keys ([`NeighbourGrid::key`]), ascending, and
    /// `starts[k]..starts[k+1]` the slots of cell `keys[k]`: for particles so scattered
    /// that even the squeezed grid holds far more cells than particles (splashsurf's
    /// `free_particles_1000` frame: 2·10⁹ cells for 1,000 particles).
    Sparse { keys: Vec<u128>, starts: Vec<u32> },
}

/// The walk over a query block's rows of cells (along x): z-slice by z-slice, y-row by
/// y-row, each row's first cell found by adding a stride to the last (`T`: a dense grid's
/// linear index, or a sparse grid's 128-bit key).
#[derive(Clone, Copy)]
pub struct Rows<T> {
    /// The next row's first cell.
    row: T,
    /// From a row to the next in its slice, and from a slice's last row to the next
    /// slice's first.
    y_step: T,
    z_step: T,
    /// Cells in a row.
    width: usize,
    /// Rows in a z-slice of the block, and rows left in the current slice.
    rows_per_slice: usize,
    left_in_slice: usize,
    /// Rows left in the block.
    left: usize,
}

impl<T: Copy + std::ops::AddAssign> Rows<T> {
    /// The rows of a block of `n` cells (x, y, z) whose first row starts at `row`.
    fn of_block(row: T, y_step: T, z_step: T, n: [usize; 3]) -> Self {
        Rows {
            row,
            y_step,
            z_step,
            width: n[0],
            rows_per_slice: n[1],
            left_in_slice: n[1],
            left: n[1] * n[2],
        }
    }

    /// The first cell of the next row, if any.
    #[inline]
    fn next_row(&mut self) -> Option<T> {
        if self.left == 0 {
            return None;
        }
        self.left -= 1;
        self.left_in_slice -= 1;
        let first = self.row;
        if self.left_in_slice == 0 {
            self.left_in_slice = self.rows_per_slice;
            self.row += self.z_step;
        } else {
            self.row += self.y_step;
        }
        Some(first)
    }
}

/// The slot ranges of one neighbour query (see [`NeighbourGrid::candidate_ranges`]): the
/// block's rows one after the other, each found by adding a stride to the last, so a row
/// of a dense grid costs two offset loads, not two cell indices computed from coordinates
/// (a sparse grid's, a search among its occupied cells).
pub enum CandidateRanges<'a> {
    Empty,
    Dense {
        offsets: &'a [u32],
        rows: Rows<usize>,
    },
    Sparse {
        keys: &'a [u128],
        starts: &'a [u32],
        rows: Rows<u128>,
    },
}

impl Iterator for CandidateRanges<'_> {
    type Item = Range<usize>;

    #[inline]
    fn next(&mut self) -> Option<Range<usize>> {
        match self {
            CandidateRanges::Empty => None,
            CandidateRanges::Dense { offsets, rows } => {
                while let Some(first) = rows.next_row() {
                    let start = offsets[first] as usize;
                    let end = offsets[first + rows.width] as usize;
                    if start < end {
                        return Some(start..end);
                    }
                }
                None
            }
            CandidateRanges::Sparse { keys, starts, rows } => {
                while let Some(first) = rows.next_row() {
                    let past = first + rows.width as u128;
                    let k = keys.partition_point(|&c| c < first);
                    let end = k + keys[k..].iter().take_while(|&&c| c < past).count();
                    if end > k {
                        return Some(starts[k] as usize..starts[end] as usize);
                    }
                }
                None
            }
        }
    }
}

/// Integer cell coordinates of `p` in the unsqueezed cells of edge 1 / `inv_cell` from
/// `origin` (may lie outside the box for query points).
#[inline]
fn box_coords(origin: DVec3, inv_cell: f64, p: DVec3) -> [i64; 3] {
    let c = (p - origin) * inv_cell;
    [floor_i64(c.x), floor_i64(c.y), floor_i64(c.z)]
}

/// `v.floor() as i64` without the library call `floor` is on baseline x86-64 (no
/// SSE4.1 `roundsd`): truncate, then step down for negative non-integers. Equal to it for
/// every finite `v` within ±2⁶³; NaN gives 0 as `as` does.
#[inline(always)]
pub(crate) fn floor_i64(v: f64) -> i64 {
    let t = v as i64;
    t - i64::from((t as f64) > v)
}

/// Axis-aligned bounds of a non-empty point set.
pub fn bounds(points: &[DVec3]) -> (DVec3, DVec3) {
    points.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), &p| (lo.min(p), hi.max(p)),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Asserts that the candidates of a query at `p` hold exactly the points of `pts`
    /// within `r` once filtered by distance, as a brute-force search finds them.
    fn assert_exact_neighbours(grid: &NeighbourGrid, pts: &[DVec3], p: DVec3, reach: i64, r: f64) {
        let mut found: Vec<usize> = grid
            .candidate_ranges(p, reach)
            .flat_map(|range| grid.order()[range].to_vec())
            .map(|i| i as usize)
            .filter(|&i| pts[i].distance(p) < r)
            .collect();
        found.sort_unstable();
        let brute: Vec<usize> = (0..pts.len()).filter(|&i| pts[i].distance(p) < r).collect();
        assert_eq!(found, brute, "query at {p}");
    }

    /// Asserts that the ranges of a box query hold every point of `pts` inside the box.
    fn assert_box_holds(grid: &NeighbourGrid, pts: &[DVec3], lo: DVec3, hi: DVec3) {
        let boxed: Vec<usize> = grid
            .ranges_in_box(lo, hi)
            .flat_map(|range| grid.order()[range].to_vec())
            .map(|i| i as usize)
            .collect();
        let inside = (0..pts.len()).filter(|&i| pts[i].cmpge(lo).all() && pts[i].cmple(hi).all());
        assert!(
            inside.into_iter().all(|i| boxed.contains(&i)),
            "box {lo}..{hi}"
        );
    }

    #[test]
    fn candidates_cover_every_point_within_one_cell() {
        let mut rnd = crate::test_rng::unit(12345);
        let pts: Vec<DVec3> = (0..3000)
            .map(|_| DVec3::new(rnd(), rnd() * 0.5, rnd() * 2.0))
            .collect();
        let r = 0.13;
        for (cell, reach) in [(r, 1), (r / 2.0, 2), (r / 3.0, 3)] {
            let grid = NeighbourGrid::build(&pts, cell, reach, 1 << 30).unwrap();
            for _ in 0..200 {
                let p = DVec3::new(rnd() * 1.2 - 0.1, rnd() * 0.7 - 0.1, rnd() * 2.2 - 0.1);
                assert_exact_neighbours(&grid, &pts, p, reach, r);
            }
        }
    }

    /// A particle flung to x = 1e30 spreads the box past what a grid indexes: the error
    /// names it (and the other extreme along that axis), not only the bounds.
    #[test]
    fn a_particle_far_from_the_rest_is_named() {
        let mut pts: Vec<DVec3> = (0..50).map(|i| DVec3::splat(i as f64 * 0.01)).collect();
        pts[42].x = 1e30;
        let e = NeighbourGrid::build(&pts, 0.05, 1, 1 << 30)
            .err()
            .unwrap()
            .to_string();
        assert!(
            e.contains("axis 0") && e.contains("particle 42 at [1e30"),
            "{e}"
        );
        assert!(e.contains("particle 0 at [0.0"), "{e}");
    }

    #[test]
    fn floor_i64_matches_floor() {
        for v in [
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            2.999999,
            -2.999999,
            1e15 + 0.5,
            -1e15 - 0.5,
            f64::MIN_POSITIVE,
            -f64::MIN_POSITIVE,
            4503599627370497.0,
            -4503599627370497.0,
        ] {
            assert_eq!(floor_i64(v), v.floor() as i64, "{v}");
        }
    }

    #[test]
    fn particles_scattered_over_an_absurd_box_cost_memory_by_particle() {
        // Spread evenly over a box of 10¹² cells an axis: nothing to squeeze, so only the
        // occupied cells are listed; a budget below that is refused before allocating.
        let pts: Vec<DVec3> = (0..1000)
            .map(|i| DVec3::new(i as f64, (i * 7 % 1000) as f64, (i * 13 % 1000) as f64) * 1e6)
            .collect();
        let grid = NeighbourGrid::build(&pts, 1e-3, 1, 1 << 30).unwrap();
        assert!(matches!(grid.cells, Cells::Sparse { ref keys, .. } if keys.len() == 1000));
        assert!(grid.layout().is_none());
        for (i, &p) in pts.iter().enumerate().step_by(37) {
            let near: Vec<u32> = grid
                .candidate_ranges(p + DVec3::splat(4e-4), 1)
                .flat_map(|r| grid.order()[r].to_vec())
                .collect();
            assert_eq!(near, [i as u32]);
        }
        let err = NeighbourGrid::build(&pts, 1e-3, 1, 10_000).unwrap_err();
        assert!(matches!(err, Error::OverBudget { .. }), "{err}");
        // Farther apart than a cell index reaches: refused (it was clamped onto the
        // box's last cell, where no query near the particle looked).
        let far = [DVec3::ZERO, DVec3::new(1e13, 0.0, 0.0)];
        let err = NeighbourGrid::build(&far, 1e-3, 1, 1 << 30).unwrap_err();
        assert!(
            matches!(err, Error::InvalidInput(_)) && err.to_string().contains("axis 0"),
            "{err}"
        );
        // A diagonal line fills a slab of every axis all along: nothing to squeeze, and an
        // offset table a small share of the budget stays dense, with the GPU's layout.
        let line: Vec<DVec3> = (0..300).map(|i| DVec3::splat(i as f64 * 0.05)).collect();
        let dense = NeighbourGrid::build(&line, 0.05, 2, 1 << 30).unwrap();
        assert!(dense.squeeze.is_none() && dense.layout().is_some());

        // A cluster among them: many particles a cell, rows of several cells.
        let mut rnd = crate::test_rng::unit(4242);
        let centre = DVec3::splat(5e8);
        let mut all = pts.clone();
        all.extend((0..400).map(|_| centre + DVec3::new(rnd(), rnd(), rnd()) * 0.01));
        let r = 2e-3;
        let grid = NeighbourGrid::build(&all, r / 2.0, 2, 1 << 30).unwrap();
        assert!(matches!(grid.cells, Cells::Sparse { .. }));
        for _ in 0..300 {
            let p = centre + DVec3::new(rnd(), rnd(), rnd()) * 0.016 - DVec3::splat(0.003);
            assert_exact_neighbours(&grid, &all, p, 2, r);
            assert_box_holds(&grid, &all, p - DVec3::splat(r), p + DVec3::splat(r));
        }
    }

    #[test]
    fn an_axis_squeezes_runs_farther_than_reach_from_every_particle_to_one_slab() {
        // Occupied 0, 1, 10, 30 with reach 2: kept 0..=3, squeezed 4..=7, kept 8..=12,
        // squeezed 13..=27, kept 28..=30.
        let m = AxisMap::new(&[0, 1, 10, 30], 2);
        assert_eq!(m.len, 4 + 1 + 5 + 1 + 3);
        let expect = [
            (-1, -1),
            (0, 0),
            (3, 3),
            (4, 4),
            (7, 4),
            (8, 5),
            (10, 7),
            (12, 9),
            (13, 10),
            (27, 10),
            (28, 11),
            (30, 13),
            (31, 14),
        ];
        for (i, c) in expect {
            assert_eq!(m.map(i), c, "slab {i}");
        }
        // From a squeezed slab the nearest particle's slab is reach + 1 away.
        assert_eq!(m.map(10) - m.map(7), 3);
        assert_eq!(m.map(30) - m.map(27), 3);
    }

    #[test]
    fn stray_particles_far_from_the_fluid_cost_cells_near_them_not_the_box() {
        // A block of fluid, one particle far off on every axis, one along x alone, and a
        // particle just past `reach` cells from the block's edge (a squeezed run of one).
        let mut rnd = crate::test_rng::unit(777);
        let mut pts: Vec<DVec3> = (0..4000).map(|_| DVec3::new(rnd(), rnd(), rnd())).collect();
        pts.push(DVec3::splat(1e4));
        pts.push(DVec3::new(-5e3, 0.5, 0.5));
        pts.push(DVec3::new(1.0 + 0.1 * 3.5, 0.5, 0.5));
        let r = 0.1;
        for (cell, reach) in [(r, 1), (r / 2.0, 2)] {
            let grid = NeighbourGrid::build(&pts, cell, reach, 1 << 30).unwrap();
            assert!(grid.squeeze.is_some() && grid.layout().is_none());
            let cells: usize = grid.dims.iter().product();
            assert!(cells < 100_000, "{:?}", grid.dims); // the box: 1.5e5 cells an axis
            let mut queries: Vec<DVec3> = (0..300)
                .map(|_| DVec3::new(rnd() * 1.6 - 0.3, rnd() * 1.6 - 0.3, rnd() * 1.6 - 0.3))
                .collect();
            for &stray in &pts[4000..] {
                queries
                    .extend((0..50).map(|_| stray + DVec3::new(rnd(), rnd(), rnd()) * 0.3 - 0.15));
            }
            queries.push(DVec3::splat(5e3)); // deep in the squeezed space
            queries.push(DVec3::splat(-1e5)); // outside the box
            for &p in &queries {
                assert_exact_neighbours(&grid, &pts, p, reach, r);
                assert_box_holds(&grid, &pts, p - DVec3::splat(r), p + DVec3::splat(r));
            }
        }
        // Where the box is not mostly empty, nothing is squeezed (queries stay as fast).
        let dense = NeighbourGrid::build(&pts[..4000], r, 1, 1 << 30).unwrap();
        assert!(dense.squeeze.is_none() && dense.layout().is_some());
    }
}
