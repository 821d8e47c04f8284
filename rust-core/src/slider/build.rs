//! Precomputation: sort the nodes by value, derive each node's block B_r (the edges that
//! turn on and off as the isovalue passes it), consolidate blocks into skip-list levels
//! with redundant edges removed, and write everything into one store file.

use super::store::{
    neighbour, rises, write_varints, Kind, CHUNK, DIRECTORY_ENTRY, FIXED_HEADER, MAGIC, VERSION,
};
use crate::error::{Error, Result};
use crate::field::grid::{Lattice, Volume};
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
    /// Bytes the precomputation may hold in memory (the volume excluded); larger
    /// volumes are refused before allocating (an external-memory sort is not built yet).
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

/// What a build produced.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BuildStats {
    pub nodes: u64,
    /// Blocks per level, level 1 first.
    pub level_blocks: Vec<u64>,
    /// Edge entries (E+ and E−) per level, level 1 first.
    pub level_edges: Vec<u64>,
    pub file_bytes: u64,
    pub seconds: f64,
}

/// One skip-list level in memory.
#[derive(Default)]
struct LevelData {
    starts: Vec<u32>,
    plus_offsets: Vec<u64>,
    minus_offsets: Vec<u64>,
    plus: Vec<u32>,
    minus: Vec<u32>,
}

