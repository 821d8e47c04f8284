//! The field at the finest-lattice nodes near the surface, evaluated once and shared: the
//! error criterion compares every candidate cell's 5³ lattice, and the level-2 and
//! level-3 cells contour (a subset of) the same nodes. Evaluated cell by cell, a node on
//! a cell's face or corner was computed up to eight times, and a 5³ block does not pay
//! for a block evaluation's set-up (`ScalarField::values_on_tile`, which for SPH visits
//! each particle's covered nodes instead of each node's particles).
//!
//! Nodes are stored in a sparse set of tiles of [`TILE`]³ nodes, tile t holding the
//! nodes `TILE·t .. TILE·t + TILE` per axis (the lower nodes of a 2×2×2 block of coarse
//! cells), each tile evaluating only the nodes some covered cell asked for. The coarse
//! grid's nodes, which level 1 and the criterion's sign pass read everywhere, are kept
//! apart in one dense array. Values are the field's to the bit (`values_on_tile`
//! promises it), so reading a node here or evaluating it gives the same surface,
//! whichever cells asked first.

use super::grid::{subdivisions, CoarseGrid, FINE_PER_COARSE};
use crate::error::{Error, Result};
use crate::field::{ScalarField, TILE};
use crate::progress::{for_ranges, Progress};
use rayon::prelude::*;

const TILE3: usize = TILE * TILE * TILE;
const ABSENT: u32 = u32::MAX;
/// Finest nodes per coarse cell edge, both ends included.
const M: usize = FINE_PER_COARSE as usize + 1;

/// A node mask of one tile: bit x of `rows[y + TILE · z]` for local node (x, y, z).
type Rows = [u8; TILE * TILE];

/// Finest-lattice node values: a dense array at the coarse nodes, sparse tiles elsewhere.
#[derive(Clone, Debug, Default)]
pub struct Lattice {
    /// Coarse cells per axis.
    cells: [usize; 3],
    /// Tiles per axis.
    tiles: [usize; 3],
    /// For each tile, x fastest: its slot in `marked` and `values`, or `ABSENT`.
    slot: Vec<u32>,
    /// The nodes of each stored tile that hold a value.
    marked: Vec<Rows>,
    /// `TILE3` values per stored tile, x fastest within the tile.
    values: Vec<f64>,
    /// The field at every coarse node, x fastest; empty until [`Lattice::cover_corners`].
    corners: Vec<f64>,
}

impl Lattice {
    /// An empty store for `grid`'s finest lattice.
    pub fn new(grid: &CoarseGrid) -> Self {
        let nodes = grid.cells.map(|c| (c * FINE_PER_COARSE) as usize + 1);
        let tiles = nodes.map(|n| n.div_ceil(TILE));
        Lattice {
            cells: grid.cells.map(|c| c as usize),
            tiles,
            slot: vec![ABSENT; tiles.iter().product()],
            ..Lattice::default()
        }
    }

    /// Bytes the store holds.
    pub fn bytes(&self) -> u64 {
        (self.slot.len() * 4
            + self.marked.len() * TILE * TILE
            + (self.values.len() + self.corners.len()) * 8) as u64
    }

    /// Bytes of the coarse-node array of `grid`.
    pub fn corner_bytes(grid: &CoarseGrid) -> u64 {
        grid.cells.iter().map(|&c| c as u64 + 1).product::<u64>() * 8
    }

    /// Evaluates the field at every coarse node (node by node: most lie far from any
    /// surface, where a tile would be wasted), unless done already; returns the
    /// evaluations made. Refuses, before allocating, to take the store past `budget`
    /// bytes. Reports as it goes.
    pub fn cover_corners<F: ScalarField + ?Sized>(
        &mut self,
        field: &F,
        grid: &CoarseGrid,
        budget: u64,
        progress: &mut Progress,
    ) -> Result<u64> {
        if !self.corners.is_empty() {
            return Ok(0);
        }
        let needed = self.bytes() + Self::corner_bytes(grid);
        if needed > budget {
            return Err(Error::OverBudget {
                what: format!(
                    "the field at the {}×{}×{} coarse nodes",
                    grid.cells[0] + 1,
                    grid.cells[1] + 1,
                    grid.cells[2] + 1
                ),
                needed_bytes: needed,
                budget_bytes: budget,
            });
        }
        let n = self.cells.map(|c| c + 1);
        let mut corners = Vec::with_capacity(n[0] * n[1] * n[2]);
        for_ranges(
            n[0] * n[1] * n[2],
            progress,
            |nodes| -> Vec<f64> {
                nodes
                    .into_par_iter()
                    .map(|v| {
                        let c = [v % n[0], v / n[0] % n[1], v / (n[0] * n[1])];
                        let node = c.map(|x| (x * FINE_PER_COARSE as usize) as i64);
                        field.value(grid.point(node, 0))
                    })
                    .collect()
            },
            |part| corners.extend(part),
        )?;
        self.corners = corners;
        Ok(self.corners.len() as u64)
    }

