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
/// took 1.39 GB in 8³ bricks and 0.80 GB in 4³ ones (16 bytes a node, before a field
/// that is its own weight kept one number). A cell then finds its corners in one
/// brick 27 times in 64 instead of 343 in 512.
type Shape = BrickShape<2>;

/// Low bits of a node's brick order that number it within its row along x.
const ROW_BITS: u32 = 2;
const _: () = assert!(ROW == 1 << ROW_BITS, "a row is a brick's extent along x");

/// What a cache brick stores per node: the sample, or its value alone where the value is
/// the sum of weights ([`SphField::value_is_weight`]: the free surface's field), so that
/// the pair would hold the same number twice.
trait Stored: Copy + Default + Send + Sync {
    fn store(sample: NodeSample) -> Self;
    fn sample(self) -> NodeSample;
}

impl Stored for NodeSample {
    fn store(sample: NodeSample) -> Self {
        sample
    }
    fn sample(self) -> NodeSample {
        self
    }
}

impl Stored for f64 {
    fn store((value, weight): NodeSample) -> Self {
        debug_assert_eq!(value.to_bits(), weight.to_bits(), "the value is the weight");
        value
    }
    fn sample(self) -> NodeSample {
        (self, self)
    }
}

/// The cache's map, by what it stores: half the bytes for the free surface's field.
enum Map {
    Values(BrickMap<f64, 2>),
    Samples(BrickMap<NodeSample, 2>),
}

impl Default for Map {
    fn default() -> Self {
        Map::Samples(BrickMap::default())
    }
}

/// Runs `$body` with `$m` bound to the map, whichever it is.
macro_rules! with_map {
    ($map:expr, $m:ident => $body:expr) => {
        match $map {
            Map::Values($m) => $body,
            Map::Samples($m) => $body,
        }
    };
}

/// Sparse cache of evaluated nodes.
#[derive(Default)]
pub struct NodeCache {
    map: Map,
    /// Node reads by cells.
    pub lookups: u64,
    /// Nodes evaluated (misses).
    pub evaluations: u64,
}

