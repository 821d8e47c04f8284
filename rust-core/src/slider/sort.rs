//! The nodes in value order, ties by index: sorted whole in memory when the build's
//! memory budget holds it, else as an external-memory sort (sorted runs spooled to disk,
//! then merged). Both give the same order, handed on a batch at a time, so everything
//! derived from it (the level-0 masks, the skip-list levels) is built by one pass either
//! way and the store is the same byte for byte.

use super::store::write_le;
use crate::error::{Error, Result};
use crate::field::grid::Values;
use crate::io::Spool;
use crate::progress::Progress;
use rayon::prelude::*;
use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::path::Path;

/// Nodes handed on at a time.
pub(crate) const BATCH: usize = 1 << 16;

/// Fewest nodes a merge reads from a run at a time: below this the merge is all reads.
const MIN_BUFFER_NODES: u64 = 1 << 10;

/// Most runs merged at once: each holds a file open, and a process may usually open 1,024.
const MAX_RUNS: u64 = 512;

/// How the nodes are sorted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Plan {
    /// One sort of all node indices.
    InMemory,
    /// Runs of `run_nodes` sorted in memory and spooled, merged reading `buffer_nodes`
    /// of each run at a time.
    External { run_nodes: u64, buffer_nodes: u64 },
}

impl Plan {
    /// An external-memory sort within `budget` bytes for `n` nodes: half the budget for
    /// the run being sorted, then a quarter for the merge's read buffers (the rest, while
    /// merging, is for the skip-list levels' open blocks). `None` when the buffers would be
    /// too small or the runs too many.
    pub(crate) fn external(n: u64, budget: u64) -> Option<Plan> {
        let run_nodes = (budget / 8).min(n.max(1));
        if run_nodes == 0 {
            return None;
        }
        let runs = n.div_ceil(run_nodes).max(1);
        let buffer_nodes = (budget / 16 / runs).min(run_nodes);
        (buffer_nodes >= MIN_BUFFER_NODES.min(n.max(1)) && runs <= MAX_RUNS).then_some(
            Plan::External {
                run_nodes,
                buffer_nodes,
            },
        )
    }

    /// The smallest budget [`Plan::external`] accepts for `n` nodes (for the error that
    /// refuses a smaller one).
    pub(crate) fn least_external_budget(n: u64) -> u64 {
        let (mut lo, mut hi) = (1u64, 16 * n.max(1) + (1 << 20));
        while lo < hi {
            let mid = lo + (hi - lo) / 2;
            if Plan::external(n, mid).is_some() {
                hi = mid;
            } else {
                lo = mid + 1;
            }
        }
        lo
    }
}

/// The sorted node indices, kept for the store's ORDER section.
pub(crate) enum Order {
    Memory(Vec<u32>),
    /// Merged from this many sorted runs on disk.
    Spooled {
        order: Spool,
        runs: usize,
    },
}

impl Order {
    /// Little-endian bytes of the indices, a bounded slice at a time.
    pub(crate) fn write_le(
        &self,
        out: &mut dyn FnMut(&[u8]) -> std::io::Result<()>,
    ) -> std::io::Result<()> {
        match self {
            Order::Memory(v) => write_le(v, u32::to_le_bytes, out),
            Order::Spooled { order, .. } => order.read_into(out),
        }
    }

    /// Sorted runs spooled to disk (0: sorted in memory).
    pub(crate) fn runs(&self) -> usize {
        match self {
            Order::Memory(_) => 0,
            Order::Spooled { runs, .. } => *runs,
        }
    }
}

/// Sort key of node `i`: its value's bits mapped so that unsigned order is `f32::total_cmp`
/// order, then the index.
#[inline]
fn key(values: &Values, i: u32) -> u64 {
    let bits = values.get(i as usize).to_bits();
    let ordered = if bits >> 31 == 1 {
        !bits
    } else {
        bits | 1 << 31
    };
    (ordered as u64) << 32 | i as u64
}