    /// The value at coarse node `c` (after [`Lattice::cover_corners`]).
    #[inline]
    pub fn corner(&self, c: [u32; 3]) -> f64 {
        let n = self.cells.map(|c| c + 1);
        self.corners[c[0] as usize + n[0] * (c[1] as usize + n[1] * c[2] as usize)]
    }

    /// What level `level`'s cells contour: the coarse nodes for level 1 (see
    /// [`Lattice::cover_corners`]), every second finest node of the level-2 cells, every
    /// finest node of the level-3 cells. Returns the evaluations made.
    pub fn cover_level<F: ScalarField + ?Sized>(
        &mut self,
        field: &F,
        grid: &CoarseGrid,
        levels: &[u8],
        level: u8,
        budget: u64,
        progress: &mut Progress,
    ) -> Result<u64> {
        if level == 1 {
            return self.cover_corners(field, grid, budget, progress);
        }
        let cells: Vec<usize> = (0..levels.len())
            .into_par_iter()
            .filter(|&i| levels[i] == level)
            .collect();
        let stride = FINE_PER_COARSE / subdivisions(level);
        self.cover(field, grid, &cells, stride as usize, budget, progress)
    }

    /// Evaluates the nodes of the coarse cells `cells` on every `stride`-th finest node
    /// (1, 2 or 4) not stored yet, tile by tile in parallel; returns the evaluations
    /// made. Refuses, before allocating, tiles that would take the store past `budget`
    /// bytes. Reports between blocks of tiles (a fine grid's cover takes tens of seconds).
    pub fn cover<F: ScalarField + ?Sized>(
        &mut self,
        field: &F,
        grid: &CoarseGrid,
        cells: &[usize],
        stride: usize,
        budget: u64,
        progress: &mut Progress,
    ) -> Result<u64> {
        assert!(TILE.is_multiple_of(stride) && (FINE_PER_COARSE as usize).is_multiple_of(stride));
        let tiles = self.tiles;
        // The cells by the layer of tiles (along z) their nodes reach into, one or two
        // each: the tiles a cover needs are then found layer by layer, with a report
        // after each, instead of in one sort of every (tile, cell) pair (tens of seconds
        // on a fine grid, which no cancel could interrupt).
        let mut by_layer: Vec<Vec<usize>> = vec![Vec::new(); tiles[2]];
        for &cell in cells {
            let z = grid.coords(cell)[2] as usize * FINE_PER_COARSE as usize;
            for layer in &mut by_layer[z / TILE..=(z + M - 1) / TILE] {
                layer.push(cell);
            }
        }
        let mut wanted: Vec<(usize, Rows)> = Vec::new();
        progress.nested(0.0, 0.2, |p| {
            for (z, layer) in by_layer.iter().enumerate() {
                wanted.extend(self.wanted_in_layer(grid, z, layer, stride));
                p.report((z + 1) as f64 / by_layer.len() as f64)?;
            }
            Ok(())
        })?;
        drop(by_layer);
        let new_tiles = wanted.iter().filter(|w| self.stored(w.0).is_none()).count();
        let needed = self.bytes() + (new_tiles * (TILE3 * 8 + TILE * TILE)) as u64;
        if needed > budget {
            return Err(Error::OverBudget {
                what: format!("the finest-lattice values of {new_tiles} more tiles"),
                needed_bytes: needed,
                budget_bytes: budget,
            });
        }
        for (t, _) in &wanted {
            if self.slot[*t] == ABSENT {
                self.slot[*t] = self.marked.len() as u32;
                self.marked.push([0; TILE * TILE]);
            }
        }
        // The work by slot, so that each tile's storage is handed to one task.
        let mut work: Vec<Option<(usize, Rows)>> = vec![None; self.marked.len()];
        for (t, rows) in wanted {
            work[self.slot[t] as usize] = Some((t, rows));
        }
        // Blocks of slots, each spread over the threads, a report after each. The new
        // tiles' values (gigabytes on a fine grid) are allocated block by block too, so
        // that a cancel is answered during the allocation as well.
        const BLOCK: usize = 4096;
        let mut evaluations = 0;
        let count = work.len().div_ceil(BLOCK);
        // Reserved whole (pages untouched until filled): growing block by block would
        // copy the store at each doubling and hold it twice meanwhile.
        self.values
            .reserve_exact(work.len() * TILE3 - self.values.len());
        let done = progress.nested(0.2, 1.0, |p| {
            for (b, work) in work.chunks(BLOCK).enumerate() {
                let slots = b * BLOCK..b * BLOCK + work.len();
                if self.values.len() < slots.end * TILE3 {
                    self.values.resize(slots.end * TILE3, f64::NAN);
                }
                let values = &mut self.values[slots.start * TILE3..slots.end * TILE3];
                let marked = &mut self.marked[slots];
                evaluations += Self::evaluate(field, grid, tiles, values, marked, work);
                p.report((b + 1) as f64 / count as f64)?;
            }
            Ok(())
        });
        if done.is_err() {
            // Stopped: the tiles given slots but no values yet are let go again.
            self.keep_slots(self.values.len() / TILE3);
        }
        done.map(|()| evaluations)
    }

