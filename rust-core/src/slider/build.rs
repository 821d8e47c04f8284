//! Precomputation: sort the nodes by value, derive each node's block B_r (the edges that
//! turn on and off as the isovalue passes it), consolidate blocks into skip-list levels
//! with redundant edges removed, and write everything into one store file.

use super::sort::{self, Order, Plan};
use super::store::{
    header_length, neighbour, rises, write_le, write_varints, Kind, CHUNK, DIRECTORY_ENTRY,
    FIXED_HEADER, MAGIC, VERSION,
};
use super::value_bricks::ValueBricks;
use crate::error::{Error, Result};
use crate::field::grid::{Lattice, Values, Volume};
use crate::io::Spool;
use crate::progress::Progress;
use rayon::prelude::*;
use rustc_hash::FxHashSet;
use std::io::{Seek, SeekFrom, Write};
use std::path::Path;

/// Parameters of the precomputation.
#[derive(Clone, Debug)]
pub struct BuildParams {
    /// A skip-list block closes once the edges it turned on and off again (redundant
    /// edges) exceed this fraction of the edges active at its end (the paper's threshold).
    pub threshold: f64,
    /// Most levels above level 0.
    pub max_levels: usize,
    /// Bytes the precomputation may hold in memory (the volume excluded). Beyond what an
    /// in-memory build needs (29 bytes a node), the node order is sorted on disk and the
    /// skip-list levels are spooled there, beside the output; a budget too small even
    /// for that is refused before any work.
    pub memory_budget: u64,
}

impl Default for BuildParams {
    fn default() -> Self {
        BuildParams {
            threshold: 0.25,
            max_levels: 12,
            memory_budget: crate::field::DEFAULT_MEMORY_BUDGET,
        }
    }
}

/// Refuses a store path that names the volume it is built from: the store's rename would
/// replace the user's data.
pub fn check_store_path(volume: &Path, store: &Path) -> Result<()> {
    let same = match (std::fs::canonicalize(volume), std::fs::canonicalize(store)) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    };
    if same {
        return Err(Error::InvalidInput(format!(
            "{}: the store would replace the volume it is built from; name another store path",
            store.display()
        )));
    }
    Ok(())
}

/// Most skip-list levels a build may ask for: each level at least halves the blocks of
/// the one below, so 64 cover any node count; each asked-for level holds its own buffers,
/// which is why an absurd count is refused rather than clamped silently.
pub(crate) const MAX_LEVELS: usize = 64;

/// What a build produced.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BuildStats {
    pub nodes: u64,
    /// Blocks per level, level 1 first.
    pub level_blocks: Vec<u64>,
    /// Edge entries (E+ and E−) per level, level 1 first.
    pub level_edges: Vec<u64>,
    pub file_bytes: u64,
    /// Runs the node values were sorted in on disk (0: sorted in memory, the budget held
    /// the whole build).
    pub sorted_runs: u64,
    pub seconds: f64,
}

/// One skip-list level as it is built: block starts and list offsets in memory, the edge
/// lists (LEB128 gaps per block, ascending) in spools, on disk for an external-memory build.
struct Level {
    starts: Vec<u32>,
    plus_offsets: Vec<u64>,
    minus_offsets: Vec<u64>,
    plus: Spool,
    minus: Spool,
    /// Edge entries, E+ and E− together.
    entries: u64,
}

impl Level {
    fn blocks(&self) -> usize {
        self.starts.len().saturating_sub(1)
    }

    fn held_bytes(&self) -> u64 {
        (self.starts.capacity() * 4
            + (self.plus_offsets.capacity() + self.minus_offsets.capacity()) * 8) as u64
            + self.plus.held_bytes()
            + self.minus.held_bytes()
    }
}

