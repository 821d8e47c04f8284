//! The CPU's side of the isovalue at finest nodes whose f32 value is too close to call.
//!
//! The kernels evaluate the field in f32, the CPU in f64 (`gpu/mod.rs`). A node whose
//! value lies within rounding of the isovalue can fall on the other side on the GPU, and
//! one such node changes the cases of the sub-cells around it, the cut edges, and the
//! finest edge a coarse edge's bisection ends on: the surfaces differ in topology, not
//! just in the last digits. Every sign test at a finest node goes through `settled` in
//! level.wgsl: a value farther than [`Sides::margin`] from the isovalue decides by
//! itself (the f32 error is far below the margin, so the CPU agrees); a closer one is
//! looked up in a sorted table of nodes whose value the host computed in f64, and takes
//! a value on the CPU's side. A node not in the table yet is appended to a pending list
//! and keeps its f32 value; [`Sides::settle`] evaluates the pending nodes on the CPU and
//! runs the pass again until it meets none. The table lives for the whole extraction, so
//! every level, every bisection and crack filling (which reads the levels' settled
//! values) see one side per node.
//!
//! Points between finest nodes (the last bisection halvings) keep their f32 side: they
//! move a vertex within one bisection unit, never onto another finest edge. Where the
//! last interval's end values are too close to each other for their f32 rounding, the
//! host interpolates between its own ([`Sides::last_interval`]).

use super::device::{gpu_error, Gpu};
use crate::adaptive::grid::CoarseGrid;
use crate::adaptive::levels::along;
use crate::error::Result;
use crate::field::sph::SphField;
use crate::field::ScalarField;
use crate::mc::VirtualGrid;
use rayon::prelude::*;

/// Margin around the isovalue, relative to the field's scale (see [`Sides::new`]): the
/// f32 sum's error is ~1e-6 of it on ordinary domains and stays below 1e-4 with particle
/// coordinates 2000 smoothing lengths from the grid origin. Two cases fall outside that
/// bound: an isovalue below 1/256 of one particle's value puts every empty node in the
/// margin (correct, but each is evaluated on the host), and a Shepard-normalised field
/// where the sum of weights tends to zero at the fringe of the fluid, whose f32 quotient
/// can be far off.
const RELATIVE_MARGIN: f64 = 1.0 / 256.0;

/// Rounds of [`Sides::settle`] before giving up: each settles every node the pending
/// list held (growing the list when more were met than it held), and a rerun meets only
/// those left over and nodes a settled value newly sent it to (bisection), so two or
/// three suffice.
const MAX_ROUNDS: usize = 16;

/// Nodes a pending list holds before the first round grows it.
const FIRST_CAPACITY: usize = 256;

/// The settled nodes of one extraction, on the host and on the device.
pub struct Sides<'a> {
    field: &'a SphField,
    grid: &'a CoarseGrid,
    /// The CPU's isovalue, which decides a settled node's side.
    pub iso: f64,
    /// The isovalue the kernels compare with.
    pub iso32: f32,
    /// Values within this of `iso32` are looked up.
    pub margin: f32,
    /// Settled nodes: (node key, f32 value on the CPU's side), sorted by key.
    known: Vec<(u64, f32)>,
    /// `known` as level.wgsl's `sides` reads it, with a sentinel after the last entry.
    table: wgpu::Buffer,
}

