//! Uniform neighbour grid: particles bucketed by counting sort into cubic cells, so any
//! point's neighbours within `reach` cells lie in the (2·reach+1)³ block around it. Cells
//! are ordered x fastest, so each row of a query block is one contiguous slice of the
//! sorted particles: (2·reach+1)² range look-ups per query.

use crate::error::{Error, Result};
use glam::DVec3;
use rayon::prelude::*;
use std::ops::Range;

/// Particles bucketed into a dense grid of cubic cells.
#[derive(Clone, Debug)]
pub struct NeighbourGrid {
    origin: DVec3,
    inv_cell: f64,
    dims: [usize; 3],
    /// `offsets[c]..offsets[c+1]` are the sorted slots of cell c.
    offsets: Vec<u32>,
    /// Original particle index of each sorted slot; within a cell, ascending.
    order: Vec<u32>,
}

impl NeighbourGrid {
    /// Buckets `positions` into cells of edge `cell_size`. Refuses, before allocating, a
    /// grid whose offset table would exceed `memory_budget` bytes.
    pub fn build(positions: &[DVec3], cell_size: f64, memory_budget: u64) -> Result<Self> {
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
        let mut dims = [0usize; 3];
        let mut ncells: u128 = 1;
        for a in 0..3 {
            let n = ((hi[a] - lo[a]) / cell_size).floor() + 1.0;
            dims[a] = n.min(1e15) as usize;
            ncells *= dims[a] as u128;
        }
        let needed = (ncells + 1) * 4 + positions.len() as u128 * 8;
        if needed > memory_budget as u128 || ncells >= u32::MAX as u128 {
            return Err(Error::OverBudget {
                what: format!(
                    "a neighbour grid of {}×{}×{} cells (particles spread over {:?}..{:?} with support {cell_size})",
                    dims[0], dims[1], dims[2], lo.to_array(), hi.to_array()
                ),
                needed_bytes: needed.min(u64::MAX as u128) as u64,
                budget_bytes: memory_budget,
            });
        }
        let mut grid = NeighbourGrid {
            origin: lo,
            inv_cell: 1.0 / cell_size,
            dims,
            offsets: Vec::new(),
            order: Vec::new(),
        };
        let cell_of: Vec<u32> = positions
            .par_iter()
            .map(|&p| {
                // Clamped: (hi - lo) / cell can round below the product used here, and a
                // particle on the upper bound would land one cell past the row's end,
                // i.e. in the next row, where no query near it looks.
                let c = grid.cell_coords(p);
                let c: [usize; 3] =
                    std::array::from_fn(|a| c[a].clamp(0, dims[a] as i64 - 1) as usize);
                grid.linear(c[0], c[1], c[2]) as u32
            })
            .collect();
        // Counting sort; the scatter runs in particle order so each cell lists its
        // particles ascending, which keeps every later sum in the same order.
        let mut offsets = vec![0u32; ncells as usize + 1];
        for &c in &cell_of {
            offsets[c as usize + 1] += 1;
        }
        for i in 1..offsets.len() {
            offsets[i] += offsets[i - 1];
        }
        let mut cursor = offsets.clone();
        let mut order = vec![0u32; positions.len()];
        for (i, &c) in cell_of.iter().enumerate() {
            order[cursor[c as usize] as usize] = i as u32;
            cursor[c as usize] += 1;
        }
        grid.offsets = offsets;
        grid.order = order;
        Ok(grid)
    }

    /// Original particle index of each sorted slot.
    pub fn order(&self) -> &[u32] {
        &self.order
    }

    /// (origin, 1 / cell size, cells per axis, slot offsets per cell plus one): the
    /// layout a GPU kernel needs to repeat [`NeighbourGrid::for_each_candidate_range`].
    pub fn layout(&self) -> (DVec3, f64, [usize; 3], &[u32]) {
        (self.origin, self.inv_cell, self.dims, &self.offsets)
    }

    fn linear(&self, x: usize, y: usize, z: usize) -> usize {
        x + self.dims[0] * (y + self.dims[1] * z)
    }

    /// Integer cell coordinates of `p` (may lie outside the grid for query points).
    #[inline]
    fn cell_coords(&self, p: DVec3) -> [i64; 3] {
        let c = (p - self.origin) * self.inv_cell;
        [floor_i64(c.x), floor_i64(c.y), floor_i64(c.z)]
    }