/// The six lattice neighbours of node `j`: (direction 2a+s, edge id) for those inside.
/// Level-0 blocks are this list split by the activation mask.
#[inline]
pub(crate) fn node_edges(lattice: &Lattice, j: usize) -> impl Iterator<Item = (usize, u32)> + '_ {
    let c = lattice.coords(j);
    (0..6).filter_map(move |d| {
        let (a, up) = (d / 2, d % 2 == 1);
        if up {
            (c[a] + 1 < lattice.dims[a]).then(|| (d, (j * 3 + a) as u32))
        } else {
            (c[a] > 0).then(|| (d, ((j - lattice.stride(a)) * 3 + a) as u32))
        }
    })
}

/// Accumulates consecutive child blocks into one block of the next level.
struct Consolidator {
    threshold: f64,
    plus: FxHashSet<u32>,
    minus: Vec<u32>,
    redundant: usize,
    children: usize,
    /// Edges active after the last child (the k of the paper's criterion).
    active: i64,
    /// The lists of the block closed last, ascending: what the next level reads.
    closed_plus: Vec<u32>,
    closed_minus: Vec<u32>,
    out: Level,
}

impl Consolidator {
    fn new(threshold: f64, on_disk: bool, dir: &Path) -> std::io::Result<Self> {
        Ok(Consolidator {
            threshold,
            plus: FxHashSet::default(),
            minus: Vec::new(),
            redundant: 0,
            children: 0,
            active: 0,
            closed_plus: Vec::new(),
            closed_minus: Vec::new(),
            out: Level {
                starts: vec![0],
                plus_offsets: vec![0],
                minus_offsets: vec![0],
                plus: Spool::new(on_disk, dir)?,
                minus: Spool::new(on_disk, dir)?,
                entries: 0,
            },
        })
    }

    fn turn_on(&mut self, e: u32) {
        self.plus.insert(e);
        self.active += 1;
    }

    fn turn_off(&mut self, e: u32) {
        self.active -= 1;
        if self.plus.remove(&e) {
            self.redundant += 1;
        } else {
            self.minus.push(e);
        }
    }

    /// Ends a child block that ends at rank `end`; closes the parent block when the
    /// redundancy passes the threshold (and it holds at least two children), or at the
    /// `last` child. True when a block closed (its lists are in `closed_plus` and
    /// `closed_minus`).
    fn child_done(&mut self, end: usize, last: bool, bytes: &mut Vec<u8>) -> std::io::Result<bool> {
        self.children += 1;
        let full = self.children >= 2
            && self.redundant as f64 > self.threshold * self.active.max(1) as f64;
        if !(full || last) {
            return Ok(false);
        }
        self.closed_plus.clear();
        self.closed_plus.extend(self.plus.drain());
        self.closed_plus.sort_unstable();
        // Room for a block like this one, no more: a set would otherwise keep its largest
        // capacity, on every level at once.
        self.plus.shrink_to(self.closed_plus.len());
        self.closed_minus.clear();
        std::mem::swap(&mut self.closed_minus, &mut self.minus);
        self.closed_minus.sort_unstable();
        let out = &mut self.out;
        for (list, spool, offsets) in [
            (&self.closed_plus, &mut out.plus, &mut out.plus_offsets),
            (&self.closed_minus, &mut out.minus, &mut out.minus_offsets),
        ] {
            bytes.clear();
            write_varints(list, bytes);
            spool.write(bytes)?;
            offsets.push(spool.len());
        }
        out.entries += (self.closed_plus.len() + self.closed_minus.len()) as u64;
        out.starts.push(end as u32);
        self.redundant = 0;
        self.children = 0;
        Ok(true)
    }

    fn held_bytes(&self) -> u64 {
        // A hash set slot: the id and a control byte.
        (self.plus.capacity() * 5
            + (self.minus.capacity() + self.closed_plus.capacity() + self.closed_minus.capacity())
                * 4) as u64
            + self.out.held_bytes()
    }
}

/// Every skip-list level built in one pass over the sorted nodes: each level's closed
/// blocks are the next level's children as they close, so no level is held whole to
/// build the one above it.
struct Cascade {
    levels: Vec<Consolidator>,
    bytes: Vec<u8>,
}