impl NodeCache {
    /// A cache for the nodes of `grid` sampled from `field`, its bricks found by
    /// arithmetic when the index for the whole grid (4 bytes per 64 nodes) stays within
    /// `index_bytes`, else by hashing.
    pub fn for_grid(field: &SphField, grid: &VirtualGrid, index_bytes: u64) -> Self {
        let extent = grid.cells.map(|c| c + 1);
        let map = if field.value_is_weight() {
            Map::Values(BrickMap::for_extent(extent, index_bytes))
        } else {
            Map::Samples(BrickMap::for_extent(extent, index_bytes))
        };
        NodeCache {
            map,
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
        let evaluations = with_map!(&mut self.map, m => fill_corners(m, field, grid, cells, room))?;
        self.lookups += 8 * cells.len() as u64;
        self.evaluations += evaluations;
        Ok(())
    }

    /// The eight corner samples of `cell`.
    pub fn corners(&self, cell: u64) -> [NodeSample; 8] {
        with_map!(&self.map, m => m.corners(cell).map(Stored::sample))
    }

    /// Bytes the cache holds.
    pub fn bytes(&self) -> u64 {
        with_map!(&self.map, m => m.bytes())
    }

    /// Number of cached nodes.
    pub fn len(&self) -> usize {
        with_map!(&self.map, m => m.len())
    }

    /// True when nothing is cached.
    pub fn is_empty(&self) -> bool {
        with_map!(&self.map, m => m.is_empty())
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

/// [`NodeCache::ensure_corners`] on its map, once the corner list fits `room`: returns the
/// nodes evaluated, or the bytes it would take past `room`.
fn fill_corners<T: Stored>(
    map: &mut BrickMap<T, 2>,
    field: &SphField,
    grid: &VirtualGrid,
    cells: &[u64],
    room: u64,
) -> Result<u64, u64> {
    let shared = &*map;
    // Each missing node's whole row of `ROW` nodes along x (a row's nodes differ in the
    // low bits of their brick order): the row shares one neighbour scan and has no branch
    // per node, so it costs little more than its one missing node, and three in four of a
    // row's nodes are read sooner or later (demo frame). In brick order: neighbouring rows
    // are evaluated together (their particles are in cache) and each brick is then filled
    // by one thread.
    let mut rows: Vec<u64> = cells
        .par_iter()
        .flat_map_iter(|&c| {
            let present = shared.present_corners(c);
            (0..8)
                .filter(move |k| present >> k & 1 == 0)
                .map(move |k| Shape::order(VirtualGrid::corner(c, k)) >> ROW_BITS)
        })
        .collect();
    radix::sort_unique(&mut rows);
    // The new bricks, the row list as allocated, and the insertion's two lists of the
    // bricks it fills (72 bytes a brick; at most a brick a row).
    let bricks = map.absent_bricks_in_order(rows.iter().map(|r| r << ROW_BITS)) as u64;
    let needed =
        bricks * map.bytes_per_new_brick() + rows.capacity() as u64 * 8 + rows.len() as u64 * 72;
    if needed > room {
        return Err(needed);
    }
    let last = grid.cells;
    let rows = &rows;
    let evaluated = map.insert_runs_in_brick_order(rows, |i| {
        let keys: [u64; ROW] =
            std::array::from_fn(|l| Shape::key_of_order(rows[i] << ROW_BITS | l as u64));
        let at = keys.map(|k| grid.node_position(k));
        let samples = field.values_on_row(at.map(|p| p.x), at[0].y, at[0].z);
        // Nodes past the grid's last along x are left out.
        let inside = (0..ROW)
            .filter(|&l| VirtualGrid::coords(keys[l])[0] <= last[0])
            .fold(0u32, |mask, l| mask | 1 << l);
        (samples.map(T::store), inside)
    });
    Ok(evaluated as u64)
}

impl NodeValues for NodeCache {
    fn node(&self, node: u64) -> NodeSample {
        with_map!(&self.map, m => m.get(node).map(Stored::sample))
            .expect("node evaluated before it is read")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::particles::ParticleData;
    use crate::field::sph::{Quantity, SmoothingLength, SphSettings};
    use glam::DVec3;

    /// The free surface's field (the sum of weights) is cached one number a node: the
    /// same corners, to the bit, as a cache of both numbers and as the field at each node,
    /// in fewer bytes.
    #[test]
    fn a_field_that_is_its_weight_caches_one_number_a_node() {
        let mut next = crate::test_rng::unit(3);
        let positions = (0..6 * 6 * 6)
            .map(|i| {
                let c = DVec3::new((i % 6) as f64, (i / 6 % 6) as f64, (i / 36) as f64);
                (c + DVec3::new(next(), next(), next()) * 0.3) * 0.1
            })
            .collect();
        let data = ParticleData {
            positions,
            ..Default::default()
        };
        let settings = SphSettings {
            smoothing_length: SmoothingLength::Constant(0.1),
            quantity: Quantity::SumOfWeights,
            ..SphSettings::default()
        };
        let field = SphField::new(&data, &settings).unwrap();
        assert!(field.value_is_weight());
        let (lo, hi) = field.bounds();
        let pad = DVec3::splat(field.max_support());
        let grid = VirtualGrid::covering(lo - pad, hi + pad, 0.04, "grid_factor").unwrap();
        let cells: Vec<u64> = (0..8 * 8 * 8)
            .map(|i| VirtualGrid::key(4 + i % 8, 4 + i / 8 % 8, 4 + i / 64))
            .collect();
        let mut one = NodeCache::for_grid(&field, &grid, 1 << 20);
        assert!(matches!(one.map, Map::Values(_)));
        let extent = grid.cells.map(|c| c + 1);
        let mut both = NodeCache {
            map: Map::Samples(BrickMap::for_extent(extent, 1 << 20)),
            ..NodeCache::default()
        };
        for cache in [&mut one, &mut both] {
            cache
                .ensure_corners(&field, &grid, &cells, u64::MAX)
                .unwrap();
        }
        assert_eq!(one.len(), both.len());
        // The corners' 9³ nodes, their rows of four along x whole: 12 × 9 × 9.
        assert_eq!(one.len(), 12 * 9 * 9);
        let bits = |s: NodeSample| (s.0.to_bits(), s.1.to_bits());
        for &cell in &cells {
            let (a, b) = (one.corners(cell), both.corners(cell));
            for (k, (&a, &b)) in a.iter().zip(&b).enumerate() {
                let node = VirtualGrid::corner(cell, k);
                let at = field.value_and_weight(grid.node_position(node));
                assert_eq!(bits(a), bits(b), "corner {k} of {cell}");
                assert_eq!(bits(a), bits(at), "corner {k} of {cell}");
                assert_eq!(bits(one.node(node)), bits(at));
            }
        }
        assert!(
            one.bytes() * 5 < both.bytes() * 3,
            "{} vs {} bytes",
            one.bytes(),
            both.bytes()
        );
    }
}
