//! Node cache: each virtual-grid node is evaluated once per extraction, whatever the
//! number of cells and isovalues that touch it. It holds only nodes of cells that were
//! visited, so its size follows the surface, not the grid.

use crate::field::sph::{SphField, ROW};
use crate::mc::bricks::{BrickMap, BrickShape};
use crate::mc::radix;
use crate::mc::VirtualGrid;
use rayon::prelude::*;

/// (field value, sum of weights) at a node.
pub type NodeSample = (f64, f64);

/// Anything that knows the field at grid nodes: the sparse cache here, or the dense
/// full grid of the baseline.
pub trait NodeValues: Sync {
    /// The sample at `node`; the node must have been evaluated.
    fn node(&self, node: u64) -> NodeSample;
}

/// The cache's bricks: 4³ nodes. A surface crossing a brick at a slant fills about a
/// fifth of an 8³ brick's nodes but a third of a 4³ one's: on the 1M-particle frame
/// (`isobar sph … --preview`, `NodeCache::bytes` after tracking) the 16.0 M cached nodes
/// took 1.39 GB in 8³ bricks and 0.80 GB in 4³ ones. A cell then finds its corners in one
/// brick 27 times in 64 instead of 343 in 512.
type Shape = BrickShape<2>;

/// Low bits of a node's brick order that number it within its row along x.
const ROW_BITS: u32 = 2;
const _: () = assert!(ROW == 1 << ROW_BITS, "a row is a brick's extent along x");

/// Sparse cache of evaluated nodes.
#[derive(Default)]
pub struct NodeCache {
    map: BrickMap<NodeSample, 2>,
    /// Node reads by cells.
    pub lookups: u64,
    /// Nodes evaluated (misses).
    pub evaluations: u64,
}

impl NodeCache {
    /// A cache for the nodes of `grid`, its bricks found by arithmetic when the index for
    /// the whole grid (4 bytes per 64 nodes) stays within `index_bytes`, else by hashing.
    pub fn for_grid(grid: &VirtualGrid, index_bytes: u64) -> Self {
        NodeCache {
            map: BrickMap::for_extent(grid.cells.map(|c| c + 1), index_bytes),
            ..NodeCache::default()
        }
    }

    /// Makes sure the eight corners of every cell in `cells` are evaluated, growing the
    /// cache (and the lists it builds on the way) by at most `room` bytes. Else nothing is
    /// evaluated and the error holds the bytes it would have taken: a wave of scattered
    /// cells (the seeds of a grid far finer than the particles) needs a brick per corner,
    /// and is refused before any is allocated.
    pub fn ensure_corners(
        &mut self,
        field: &SphField,
        grid: &VirtualGrid,
        cells: &[u64],
        room: u64,
    ) -> Result<(), u64> {
        // The corner list before it is made unique: 8 keys a cell.
        let listed = cells.len() as u64 * 8 * 8;
        if listed > room {
            return Err(listed);
        }
        let map = &self.map;
        // Each missing node's whole row of `ROW` nodes along x (a row's nodes differ in
        // the low bits of their brick order): the row shares one neighbour scan and has
        // no branch per node, so it costs little more than its one missing node, and
        // three in four of a row's nodes are read sooner or later (demo frame). In brick
        // order: neighbouring rows are evaluated together (their particles are in cache)
        // and each brick is then filled by one thread.
        let mut rows: Vec<u64> = cells
            .par_iter()
            .flat_map_iter(|&c| {
                let present = map.present_corners(c);
                (0..8)
                    .filter(move |k| present >> k & 1 == 0)
                    .map(move |k| Shape::order(VirtualGrid::corner(c, k)) >> ROW_BITS)
            })
            .collect();
        radix::sort_unique(&mut rows);
        // The new bricks, the row list as allocated, and the insertion's two lists of the
        // bricks it fills (72 bytes a brick; at most a brick a row).
        let bricks = map.absent_bricks_in_order(rows.iter().map(|r| r << ROW_BITS)) as u64;
        let needed = bricks * map.bytes_per_new_brick()
            + rows.capacity() as u64 * 8
            + rows.len() as u64 * 72;
        if needed > room {
            return Err(needed);
        }
        let last = grid.cells;
        let rows = &rows;
        self.lookups += 8 * cells.len() as u64;
        self.evaluations += self.map.insert_runs_in_brick_order(rows, |i| {
            let keys: [u64; ROW] =
                std::array::from_fn(|l| Shape::key_of_order(rows[i] << ROW_BITS | l as u64));
            let at = keys.map(|k| grid.node_position(k));
            let samples = field.values_on_row(at.map(|p| p.x), at[0].y, at[0].z);
            // Nodes past the grid's last along x are left out.
            let inside = (0..ROW)
                .filter(|&l| VirtualGrid::coords(keys[l])[0] <= last[0])
                .fold(0u32, |mask, l| mask | 1 << l);
            (samples, inside)
        }) as u64;
        Ok(())
    }

    /// The eight corner samples of `cell`.
    pub fn corners(&self, cell: u64) -> [NodeSample; 8] {
        self.map.corners(cell)
    }

    /// Bytes the cache holds.
    pub fn bytes(&self) -> u64 {
        self.map.bytes()
    }

    /// Number of cached nodes.
    pub fn len(&self) -> usize {
        self.map.len()
    }

    /// True when nothing is cached.
    pub fn is_empty(&self) -> bool {
        self.map.is_empty()
    }

    /// Fraction of node reads served without evaluating.
    pub fn hit_ratio(&self) -> f64 {
        if self.lookups == 0 {
            0.0
        } else {
            // Nodes evaluated ahead of a lookup (a wave's corners) can outnumber the
            // lookups of a walk that finds nothing: no hits then, not a negative share.
            (1.0 - self.evaluations as f64 / self.lookups as f64).max(0.0)
        }
    }
}

impl NodeValues for NodeCache {
    fn node(&self, node: u64) -> NodeSample {
        self.map
            .get(node)
            .expect("node evaluated before it is read")
    }
}
