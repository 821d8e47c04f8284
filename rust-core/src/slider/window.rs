//! Cells listed once each and in ascending order, from items visited in ascending order.
//!
//! An update lists the cells around its changed edges: up to four per edge, each cell
//! once, ascending (the order decides I, see `runtime::ascending`). The edges come sorted,
//! and the cells around an edge lie at most a slab and a row below its node, so a ring
//! of bits as wide as that reach (16 KiB at 256³, in L1) is enough to remove repeats and
//! order them: cells that no later edge can reach leave the ring in order. A bit set over
//! the whole lattice (2 MiB at 256³) did the same with a cache miss per cell and a sort
//! of the result.

/// A ring of cell bits covering the cells still reachable, with a summary bit per word
/// so that flushing skips empty words.
#[derive(Default)]
pub(crate) struct CellWindow {
    words: Vec<u64>,
    summary: Vec<u64>,
    /// Every cell below word `lo` (absolute, cell / 64) has been flushed.
    lo: usize,
    /// How far below the item being visited its cells may lie.
    reach: usize,
}

impl CellWindow {
    /// Starts a pass whose items mark cells at most `reach` below themselves.
    pub(crate) fn start(&mut self, reach: usize) {
        let words = (reach / 64 + 2).next_power_of_two().max(64);
        if self.words.len() != words {
            self.words = vec![0; words];
            self.summary = vec![0; words / 64];
        }
        self.lo = 0;
        self.reach = reach;
    }

    /// Moves to item `at` (items come ascending): cells below `at − reach` can no longer
    /// be marked, so they go to `out`, ascending.
    #[inline]
    pub(crate) fn advance(&mut self, at: usize, out: &mut Vec<u32>) {
        let bound = at.saturating_sub(self.reach) / 64;
        if bound > self.lo {
            self.flush_to(bound, out);
        }
    }

    /// Marks `cell`, which lies within the reach of the current item.
    #[inline]
    pub(crate) fn mark(&mut self, cell: u32) {
        let w = cell as usize / 64;
        debug_assert!(w >= self.lo && w < self.lo + self.words.len());
        let slot = w & (self.words.len() - 1);
        self.words[slot] |= 1 << (cell % 64);
        self.summary[slot / 64] |= 1 << (slot % 64);
    }

    /// Bytes held (the ring and its summary).
    pub(crate) fn held_bytes(&self) -> u64 {
        ((self.words.capacity() + self.summary.capacity()) * 8) as u64
    }

    /// Ends the pass: every cell still marked goes to `out`, ascending.
    pub(crate) fn finish(&mut self, out: &mut Vec<u32>) {
        self.flush_to(self.lo + self.words.len(), out);
    }

    /// Sends the marked cells of words `lo..to` to `out` and moves `lo` to `to`.
    fn flush_to(&mut self, to: usize, out: &mut Vec<u32>) {
        let ring = self.words.len();
        // Only the ring's words can hold marks: a longer jump flushes the whole ring.
        let n = (to - self.lo).min(ring);
        let s0 = self.lo & (ring - 1);
        let first = n.min(ring - s0);
        self.emit(s0, first, self.lo, out);
        if n > first {
            self.emit(0, n - first, self.lo + first, out);
        }
        self.lo = to;
    }

    /// Sends the marked cells of ring slots `from..from + count`, whose first slot holds
    /// absolute word `word`, to `out` in slot order, and clears them.
    fn emit(&mut self, from: usize, count: usize, word: usize, out: &mut Vec<u32>) {
        let end = from + count;
        let mut s = from;
        while s < end {
            let sw = s / 64;
            let limit = ((sw + 1) * 64).min(end);
            let mut bits = self.summary[sw] & (!0u64 << (s % 64));
            if !limit.is_multiple_of(64) {
                bits &= (1u64 << (limit % 64)) - 1;
            }
            self.summary[sw] &= !bits;
            while bits != 0 {
                let slot = sw * 64 + bits.trailing_zeros() as usize;
                let base = (word + slot - from) * 64;
                let mut cells = std::mem::take(&mut self.words[slot]);
                while cells != 0 {
                    out.push((base + cells.trailing_zeros() as usize) as u32);
                    cells &= cells - 1;
                }
                bits &= bits - 1;
            }
            s = limit;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Items ascending, each marking a few cells within reach below it (with repeats),
    /// some far apart (jumps past the ring, across its wrap): the cells come out once
    /// each, ascending, as sorting and deduplicating them gives; a second pass on the
    /// same window starts clean.
    #[test]
    fn lists_each_cell_once_in_ascending_order() {
        let mut next = crate::test_rng::lcg(11);
        let mut window = CellWindow::default();
        for (reach, items) in [(300usize, 2_000usize), (65_793, 5_000), (1, 500)] {
            for _ in 0..2 {
                let mut at = (next() % 1_000) as usize;
                let mut expected = Vec::new();
                let mut got = Vec::new();
                window.start(reach);
                for _ in 0..items {
                    at += match next() % 10 {
                        0 => (next() % 3_000_000) as usize,
                        1..=3 => 0,
                        _ => (next() % 200) as usize,
                    };
                    window.advance(at, &mut got);
                    for _ in 0..4 {
                        let cell = (at - (next() as usize % (reach + 1)).min(at)) as u32;
                        window.mark(cell);
                        expected.push(cell);
                    }
                }
                window.finish(&mut got);
                expected.sort_unstable();
                expected.dedup();
                assert_eq!(got, expected, "reach {reach}");
            }
        }
    }
}