impl Cascade {
    fn new(params: &BuildParams, on_disk: bool, dir: &Path) -> std::io::Result<Self> {
        let levels = (0..params.max_levels.max(1))
            .map(|_| Consolidator::new(params.threshold, on_disk, dir))
            .collect::<std::io::Result<_>>()?;
        Ok(Cascade {
            levels,
            bytes: Vec::new(),
        })
    }

    /// Node `j`, the `rank`-th (from 1) in value order, with level-0 mask `mask`.
    fn node(
        &mut self,
        lattice: &Lattice,
        rank: usize,
        j: usize,
        mask: u8,
        last: bool,
    ) -> std::io::Result<()> {
        let c = &mut self.levels[0];
        for (d, e) in node_edges(lattice, j) {
            if mask >> d & 1 == 1 {
                c.turn_on(e);
            } else {
                c.turn_off(e);
            }
        }
        let mut l = 0;
        while self.levels[l].child_done(rank, last, &mut self.bytes)? {
            if l + 1 == self.levels.len() {
                break;
            }
            let (below, above) = self.levels.split_at_mut(l + 1);
            let (child, parent) = (&below[l], &mut above[0]);
            for &e in &child.closed_plus {
                parent.turn_on(e);
            }
            for &e in &child.closed_minus {
                parent.turn_off(e);
            }
            l += 1;
        }
        Ok(())
    }

    fn held_bytes(&self) -> u64 {
        self.levels
            .iter()
            .map(Consolidator::held_bytes)
            .sum::<u64>()
            + self.bytes.capacity() as u64
    }

    /// The levels to store: level 1, then each level above while the one below has more
    /// than one block and it has fewer blocks than the one below.
    fn finish(self) -> std::io::Result<Vec<Level>> {
        let mut kept: Vec<Level> = Vec::new();
        for c in self.levels {
            let mut level = c.out;
            if let Some(below) = kept.last() {
                if below.blocks() <= 1 || level.blocks() >= below.blocks() {
                    break;
                }
            }
            level.plus.finish()?;
            level.minus.finish()?;
            kept.push(level);
        }
        Ok(kept)
    }
}

/// Bit d: the edge from node `j` to its neighbour d turns on as the isovalue passes the
/// node going up.
fn node_mask(lattice: &Lattice, values: &Values, j: usize) -> u8 {
    let vj = values.get(j);
    let mut m = 0u8;
    for (d, _) in node_edges(lattice, j) {
        let k = neighbour(lattice, j, d);
        if rises(vj, j, values.get(k), k) {
            m |= 1 << d;
        }
    }
    m
}

/// Builds the store of `volume` at `path` (written to a temporary sibling, then renamed).
pub fn build_store(
    volume: &Volume,
    path: &Path,
    params: &BuildParams,
    progress: &mut Progress,
) -> Result<BuildStats> {
    build_store_sorted(volume, path, params, None, progress)
}