impl LevelData {
    fn blocks(&self) -> usize {
        self.starts.len().saturating_sub(1)
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
    out: LevelData,
}

impl Consolidator {
    fn new(threshold: f64) -> Self {
        let mut out = LevelData::default();
        out.starts.push(0);
        out.plus_offsets.push(0);
        out.minus_offsets.push(0);
        Consolidator {
            threshold,
            plus: FxHashSet::default(),
            minus: Vec::new(),
            redundant: 0,
            children: 0,
            active: 0,
            out,
        }
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
    /// redundancy passes the threshold (and it holds at least two children).
    fn child_done(&mut self, end: usize, last: bool) {
        self.children += 1;
        let full = self.children >= 2
            && self.redundant as f64 > self.threshold * self.active.max(1) as f64;
        if full || (last && self.children > 0) {
            let mut plus: Vec<u32> = self.plus.drain().collect();
            plus.sort_unstable();
            self.minus.sort_unstable();
            self.out.plus.extend_from_slice(&plus);
            self.out.minus.append(&mut self.minus);
            self.out.plus_offsets.push(self.out.plus.len() as u64);
            self.out.minus_offsets.push(self.out.minus.len() as u64);
            self.out.starts.push(end as u32);
            self.redundant = 0;
            self.children = 0;
        }
    }
}

/// Builds the store of `volume` at `path` (written to a temporary sibling, then renamed).
pub fn build_store(
    volume: &Volume,
    path: &Path,
    params: &BuildParams,
    progress: &mut Progress,
) -> Result<BuildStats> {
    let start = std::time::Instant::now();
    if !(params.threshold > 0.0 && params.threshold.is_finite()) {
        return Err(Error::InvalidParameter {
            name: "threshold",
            message: format!("must be positive, got {}", params.threshold),
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
    // order + masks, and the levels (about as many edge entries as level 0's 3 edges per
    // node, twice, in the worst case).
    let needed = n as u64 * (4 + 1) + n as u64 * 3 * 2 * 4;
    if needed > params.memory_budget {
        return Err(Error::OverBudget {
            what: format!(
                "precomputing a slider store for {}×{}×{} nodes (external-memory sorting is not implemented yet)",
                lattice.dims[0], lattice.dims[1], lattice.dims[2]
            ),
            needed_bytes: needed,
            budget_bytes: params.memory_budget,
        });
    }

    progress.phase("sorting node values", 0.0, 0.3)?;
    let values = &volume.values;
    let mut order: Vec<u32> = (0..n as u32).collect();
    order.par_sort_unstable_by(|&a, &b| {
        values
            .get(a as usize)
            .total_cmp(&values.get(b as usize))
            .then(a.cmp(&b))
    });
    progress.phase("edge lists", 0.3, 0.4)?;
    // Bit d: the edge to neighbour d turns on as the isovalue passes the node going up.
    let mask: Vec<u8> = order
        .par_iter()
        .map(|&j| {
            let j = j as usize;
            let vj = values.get(j);
            let mut m = 0u8;
            for (d, _) in node_edges(&lattice, j) {
                let k = neighbour(&lattice, j, d);
                if rises(vj, j, values.get(k), k) {
                    m |= 1 << d;
                }
            }
            m
        })
        .collect();

    progress.phase("skip-list levels", 0.4, 0.8)?;
    let mut levels: Vec<LevelData> = Vec::new();
    // Level 1 straight from level 0's blocks.
    let mut c = Consolidator::new(params.threshold);
    for r in 0..n {
        let m = mask[r];
        for (d, e) in node_edges(&lattice, order[r] as usize) {
            if m >> d & 1 == 1 {
                c.turn_on(e);
            } else {
                c.turn_off(e);
            }
        }
        c.child_done(r + 1, r + 1 == n);
        if r % (1 << 20) == 0 {
            progress.report(r as f64 / n as f64 * 0.5)?;
        }
    }
    levels.push(c.out);
    while levels.len() < params.max_levels {
        let below = levels.last().expect("level 1 exists");
        if below.blocks() <= 1 {
            break;
        }
        let mut c = Consolidator::new(params.threshold);
        for k in 0..below.blocks() {
            let (p0, p1) = (
                below.plus_offsets[k] as usize,
                below.plus_offsets[k + 1] as usize,
            );
            let (m0, m1) = (
                below.minus_offsets[k] as usize,
                below.minus_offsets[k + 1] as usize,
            );
            for &e in &below.plus[p0..p1] {
                c.turn_on(e);
            }
            for &e in &below.minus[m0..m1] {
                c.turn_off(e);
            }
            c.child_done(below.starts[k + 1] as usize, k + 1 == below.blocks());
        }
        if c.out.blocks() >= below.blocks() {
            break;
        }
        levels.push(c.out);
        progress.report(0.5 + 0.5 * levels.len() as f64 / params.max_levels as f64)?;
    }

    progress.phase("writing the store", 0.8, 1.0)?;
    let mut stats = BuildStats {
        nodes: n as u64,
        level_blocks: levels.iter().map(|l| l.blocks() as u64).collect(),
        level_edges: levels
            .iter()
            .map(|l| (l.plus.len() + l.minus.len()) as u64)
            .collect(),
        ..BuildStats::default()
    };
    write_store(path, volume, params, &order, &mask, &levels)?;
    stats.file_bytes = std::fs::metadata(path)
        .map_err(|e| Error::io(path, e))?
        .len();
    stats.seconds = start.elapsed().as_secs_f64();
    progress.report(1.0)?;
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

/// A level's edge lists as LEB128 gaps, with byte offsets per block.
fn encode_lists(offsets: &[u64], ids: &[u32]) -> (Vec<u64>, Vec<u8>) {
    let mut bytes = Vec::with_capacity(ids.len() * 2);
    let mut out = Vec::with_capacity(offsets.len());
    out.push(0);
    for w in offsets.windows(2) {
        write_varints(&ids[w[0] as usize..w[1] as usize], &mut bytes);
        out.push(bytes.len() as u64);
    }
    (out, bytes)
}

/// Writes sections after a placeholder header, then CHECKS, then the header with the
/// directory.
fn write_store(
    path: &Path,
    volume: &Volume,
    params: &BuildParams,
    order: &[u32],
    mask: &[u8],
    levels: &[LevelData],
) -> Result<()> {
    let lattice = &volume.lattice;
    let sections = 4 + levels.len();
    let dir_end = FIXED_HEADER + sections * DIRECTORY_ENTRY;
    let header_len = (dir_end + 4).next_multiple_of(8);
    let encoded: Vec<_> = levels
        .par_iter()
        .map(|l| {
            (
                encode_lists(&l.plus_offsets, &l.plus),
                encode_lists(&l.minus_offsets, &l.minus),
            )
        })
        .collect();
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
            &[&|out| volume.values.write_le(out)],
        )?;
        let c = Some(&mut chunks);
        section(w, Kind::Order, 0, true, c, &[&|out| write_u32s(order, out)])?;
        let c = Some(&mut chunks);
        section(w, Kind::Mask, 0, true, c, &[&|out| out(mask)])?;
        for (l, (level, ((plus_offsets, plus), (minus_offsets, minus)))) in
            levels.iter().zip(&encoded).enumerate()
        {
            section(
                w,
                Kind::Level,
                l as u32 + 1,
                true,
                Some(&mut chunks),
                &[
                    &|out| out(&(level.blocks() as u64).to_le_bytes()),
                    &|out| write_u64s(plus_offsets, out),
                    &|out| write_u64s(minus_offsets, out),
                    &|out| write_u32s(&level.starts, out),
                    &|out| out(plus),
                    &|out| out(minus),
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
            &[&|out| write_u32s(&sums, out)],
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

fn write_u32s(v: &[u32], out: &mut Sink) -> std::io::Result<()> {
    for chunk in v.chunks(1 << 16) {
        let bytes: Vec<u8> = chunk.iter().flat_map(|x| x.to_le_bytes()).collect();
        out(&bytes)?;
    }
    Ok(())
}

fn write_u64s(v: &[u64], out: &mut Sink) -> std::io::Result<()> {
    for chunk in v.chunks(1 << 15) {
        let bytes: Vec<u8> = chunk.iter().flat_map(|x| x.to_le_bytes()).collect();
        out(&bytes)?;
    }
    Ok(())
}
