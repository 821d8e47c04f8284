//! Where the store keeps each node's value: VALUES is cut into bricks of one page
//! (4 KiB: 16×8×8 f32, 16×16×8 u16 or 16×16×16 u8 values, x fastest inside a brick,
//! bricks x fastest), the bricks on the volume's far faces padded with zeros.
//!
//! Why bricks: the slider reads values only around the surface, a sheet through the
//! volume, and the kernel maps the store a page at a time. In x-fastest order a page of
//! a 256-wide f32 volume is four whole rows, so a sheet crossing them drags in 256 nodes
//! along x for every few it needs; a brick is a compact block around them. On MNI152
//! 256³ the starting surface's values (its active edges' nodes and their neighbours)
//! lie in 7,665 pages in x-fastest order and in 2,670 bricks: 30 MiB of the store
//! resident against 10.4.
//!
//! A node's byte offset is separable, one table lookup per axis, so reading a value by
//! its coordinates costs what `x + nx·(y + ny·z)` did.
//!
//! Why not read the bricks through the store's map: on a read fault the kernel maps the
//! pages around the faulting one that are in the page cache (fault-around, 64 KiB), and
//! `MADV_RANDOM` does not stop it (checked on Linux 6.18): each brick touched brought 16
//! into the process, 32 MiB of the 64 MiB VALUES resident at MNI152's starting surface.
//! [`BrickCache`] reads each brick the slider touches with one `pread` instead, checked
//! against its chunk's checksum as it arrives, into memory of the process's own.

use crate::field::grid::{ValueType, Values};
use crate::prefetch::prefetch_address;
use memmap2::{Advice, MmapMut, UncheckedAdvice};
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};

/// Bytes of one brick: a page, and the store's checksummed chunk.
pub(crate) const BRICK_BYTES: usize = 4096;

/// The bricked layout of one volume's values.
#[derive(Clone, Debug)]
pub(crate) struct ValueBricks {
    /// Per axis, the byte offset each coordinate adds: node `c`'s value starts at
    /// `along[0][c[0]] + along[1][c[1]] + along[2][c[2]]`.
    along: [Vec<usize>; 3],
    dims: [usize; 3],
    /// Nodes per brick along each axis.
    shape: [usize; 3],
    /// Bricks along each axis.
    counts: [usize; 3],
}

impl ValueBricks {
    /// Nodes per brick along each axis for `value_type`.
    fn shape(value_type: ValueType) -> [usize; 3] {
        let shape = match value_type {
            ValueType::F32 => [16, 8, 8],
            ValueType::U16 => [16, 16, 8],
            ValueType::U8 => [16, 16, 16],
        };
        debug_assert_eq!(
            shape.iter().product::<usize>() * value_type.size(),
            BRICK_BYTES
        );
        shape
    }

    /// Bytes of VALUES for a `dims` volume of `value_type` values (what [`ValueBricks::bytes`]
    /// will say, without building the tables: a store's header is checked with it first).
    pub(crate) fn bytes_for(dims: [usize; 3], value_type: ValueType) -> Option<usize> {
        let shape = Self::shape(value_type);
        (0..3).try_fold(BRICK_BYTES, |n, a| {
            n.checked_mul(dims[a].div_ceil(shape[a]))
        })
    }

    /// The layout of a `dims` volume of `value_type` values.
    pub(crate) fn new(dims: [usize; 3], value_type: ValueType) -> ValueBricks {
        let size = value_type.size();
        let shape = Self::shape(value_type);
        let counts = [0, 1, 2].map(|a| dims[a].div_ceil(shape[a]));
        let brick_step = [1, counts[0], counts[0] * counts[1]].map(|s| s * BRICK_BYTES);
        let node_step = [1, shape[0], shape[0] * shape[1]].map(|s| s * size);
        let along = [0, 1, 2].map(|a| {
            (0..dims[a])
                .map(|c| c / shape[a] * brick_step[a] + c % shape[a] * node_step[a])
                .collect()
        });
        ValueBricks {
            along,
            dims,
            shape,
            counts,
        }
    }