/// [`build_store`], sorting as `plan` says when given (tests: several runs on disk for a
/// small volume), else as the memory budget allows.
fn build_store_sorted(
    volume: &Volume,
    path: &Path,
    params: &BuildParams,
    plan: Option<Plan>,
    progress: &mut Progress,
) -> Result<BuildStats> {
    let start = std::time::Instant::now();
    if !(params.threshold > 0.0 && params.threshold.is_finite()) {
        return Err(Error::InvalidParameter {
            name: "threshold",
            message: format!("must be positive, got {}", params.threshold),
        });
    }
    if params.max_levels > MAX_LEVELS {
        return Err(Error::InvalidParameter {
            name: "max_levels",
            message: format!(
                "must be at most {MAX_LEVELS} (a level's blocks hold two or more of the level \
                 below, so more levels than that can never fill), got {}",
                params.max_levels
            ),
        });
    }
    let lattice = volume.lattice;
    let n = lattice.node_count();
    if n as u64 * 3 >= u32::MAX as u64 {
        return Err(Error::InvalidInput(format!(
            "a slider store holds at most {} nodes (edge ids are 32-bit), this volume has {n}",
            u32::MAX / 3
        )));
    }
    // In memory: order + masks, and the levels (about as many edge entries as level 0's
    // 3 edges per node, twice, in the worst case). Beyond the budget, the order is sorted
    // on disk and the levels' lists are spooled there; only their open blocks stay.
    let in_memory = n as u64 * (4 + 1) + n as u64 * 3 * 2 * 4;
    let [nx, ny, nz] = lattice.dims;
    let plan = if let Some(plan) = plan {
        plan
    } else if in_memory <= params.memory_budget {
        Plan::InMemory
    } else {
        Plan::external(n as u64, params.memory_budget).ok_or_else(|| Error::OverBudget {
            what: format!(
                "precomputing a slider store for {nx}×{ny}×{nz} nodes, even sorting them on disk,"
            ),
            needed_bytes: Plan::least_external_budget(n as u64),
            budget_bytes: params.memory_budget,
        })?
    };
    let on_disk = plan != Plan::InMemory;
    let dir = crate::io::parent_dir(path);
    let io = |e| Error::io(path, e);
    // What the merge's read buffers leave (see `Plan::external`).
    let levels_budget = params.memory_budget - params.memory_budget / 4;
    let values = &volume.values;
    let mut mask = Spool::new(on_disk, &dir).map_err(io)?;
    let mut cascade = Cascade::new(params, on_disk, &dir).map_err(io)?;
    let mut masks: Vec<u8> = Vec::new();
    let mut rank = 0;
    let order = sort::sorted_nodes(values, plan, &dir, path, progress, |batch| {
        batch
            .par_iter()
            .map(|&j| node_mask(&lattice, values, j as usize))
            .collect_into_vec(&mut masks);
        mask.write(&masks).map_err(io)?;
        for (&j, &m) in batch.iter().zip(&masks) {
            rank += 1;
            cascade
                .node(&lattice, rank, j as usize, m, rank == n)
                .map_err(io)?;
        }
        let held = cascade.held_bytes();
        if on_disk && held > levels_budget {
            return Err(Error::OverBudget {
                // The open blocks follow the surfaces of the isovalues passed so far: this
                // is where they crossed the budget, not their peak, which may lie ahead.
                what: format!(
                    "precomputing a slider store for {nx}×{ny}×{nz} nodes (the skip-list \
                     levels' open blocks, which grow with the surface: counted {rank} of \
                     the {n} nodes in, so the whole build may need more)"
                ),
                needed_bytes: params.memory_budget - levels_budget + held,
                budget_bytes: params.memory_budget,
            });
        }
        Ok(())
    })?;
    mask.finish().map_err(io)?;
    let levels = cascade.finish().map_err(io)?;

    progress.phase("writing the store", 0.8, 1.0)?;
    let mut stats = BuildStats {
        nodes: n as u64,
        level_blocks: levels.iter().map(|l| l.blocks() as u64).collect(),
        level_edges: levels.iter().map(|l| l.entries).collect(),
        sorted_runs: order.runs() as u64,
        ..BuildStats::default()
    };
    write_store(path, volume, params, &order, &mask, &levels)?;
    stats.file_bytes = std::fs::metadata(path)
        .map_err(|e| Error::io(path, e))?
        .len();
    stats.seconds = start.elapsed().as_secs_f64();
    progress.done();
    Ok(stats)
}

/// Receives a section's bytes, piece by piece.
type Sink<'a> = dyn FnMut(&[u8]) -> std::io::Result<()> + 'a;
/// Writes one piece of a section into a sink.
type Part<'a> = &'a dyn Fn(&mut Sink) -> std::io::Result<()>;

/// CRC32 of every CHUNK bytes of the body, fed as it is written.
struct ChunkSums {
    sums: Vec<u32>,
    hasher: crc32fast::Hasher,
    filled: usize,
}

impl ChunkSums {
    fn update(&mut self, mut bytes: &[u8]) {
        while !bytes.is_empty() {
            let take = (CHUNK - self.filled).min(bytes.len());
            self.hasher.update(&bytes[..take]);
            self.filled += take;
            bytes = &bytes[take..];
            if self.filled == CHUNK {
                let h = std::mem::take(&mut self.hasher);
                self.sums.push(h.finalize());
                self.filled = 0;
            }
        }
    }