impl<'a> Sides<'a> {
    /// No node settled yet. The margin is [`RELATIVE_MARGIN`] of the isovalue or of the
    /// largest value one particle adds at its centre, whichever is larger (the second
    /// bounds the summands, whose rounding the f32 error comes from).
    pub fn new(gpu: &Gpu, field: &'a SphField, grid: &'a CoarseGrid, iso: f64) -> Sides<'a> {
        let f0 = field.kernel().shape(0.0).0;
        let largest = (0..field.len())
            .into_par_iter()
            .map(|slot| {
                let (_, _, _, weight_scale, value) = field.packed(slot);
                if field.shepard() {
                    value.abs()
                } else {
                    (weight_scale * value * f0).abs()
                }
            })
            .reduce(|| 0.0, f64::max);
        Sides {
            field,
            grid,
            iso,
            iso32: iso as f32,
            margin: (RELATIVE_MARGIN * iso.abs().max(largest)) as f32,
            known: Vec::new(),
            table: table(gpu, &[]),
        }
    }

    /// The table, bound at 23.
    pub fn table(&self) -> &wgpu::Buffer {
        &self.table
    }

    /// How many nodes have been settled: one host evaluation each.
    pub fn settled(&self) -> usize {
        self.known.len()
    }

    /// Runs `pass` (given the pending list to bind at 24, and whether it is the first
    /// round) until a round leaves no node pending, settling the pending nodes between
    /// rounds. A round must recompute everything that read a pending node's f32 value.
    pub fn settle(
        &mut self,
        gpu: &Gpu,
        mut pass: impl FnMut(&Self, &wgpu::Buffer, bool) -> Result<()>,
    ) -> Result<()> {
        let mut capacity = FIRST_CAPACITY;
        for round in 0..MAX_ROUNDS {
            // Word 0 counts; then two words a node.
            let pending = gpu.zeroed::<u32>("pending nodes", 1 + 2 * capacity)?;
            pass(self, &pending, round == 0)?;
            let count = gpu.read::<u32>(&pending, 1)?[0] as usize;
            if count == 0 {
                return Ok(());
            }
            let keys = gpu.read_at::<u32>(&pending, 1, 2 * count.min(capacity))?;
            self.add(
                gpu,
                keys.chunks_exact(2)
                    .map(|w| w[0] as u64 | (w[1] as u64) << 32),
            );
            capacity = capacity.max(count.next_power_of_two());
        }
        Err(gpu_error(format!(
            "node sides did not settle in {MAX_ROUNDS} rounds"
        )))
    }

    /// Evaluates the nodes `keys` names on the CPU and adds them to the table.
    fn add(&mut self, gpu: &Gpu, keys: impl Iterator<Item = u64>) {
        let mut new: Vec<u64> = keys
            .filter(|k| self.known.binary_search_by_key(k, |e| e.0).is_err())
            .collect();
        new.sort_unstable();
        new.dedup();
        let settled: Vec<(u64, f32)> = new
            .par_iter()
            .map(|&key| (key, self.settled_value(key)))
            .collect();
        self.known.extend(settled);
        self.known.sort_unstable_by_key(|e| e.0);
        self.table = table(gpu, &self.known);
    }

    /// The last bisection interval of edge `key` (its first unit `lo`, in 2^-`shift`
    /// finest cells) and the end values to interpolate on it, from the kernel's interval
    /// and f32 `ends`. Where those differ by less than the margin, the surface runs nearly
    /// along the edge and their rounding would move the point by a sizeable part of the
    /// interval: the CPU evaluates the ends in f64, and where they then lie on one side
    /// (a halving between finest nodes took the other side in f32), moves one unit toward
    /// the crossing, staying on the same finest edge. `start_inside`: the edge start's
    /// side. Also returns the CPU's field evaluations.
    pub fn last_interval(
        &self,
        key: u64,
        shift: u32,
        lo: i64,
        ends: (f64, f64),
        start_inside: bool,
    ) -> (i64, (f64, f64), u64) {
        if (ends.1 - ends.0).abs() >= self.margin as f64 {
            return (lo, ends, 0);
        }
        let value = |t| self.field.value(along(self.grid, key, shift, t));
        let on_node = |t: i64| t & ((1 << shift) - 1) == 0;
        let (a, b) = (value(lo), value(lo + 1));
        let (a_inside, b_inside) = (a > self.iso, b > self.iso);
        if a_inside != b_inside {
            (lo, (a, b), 2)
        } else if a_inside == start_inside && !on_node(lo + 1) {
            (lo + 1, (b, value(lo + 2)), 3)
        } else if a_inside != start_inside && !on_node(lo) {
            (lo - 1, (value(lo - 1), a), 3)
        } else {
            (lo, (a, b), 2)
        }
    }

    /// The CPU's value at node `key` as the f32 the kernels compare: rounded, and moved
    /// to the isovalue's other side where rounding crossed it.
    fn settled_value(&self, key: u64) -> f32 {
        let node = VirtualGrid::coords(key).map(|c| c as i64);
        let value = self.field.value(self.grid.point(node, 0));
        let inside = value > self.iso;
        let rounded = value as f32;
        if (rounded > self.iso32) == inside {
            rounded
        } else if inside {
            self.iso32.next_up()
        } else {
            self.iso32
        }
    }
}

/// `known` as level.wgsl's `sides` reads it: key words, value bits, then the sentinel.
fn table(gpu: &Gpu, known: &[(u64, f32)]) -> wgpu::Buffer {
    let words: Vec<[u32; 4]> = known
        .iter()
        .map(|&(key, value)| [key as u32, (key >> 32) as u32, value.to_bits(), 0])
        .chain(std::iter::once([u32::MAX; 4]))
        .collect();
    gpu.upload("settled nodes", &words)
}
