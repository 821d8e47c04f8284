//! The slider's store file: one file, memory-mapped at run time.
//!
//! ```text
//! header (104 bytes, little endian)
//!   0  magic "ISOSLIDE"      8  version u32        12 header length u32 (incl. directory + crc)
//!   16 dims u32×3            28 value type u8 (1 f32, 2 u16, 3 u8), 3 bytes padding
//!   32 origin f64×3          56 spacing f64×3      80 node count u64
//!   88 skip-list threshold f64                     96 levels above 0 u32   100 sections u32
//! directory: per section kind u32, level u32, offset u64, length u64, crc32 u32, 0 u32
//! crc32 of header + directory, u32; padding to 8 bytes
//! sections, 8-byte aligned:
//!   VALUES  node values in their type, x fastest
//!   ORDER   u32 node ids sorted by (value, id): block B_r of level 0 is node ORDER[r]
//!   MASK    u8 per block of level 0: bit 2a+s set when the edge to the neighbour along
//!           axis a (s = 0: −, 1: +) becomes active as the isovalue passes the node going up
//!           (E+); the node's other edges become inactive (E−)
//!   LEVEL L (L ≥ 1) blocks: n u64, E+ offsets u64×(n+1), E− offsets u64×(n+1),
//!           first ranks u32×(n+1) (the last is the end), E+ edges u32…, E− edges u32…
//! ```
//!
//! An edge is `node · 3 + axis` (from its lower node), a cell is its lower corner node.
//! Interpolation data (the end values and, through neighbours, the gradients) comes from
//! VALUES, which is read only around the surface.

use crate::error::{Error, Result};
use crate::field::grid::{Lattice, ValueType};
use glam::DVec3;
use memmap2::Mmap;
use std::path::{Path, PathBuf};

/// First bytes of every store.
pub const MAGIC: &[u8; 8] = b"ISOSLIDE";
/// The version this build writes and reads.
pub const VERSION: u32 = 1;
pub(crate) const FIXED_HEADER: usize = 104;
pub(crate) const DIRECTORY_ENTRY: usize = 32;
const MAX_SECTIONS: usize = 64;

/// What a section holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Kind {
    Values = 1,
    Order = 2,
    Mask = 3,
    Level = 4,
}

impl Kind {
    fn from_code(c: u32) -> Option<Kind> {
        Some(match c {
            1 => Kind::Values,
            2 => Kind::Order,
            3 => Kind::Mask,
            4 => Kind::Level,
            _ => return None,
        })
    }
    fn name(self) -> &'static str {
        match self {
            Kind::Values => "values",
            Kind::Order => "order",
            Kind::Mask => "mask",
            Kind::Level => "level",
        }
    }
}

/// One skip-list level above 0, as byte ranges of the map.
#[derive(Clone, Debug)]
pub(crate) struct Level {
    pub(crate) blocks: usize,
    plus_offsets: usize,
    minus_offsets: usize,
    starts: usize,
    plus: usize,
    minus: usize,
}

/// An opened store: the mapped file and where each section is.
pub struct Store {
    map: Mmap,
    path: PathBuf,
    pub(crate) lattice: Lattice,
    pub(crate) value_type: ValueType,
    pub(crate) nodes: usize,
    /// Redundancy threshold the levels were built with.
    pub threshold: f64,
    values: usize,
    order: usize,
    mask: usize,
    pub(crate) levels: Vec<Level>,
}

#[inline]
fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

#[inline]
fn u64_at(b: &[u8], at: usize) -> u64 {
    let mut a = [0u8; 8];
    a.copy_from_slice(&b[at..at + 8]);
    u64::from_le_bytes(a)
}

fn f64_at(b: &[u8], at: usize) -> f64 {
    f64::from_bits(u64_at(b, at))
}

impl Store {
    /// Maps `path` and checks it whole: magic, version, header and section checksums,
    /// section sizes against the header, and the skip-list tables. A store from another
    /// version, a truncated or a corrupt one is refused with an error naming the file.
    pub fn open(path: &Path) -> Result<Store> {
        let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
        // SAFETY: the map is read-only; isobar writes stores by rename, never in place, so
        // the mapped file does not change under us unless someone else truncates it.
        let map = unsafe { Mmap::map(&file) }.map_err(|e| Error::io(path, e))?;
        Self::from_map(map, path)
    }

