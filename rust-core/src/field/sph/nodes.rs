//! The field at every node of a lattice, tile by tile: what the full-grid baseline asks
//! for. (Surface tracking's node cache takes rows of four nodes instead,
//! [`SphField::values_on_row`]: its wavefronts touch about 15 nodes of a tile at a time,
//! too few to pay for a tile's set-up.)
//!
//! Evaluating node by node, each node scans its whole candidate block of particles and
//! keeps about one in four (the support sphere fills a quarter of the block). Here the
//! nodes are taken an 8×8×8 tile at a time and the loop is turned around: each particle
//! near the tile finds, row by row, the nodes its support covers, and the distance test
//! runs only for those. A tile's particles come in ascending slot order, the order the
//! node-by-node loop sums in, and each node's distance and weight are computed by the same
//! expressions, so every node's value is the same to the bit as
//! [`SphField::value_and_weight`] at its position.

use super::{Kernel, SphField};
use crate::field::neighbours::floor_i64;
use crate::field::TILE;
use crate::mc::VirtualGrid;
use glam::DVec3;
use rayon::prelude::*;

/// Nodes per tile.
const TILE3: usize = TILE * TILE * TILE;

/// Dense storage of a grid's first `nodes` nodes per axis, tile by tile: each tile's
/// `TILE`³ samples are contiguous, so tiles are filled in parallel without sorting or
/// scattering. Tiles at the far faces are padded.
#[derive(Clone, Copy, Debug)]
pub struct NodeTiles {
    nodes: [usize; 3],
    tiles: [usize; 3],
}

impl NodeTiles {
    pub fn new(nodes: [usize; 3]) -> Self {
        NodeTiles {
            nodes,
            tiles: nodes.map(|n| n.div_ceil(TILE)),
        }
    }

    /// Samples the layout holds, padding included.
    pub fn slots(&self) -> u128 {
        self.tiles.iter().map(|&t| t as u128).product::<u128>() * TILE3 as u128
    }

    /// Samples in one layer of tiles (`TILE` node slices).
    pub fn layer_len(&self) -> usize {
        self.tiles[0] * self.tiles[1] * TILE3
    }

    /// Layers of tiles.
    pub fn layers(&self) -> usize {
        self.tiles[2]
    }

    /// Where node `key` is stored.
    #[inline]
    pub fn index(&self, key: u64) -> usize {
        let [x, y, z] = VirtualGrid::coords(key).map(|c| c as usize);
        let tile = x / TILE + self.tiles[0] * (y / TILE + self.tiles[1] * (z / TILE));
        tile * TILE3 + x % TILE + TILE * (y % TILE + TILE * (z % TILE))
    }
}

impl SphField {
    /// (A, S) at every node of layer `layer` of `tiles` (see [`NodeTiles`]) into `out`,
    /// `tiles.layer_len()` samples; padding nodes get (0, 0).
    pub fn values_and_weights_on_tile_layer(
        &self,
        grid: &VirtualGrid,
        tiles: &NodeTiles,
        layer: usize,
        out: &mut [(f64, f64)],
    ) {
        assert_eq!(out.len(), tiles.layer_len(), "one layer of tiles");
        out.par_chunks_mut(TILE3).enumerate().for_each(|(t, sums)| {
            let corner = [t % tiles.tiles[0], t / tiles.tiles[0], layer].map(|c| c * TILE);
            let reach: [usize; 3] = std::array::from_fn(|a| (tiles.nodes[a] - corner[a]).min(TILE));
            let row = ((1u32 << reach[0]) - 1) as u8;
            let mut rows = [0u8; TILE * TILE];
            for z in 0..reach[2] {
                for y in 0..reach[1] {
                    rows[y + TILE * z] = row;
                }
            }
            sums.fill((0.0, 0.0));
            let sums: &mut [(f64, f64); TILE3] = sums.try_into().expect("a tile");
            self.fill_tile(grid, corner.map(|c| c as u32), &rows, sums);
        });
    }