    /// Forgets every tile in a slot from `kept` on (the store as it was before a cover
    /// that gave those slots).
    fn keep_slots(&mut self, kept: usize) {
        for slot in &mut self.slot {
            if *slot != ABSENT && *slot as usize >= kept {
                *slot = ABSENT;
            }
        }
        self.marked.truncate(kept);
        self.values.truncate(kept * TILE3);
    }

    /// The tiles of z-layer `z` that `cells` (each reaching into it) need evaluated, in
    /// tile order, each with the mask of its nodes not stored yet.
    fn wanted_in_layer(
        &self,
        grid: &CoarseGrid,
        z: usize,
        cells: &[usize],
        stride: usize,
    ) -> Vec<(usize, Rows)> {
        let tiles = self.tiles;
        // (tile, cell) for every tile of the layer holding some node of a cell.
        let mut touches: Vec<(usize, usize)> = cells
            .par_iter()
            .flat_map_iter(|&cell| {
                let c = grid.coords(cell).map(|x| (x * FINE_PER_COARSE) as usize);
                let lo = c.map(|x| x / TILE);
                let hi = c.map(|x| (x + M - 1) / TILE);
                (lo[1]..=hi[1]).flat_map(move |y| {
                    (lo[0]..=hi[0]).map(move |x| (x + tiles[0] * (y + tiles[1] * z), cell))
                })
            })
            .collect();
        touches.par_sort_unstable();
        touches.dedup();
        let groups: Vec<&[(usize, usize)]> = touches.chunk_by(|a, b| a.0 == b.0).collect();
        groups
            .par_iter()
            .filter_map(|g| {
                let t = g[0].0;
                let mut rows = [0u8; TILE * TILE];
                for &(_, cell) in g.iter() {
                    self.mark_cell(grid, t, cell, stride, &mut rows);
                }
                if let Some(slot) = self.stored(t) {
                    for (r, m) in rows.iter_mut().zip(&self.marked[slot]) {
                        *r &= !m;
                    }
                }
                rows.iter().any(|&r| r != 0).then_some((t, rows))
            })
            .collect()
    }