    /// Byte offset in VALUES of node `c`'s value (`c` inside the volume).
    #[inline(always)]
    pub(crate) fn at(&self, c: [usize; 3]) -> usize {
        debug_assert!(
            (0..3).all(|a| c[a] < self.dims[a]),
            "node {c:?} outside the volume"
        );
        self.along[0][c[0]] + self.along[1][c[1]] + self.along[2][c[2]]
    }

    /// Bricks of VALUES, padding included.
    pub(crate) fn count(&self) -> usize {
        self.counts.iter().product()
    }

    /// Bytes of VALUES.
    pub(crate) fn bytes(&self) -> usize {
        self.count() * BRICK_BYTES
    }

    /// Hands VALUES to `out`, brick after brick, a bounded run of bricks at a time: the
    /// one writer of the section (the store build, and the check that a store holds a
    /// volume).
    pub(crate) fn write<E>(
        &self,
        values: &Values,
        out: &mut dyn FnMut(&[u8]) -> std::result::Result<(), E>,
    ) -> std::result::Result<(), E> {
        match values {
            Values::F32(v) => self.write_typed(v, f32::to_le_bytes, out),
            Values::U16(v) => self.write_typed(v, u16::to_le_bytes, out),
            Values::U8(v) => self.write_typed(v, |b| [b], out),
        }
    }

    fn write_typed<T: Copy, const N: usize, E>(
        &self,
        v: &[T],
        bytes: fn(T) -> [u8; N],
        out: &mut dyn FnMut(&[u8]) -> std::result::Result<(), E>,
    ) -> std::result::Result<(), E> {
        const RUN: usize = 16 * BRICK_BYTES;
        let ([nx, ny, nz], [sx, sy, sz]) = (self.dims, self.shape);
        debug_assert_eq!(v.len(), nx * ny * nz);
        let mut buf = Vec::with_capacity(RUN);
        for bz in 0..self.counts[2] {
            for by in 0..self.counts[1] {
                for bx in 0..self.counts[0] {
                    for z in bz * sz..(bz + 1) * sz {
                        for y in by * sy..(by + 1) * sy {
                            for x in bx * sx..(bx + 1) * sx {
                                if x < nx && y < ny && z < nz {
                                    buf.extend_from_slice(&bytes(v[x + nx * (y + ny * z)]));
                                } else {
                                    buf.extend_from_slice(&[0; N]);
                                }
                            }
                        }
                    }
                    if buf.len() >= RUN {
                        out(&buf)?;
                        buf.clear();
                    }
                }
            }
        }
        if !buf.is_empty() {
            out(&buf)?;
        }
        Ok(())
    }
}

/// One brick's bytes.
pub(crate) type Brick = [u8; BRICK_BYTES];

/// The bricks of VALUES read so far, at their offsets in an anonymous mapping as long as
/// VALUES: a brick's page becomes memory only when the brick is read into it, and a
/// value is read at the same offset as in the file, after one bit test (what reading
/// through the file's map cost). Shared by the threads of an update: a brick is read
/// by the thread that claims it; one that finds it claimed and not yet read reads its
/// own copy. Emptied between updates by [`BrickCache::clear`].
pub(crate) struct BrickCache {
    region: MmapMut,
    /// `region`'s first byte and length: every access goes through `base`, as no
    /// reference to the whole region may be made while a thread writes a brick in it.
    base: *mut u8,
    len: usize,
    /// The system's page size: what `MADV_DONTNEED` frees at the least.
    page: usize,
    /// Bit per brick: its bytes are in `region` (set with release ordering after the
    /// write, tested with acquire ordering before the read).
    loaded: Vec<AtomicU64>,
    /// Bit per brick: a thread has taken it to read.
    claimed: Vec<AtomicU64>,
    count: AtomicUsize,
}

// SAFETY: `base` points into `region`, owned by the cache; a brick's bytes are written
// only by the one thread that claimed it, before its `loaded` bit is published, and read
// only after that bit is seen; `clear` takes `&mut self`.
unsafe impl Send for BrickCache {}
unsafe impl Sync for BrickCache {}