    /// [`ScalarField::values_on_tile`](crate::field::ScalarField::values_on_tile).
    pub(crate) fn values_on_lattice_tile(
        &self,
        origin: DVec3,
        spacing: f64,
        first: [i64; 3],
        rows: &[u8; TILE * TILE],
        out: &mut [f64; TILE3],
    ) {
        let grid = VirtualGrid {
            origin,
            offset: first,
            cell_size: spacing,
            cells: [TILE as u32 - 1; 3],
        };
        let mut tile = [(0.0, 0.0); TILE3];
        self.fill_tile(&grid, [0; 3], rows, &mut tile);
        for (r, &marked) in rows.iter().enumerate() {
            let mut bits = marked;
            while bits != 0 {
                let l = TILE * r + bits.trailing_zeros() as usize;
                bits &= bits - 1;
                out[l] = tile[l].0;
            }
        }
    }

    /// Writes (A, S) for the nodes `rows` marks (one byte per (y, z) row of the tile whose
    /// first node is `corner`, bit x for node x) into `out`, by local index.
    fn fill_tile(
        &self,
        grid: &VirtualGrid,
        corner: [u32; 3],
        rows: &[u8; TILE * TILE],
        out: &mut [(f64, f64); TILE3],
    ) {
        if self.unit_values {
            with_kernel!(self.kernel, K => self.fill_tile_with::<true>(K, grid, corner, rows, out))
        } else {
            with_kernel!(self.kernel, K => self.fill_tile_with::<false>(K, grid, corner, rows, out))
        }
    }