    fn finish(mut self) -> Vec<u32> {
        if self.filled > 0 {
            self.sums.push(self.hasher.finalize());
        }
        self.sums
    }
}

/// Writes sections after a placeholder header, then CHECKS, then the header with the
/// directory.
fn write_store(
    path: &Path,
    volume: &Volume,
    params: &BuildParams,
    order: &Order,
    mask: &Spool,
    levels: &[Level],
) -> Result<()> {
    let lattice = &volume.lattice;
    let sections = 4 + levels.len();
    let header_len = header_length(sections);
    super::super::io::write_atomically(path, |w| {
        w.write_all(&vec![0u8; header_len])?;
        let mut at = header_len as u64;
        let mut directory: Vec<u8> = Vec::with_capacity(sections * DIRECTORY_ENTRY);
        let mut chunks = ChunkSums {
            sums: Vec::new(),
            hasher: crc32fast::Hasher::new(),
            filled: 0,
        };
        let mut section = |w: &mut std::io::BufWriter<std::fs::File>,
                           kind: Kind,
                           level: u32,
                           pad: bool,
                           chunks: Option<&mut ChunkSums>,
                           parts: &[Part]|
         -> std::io::Result<()> {
            let mut crc = crc32fast::Hasher::new();
            let mut len = 0u64;
            let mut chunks = chunks;
            for part in parts {
                part(&mut |bytes: &[u8]| {
                    crc.update(bytes);
                    if let Some(c) = chunks.as_deref_mut() {
                        c.update(bytes);
                    }
                    len += bytes.len() as u64;
                    w.write_all(bytes)
                })?;
            }
            let pad = if pad {
                (len.next_multiple_of(8) - len) as usize
            } else {
                0
            };
            w.write_all(&[0u8; 8][..pad])?;
            if let Some(c) = chunks {
                c.update(&[0u8; 8][..pad]);
            }
            directory.extend_from_slice(&(kind as u32).to_le_bytes());
            directory.extend_from_slice(&level.to_le_bytes());
            directory.extend_from_slice(&at.to_le_bytes());
            directory.extend_from_slice(&len.to_le_bytes());
            directory.extend_from_slice(&crc.finalize().to_le_bytes());
            directory.extend_from_slice(&0u32.to_le_bytes());
            at += len + pad as u64;
            Ok(())
        };
        let c = Some(&mut chunks);
        section(
            w,
            Kind::Values,
            0,
            true,
            c,
            &[&|out| {
                ValueBricks::new(lattice.dims, volume.values.value_type())
                    .write(&volume.values, out)
            }],
        )?;
        let c = Some(&mut chunks);
        section(w, Kind::Order, 0, true, c, &[&|out| order.write_le(out)])?;
        let c = Some(&mut chunks);
        section(w, Kind::Mask, 0, true, c, &[&|out| mask.read_into(out)])?;
        for (l, level) in levels.iter().enumerate() {
            section(
                w,
                Kind::Level,
                l as u32 + 1,
                true,
                Some(&mut chunks),
                &[
                    &|out| out(&(level.blocks() as u64).to_le_bytes()),
                    &|out| write_le(&level.plus_offsets, u64::to_le_bytes, out),
                    &|out| write_le(&level.minus_offsets, u64::to_le_bytes, out),
                    &|out| write_le(&level.starts, u32::to_le_bytes, out),
                    &|out| level.plus.read_into(out),
                    &|out| level.minus.read_into(out),
                ],
            )?;
        }
        let sums = std::mem::replace(
            &mut chunks,
            ChunkSums {
                sums: Vec::new(),
                hasher: crc32fast::Hasher::new(),
                filled: 0,
            },
        )
        .finish();
        // The file ends where CHECKS ends: its length is part of what is checked.
        section(
            w,
            Kind::Checks,
            0,
            false,
            None,
            &[&|out| write_le(&sums, u32::to_le_bytes, out)],
        )?;
        let mut header = Vec::with_capacity(header_len);
        header.extend_from_slice(MAGIC);
        header.extend_from_slice(&VERSION.to_le_bytes());
        header.extend_from_slice(&(header_len as u32).to_le_bytes());
        for d in lattice.dims {
            header.extend_from_slice(&(d as u32).to_le_bytes());
        }
        header.extend_from_slice(&[volume.values.value_type().code(), 0, 0, 0]);
        for v in lattice
            .origin
            .to_array()
            .into_iter()
            .chain(lattice.spacing.to_array())
        {
            header.extend_from_slice(&v.to_le_bytes());
        }
        header.extend_from_slice(&(lattice.node_count() as u64).to_le_bytes());
        header.extend_from_slice(&params.threshold.to_le_bytes());
        header.extend_from_slice(&(levels.len() as u32).to_le_bytes());
        header.extend_from_slice(&(sections as u32).to_le_bytes());
        debug_assert_eq!(header.len(), FIXED_HEADER);
        header.extend_from_slice(&directory);
        let crc = crc32fast::hash(&header);
        header.extend_from_slice(&crc.to_le_bytes());
        header.resize(header_len, 0);
        w.seek(SeekFrom::Start(0))?;
        w.write_all(&header)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::grid::Values;
    use glam::DVec3;

    #[test]
    fn stores_sorted_in_runs_on_disk_are_the_in_memory_store() {
        // Rings of values with many ties (u8), so ties by index matter across runs.
        let dims = [30, 26, 22];
        let lattice = Lattice::new(dims, DVec3::ZERO, DVec3::ONE).unwrap();
        let v: Vec<u8> = (0..lattice.node_count())
            .map(|i| {
                let [x, y, z] = lattice.coords(i).map(|c| c as f64);
                let r = ((x - 14.2).powi(2) + (y - 12.7).powi(2) + (z - 10.1).powi(2)).sqrt();
                (r * 3.0 + (x * 0.7).sin() * 4.0) as u8
            })
            .collect();
        let volume = Volume::new(lattice, Values::U8(v)).unwrap();
        let dir = std::env::temp_dir().join(format!("isobar-runs-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let params = BuildParams::default();
        let build = |name: &str, plan: Option<Plan>| {
            let path = dir.join(name);
            let stats =
                build_store_sorted(&volume, &path, &params, plan, &mut Progress::none()).unwrap();
            (std::fs::read(&path).unwrap(), stats.sorted_runs)
        };
        let (whole, runs) = build("whole.isoslider", None);
        assert_eq!(runs, 0);
        for (run_nodes, buffer_nodes, runs) in [(17_160, 17_160, 1), (2_000, 300, 9), (999, 1, 18)]
        {
            let plan = Plan::External {
                run_nodes,
                buffer_nodes,
            };
            let (spooled, sorted_runs) = build("spooled.isoslider", Some(plan));
            assert!(spooled == whole, "{plan:?}: a different store");
            assert_eq!(sorted_runs, runs, "{plan:?}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// An absurd level count (a wrapped -1 from a host) is refused by name before any
    /// level's buffers exist; it used to allocate them all and abort.
    #[test]
    fn absurd_level_counts_are_refused() {
        let lattice = Lattice::new([2, 2, 2], DVec3::ZERO, DVec3::ONE).unwrap();
        let volume = Volume::new(lattice, Values::F32((0..8).map(|i| i as f32).collect())).unwrap();
        let path =
            std::env::temp_dir().join(format!("isobar-levels-{}.isoslider", std::process::id()));
        for max_levels in [MAX_LEVELS + 1, u32::MAX as usize, usize::MAX] {
            let params = BuildParams {
                max_levels,
                ..BuildParams::default()
            };
            let e = build_store(&volume, &path, &params, &mut Progress::none()).unwrap_err();
            assert!(e.to_string().contains("max_levels"), "{e}");
            assert!(!path.exists(), "nothing written");
        }
        let params = BuildParams {
            max_levels: MAX_LEVELS,
            ..BuildParams::default()
        };
        build_store(&volume, &path, &params, &mut Progress::none()).unwrap();
        std::fs::remove_file(&path).unwrap();
    }
}