/// Sorts the `values.len()` nodes as `plan` says and hands them to `each` in order,
/// [`BATCH`] at a time; returns the order. Spools go into `dir`; errors name `path`.
pub(crate) fn sorted_nodes(
    values: &Values,
    plan: Plan,
    dir: &Path,
    path: &Path,
    progress: &mut Progress,
    mut each: impl FnMut(&[u32]) -> Result<()>,
) -> Result<Order> {
    let n = values.len() as u64;
    let io = |e| Error::io(path, e);
    match plan {
        Plan::InMemory => {
            progress.phase("sorting node values", 0.0, 0.3)?;
            let mut order: Vec<u32> = (0..n as u32).collect();
            order.par_sort_unstable_by_key(|&i| key(values, i));
            progress.phase("edge lists and skip-list levels", 0.3, 0.8)?;
            for (k, batch) in order.chunks(BATCH).enumerate() {
                each(batch)?;
                progress.report((k * BATCH) as f64 / n as f64)?;
            }
            Ok(Order::Memory(order))
        }
        Plan::External {
            run_nodes,
            buffer_nodes,
        } => {
            progress.phase("sorting node values in runs on disk", 0.0, 0.3)?;
            let mut runs = Vec::new();
            let mut ids: Vec<u32> = Vec::with_capacity(run_nodes as usize);
            for first in (0..n).step_by(run_nodes as usize) {
                ids.clear();
                ids.extend(first as u32..(first + run_nodes).min(n) as u32);
                ids.par_sort_unstable_by_key(|&i| key(values, i));
                let mut run = Spool::file(dir).map_err(io)?;
                write_le(&ids, u32::to_le_bytes, &mut |b| run.write(b)).map_err(io)?;
                run.finish().map_err(io)?;
                runs.push(run);
                progress.report(first as f64 / n as f64)?;
            }
            drop(ids);
            progress.phase("merging runs; edge lists and skip-list levels", 0.3, 0.8)?;
            let mut readers: Vec<RunReader> = runs
                .iter()
                .map(|run| RunReader::new(run, buffer_nodes as usize))
                .collect();
            let mut heap = BinaryHeap::with_capacity(readers.len());
            for (r, reader) in readers.iter_mut().enumerate() {
                if let Some(i) = reader.next().map_err(io)? {
                    heap.push(Reverse((key(values, i), r)));
                }
            }
            let mut order = Spool::file(dir).map_err(io)?;
            let mut batch = Vec::with_capacity(BATCH);
            let mut done = 0u64;
            while let Some(Reverse((k, r))) = heap.pop() {
                batch.push(k as u32);
                if let Some(i) = readers[r].next().map_err(io)? {
                    heap.push(Reverse((key(values, i), r)));
                }
                if batch.len() == BATCH || heap.is_empty() {
                    write_le(&batch, u32::to_le_bytes, &mut |b| order.write(b)).map_err(io)?;
                    each(&batch)?;
                    done += batch.len() as u64;
                    progress.report(done as f64 / n as f64)?;
                    batch.clear();
                }
            }
            order.finish().map_err(io)?;
            Ok(Order::Spooled {
                order,
                runs: readers.len(),
            })
        }
    }
}

/// Reads one spooled run of node indices, `buffer` bytes at a time.
struct RunReader<'a> {
    run: &'a Spool,
    at: u64,
    buffer: Vec<u8>,
    filled: usize,
    next: usize,
}

impl<'a> RunReader<'a> {
    fn new(run: &'a Spool, buffer_nodes: usize) -> Self {
        RunReader {
            run,
            at: 0,
            buffer: vec![0; buffer_nodes * 4],
            filled: 0,
            next: 0,
        }
    }

    fn next(&mut self) -> std::io::Result<Option<u32>> {
        if self.next == self.filled {
            self.filled = self.run.read_at(self.at, &mut self.buffer)?;
            self.at += self.filled as u64;
            self.next = 0;
            if self.filled == 0 {
                return Ok(None);
            }
        }
        let b = &self.buffer[self.next..self.next + 4];
        self.next += 4;
        Ok(Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]])))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn external_order_is_the_in_memory_order() {
        // Values with many ties, negative zero, both signs and subnormals: ties go by index.
        let n = 5_000u32;
        let v: Vec<f32> = (0..n)
            .map(|i| match i % 7 {
                0 => -0.0,
                1 => 0.0,
                2 => f32::MIN_POSITIVE / 4.0,
                3 => -((i * 37 % 101) as f32),
                _ => ((i * 7919) % 613) as f32 * 0.25,
            })
            .collect();
        let values = Values::F32(v.clone());
        let mut expected: Vec<u32> = (0..n).collect();
        expected.sort_by(|&a, &b| v[a as usize].total_cmp(&v[b as usize]).then(a.cmp(&b)));
        let dir = std::env::temp_dir();
        for plan in [
            Plan::InMemory,
            Plan::External {
                run_nodes: 700,
                buffer_nodes: 64,
            },
        ] {
            let mut seen = Vec::new();
            let order = sorted_nodes(&values, plan, &dir, &dir, &mut Progress::none(), |b| {
                assert!(b.len() <= BATCH);
                seen.extend_from_slice(b);
                Ok(())
            })
            .unwrap();
            assert_eq!(seen, expected, "{plan:?}");
            let mut bytes = Vec::new();
            order
                .write_le(&mut |b| {
                    bytes.extend_from_slice(b);
                    Ok(())
                })
                .unwrap();
            let back: Vec<u32> = (bytes.chunks(4))
                .map(|b| u32::from_le_bytes(b.try_into().unwrap()))
                .collect();
            assert_eq!(back, expected, "{plan:?}");
        }
    }

    #[test]
    fn external_plans_fit_their_budget() {
        for n in [1u64, 1000, 1 << 20, 1 << 30, 1_400_000_000] {
            let least = Plan::least_external_budget(n);
            assert!(Plan::external(n, least).is_some());
            assert!(least == 1 || Plan::external(n, least - 1).is_none());
            let Some(Plan::External {
                run_nodes,
                buffer_nodes,
            }) = Plan::external(n, least)
            else {
                unreachable!()
            };
            // A run's ids within half the budget, the merge's buffers within a quarter,
            // and few enough runs to hold open.
            assert!(run_nodes * 4 <= least / 2 + 4, "n {n}");
            assert!(n.div_ceil(run_nodes) <= MAX_RUNS, "n {n}");
            assert!(
                buffer_nodes * 4 * n.div_ceil(run_nodes) <= least / 4 + 4,
                "n {n}"
            );
        }
    }
}
