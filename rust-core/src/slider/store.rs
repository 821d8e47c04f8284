//! The slider's store file: one file, memory-mapped at run time but for VALUES, which
//! the slider reads a brick at a time (`value_bricks`).
//!
//! ```text
//! header (104 bytes, little endian)
//!   0  magic "ISOSLIDE"      8  version u32        12 header length u32 (incl. directory + crc)
//!   16 dims u32×3            28 value type u8 (1 f32, 2 u16, 3 u8), 3 bytes padding
//!   32 origin f64×3          56 spacing f64×3      80 node count u64
//!   88 skip-list threshold f64                     96 levels above 0 u32   100 sections u32
//! directory: per section kind u32, level u32, offset u64, length u64, crc32 u32, 0 u32
//! crc32 of header + directory, u32; zeros to 4096 bytes (so every chunk below is a page)
//! sections, 8-byte aligned (VALUES, first, on a page), in this order (the file ends
//! exactly where CHECKS ends):
//!   VALUES  node values in their type, in 4096-byte bricks (see `value_bricks`)
//!   ORDER   u32 node ids sorted by (value, id): block B_r of level 0 is node ORDER[r]
//!   MASK    u8 per block of level 0: bit 2a+s set when the edge to the neighbour along
//!           axis a (s = 0: −, 1: +) becomes active as the isovalue passes the node going
//!           up (E+: the neighbour comes later in the order, see [`rises`]); the node's
//!           other edges become inactive (E−). Derivable from VALUES, but kept: reading it
//!           is one sequential byte per block where deriving it reads six neighbours
//!   LEVEL L (L ≥ 1) blocks: n u64, E+ byte offsets u64×(n+1), E− byte offsets u64×(n+1),
//!           first ranks u32×(n+1) (the last is the end), E+ bytes, E− bytes; a block's
//!           list is its edge ids ascending, each as the LEB128 varint of its gap to the
//!           previous one (the first from 0)
//!   CHECKS  crc32 u32 per 4096-byte chunk of the bytes from the end of the header to
//!           the start of CHECKS
//! ```
//!
//! An edge is `node · 3 + axis` (from its lower node), a cell is its lower corner node.
//! Interpolation data (the end values and, through neighbours, the gradients) comes from
//! VALUES, which is read only around the surface, a brick at a time by `pread` into the
//! store's brick cache (version 3; version 2 kept VALUES x fastest, read through the map).
//!
//! Opening reads the header, the directory, CHECKS and the skip-list tables (a few
//! kilobytes a level) and checks every size against the file's length, so a truncated
//! or foreign file is refused at once; the data is checked a chunk at a time on first
//! touch ([`Store::ensure`], or as a brick is read) or all at once by [`Store::verify`],
//! so resident memory follows what the slider reads and a corrupt chunk is refused
//! before its data is used.

use super::value_bricks::{Brick, BrickCache, ValueBricks, BRICK_BYTES};
use crate::error::{Error, Result};
use crate::field::grid::{Lattice, NodeCoords, ValueType, Volume};
use glam::DVec3;
use memmap2::Mmap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// First bytes of every store.
pub const MAGIC: &[u8; 8] = b"ISOSLIDE";
/// The version this build writes and reads.
pub(crate) const VERSION: u32 = 3;
/// Bytes per checksummed chunk: a page (checking one touches no other) and a brick.
pub(crate) const CHUNK: usize = BRICK_BYTES;
pub(crate) const FIXED_HEADER: usize = 104;
pub(crate) const DIRECTORY_ENTRY: usize = 32;
const MAX_SECTIONS: usize = 64;

/// Bytes of the header of a store with `sections` sections: the fixed part, the
/// directory and its checksum, padded with zeros to a chunk so that the body (VALUES'
/// bricks first) starts on a page.
pub(crate) fn header_length(sections: usize) -> usize {
    (FIXED_HEADER + sections * DIRECTORY_ENTRY + 4).next_multiple_of(CHUNK)
}