impl BrickCache {
    /// An empty cache for `count` bricks (address space only).
    pub(crate) fn new(count: usize) -> std::io::Result<BrickCache> {
        let mut region = MmapMut::map_anon((count * BRICK_BYTES).max(BRICK_BYTES))?;
        // A huge page would make one brick's read two megabytes of memory.
        let _ = region.advise(Advice::NoHugePage);
        let bits = || (0..count.div_ceil(64)).map(|_| AtomicU64::new(0)).collect();
        // SAFETY: sysconf reads a constant of the system.
        let page = unsafe { libc::sysconf(libc::_SC_PAGESIZE) };
        Ok(BrickCache {
            base: region.as_mut_ptr(),
            len: region.len(),
            page: usize::try_from(page)
                .unwrap_or(BRICK_BYTES)
                .max(BRICK_BYTES),
            region,
            loaded: bits(),
            claimed: bits(),
            count: AtomicUsize::new(0),
        })
    }

    /// Brick `b` if it has been read.
    #[inline(always)]
    pub(crate) fn get(&self, b: usize) -> Option<&Brick> {
        let held = self.loaded[b / 64].load(Ordering::Acquire) >> (b % 64) & 1 == 1;
        // SAFETY: a loaded brick lies inside `region` and is no longer written.
        held.then(|| unsafe { &*(self.base.add(b * BRICK_BYTES) as *const Brick) })
    }

    /// Starts loading byte `at` of VALUES into the CPU caches if its brick has been read
    /// (a hint: an unread brick's page is not there to load, and nothing faults).
    #[inline(always)]
    pub(crate) fn prefetch(&self, at: usize) {
        if at < self.len {
            // SAFETY: inside `region` (by address only: no reference is made).
            prefetch_address(unsafe { self.base.add(at) });
        }
    }

    /// Brick `b`, filled by `read` if it has not been read yet (an error leaves it
    /// unread). Where another thread is reading it at this moment, `read` fills `spare`
    /// and that is returned.
    pub(crate) fn get_or_read<'a, E>(
        &'a self,
        b: usize,
        spare: &'a mut Brick,
        read: impl FnOnce(&mut Brick) -> Result<(), E>,
    ) -> Result<&'a Brick, E> {
        if let Some(brick) = self.get(b) {
            return Ok(brick);
        }
        let (w, bit) = (b / 64, 1u64 << (b % 64));
        if self.claimed[w].fetch_or(bit, Ordering::AcqRel) & bit != 0 {
            read(spare)?;
            return Ok(spare);
        }
        // SAFETY: inside `region`; this thread holds the claim, and nobody reads the
        // brick before its `loaded` bit is set below.
        let brick = unsafe { &mut *(self.base.add(b * BRICK_BYTES) as *mut Brick) };
        if let Err(e) = read(brick) {
            self.claimed[w].fetch_and(!bit, Ordering::AcqRel);
            return Err(e);
        }
        self.loaded[w].fetch_or(bit, Ordering::Release);
        self.count.fetch_add(1, Ordering::Relaxed);
        Ok(brick)
    }

    /// Bytes of the bricks held.
    pub(crate) fn bytes(&self) -> usize {
        self.count.load(Ordering::Relaxed) * BRICK_BYTES
    }

    /// Frees the bricks held whose bit in `keep` (one per brick) is clear: their pages go
    /// back to the system.
    pub(crate) fn retain(&mut self, keep: &[u64]) {
        let mut run: Option<(usize, usize)> = None;
        let mut dropped = 0;
        for (w, (loaded, claimed)) in self.loaded.iter_mut().zip(&mut self.claimed).enumerate() {
            let mut gone = *loaded.get_mut() & !keep[w];
            *loaded.get_mut() &= !gone;
            *claimed.get_mut() &= !gone;
            dropped += gone.count_ones() as usize;
            while gone != 0 {
                let b = w * 64 + gone.trailing_zeros() as usize;
                gone &= gone - 1;
                run = match run {
                    Some((first, end)) if end == b => Some((first, b + 1)),
                    Some(r) => {
                        free(&self.region, self.page, r);
                        Some((b, b + 1))
                    }
                    None => Some((b, b + 1)),
                };
            }
        }
        if let Some(r) = run {
            free(&self.region, self.page, r);
        }
        *self.count.get_mut() -= dropped;
    }

    /// Frees every brick held: their pages go back to the system.
    pub(crate) fn clear(&mut self) {
        if *self.count.get_mut() == 0 {
            return;
        }
        // SAFETY: an anonymous private mapping reads as zeros after `DontNeed`, and
        // with `&mut self` no reference into it is held; no brick counts as read.
        let _ = unsafe { self.region.unchecked_advise(UncheckedAdvice::DontNeed) };
        for w in self.loaded.iter_mut().chain(self.claimed.iter_mut()) {
            *w.get_mut() = 0;
        }
        *self.count.get_mut() = 0;
    }
}