    fn from_map(map: Mmap, path: &Path) -> Result<Store> {
        let err = |m: String| Error::format(path, m);
        let b = &map[..];
        if b.len() < 12 || &b[..8] != MAGIC {
            return Err(err(
                "not an isobar slider store (no ISOSLIDE magic); build one with `isobar slide-build`"
                    .into(),
            ));
        }
        let version = u32_at(b, 8);
        if version != VERSION {
            return Err(err(format!(
                "slider store version {version}, this isobar reads version {VERSION}; rebuild it with `isobar slide-build`"
            )));
        }
        if b.len() < FIXED_HEADER {
            return Err(err(format!(
                "truncated: {} bytes, shorter than the {FIXED_HEADER}-byte header",
                b.len()
            )));
        }
        let sections = u32_at(b, 100) as usize;
        if sections > MAX_SECTIONS {
            return Err(err(format!(
                "corrupt header: {sections} sections (at most {MAX_SECTIONS})"
            )));
        }
        let dir_end = FIXED_HEADER + sections * DIRECTORY_ENTRY;
        let header_len = u32_at(b, 12) as usize;
        if header_len != (dir_end + 4).next_multiple_of(8) {
            return Err(err(format!(
                "corrupt header: length {header_len} does not match {sections} sections"
            )));
        }
        if b.len() < dir_end + 4 {
            return Err(err("truncated inside the section directory".into()));
        }
        if crc32fast::hash(&b[..dir_end]) != u32_at(b, dir_end) {
            return Err(err("corrupt header: checksum mismatch".into()));
        }
        let dims = [u32_at(b, 16), u32_at(b, 20), u32_at(b, 24)].map(|d| d as usize);
        let value_type = ValueType::from_code(b[28])
            .ok_or_else(|| err(format!("unknown value type code {}", b[28])))?;
        let origin = DVec3::new(f64_at(b, 32), f64_at(b, 40), f64_at(b, 48));
        let spacing = DVec3::new(f64_at(b, 56), f64_at(b, 64), f64_at(b, 72));
        let lattice = Lattice::new(dims, origin, spacing).map_err(|e| err(e.to_string()))?;
        let nodes = u64_at(b, 80) as usize;
        if nodes != lattice.node_count() || (nodes as u64) * 3 >= u32::MAX as u64 {
            return Err(err(format!(
                "corrupt header: {nodes} nodes for {}×{}×{}",
                dims[0], dims[1], dims[2]
            )));
        }
        let threshold = f64_at(b, 88);
        let level_count = u32_at(b, 96) as usize;

        let mut found: Vec<(Kind, usize, usize, usize)> = Vec::new();
        for s in 0..sections {
            let e = FIXED_HEADER + s * DIRECTORY_ENTRY;
            let kind = Kind::from_code(u32_at(b, e))
                .ok_or_else(|| err(format!("section {s} has unknown kind {}", u32_at(b, e))))?;
            let level = u32_at(b, e + 4) as usize;
            let offset = u64_at(b, e + 8);
            let length = u64_at(b, e + 16);
            let end = offset.saturating_add(length);
            if end > b.len() as u64 {
                return Err(err(format!(
                    "truncated: section '{}' ends at byte {end} but the file has {} bytes",
                    kind.name(),
                    b.len()
                )));
            }
            let (offset, length) = (offset as usize, length as usize);
            if crc32fast::hash(&b[offset..offset + length]) != u32_at(b, e + 24) {
                return Err(err(format!(
                    "corrupt: section '{}'{} fails its checksum",
                    kind.name(),
                    if kind == Kind::Level {
                        format!(" {level}")
                    } else {
                        String::new()
                    }
                )));
            }
            found.push((kind, level, offset, length));
        }
        let section = |kind: Kind, level: usize, want: Option<usize>| -> Result<(usize, usize)> {
            let &(_, _, offset, length) = found
                .iter()
                .find(|s| s.0 == kind && s.1 == level)
                .ok_or_else(|| err(format!("missing section '{}'", kind.name())))?;
            if let Some(w) = want {
                if w != length {
                    return Err(err(format!(
                        "section '{}' holds {length} bytes, {w} expected",
                        kind.name()
                    )));
                }
            }
            Ok((offset, length))
        };
        let values = section(Kind::Values, 0, Some(nodes * value_type.size()))?.0;
        let order = section(Kind::Order, 0, Some(nodes * 4))?.0;
        let mask = section(Kind::Mask, 0, Some(nodes))?.0;
        if (order..order + nodes * 4)
            .step_by(4)
            .any(|at| u32_at(b, at) as usize >= nodes)
        {
            return Err(err(
                "corrupt: section 'order' names a node out of range".into()
            ));
        }
        let mut levels = Vec::with_capacity(level_count);
        for l in 1..=level_count {
            let (offset, length) = section(Kind::Level, l, None)?;
            levels.push(
                parse_level(b, offset, length, nodes)
                    .map_err(|m| err(format!("corrupt: skip-list level {l}: {m}")))?,
            );
        }
        // Verifying read every page; hand them back so that resident memory follows what
        // the slider touches, not the file size. The map is read-only and file-backed, so
        // dropped pages are read again from the file when needed.
        // SAFETY: no reference into the map's pages is held across this call that could
        // observe different contents: the file is not written while mapped (see `open`).
        let _ = unsafe { map.unchecked_advise(memmap2::UncheckedAdvice::DontNeed) };
        Ok(Store {
            path: path.to_path_buf(),
            lattice,
            value_type,
            nodes,
            threshold,
            values,
            order,
            mask,
            levels,
            map,
        })
    }

    /// The file this store was opened from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Lattice of the volume.
    pub fn lattice(&self) -> &Lattice {
        &self.lattice
    }

    /// Number of skip-list levels above level 0.
    pub fn level_count(&self) -> usize {
        self.levels.len()
    }