/// What a section holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Kind {
    Values = 1,
    Order = 2,
    Mask = 3,
    Level = 4,
    Checks = 5,
}

impl Kind {
    fn from_code(c: u32) -> Option<Kind> {
        Some(match c {
            1 => Kind::Values,
            2 => Kind::Order,
            3 => Kind::Mask,
            4 => Kind::Level,
            5 => Kind::Checks,
            _ => return None,
        })
    }
    fn name(self) -> &'static str {
        match self {
            Kind::Values => "values",
            Kind::Order => "order",
            Kind::Mask => "mask",
            Kind::Level => "level",
            Kind::Checks => "checks",
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

/// An opened store: the mapped file, where each section is, and the bricks of VALUES
/// read so far.
pub struct Store {
    map: Mmap,
    /// The file, for reading VALUES' bricks.
    file: std::fs::File,
    path: PathBuf,
    pub(crate) lattice: Lattice,
    /// The lattice's index-to-coordinates without `div` (every map key of an update).
    pub(crate) coords: NodeCoords,
    pub(crate) value_type: ValueType,
    pub(crate) nodes: usize,
    /// Redundancy threshold the levels were built with.
    pub threshold: f64,
    /// Offset of VALUES, where each node's value lies in it, and the bricks read.
    values: usize,
    bricks: ValueBricks,
    cache: BrickCache,
    /// The smallest and largest values (read at open).
    range: (f32, f32),
    order: usize,
    mask: usize,
    pub(crate) levels: Vec<Level>,
    /// First byte of the checksummed body (the end of the header).
    body: usize,
    /// End of the body: where CHECKS starts.
    body_end: usize,
    /// Byte offset of CHECKS.
    checks: usize,
    /// One bit per body chunk: its checksum has been verified.
    verified: Vec<AtomicU64>,
    /// (kind, level, offset, length) of every section, to name them in errors.
    sections: Vec<(Kind, usize, usize, usize)>,
}

#[inline]
fn u32_at(b: &[u8], at: usize) -> u32 {
    // One bounds check for the four bytes (not one per byte): every value read goes
    // through here.
    let mut a = [0u8; 4];
    a.copy_from_slice(&b[at..at + 4]);
    u32::from_le_bytes(a)
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
    /// Maps `path` and checks what opening needs: magic, version, the header and chunk
    /// table checksums, section sizes against the file length, and the skip-list tables.
    /// A store from another version, a truncated one or a corrupt header is refused here
    /// with an error naming the file; data chunks are checked when first read (or all at
    /// once by [`Store::verify`]).
    pub fn open(path: &Path) -> Result<Store> {
        let file = crate::io::open_regular(path)?;
        // SAFETY: the map is read-only; isobar writes stores by rename, never in place, so
        // the mapped file does not change under us unless someone else truncates it.
        let map = unsafe { Mmap::map(&file) }.map_err(|e| Error::io(path, e))?;
        Self::from_map(map, file, path)
    }

    fn from_map(map: Mmap, file: std::fs::File, path: &Path) -> Result<Store> {
        let err = |m: String| Error::format(path, m);
        let b = &map[..];
        if b.len() < 8 || &b[..8] != MAGIC {
            return Err(err(
                "not an isobar slider store (no ISOSLIDE magic); build one with `isobar slide-build`"
                    .into(),
            ));
        }
        if b.len() < 12 {
            return Err(err(format!("truncated: {} bytes, no version", b.len())));
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
        if header_len != header_length(sections) {
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
        if b.len() < header_len {
            return Err(err(format!(
                "truncated: {} bytes, inside the {header_len}-byte header",
                b.len()
            )));
        }
        if b[dir_end + 4..header_len].iter().any(|&x| x != 0) {
            return Err(err("corrupt header: its padding is not zero".into()));
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
            if offset < header_len as u64 {
                return Err(err(format!(
                    "corrupt: section '{}' starts inside the header",
                    kind.name()
                )));
            }
            found.push((kind, level, offset as usize, length as usize));
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
        // The chunk checksums: read whole (4 bytes per 4 KiB), checked against the
        // directory, and sized by the file, so a truncated body is refused here.
        let (checks, checks_len) = section(Kind::Checks, 0, None)?;
        let body = header_len;
        let chunks = (checks - body).div_ceil(CHUNK);
        if checks_len != 4 * chunks || checks + checks_len != b.len() {
            return Err(err(format!(
                "truncated or corrupt: {} bytes, the directory describes {}",
                b.len(),
                checks + 4 * chunks
            )));
        }
        let dir_crc = |kind: Kind| {
            let s = (0..sections)
                .find(|&s| u32_at(b, FIXED_HEADER + s * DIRECTORY_ENTRY) == kind as u32)
                .expect("found above");
            u32_at(b, FIXED_HEADER + s * DIRECTORY_ENTRY + 24)
        };
        if crc32fast::hash(&b[checks..checks + checks_len]) != dir_crc(Kind::Checks) {
            return Err(err("corrupt: section 'checks' fails its checksum".into()));
        }
        if found
            .iter()
            .any(|&(k, _, o, l)| k != Kind::Checks && o + l > checks)
        {
            return Err(err("corrupt directory: a section overlaps 'checks'".into()));
        }
        // The size first: a header naming absurd dims cannot make the tables be built.
        let values_bytes = ValueBricks::bytes_for(dims, value_type)
            .ok_or_else(|| err(format!("corrupt header: dims {dims:?} overflow")))?;
        let values = section(Kind::Values, 0, Some(values_bytes))?.0;
        let bricks = ValueBricks::new(dims, value_type);
        if values % CHUNK != 0 {
            return Err(err(
                "corrupt: section 'values' does not start on a page".into()
            ));
        }
        let order = section(Kind::Order, 0, Some(nodes * 4))?.0;
        let mask = section(Kind::Mask, 0, Some(nodes))?.0;
        let mut store = Store {
            path: path.to_path_buf(),
            lattice,
            coords: NodeCoords::new(&lattice),
            value_type,
            nodes,
            threshold,
            values,
            cache: BrickCache::new(bricks.count()).map_err(|e| Error::io(path, e))?,
            bricks,
            range: (0.0, 0.0),
            order,
            mask,
            levels: Vec::with_capacity(level_count),
            body,
            body_end: checks,
            checks,
            verified: (0..chunks.div_ceil(64))
                .map(|_| AtomicU64::new(0))
                .collect(),
            sections: found.clone(),
            map,
            file,
        };
        for l in 1..=level_count {
            let (offset, length) = section(Kind::Level, l, None)?;
            let level = store.parse_level(offset, length).map_err(|m| match m {
                LevelError::Store(e) => e,
                LevelError::Table(m) => err(format!("corrupt: skip-list level {l}: {m}")),
            })?;
            store.levels.push(level);
        }
        // The smallest and largest values, read by `value_range` and the empty surface.
        let last = nodes - 1;
        store.ensure(order, order + 4)?;
        store.ensure(order + 4 * last, order + 4 * nodes)?;
        store.range = (
            store.checked_value(store.order_checked(0)?)?,
            store.checked_value(store.order_checked(last)?)?,
        );
        // Nothing read at open stays: the slider's first update reads what it needs.
        store.cache.clear();
        store.release(0..store.map.len());
        Ok(store)
    }

    /// Checks the chunks holding bytes `from..to` of the file, each once: a chunk whose
    /// checksum fails is refused with an error naming the section.
    #[inline]
    pub(crate) fn ensure(&self, from: usize, to: usize) -> Result<()> {
        if from >= to {
            return Ok(());
        }
        let (first, last) = ((from - self.body) / CHUNK, (to - 1 - self.body) / CHUNK);
        for c in first..=last {
            let bit = 1u64 << (c % 64);
            if self.verified[c / 64].load(Ordering::Relaxed) & bit == 0 {
                self.verify_chunk(c)?;
                self.verified[c / 64].fetch_or(bit, Ordering::Relaxed);
            }
        }
        Ok(())
    }

    #[cold]
    fn verify_chunk(&self, c: usize) -> Result<()> {
        let lo = self.body + c * CHUNK;
        let hi = (lo + CHUNK).min(self.body_end);
        self.check_chunk(c, &self.map[lo..hi])
    }

    /// Checks `bytes`, read from chunk `c`, against the chunk's checksum.
    fn check_chunk(&self, c: usize, bytes: &[u8]) -> Result<()> {
        if crc32fast::hash(bytes) == u32_at(&self.map, self.checks + 4 * c) {
            return Ok(());
        }
        let lo = self.body + c * CHUNK;
        let hi = lo + bytes.len();
        let what = self
            .sections
            .iter()
            .find(|s| s.2 < hi && lo < s.2 + s.3)
            .map_or("padding".to_string(), |s| match s.0 {
                Kind::Level => format!("section 'level' {}", s.1),
                k => format!("section '{}'", k.name()),
            });
        Err(Error::format(
            &self.path,
            format!("corrupt: {what} fails its checksum (bytes {lo}..{hi})"),
        ))
    }

    /// Checks every chunk of the file (what opening does lazily, all at once).
    pub fn verify(&self) -> Result<()> {
        self.ensure(self.body, self.body_end)?;
        // Verifying read every page; hand them back so that resident memory follows
        // what the slider touches.
        self.release(0..self.map.len());
        Ok(())
    }

    /// Hands back the pages of ORDER, MASK and the levels (what a walk reads).
    pub(crate) fn release_lists(&self) {
        self.release(self.order..self.body_end);
    }

    /// Drops the mapped pages of `bytes` from this process's resident memory (they stay
    /// in the page cache and are read back on the next touch); the page holding the
    /// range's first byte goes too.
    fn release(&self, bytes: std::ops::Range<usize>) {
        // SAFETY: the map is read-only and file-backed, and the file is not written
        // while mapped (see `open`): no reference into the pages held across this call
        // can observe different contents, as dropped pages are read back from the file.
        let _ = unsafe {
            self.map.unchecked_advise_range(
                memmap2::UncheckedAdvice::DontNeed,
                bytes.start,
                bytes.len(),
            )
        };
    }

    /// Refuses a store whose file was cut shorter since it was mapped (by another
    /// process: isobar replaces stores by rename, which leaves the mapped file whole).
    /// Reading a mapped page past the new end would kill the process with SIGBUS; one
    /// `fstat` before each walk turns that into an error, unless the cut lands during it.
    pub(crate) fn check_length(&self) -> Result<()> {
        let len = self
            .file
            .metadata()
            .map_err(|e| Error::io(&self.path, e))?
            .len();
        if len < self.map.len() as u64 {
            return Err(Error::format(
                &self.path,
                format!(
                    "truncated to {len} of its {} bytes while open; reopen the store, or rebuild it",
                    self.map.len()
                ),
            ));
        }
        Ok(())
    }

    /// The file this store was opened from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Whether this store was built from `volume`: the same lattice, value type and
    /// values, byte for byte. The values are read from the file with `pread`, not
    /// through the map, so the check leaves none of them mapped (resident) in the
    /// process; it stops at the first differing piece.
    pub fn holds(&self, volume: &Volume) -> Result<bool> {
        use std::os::unix::fs::FileExt;
        if volume.lattice != self.lattice || volume.values.value_type() != self.value_type {
            return Ok(false);
        }
        let file = std::fs::File::open(&self.path).map_err(|e| Error::io(&self.path, e))?;
        let (mut at, mut stored) = (self.values as u64, Vec::new());
        let mut failed = None;
        let same = self
            .bricks
            .write(&volume.values, &mut |bytes: &[u8]| {
                stored.resize(bytes.len(), 0);
                if let Err(e) = file.read_exact_at(&mut stored, at) {
                    failed = Some(e);
                    return Err(());
                }
                at += bytes.len() as u64;
                if stored == bytes {
                    Ok(())
                } else {
                    Err(())
                }
            })
            .is_ok();
        match failed {
            Some(e) => Err(Error::io(&self.path, e)),
            None => Ok(same),
        }
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
        self.range
    }

    /// Number of nodes.
    pub fn node_count(&self) -> usize {
        self.nodes
    }

    /// Bytes of the mapped file.
    pub fn file_size(&self) -> u64 {
        self.map.len() as u64
    }

    /// Value of node `c` in `brick`, at byte `at` of VALUES.
    #[inline(always)]
    fn value_in(&self, brick: &Brick, at: usize) -> f32 {
        let at = at % BRICK_BYTES;
        match self.value_type {
            ValueType::F32 => f32::from_bits(u32_at(brick, at)),
            ValueType::U16 => u16::from_le_bytes([brick[at], brick[at + 1]]) as f32,
            ValueType::U8 => brick[at] as f32,
        }
    }

    /// Starts loading node `c`'s value into the CPU caches if its brick has been read (a
    /// hint: reads nothing from the file).
    #[inline(always)]
    pub(crate) fn prefetch_value_at(&self, c: [usize; 3]) {
        self.cache.prefetch(self.bricks.at(c));
    }

    /// Value of node `i` (below the node count), its brick read and checked first.
    #[inline(always)]
    pub(crate) fn checked_value(&self, i: usize) -> Result<f32> {
        self.checked_value_at(self.coords.coords(i))
    }

    /// Value of node `c` (inside the lattice), its brick read and checked first.
    #[inline(always)]
    pub(crate) fn checked_value_at(&self, c: [usize; 3]) -> Result<f32> {
        let at = self.bricks.at(c);
        match self.cache.get(at / BRICK_BYTES) {
            Some(brick) => Ok(self.value_in(brick, at)),
            None => self.read_value(at),
        }
    }

    /// Value of node `c` if its brick has already been read, else `None` (nothing is
    /// read here): the hot path of reads that mostly hit read bricks.
    #[inline(always)]
    pub(crate) fn verified_value_at(&self, c: [usize; 3]) -> Option<f32> {
        let at = self.bricks.at(c);
        self.cache
            .get(at / BRICK_BYTES)
            .map(|brick| self.value_in(brick, at))
    }

    /// The value at byte `at` of VALUES, its brick read from the file into the cache
    /// first and checked against its chunk's checksum.
    #[cold]
    fn read_value(&self, at: usize) -> Result<f32> {
        use std::os::unix::fs::FileExt;
        let b = at / BRICK_BYTES;
        let from = self.values + b * BRICK_BYTES;
        let mut spare = [0u8; BRICK_BYTES];
        let brick = self.cache.get_or_read(b, &mut spare, |brick| {
            self.file
                .read_exact_at(brick, from as u64)
                .map_err(|e| Error::io(&self.path, e))?;
            self.check_chunk((from - self.body) / CHUNK, brick)
        })?;
        Ok(self.value_in(brick, at))
    }

    /// Bytes of VALUES' bricks held in memory.
    pub fn values_held(&self) -> usize {
        self.cache.bytes()
    }

    /// Keeps the bricks of VALUES holding the nodes (inside the lattice) that `reads`
    /// hands to the function it is given, and frees the rest.
    pub(crate) fn retain_values(&mut self, reads: impl FnOnce(&mut dyn FnMut([usize; 3]))) {
        let mut keep = vec![0u64; self.bricks.count().div_ceil(64)];
        let bricks = &self.bricks;
        reads(&mut |n| {
            let b = bricks.at(n) / BRICK_BYTES;
            keep[b / 64] |= 1 << (b % 64);
        });
        self.cache.retain(&keep);
    }

    /// Bytes of VALUES in the file (the volume's values, bricked).
    pub(crate) fn values_bytes(&self) -> usize {
        self.bricks.bytes()
    }

    /// Whether the chunk holding byte `at` has been checked (the hot path of every
    /// checked read: one bit test).
    #[inline(always)]
    fn chunk_checked(&self, at: usize) -> bool {
        let c = (at - self.body) / CHUNK;
        self.verified[c / 64].load(Ordering::Relaxed) >> (c % 64) & 1 == 1
    }

    /// Node of level-0 block `r` (chunk checked, id in range).
    #[inline]
    pub(crate) fn order_checked(&self, r: usize) -> Result<usize> {
        if !self.chunk_checked(self.order + 4 * r) {
            self.ensure(self.order + 4 * r, self.order + 4 * r + 4)?;
        }
        let j = u32_at(&self.map, self.order + 4 * r) as usize;
        if j >= self.nodes {
            return Err(Error::format(
                &self.path,
                format!("corrupt: section 'order' names node {j} at rank {r}, out of range"),
            ));
        }
        Ok(j)
    }

    /// Activation mask of level-0 block `r` (chunk checked).
    #[inline]
    pub(crate) fn mask_checked(&self, r: usize) -> Result<u8> {
        if !self.chunk_checked(self.mask + r) {
            self.ensure(self.mask + r, self.mask + r + 1)?;
        }
        Ok(self.map[self.mask + r])
    }

    /// Number of nodes whose value is ≤ `iso`: the level-0 position of isovalue `iso`.
    pub(crate) fn rank_of(&self, iso: f64) -> Result<usize> {
        let (mut lo, mut hi) = (0usize, self.nodes);
        while lo < hi {
            let mid = (lo + hi) / 2;
            if (self.checked_value(self.order_checked(mid)?)? as f64) <= iso {
                lo = mid + 1;
            } else {
                hi = mid;
            }
        }
        Ok(lo)
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

    /// E+ and E− of block `k` of `level` (chunks checked), as iterators over edge ids.
    pub(crate) fn block_edges(
        &self,
        level: &Level,
        k: usize,
    ) -> Result<(Varints<'_>, Varints<'_>)> {
        let b = &self.map[..];
        let range = |offsets: usize, base: usize| -> Result<Varints<'_>> {
            let from = base + u64_at(b, offsets + 8 * k) as usize;
            let to = base + u64_at(b, offsets + 8 * (k + 1)) as usize;
            self.ensure(from, to)?;
            Ok(Varints {
                bytes: &b[from..to],
                prev: 0,
            })
        };
        Ok((
            range(level.plus_offsets, level.plus)?,
            range(level.minus_offsets, level.minus)?,
        ))
    }

    /// Checks a level's tables (sizes, monotone offsets and starts covering 0..nodes).
    fn parse_level(&self, offset: usize, length: usize) -> std::result::Result<Level, LevelError> {
        let b = &self.map[..];
        if length < 8 {
            return Err(LevelError::Table("too short".into()));
        }
        self.ensure(offset, offset + 8)?;
        let blocks = u64_at(b, offset) as usize;
        let fixed = blocks
            .checked_add(1)
            .and_then(|n| n.checked_mul(20))
            .and_then(|n| n.checked_add(8))
            .filter(|&n| n <= length)
            .ok_or(LevelError::Table(
                "block tables longer than the section".into(),
            ))?;
        self.ensure(offset, offset + fixed)?;
        let plus_offsets = offset + 8;
        let minus_offsets = plus_offsets + 8 * (blocks + 1);
        let starts = minus_offsets + 8 * (blocks + 1);
        let plus = starts + 4 * (blocks + 1);
        let mono = |at: usize, width: usize| -> std::result::Result<u64, LevelError> {
            let mut prev = 0u64;
            for k in 0..=blocks {
                let v = if width == 8 {
                    u64_at(b, at + 8 * k)
                } else {
                    u32_at(b, at + 4 * k) as u64
                };
                if v < prev || (k == 0 && v != 0) {
                    return Err(LevelError::Table(format!(
                        "table at byte {at} is not increasing from 0"
                    )));
                }
                prev = v;
            }
            Ok(prev)
        };
        let plus_bytes = mono(plus_offsets, 8)? as usize;
        let minus_bytes = mono(minus_offsets, 8)? as usize;
        if mono(starts, 4)? as usize != self.nodes {
            return Err(LevelError::Table("blocks do not cover every node".into()));
        }
        if fixed + plus_bytes + minus_bytes != length {
            return Err(LevelError::Table(
                "edge lists do not fill the section".into(),
            ));
        }
        Ok(Level {
            blocks,
            plus_offsets,
            minus_offsets,
            starts,
            plus,
            minus: plus + plus_bytes,
        })
    }
}

/// Why a level was refused: a failed chunk, or tables that do not fit.
enum LevelError {
    Store(Error),
    Table(String),
}

impl From<Error> for LevelError {
    fn from(e: Error) -> Self {
        LevelError::Store(e)
    }
}

/// Whether the edge from node `j` (value `vj`) to its neighbour `k` (value `vk`) turns
/// on as the isovalue passes `j` going up: `k` comes later in the level-0 order, by value
/// then by id. The build and the run time share it.
#[inline]
pub(crate) fn rises(vj: f32, j: usize, vk: f32, k: usize) -> bool {
    match vk.total_cmp(&vj) {
        std::cmp::Ordering::Greater => true,
        std::cmp::Ordering::Less => false,
        std::cmp::Ordering::Equal => k > j,
    }
}

/// The neighbour of node `j` in direction `d` (2a+s, as
/// [`super::build::node_edges`] numbers them).
#[inline]
pub(crate) fn neighbour(lattice: &Lattice, j: usize, d: usize) -> usize {
    let s = lattice.stride(d / 2);
    if d % 2 == 1 {
        j + s
    } else {
        j - s
    }
}

/// Ascending edge ids decoded from LEB128 gaps. A malformed list (a varint running past
/// the end) ends early; ids are range-checked where they are used.
pub(crate) struct Varints<'a> {
    bytes: &'a [u8],
    prev: u32,
}

impl Iterator for Varints<'_> {
    type Item = u32;
    #[inline]
    fn next(&mut self) -> Option<u32> {
        let mut gap = 0u32;
        let mut shift = 0;
        loop {
            let (&byte, rest) = self.bytes.split_first()?;
            self.bytes = rest;
            gap |= ((byte & 0x7f) as u32).wrapping_shl(shift);
            if byte & 0x80 == 0 {
                break;
            }
            shift += 7;
        }
        self.prev = self.prev.wrapping_add(gap);
        Some(self.prev)
    }
}

/// Hands the little-endian bytes of `v` to `out`, a bounded slice at a time (`bytes`
/// gives one word's: `u32::to_le_bytes`, `u64::to_le_bytes`, ...): the one writer of the
/// store's integer sections (its values are written brick by brick, by `value_bricks`).
pub(crate) fn write_le<T: Copy, const N: usize, E>(
    v: &[T],
    bytes: fn(T) -> [u8; N],
    out: &mut dyn FnMut(&[u8]) -> std::result::Result<(), E>,
) -> std::result::Result<(), E> {
    const CHUNK: usize = 1 << 16;
    for chunk in v.chunks(CHUNK) {
        let b: Vec<u8> = chunk.iter().flat_map(|&x| bytes(x)).collect();
        out(&b)?;
    }
    Ok(())
}

/// Appends `ids` (ascending) to `out` as LEB128 gaps.
pub(crate) fn write_varints(ids: &[u32], out: &mut Vec<u8>) {
    let mut prev = 0u32;
    for &id in ids {
        let mut gap = id - prev;
        prev = id;
        while gap >= 0x80 {
            out.push((gap as u8) | 0x80);
            gap >>= 7;
        }
        out.push(gap as u8);
    }
}