    /// Evaluates the marked nodes of the tiles in `work` into their slots' `values`,
    /// adding them to `marked`; returns the evaluations made.
    fn evaluate<F: ScalarField + ?Sized>(
        field: &F,
        grid: &CoarseGrid,
        tiles: [usize; 3],
        values: &mut [f64],
        marked: &mut [Rows],
        work: &[Option<(usize, Rows)>],
    ) -> u64 {
        values
            .par_chunks_mut(TILE3)
            .zip(marked.par_iter_mut())
            .zip(work.par_iter())
            .map(|((out, marked), work)| {
                let Some((t, rows)) = work else { return 0 };
                let first = [
                    t % tiles[0],
                    t / tiles[0] % tiles[1],
                    t / (tiles[0] * tiles[1]),
                ]
                .map(|x| (x * TILE) as i64);
                let out: &mut [f64; TILE3] = out.try_into().expect("one tile");
                field.values_on_tile(grid.origin, grid.fine, first, rows, out);
                for (m, r) in marked.iter_mut().zip(rows) {
                    *m |= r;
                }
                rows.iter().map(|r| r.count_ones() as u64).sum::<u64>()
            })
            .sum()
    }

    /// Marks in `rows` the nodes of coarse cell `cell` on every `stride`-th finest node
    /// that lie in tile `t` (tiles start on a multiple of every stride).
    fn mark_cell(&self, grid: &CoarseGrid, t: usize, cell: usize, stride: usize, rows: &mut Rows) {
        let tile = [
            t % self.tiles[0],
            t / self.tiles[0] % self.tiles[1],
            t / (self.tiles[0] * self.tiles[1]),
        ];
        let c = grid.coords(cell);
        // The cell's local node range in the tile, per axis.
        let range: [(usize, usize); 3] = std::array::from_fn(|a| {
            let first = (c[a] * FINE_PER_COARSE) as usize;
            let lo = first.max(tile[a] * TILE) - tile[a] * TILE;
            let hi = (first + M - 1).min(tile[a] * TILE + TILE - 1) - tile[a] * TILE;
            (lo, hi)
        });
        let on_stride = |x: &usize| x.is_multiple_of(stride);
        let bits = (range[0].0..=range[0].1)
            .filter(on_stride)
            .fold(0u8, |b, x| b | 1 << x);
        for z in (range[2].0..=range[2].1).filter(on_stride) {
            for y in (range[1].0..=range[1].1).filter(on_stride) {
                rows[y + TILE * z] |= bits;
            }
        }
    }

    fn stored(&self, t: usize) -> Option<usize> {
        let slot = *self.slot.get(t)?;
        (slot != ABSENT).then_some(slot as usize)
    }

    /// The value at finest node `node`, if stored.
    #[inline]
    pub fn get(&self, node: [u32; 3]) -> Option<f64> {
        let f = FINE_PER_COARSE;
        if !self.corners.is_empty() && node.iter().all(|&x| x % f == 0) {
            return Some(self.corner(node.map(|x| x / f)));
        }
        let n = node.map(|x| x as usize);
        let slot = self
            .stored(n[0] / TILE + self.tiles[0] * (n[1] / TILE + self.tiles[1] * (n[2] / TILE)))?;
        let l = n.map(|x| x % TILE);
        (self.marked[slot][l[1] + TILE * l[2]] >> l[0] & 1 == 1)
            .then(|| self.values[slot * TILE3 + l[0] + TILE * (l[1] + TILE * l[2])])
    }

    /// The `M`³ node values of coarse cell `c`, x fastest, into `out` (the cell must
    /// have been covered).
    pub fn cell(&self, c: [u32; 3], out: &mut [f64; M * M * M]) {
        self.block(c.map(|x| x * FINE_PER_COARSE), M, 1, out);
    }

    /// The `M`³ node values of coarse cell `c` when every one is stored, else None (a
    /// cell next to the covered region, or outside the lattice).
    pub fn stored_cell(&self, c: [u32; 3]) -> Option<[f64; M * M * M]> {
        let mut out = [0.0; M * M * M];
        self.try_block(c.map(|x| x * FINE_PER_COARSE), M, 1, &mut out)
            .then_some(out)
    }

    /// The values at the `n`³ nodes `first + stride · l` (l in 0..n per axis, x fastest)
    /// into `out`; each must be stored.
    pub fn block(&self, first: [u32; 3], n: usize, stride: u32, out: &mut [f64]) {
        assert!(
            self.try_block(first, n, stride, out),
            "a node of the block from {first:?} was not covered"
        );
    }