/// Hands back the whole pages of `region` that bricks `first..end` (no longer marked
/// loaded) cover: where a page is larger than a brick, a page the run shares with a
/// kept brick stays (freeing it would zero that brick).
fn free(region: &MmapMut, page: usize, (first, end): (usize, usize)) {
    if let Some((from, to)) = whole_pages(first, end, page) {
        // SAFETY: as in `BrickCache::clear`; the caller holds the cache by `&mut`, and
        // every brick in `from..to` is unmarked.
        let _ =
            unsafe { region.unchecked_advise_range(UncheckedAdvice::DontNeed, from, to - from) };
    }
}

/// The byte range of the whole `page`-byte pages inside bricks `first..end`, if any.
fn whole_pages(first: usize, end: usize, page: usize) -> Option<(usize, usize)> {
    let (from, to) = (
        (first * BRICK_BYTES).next_multiple_of(page),
        end * BRICK_BYTES / page * page,
    );
    (from < to).then_some((from, to))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicUsize;

    /// Every node's value is written where `at` says, each brick is one page, and the
    /// padding nodes are zero: checked for each value type on a volume no brick shape
    /// divides.
    #[test]
    fn every_value_lies_where_at_says() {
        let dims = [37, 19, 21];
        let n = dims.iter().product::<usize>();
        for values in [
            Values::F32((0..n).map(|i| i as f32 + 0.5).collect()),
            Values::U16((0..n).map(|i| (i % 65_521) as u16 + 1).collect()),
            Values::U8((0..n).map(|i| (i % 251) as u8 + 1).collect()),
        ] {
            let t = values.value_type();
            let bricks = ValueBricks::new(dims, t);
            let mut file = Vec::new();
            bricks
                .write(&values, &mut |b: &[u8]| -> Result<(), ()> {
                    file.extend_from_slice(b);
                    Ok(())
                })
                .unwrap();
            assert_eq!(file.len(), bricks.bytes());
            assert_eq!(file.len() % BRICK_BYTES, 0);
            let mut used = vec![false; file.len() / t.size()];
            for z in 0..dims[2] {
                for y in 0..dims[1] {
                    for x in 0..dims[0] {
                        let at = bricks.at([x, y, z]);
                        let got = match t {
                            ValueType::F32 => {
                                f32::from_le_bytes(file[at..at + 4].try_into().unwrap())
                            }
                            ValueType::U16 => {
                                u16::from_le_bytes(file[at..at + 2].try_into().unwrap()) as f32
                            }
                            ValueType::U8 => file[at] as f32,
                        };
                        assert_eq!(got, values.get(x + dims[0] * (y + dims[1] * z)));
                        assert!(!std::mem::replace(&mut used[at / t.size()], true));
                        // A node shares its page with its brick's first corner.
                        let corner =
                            [0, 1, 2].map(|a| [x, y, z][a] / bricks.shape[a] * bricks.shape[a]);
                        assert_eq!(bricks.at(corner) / BRICK_BYTES, at / BRICK_BYTES);
                    }
                }
            }
            // Whatever no node uses is padding, and zero.
            for (k, used) in used.iter().enumerate() {
                if !used {
                    let b = &file[k * t.size()..(k + 1) * t.size()];
                    assert!(b.iter().all(|&b| b == 0), "{t:?}: padding {k}");
                }
            }
        }
    }

    fn fill(b: usize) -> impl Fn(&mut Brick) -> Result<(), String> {
        move |brick: &mut Brick| {
            for (k, x) in brick.iter_mut().enumerate() {
                *x = (b * 7 + k) as u8;
            }
            Ok(())
        }
    }

    /// Freeing a run of bricks frees only the pages wholly inside it: with 16-KiB pages
    /// (four bricks a page) a run that shares a page with a kept brick leaves that page.
    #[test]
    fn only_whole_pages_of_a_run_are_freed() {
        assert_eq!(whole_pages(0, 1, BRICK_BYTES), Some((0, BRICK_BYTES)));
        assert_eq!(
            whole_pages(3, 5, BRICK_BYTES),
            Some((3 * BRICK_BYTES, 5 * BRICK_BYTES))
        );
        let page = 4 * BRICK_BYTES;
        assert_eq!(whole_pages(0, 1, page), None);
        assert_eq!(whole_pages(2, 8, page), Some((page, 2 * page)));
        assert_eq!(whole_pages(4, 12, page), Some((page, 3 * page)));
        assert_eq!(whole_pages(5, 11, page), None);
    }

    /// Threads racing for the same bricks each get the brick's bytes; each brick is
    /// counted once; a failed read leaves its brick unread; `clear` forgets them all.
    #[test]
    fn racing_threads_read_each_brick_right() {
        let mut cache = BrickCache::new(100).unwrap();
        let reads = AtomicUsize::new(0);
        std::thread::scope(|s| {
            for _ in 0..4 {
                s.spawn(|| {
                    for b in (0..100).rev().chain(0..100) {
                        let mut spare = [0u8; BRICK_BYTES];
                        let brick = cache
                            .get_or_read(b, &mut spare, |brick| {
                                reads.fetch_add(1, Ordering::Relaxed);
                                fill(b)(brick)
                            })
                            .unwrap();
                        assert!(brick
                            .iter()
                            .enumerate()
                            .all(|(k, &x)| x == (b * 7 + k) as u8));
                    }
                });
            }
        });
        assert_eq!(cache.bytes(), 100 * BRICK_BYTES);
        // One read per brick at least; a thread reads a copy of its own only while
        // another holds the brick's claim (at most once per visit: eight per brick).
        let n = reads.load(Ordering::Relaxed);
        assert!((100..=800).contains(&n), "{n} reads");
        assert!((0..100).all(|b| cache.get(b).is_some()));

        // Keeping the even bricks below 70 frees the others; the kept read back right.
        let mut keep = vec![0u64; 2];
        for b in (0..70).step_by(2) {
            keep[b / 64] |= 1 << (b % 64);
        }
        cache.retain(&keep);
        assert_eq!(cache.bytes(), 35 * BRICK_BYTES);
        for b in 0..100 {
            let kept = b < 70 && b % 2 == 0;
            assert_eq!(cache.get(b).is_some(), kept, "brick {b}");
            if kept {
                assert_eq!(cache.get(b).unwrap()[5], (b * 7 + 5) as u8);
            }
        }
        let mut spare = [0u8; BRICK_BYTES];
        let again = cache.get_or_read(51, &mut spare, fill(51)).unwrap();
        assert_eq!(again[5], (51 * 7 + 5) as u8);

        cache.clear();
        assert_eq!(cache.bytes(), 0);
        assert!((0..100).all(|b| cache.get(b).is_none()));
        let mut spare = [0u8; BRICK_BYTES];
        let failed = cache.get_or_read(3, &mut spare, |_| Err("no".to_string()));
        assert_eq!(failed.err().as_deref(), Some("no"));
        assert!(cache.get(3).is_none() && cache.bytes() == 0);
        // After a clear and a failure the brick is read again, and right.
        let brick = cache.get_or_read(3, &mut spare, fill(3)).unwrap();
        assert_eq!(brick[10], 31);
        assert!(cache.get(3).is_some_and(|b| b[10] == 31));
    }
}