    /// Smallest and largest node value.
    pub fn value_range(&self) -> (f32, f32) {
        (
            self.value(self.order(0)),
            self.value(self.order(self.nodes - 1)),
        )
    }

    /// Number of nodes.
    pub fn node_count(&self) -> usize {
        self.nodes
    }

    /// Bytes of the mapped file.
    pub fn file_size(&self) -> u64 {
        self.map.len() as u64
    }

    /// Value of node `i`.
    #[inline]
    pub fn value(&self, i: usize) -> f32 {
        let b = &self.map[..];
        match self.value_type {
            ValueType::F32 => f32::from_bits(u32_at(b, self.values + 4 * i)),
            ValueType::U16 => {
                let at = self.values + 2 * i;
                u16::from_le_bytes([b[at], b[at + 1]]) as f32
            }
            ValueType::U8 => b[self.values + i] as f32,
        }
    }

    /// Node of level-0 block `r`.
    #[inline]
    pub(crate) fn order(&self, r: usize) -> usize {
        u32_at(&self.map, self.order + 4 * r) as usize
    }

    /// Activation mask of level-0 block `r`.
    #[inline]
    pub(crate) fn mask(&self, r: usize) -> u8 {
        self.map[self.mask + r]
    }

    /// Number of nodes whose value is ≤ `iso`: the level-0 position of isovalue `iso`.
    pub(crate) fn rank_of(&self, iso: f64) -> usize {
        let (mut lo, mut hi) = (0usize, self.nodes);
        while lo < hi {
            let mid = (lo + hi) / 2;
            if (self.value(self.order(mid)) as f64) <= iso {
                lo = mid + 1;
            } else {
                hi = mid;
            }
        }
        lo
    }

    /// First rank of block `k` of `level` (k = blocks gives the end).
    #[inline]
    pub(crate) fn start(&self, level: &Level, k: usize) -> usize {
        u32_at(&self.map, level.starts + 4 * k) as usize
    }

    /// The block of `level` whose first rank is `r`, if `r` is one of its boundaries.
    pub(crate) fn block_starting_at(&self, level: &Level, r: usize) -> Option<usize> {
        let (mut lo, mut hi) = (0usize, level.blocks + 1);
        while lo < hi {
            let mid = (lo + hi) / 2;
            if self.start(level, mid) < r {
                lo = mid + 1;
            } else {
                hi = mid;
            }
        }
        (lo <= level.blocks && self.start(level, lo) == r).then_some(lo)
    }

    /// E+ and E− of block `k` of `level`, as iterators over edge ids.
    pub(crate) fn block_edges(
        &self,
        level: &Level,
        k: usize,
    ) -> (
        impl Iterator<Item = u32> + '_,
        impl Iterator<Item = u32> + '_,
    ) {
        let b = &self.map[..];
        let range = |offsets: usize, base: usize| {
            let from = u64_at(b, offsets + 8 * k) as usize;
            let to = u64_at(b, offsets + 8 * (k + 1)) as usize;
            (from..to).map(move |i| u32_at(b, base + 4 * i))
        };
        (
            range(level.plus_offsets, level.plus),
            range(level.minus_offsets, level.minus),
        )
    }
}

/// Checks a level's tables (sizes, monotone offsets and starts covering 0..nodes).
fn parse_level(
    b: &[u8],
    offset: usize,
    length: usize,
    nodes: usize,
) -> std::result::Result<Level, String> {
    if length < 8 {
        return Err("too short".into());
    }
    let blocks = u64_at(b, offset) as usize;
    let fixed = blocks
        .checked_add(1)
        .and_then(|n| n.checked_mul(20))
        .and_then(|n| n.checked_add(8))
        .filter(|&n| n <= length)
        .ok_or("block tables longer than the section")?;
    let plus_offsets = offset + 8;
    let minus_offsets = plus_offsets + 8 * (blocks + 1);
    let starts = minus_offsets + 8 * (blocks + 1);
    let plus = starts + 4 * (blocks + 1);
    let mono = |at: usize, width: usize| -> std::result::Result<u64, String> {
        let mut prev = 0u64;
        for k in 0..=blocks {
            let v = if width == 8 {
                u64_at(b, at + 8 * k)
            } else {
                u32_at(b, at + 4 * k) as u64
            };
            if v < prev || (k == 0 && v != 0) {
                return Err(format!("table at byte {at} is not increasing from 0"));
            }
            prev = v;
        }
        Ok(prev)
    };
    let plus_count = mono(plus_offsets, 8)? as usize;
    let minus_count = mono(minus_offsets, 8)? as usize;
    if mono(starts, 4)? as usize != nodes {
        return Err("blocks do not cover every node".into());
    }
    let minus = plus + 4 * plus_count;
    if fixed + 4 * (plus_count + minus_count) != length {
        return Err("edge lists do not fill the section".into());
    }
    let limit = 3 * nodes as u32;
    if (plus..plus + 4 * (plus_count + minus_count))
        .step_by(4)
        .any(|at| u32_at(b, at) >= limit)
    {
        return Err("an edge id is out of range".into());
    }
    Ok(Level {
        blocks,
        plus_offsets,
        minus_offsets,
        starts,
        plus,
        minus,
    })
}