    /// [`SphField::fill_tile`] with the kernel known at compile time.
    #[inline(always)]
    fn fill_tile_with<const UNIT: bool>(
        &self,
        kernel: Kernel,
        grid: &VirtualGrid,
        corner: [u32; 3],
        rows: &[u8; TILE * TILE],
        out: &mut [(f64, f64); TILE3],
    ) {
        // The wanted nodes' bounding box.
        let (mut lo, mut hi) = ([TILE; 3], [0usize; 3]);
        let mut columns = 0u8;
        for (r, &bits) in rows.iter().enumerate() {
            if bits != 0 {
                let (y, z) = (r % TILE, r / TILE);
                (lo[1], hi[1]) = (lo[1].min(y), hi[1].max(y));
                (lo[2], hi[2]) = (lo[2].min(z), hi[2].max(z));
                columns |= bits;
            }
        }
        if columns == 0 {
            return;
        }
        lo[0] = columns.trailing_zeros() as usize;
        hi[0] = 7 - columns.leading_zeros() as usize;
        // Node coordinates along each axis, computed as `node_position` computes them.
        let axis = |a: usize| -> [f64; TILE] {
            std::array::from_fn(|i| {
                let lattice = grid.offset[a] + (corner[a] as usize + i) as i64;
                grid.origin[a] + lattice as f64 * grid.cell_size
            })
        };
        let (xs, ys, zs) = (axis(0), axis(1), axis(2));
        let inv_c = 1.0 / grid.cell_size;
        let reach = DVec3::splat(self.max_support);
        let box_lo = DVec3::new(xs[lo[0]], ys[lo[1]], zs[lo[2]]) - reach;
        let box_hi = DVec3::new(xs[hi[0]], ys[hi[1]], zs[hi[2]]) + reach;

        let mut a_sum = [0.0f64; TILE3];
        let mut s_sum = [0.0f64; TILE3];
        // The local index range along one axis that a support of radius `r` (in cells)
        // around `t` (in cells from the tile's first node) can reach, a node wider on
        // each side than rounding could need; the exact test is made per node.
        let span = |t: f64, r: f64, a: usize| -> std::ops::Range<usize> {
            let first = (floor_i64(t - r) - 1).max(lo[a] as i64);
            let last = (floor_i64(t + r) + 2).min(hi[a] as i64);
            if last < first {
                0..0
            } else {
                first as usize..last as usize + 1
            }
        };
        for range in self.grid.ranges_in_box(box_lo, box_hi) {
            for p in &self.particles[range] {
                let r = p.support2.sqrt() * inv_c;
                let ys_reached = span((p.pos.y - ys[0]) * inv_c, r, 1);
                let tx = (p.pos.x - xs[0]) * inv_c;
                for z in span((p.pos.z - zs[0]) * inv_c, r, 2) {
                    let dz = zs[z] - p.pos.z;
                    let dz2 = dz * dz;
                    if dz2 >= p.support2 {
                        continue;
                    }
                    for y in ys_reached.clone() {
                        let wanted = rows[y + TILE * z];
                        if wanted == 0 {
                            continue;
                        }
                        let dy = ys[y] - p.pos.y;
                        // r² = (dx² + dy²) + dz² is at least dy² + dz² in floating point
                        // too, so a row this far is out for every node on it.
                        let dyz2 = dy * dy + dz2;
                        if dyz2 >= p.support2 {
                            continue;
                        }
                        let rx = (p.support2 - dyz2).sqrt() * inv_c;
                        let first = (floor_i64(tx - rx) - 1).max(0) as u32;
                        let last = (floor_i64(tx + rx) + 2).min(TILE as i64 - 1);
                        if last < first as i64 {
                            continue;
                        }
                        let span_bits = ((1u32 << (last as u32 + 1)) - (1u32 << first)) as u8;
                        let mut bits = wanted & span_bits;
                        let row = TILE * (y + TILE * z);
                        while bits != 0 {
                            let x = bits.trailing_zeros() as usize;
                            bits &= bits - 1;
                            let dx = xs[x] - p.pos.x;
                            let r2 = dx * dx + dy * dy + dz * dz;
                            if r2 < p.support2 {
                                let w = p.weight_scale * kernel.shape(r2.sqrt() * p.inv_h).0;
                                if !UNIT {
                                    a_sum[row + x] += w * p.value;
                                }
                                s_sum[row + x] += w;
                            }
                        }
                    }
                }
            }
        }
        for (r, &wanted) in rows.iter().enumerate() {
            let mut bits = wanted;
            while bits != 0 {
                let l = TILE * r + bits.trailing_zeros() as usize;
                bits &= bits - 1;
                let s = s_sum[l];
                let a = if UNIT { s } else { a_sum[l] };
                out[l] = (self.normalised(a, s), s);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::{Quantity, SmoothingLength, SphSettings};
    use super::*;
    use crate::field::particles::{Attribute, ParticleData};

    /// A jittered slab of particles with smoothing lengths varying by 2×, a pressure
    /// array, and a few loose particles far out.
    fn particles() -> ParticleData {
        let mut next = crate::test_rng::unit(5);
        let mut positions = Vec::new();
        for i in 0..14 {
            for j in 0..11 {
                for k in 0..6 {
                    let jitter = DVec3::new(next(), next(), next()) - DVec3::splat(0.5);
                    positions.push((DVec3::new(i as f64, j as f64, k as f64) + jitter * 0.6) * 0.1);
                }
            }
        }
        positions.extend([DVec3::new(2.0, 0.3, 0.2), DVec3::new(-0.7, 1.4, 0.9)]);
        let n = positions.len();
        let h = (0..n).map(|_| 0.07 + 0.07 * next()).collect();
        let p = (0..n).map(|_| 1000.0 + 500.0 * next()).collect();
        ParticleData {
            positions,
            attributes: vec![Attribute::scalar("h", h), Attribute::scalar("p", p)],
            ..Default::default()
        }
    }

    #[test]
    fn tile_layers_give_every_node_the_pointwise_value_to_the_bit() {
        let data = particles();
        let cases = [
            (Quantity::SumOfWeights, false),
            (Quantity::Scalar("p".into()), false),
            (Quantity::Scalar("p".into()), true),
        ];
        for (kernel, (quantity, shepard)) in Kernel::ALL
            .into_iter()
            .flat_map(|k| cases.iter().cloned().map(move |c| (k, c)))
        {
            let settings = SphSettings {
                kernel,
                smoothing_length: SmoothingLength::Array("h".into()),
                quantity,
                shepard,
                ..SphSettings::default()
            };
            let field = SphField::new(&data, &settings).unwrap();
            let (lo, hi) = field.bounds();
            // A cell size that leaves partly filled tiles on every axis.
            let grid = [0.041, 0.043, 0.047, 0.053, 0.059]
                .iter()
                .map(|&c| {
                    VirtualGrid::covering(lo - DVec3::splat(0.2), hi, c, "grid_factor").unwrap()
                })
                .find(|g| {
                    g.cells
                        .iter()
                        .all(|&c| !(c as usize + 1).is_multiple_of(TILE))
                })
                .expect("padded tiles on every axis");
            let nodes = grid.cells.map(|c| c as usize + 1);
            let tiles = NodeTiles::new(nodes);
            // Filled with a marker: every real node must be overwritten, padding zeroed.
            let mut samples = vec![(7.0, 7.0); tiles.slots() as usize];
            for (layer, chunk) in samples.chunks_mut(tiles.layer_len()).enumerate() {
                field.values_and_weights_on_tile_layer(&grid, &tiles, layer, chunk);
            }
            let mut real = vec![false; samples.len()];
            let mut reached = 0;
            for z in 0..nodes[2] as u32 {
                for y in 0..nodes[1] as u32 {
                    for x in 0..nodes[0] as u32 {
                        let key = VirtualGrid::key(x, y, z);
                        let i = tiles.index(key);
                        assert!(!real[i], "two nodes share slot {i}");
                        real[i] = true;
                        let want = field.value_and_weight(grid.node_position(key));
                        let got = samples[i];
                        assert!(
                            got.0.to_bits() == want.0.to_bits()
                                && got.1.to_bits() == want.1.to_bits(),
                            "{kernel:?}, shepard {shepard}, node {x} {y} {z}: {got:?} vs {want:?}"
                        );
                        reached += usize::from(want.1 > 0.0);
                    }
                }
            }
            for (i, s) in samples.iter().enumerate() {
                assert!(real[i] || *s == (0.0, 0.0), "padding slot {i} holds {s:?}");
            }
            assert!(reached > 5000, "most nodes see particles ({reached})");
            assert!(reached < nodes.iter().product(), "some nodes see none");
        }
    }

    /// A tile anywhere on a lattice (negative indices, nodes inside the fluid and off it,
    /// all, some or none marked) gives `ScalarField::value` at each marked node to the
    /// bit and leaves the others alone, for every kernel and quantity.
    #[test]
    fn tiles_give_each_marked_node_the_pointwise_value_to_the_bit() {
        use crate::field::ScalarField;
        let data = particles();
        let mut pick = crate::test_rng::unit(9);
        for (kernel, quantity, shepard) in Kernel::ALL.into_iter().flat_map(|k| {
            [
                (k, Quantity::SumOfWeights, false),
                (k, Quantity::Scalar("p".into()), true),
            ]
        }) {
            let settings = SphSettings {
                kernel,
                smoothing_length: SmoothingLength::Array("h".into()),
                quantity,
                shepard,
                ..SphSettings::default()
            };
            let field = SphField::new(&data, &settings).unwrap();
            let origin = DVec3::new(-0.31, 0.017, -0.05);
            let spacing = 0.037;
            let mut reached = 0;
            for (t, first) in [[-3i64, 2, 1], [4, 7, 0], [20, -1, 3], [11, 5, 6]]
                .into_iter()
                .enumerate()
            {
                // All nodes, then random rows of random nodes, then none.
                let rows: [u8; TILE * TILE] = std::array::from_fn(|_| match t {
                    0 => 0xff,
                    3 => 0,
                    _ => (pick() * 256.0) as u8 & (pick() * 256.0) as u8,
                });
                let mut got = [f64::NAN; TILE3];
                field.values_on_tile(origin, spacing, first, &rows, &mut got);
                for (v, got) in got.iter().enumerate() {
                    let l = [v % TILE, v / TILE % TILE, v / (TILE * TILE)];
                    if rows[l[1] + TILE * l[2]] >> l[0] & 1 == 0 {
                        assert!(got.is_nan(), "{kernel:?}: unmarked node {l:?} written");
                        continue;
                    }
                    let x = origin
                        + DVec3::new(
                            (first[0] + l[0] as i64) as f64,
                            (first[1] + l[1] as i64) as f64,
                            (first[2] + l[2] as i64) as f64,
                        ) * spacing;
                    let want = field.value(x);
                    assert_eq!(got.to_bits(), want.to_bits(), "{kernel:?} {first:?} {l:?}");
                    reached += usize::from(field.value_and_weight(x).1 > 0.0);
                }
            }
            assert!(
                reached > 200,
                "{kernel:?}: only {reached} nodes near particles"
            );
        }
    }
}