    /// [`Lattice::block`], false as soon as a node is not stored (`out` then partly
    /// written). The tile of each node comes from per-axis tables (this runs for every
    /// node of every contoured cell).
    fn try_block(&self, first: [u32; 3], n: usize, stride: u32, out: &mut [f64]) -> bool {
        assert!(n <= M && out.len() == n * n * n);
        // Per axis and node: (tile coordinate, offset in the tile).
        let axis: [[(usize, usize); M]; 3] = std::array::from_fn(|a| {
            std::array::from_fn(|i| {
                let x = (first[a] + i as u32 * stride) as usize;
                (x / TILE, x % TILE)
            })
        });
        let mut v = 0;
        for &(tz, lz) in &axis[2][..n] {
            for &(ty, ly) in &axis[1][..n] {
                let row = ly + TILE * lz;
                for &(tx, lx) in &axis[0][..n] {
                    let t = tx + self.tiles[0] * (ty + self.tiles[1] * tz);
                    out[v] = match self.stored(t) {
                        Some(slot) if self.marked[slot][row] >> lx & 1 == 1 => {
                            self.values[slot * TILE3 + lx + TILE * row]
                        }
                        _ => {
                            let node = [tx * TILE + lx, ty * TILE + ly, tz * TILE + lz];
                            match self.get(node.map(|x| x as u32)) {
                                Some(value) => value,
                                None => return false,
                            }
                        }
                    };
                    v += 1;
                }
            }
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    struct Wavy;

    impl ScalarField for Wavy {
        fn value(&self, x: DVec3) -> f64 {
            (3.0 * x.x).sin() * (2.0 * x.y).cos() + x.z * x.z
        }
        fn value_and_gradient(&self, x: DVec3) -> (f64, DVec3) {
            (self.value(x), DVec3::ZERO)
        }
    }

    /// Checks that every node of covered cell `i` reads [`Wavy`] at that node to the bit;
    /// returns the cell's values.
    fn assert_cell_reads_wavy(lattice: &Lattice, grid: &CoarseGrid, i: usize) -> [f64; M * M * M] {
        let c = grid.coords(i);
        let mut values = [0.0; M * M * M];
        lattice.cell(c, &mut values);
        for (v, &f) in values.iter().enumerate() {
            let l = [v % M, v / M % M, v / (M * M)].map(|x| x as u32);
            let node = std::array::from_fn(|a| c[a] * 4 + l[a]);
            let at = Wavy.value(grid.point(node.map(|x| x as i64), 0));
            assert_eq!(f.to_bits(), at.to_bits(), "cell {i} node {node:?}");
        }
        values
    }

    /// Every node of the covered cells reads the field's value at that node to the bit,
    /// including the grid's last nodes (in clipped tiles), each evaluated once: a second
    /// cover evaluates only the nodes the first did not, a repeated one nothing. Nodes of
    /// cells never covered read nothing, even in a stored tile, except coarse nodes once
    /// those are covered.
    #[test]
    fn covered_cells_read_the_field_at_each_node_evaluated_once() {
        let grid = CoarseGrid {
            origin: DVec3::new(-0.3, 0.1, 0.2),
            fine: 0.037,
            cells: [5, 3, 4],
        };
        let at = |node: [u32; 3]| Wavy.value(grid.point(node.map(|x| x as i64), 0));
        let nodes_of = |cells: &[usize]| -> std::collections::BTreeSet<[u32; 3]> {
            let mut set = std::collections::BTreeSet::new();
            for &i in cells {
                let c = grid.coords(i);
                for v in 0..M * M * M {
                    let l = [v % M, v / M % M, v / (M * M)].map(|x| x as u32);
                    set.insert(std::array::from_fn(|a| c[a] * 4 + l[a]));
                }
            }
            set
        };
        // (0, 0, 0), (2, 1, 0), then (1, 1, 0) (a face shared with the second) and the
        // last cell.
        let cells = [0usize, 7, 6, grid.cell_count() - 1];
        let mut lattice = Lattice::new(&grid);
        let made = lattice
            .cover(
                &Wavy,
                &grid,
                &cells[..2],
                1,
                u64::MAX,
                &mut Progress::none(),
            )
            .unwrap();
        assert_eq!(made, nodes_of(&cells[..2]).len() as u64);
        assert_eq!(
            lattice.get([4, 8, 0]),
            None,
            "a node of the third cell only"
        );
        let made = lattice
            .cover(&Wavy, &grid, &cells, 1, u64::MAX, &mut Progress::none())
            .unwrap();
        assert_eq!(
            made,
            (nodes_of(&cells).len() - nodes_of(&cells[..2]).len()) as u64
        );
        assert_eq!(
            lattice
                .cover(&Wavy, &grid, &cells, 1, u64::MAX, &mut Progress::none())
                .unwrap(),
            0
        );
        for &i in &cells {
            let values = assert_cell_reads_wavy(&lattice, &grid, i);
            assert_eq!(
                lattice.stored_cell(grid.coords(i)),
                Some(values),
                "cell {i}"
            );
        }
        // (1, 0, 1) shares nodes with covered cells but is not covered itself.
        assert_eq!(lattice.stored_cell([1, 0, 1]), None);
        // In the first tile but a node of cell (1, 0, 1) only; a coarse node of no
        // covered cell, read once the coarse nodes are covered.
        assert_eq!(lattice.get([6, 2, 6]), None);
        assert_eq!(lattice.get([12, 4, 8]), None);
        assert_eq!(
            lattice
                .cover_corners(&Wavy, &grid, u64::MAX, &mut Progress::none())
                .unwrap(),
            6 * 4 * 5
        );
        assert_eq!(
            lattice.get([12, 4, 8]).map(f64::to_bits),
            Some(at([12, 4, 8]).to_bits())
        );
        assert_eq!(lattice.get([6, 2, 6]), None);
    }

    /// [`Wavy`], counting its evaluations.
    #[derive(Default)]
    struct Counted(std::sync::atomic::AtomicU64);

    impl ScalarField for Counted {
        fn value(&self, x: DVec3) -> f64 {
            self.0.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            Wavy.value(x)
        }
        fn value_and_gradient(&self, x: DVec3) -> (f64, DVec3) {
            (self.value(x), DVec3::ZERO)
        }
    }

    /// A cover cancelled between its blocks leaves a store whose tiles all have values:
    /// a later cover completes it, each node evaluated once in all, reading the field
    /// exactly.
    #[test]
    fn a_cancelled_cover_leaves_a_store_to_cover_again() {
        let grid = CoarseGrid {
            origin: DVec3::new(-0.3, 0.1, 0.2),
            fine: 0.01,
            cells: [40, 40, 40],
        };
        let cells: Vec<usize> = (0..grid.cell_count()).collect();
        let field = Counted::default();
        let mut lattice = Lattice::new(&grid);
        // Stop at the first report past the tiles' preparation (the first block).
        let mut stop = |fraction: f64, _: &str| fraction <= 0.2;
        let err = lattice
            .cover(
                &field,
                &grid,
                &cells,
                1,
                u64::MAX,
                &mut Progress::new(&mut stop),
            )
            .unwrap_err();
        assert!(matches!(err, Error::Cancelled));
        let kept = lattice.marked.len();
        assert!(kept > 0 && kept < 21 * 21 * 21, "{kept} tiles kept");
        assert_eq!(lattice.values.len(), kept * TILE3);
        let first = field.0.load(std::sync::atomic::Ordering::Relaxed);
        let made = lattice
            .cover(&field, &grid, &cells, 1, u64::MAX, &mut Progress::none())
            .unwrap();
        assert!(first > 0);
        assert_eq!(first + made, 161 * 161 * 161);
        assert_eq!(
            field.0.load(std::sync::atomic::Ordering::Relaxed),
            161 * 161 * 161
        );
        for &i in cells.iter().step_by(97) {
            assert_cell_reads_wavy(&lattice, &grid, i);
        }
    }

    #[test]
    fn a_store_past_the_budget_is_refused_before_it_is_filled() {
        let grid = CoarseGrid {
            origin: DVec3::ZERO,
            fine: 0.1,
            cells: [8, 8, 8],
        };
        let mut lattice = Lattice::new(&grid);
        let err = lattice
            .cover(
                &Wavy,
                &grid,
                &(0..grid.cell_count()).collect::<Vec<_>>(),
                1,
                10_000,
                &mut Progress::none(),
            )
            .unwrap_err();
        assert!(matches!(err, Error::OverBudget { .. }), "{err}");
        assert_eq!(lattice.values.len(), 0);
    }
}