    /// Each sorted-slot range that may hold a particle within `reach` cell sizes of `p`:
    /// at most (2·reach+1)² contiguous ranges, z-row by y-row.
    #[inline]
    pub fn candidate_ranges(&self, p: DVec3, reach: i64) -> CandidateRanges<'_> {
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
                return CandidateRanges::empty(self);
            }
            lo[a] = l as usize;
            n[a] = (h - l) as usize + 1;
        }
        let y_step = self.dims[0];
        CandidateRanges {
            offsets: &self.offsets,
            row: self.linear(lo[0], lo[1], lo[2]),
            width: n[0],
            rows_per_slice: n[1],
            left_in_slice: n[1],
            left: n[1] * n[2],
            y_step,
            z_step: y_step * self.dims[1] - y_step * (n[1] - 1),
        }
    }

    /// Calls `f` with each range of [`NeighbourGrid::candidate_ranges`].
    #[inline]
    pub fn for_each_candidate_range(&self, p: DVec3, reach: i64, f: impl FnMut(Range<usize>)) {
        self.candidate_ranges(p, reach).for_each(f);
    }
}

/// The slot ranges of one neighbour query (see [`NeighbourGrid::candidate_ranges`]): the
/// block's rows one after the other, each found by adding a stride to the last, so a row
/// costs two offset loads, not two cell indices computed from coordinates.
pub struct CandidateRanges<'a> {
    offsets: &'a [u32],
    /// Linear index of the next row's first cell.
    row: usize,
    /// Cells in a row.
    width: usize,
    /// Rows in a z-slice of the block, and rows left in the current slice.
    rows_per_slice: usize,
    left_in_slice: usize,
    /// Rows left in the block.
    left: usize,
    /// From a row to the next in its slice, and from a slice's last row to the next
    /// slice's first.
    y_step: usize,
    z_step: usize,
}

impl<'a> CandidateRanges<'a> {
    fn empty(grid: &'a NeighbourGrid) -> Self {
        CandidateRanges {
            offsets: &grid.offsets,
            row: 0,
            width: 0,
            rows_per_slice: 0,
            left_in_slice: 0,
            left: 0,
            y_step: 0,
            z_step: 0,
        }
    }
}

impl Iterator for CandidateRanges<'_> {
    type Item = Range<usize>;

    #[inline]
    fn next(&mut self) -> Option<Range<usize>> {
        while self.left > 0 {
            self.left -= 1;
            let row = self.row;
            self.left_in_slice -= 1;
            if self.left_in_slice == 0 {
                self.left_in_slice = self.rows_per_slice;
                self.row += self.z_step;
            } else {
                self.row += self.y_step;
            }
            let start = self.offsets[row] as usize;
            let end = self.offsets[row + self.width] as usize;
            if start < end {
                return Some(start..end);
            }
        }
        None
    }
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

    #[test]
    fn candidates_cover_every_point_within_one_cell() {
        let mut rnd = crate::test_rng::unit(12345);
        let pts: Vec<DVec3> = (0..3000)
            .map(|_| DVec3::new(rnd(), rnd() * 0.5, rnd() * 2.0))
            .collect();
        let r = 0.13;
        for (cell, reach) in [(r, 1), (r / 2.0, 2), (r / 3.0, 3)] {
            let grid = NeighbourGrid::build(&pts, cell, 1 << 30).unwrap();
            for q in 0..200 {
                let p = DVec3::new(rnd() * 1.2 - 0.1, rnd() * 0.7 - 0.1, rnd() * 2.2 - 0.1);
                let mut found = Vec::new();
                grid.for_each_candidate_range(p, reach, |range| {
                    for slot in range {
                        let i = grid.order()[slot] as usize;
                        if pts[i].distance(p) < r {
                            found.push(i);
                        }
                    }
                });
                found.sort_unstable();
                let brute: Vec<usize> =
                    (0..pts.len()).filter(|&i| pts[i].distance(p) < r).collect();
                assert_eq!(found, brute, "query {q}");
            }
        }
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
    fn absurd_extent_is_refused_before_allocating() {
        let pts = vec![DVec3::ZERO, DVec3::splat(1e9)];
        let err = NeighbourGrid::build(&pts, 1e-3, 1 << 30).unwrap_err();
        assert!(matches!(err, Error::OverBudget { .. }), "{err}");
    }
}
