//! Sparse storage over virtual-grid keys in dense bricks (8×8×8 unless a map chooses
//! 4×4×4, see [`BrickShape`]).
//!
//! A surface touches a thin shell of nodes and cells; a hash table per key spreads that
//! shell over memory, so every lookup is a cache miss and every growth a rehash of
//! everything seen so far. Bricks keep neighbouring keys together: the brick table is
//! small enough to stay in cache, most of a cell's eight corners lie in one brick, and a
//! scan in key order walks one brick at a time (the last brick is remembered). Memory
//! still follows the surface: only touched bricks exist, and an 8³ brick holds values
//! only for the 2³ sub-cubes its keys lie in when the map asks for it
//! ([`BrickShape::CHUNKED`]).

use super::VirtualGrid;
use crate::prefetch::prefetch;
use rayon::prelude::*;
use rustc_hash::FxHashMap;

/// The shape of a brick: 2^S keys along each axis, S from 1 to 3 (8³ bricks by default).
/// Smaller bricks waste less where a surface crosses a brick at a slant (the 1M-particle
/// frame's node cache filled about a fifth of its 8³ bricks' slots, a third of 4³ ones');
/// larger ones keep more of a cell's corners in
/// one brick (343 cells in 512 against 27 in 64). `C`: chunked, see
/// [`BrickShape::CHUNKED`].
pub struct BrickShape<const S: u32, const C: bool = false>;

/// Presence words a brick holds, enough for the largest shape.
const MAX_WORDS: usize = 8;
/// Most chunks a chunked brick is cut into (an 8³ brick's 2³ sub-cubes).
const CHUNKS: usize = 64;
/// A [`BrickMap::chunk_maps`] entry of a sub-cube whose keys have no values allocated.
const NO_CHUNK: u8 = u8::MAX;

impl<const S: u32, const C: bool> BrickShape<S, C> {
    const LOCAL: u32 = (1 << S) - 1;
    /// Keys per brick.
    const KEYS: usize = 1 << (3 * S);
    const WORDS: usize = Self::KEYS.div_ceil(64);
    /// Bits of a brick coordinate (grid coordinates have `AXIS_BITS` = 20).
    const BRICK_AXIS_BITS: u32 = 20 - S;

    /// Brick key and index within the brick of a grid key.
    #[inline]
    fn split(key: u64) -> (u64, usize) {
        let [x, y, z] = VirtualGrid::coords(key);
        let brick = VirtualGrid::key(x >> S, y >> S, z >> S);
        (brick, Self::local(x, y, z))
    }

    /// A chunked brick (`C`, 4³ or 8³) numbers its keys 2³ sub-cube by sub-cube and
    /// allocates a sub-cube's eight values only once one of its keys is set. A surface
    /// crosses a brick in a few of its sub-cubes: the slider's HE, whose 8³ bricks were
    /// about a twentieth full at MNI152's starting surface, held 21.2 MiB of values in
    /// whole bricks against 10.2 in 4³ sub-cubes and 4.8 in 2³ ones. A lookup then reads
    /// the brick's chunk map before the value; maps whose lookups must be a single load
    /// (the correctors' node cache) stay unchunked.
    const CHUNKED: bool = C && S >= 2;
    /// Chunk (sub-cube) edge in bits, chunks along a brick edge in bits, keys per chunk.
    const CB: u32 = 1;
    const AB: u32 = S - Self::CB;
    const CHUNK_KEYS: usize = 1 << (3 * Self::CB);

    /// Index within its brick of the key at (x, y, z): x fastest, or for chunked bricks
    /// the sub-cube (the coordinates but their low bit, x fastest) first, then x fastest
    /// within it.
    #[inline]
    fn local(x: u32, y: u32, z: u32) -> usize {
        if Self::CHUNKED {
            let (h, a, l) = (Self::CB, Self::AB, Self::LOCAL);
            let m = (1 << h) - 1;
            let sub = ((x & l) >> h) | ((y & l) >> h) << a | ((z & l) >> h) << (2 * a);
            (sub << (3 * h) | (x & m) | (y & m) << h | (z & m) << (2 * h)) as usize
        } else {
            let l = Self::LOCAL;
            ((x & l) | (y & l) << S | (z & l) << (2 * S)) as usize
        }
    }

    /// The grid key of index `local` in brick `brick`.
    #[inline]
    fn key(brick: u64, local: usize) -> u64 {
        let [bx, by, bz] = VirtualGrid::coords(brick);
        let l = local as u32;
        let [x, y, z] = if Self::CHUNKED {
            let (h, a) = (Self::CB, Self::AB);
            let (m, am) = ((1 << h) - 1, (1 << a) - 1);
            let (sub, inner) = (l >> (3 * h), l & ((1 << (3 * h)) - 1));
            [
                (sub & am) << h | (inner & m),
                (sub >> a & am) << h | (inner >> h & m),
                (sub >> (2 * a)) << h | (inner >> (2 * h)),
            ]
        } else {
            let m = Self::LOCAL;
            [l & m, l >> S & m, l >> (2 * S)]
        };
        VirtualGrid::key(bx << S | x, by << S | y, bz << S | z)
    }

    /// Where key `local` of a brick whose chunk map is `map` (empty when unchunked) sits
    /// in its values (the key's chunk must have been made).
    #[inline(always)]
    fn slot(map: &[u8], local: usize) -> usize {
        if Self::CHUNKED {
            let k = Self::CHUNK_KEYS;
            map[local / k] as usize * k + local % k
        } else {
            local
        }
    }

    /// [`BrickShape::slot`], first making the key's chunk if it has none (`chunks` of
    /// the brick's are assigned): the brick's values grow by one chunk, or reuse one
    /// they kept from before the brick was freed.
    #[inline]
    fn slot_or_make<T: Copy + Default>(
        chunks: &mut u8,
        map: &mut [u8],
        values: &mut Box<[T]>,
        local: usize,
    ) -> usize {
        if Self::CHUNKED && map[local / Self::CHUNK_KEYS] == NO_CHUNK {
            let c = *chunks;
            map[local / Self::CHUNK_KEYS] = c;
            *chunks += 1;
            let needed = (c as usize + 1) * Self::CHUNK_KEYS;
            if values.len() < needed {
                let mut grown = Vec::with_capacity(needed);
                grown.extend_from_slice(values);
                grown.resize(needed, T::default());
                *values = grown.into_boxed_slice();
            }
        }
        Self::slot(map, local)
    }

    /// Values a new brick is given: all of them, or none for a chunked brick.
    fn new_values<T: Copy + Default>() -> Box<[T]> {
        vec![T::default(); if Self::CHUNKED { 0 } else { Self::KEYS }].into_boxed_slice()
    }

    /// A sort key placing grid keys brick by brick: (brick z, y, x, index in the brick),
    /// in 60 bits. [`BrickMap::insert_runs_in_brick_order`] takes keys in this order.
    #[inline]
    pub fn order(key: u64) -> u64 {
        let [x, y, z] = VirtualGrid::coords(key);
        let bits = Self::BRICK_AXIS_BITS;
        let brick = u64::from(x >> S) | u64::from(y >> S) << bits | u64::from(z >> S) << (2 * bits);
        brick << (3 * S) | Self::local(x, y, z) as u64
    }

    /// The grid key of an [`BrickShape::order`] sort key.
    #[inline]
    pub fn key_of_order(order: u64) -> u64 {
        Self::key(Self::brick_of_order(order), Self::local_of_order(order))
    }

    /// The brick key of an [`BrickShape::order`] sort key.
    #[inline]
    fn brick_of_order(order: u64) -> u64 {
        let brick = order >> (3 * S);
        let mask = (1u64 << Self::BRICK_AXIS_BITS) - 1;
        VirtualGrid::key(
            (brick & mask) as u32,
            (brick >> Self::BRICK_AXIS_BITS & mask) as u32,
            (brick >> (2 * Self::BRICK_AXIS_BITS)) as u32,
        )
    }

    /// The index in its brick of an [`BrickShape::order`] sort key.
    #[inline]
    fn local_of_order(order: u64) -> usize {
        (order & (Self::KEYS as u64 - 1)) as usize
    }

    /// The brick holding all eight corners of `cell` and their indices in it, unless the
    /// cell straddles a brick boundary.
    #[inline]
    fn corners_in_one_brick(cell: u64) -> Option<(u64, [usize; 8])> {
        let [x, y, z] = VirtualGrid::coords(cell);
        let l = Self::LOCAL;
        if (x & l) == l || (y & l) == l || (z & l) == l {
            return None;
        }
        let (brick, local) = Self::split(cell);
        Some((
            brick,
            std::array::from_fn(|k| {
                let [dx, dy, dz] = super::corner_offset(k);
                if Self::CHUNKED {
                    // One step along axis a moves 2^(h·a) within a sub-cube; from its
                    // last layer it moves into the next sub-cube instead.
                    let (h, b) = (Self::CB, Self::AB);
                    let m = (1 << h) - 1;
                    let step = |c: u32, a: u32| {
                        if c & m == m {
                            (1 << (3 * h + b * a)) - (m << (h * a))
                        } else {
                            1 << (h * a)
                        }
                    };
                    local + (dx * step(x, 0) + dy * step(y, 1) + dz * step(z, 2)) as usize
                } else {
                    local + (dx | dy << S | dz << (2 * S)) as usize
                }
            }),
        ))
    }
}

/// One brick's presence bits and values, borrowed to be filled by one thread.
type BrickMut<'a, T> = (&'a mut Meta, &'a mut Box<[T]>, &'a mut [u8]);

/// What a brick holds besides its values: a presence bit per key, how many are present
/// and its own key. Kept apart from the values (in [`BrickMap::meta`]) so that a lookup's
/// presence word and value are two independent loads at addresses known from the brick
/// slot, not a load of the brick and then of a boxed value array behind it.
#[derive(Clone, Copy)]
struct Meta {
    present: [u64; MAX_WORDS],
    /// Keys present (0: the brick is free, on the map's free list).
    count: u32,
    /// Chunked bricks: how many chunks of the brick's values are assigned to sub-cubes
    /// (its [`BrickMap::chunk_maps`] entry says which).
    chunks: u8,
    /// The brick's own key (grid key divided by the brick edge), for iteration.
    key: u64,
}

/// Where each brick sits in `bricks`.
enum Index {
    /// Any keys: brick key -> brick.
    Hashed(FxHashMap<u64, u32>),
    /// Keys inside a known box: one slot per brick of the box ([`NO_BRICK`] where none),
    /// found by arithmetic, no hashing; costs 4 bytes per brick of the box.
    Dense { bricks: [u64; 3], slots: Vec<u32> },
}

const NO_BRICK: u32 = u32::MAX;

/// A map from grid keys to `T`, stored brick by brick.
pub struct BrickMap<T, const S: u32 = 3, const C: bool = false> {
    index: Index,
    /// Brick `i`'s values. Boxed one by one so that growing the map never copies (or
    /// briefly doubles) what it holds; the pointers sit in one small array that stays
    /// in cache, so a lookup still goes from the slot straight to the value's line.
    values: Vec<Box<[T]>>,
    meta: Vec<Meta>,
    /// Chunked maps: for each brick, the chunk of its values holding each sub-cube's
    /// keys ([`NO_CHUNK`]: none yet); a sub-cube whose keys are all removed keeps its
    /// chunk until the brick is freed. Apart from `meta` so that unchunked maps do not
    /// carry it; empty for them.
    chunk_maps: Vec<[u8; CHUNKS]>,
    /// Bricks emptied by [`BrickMap::remove`], reused before new ones are allocated, so
    /// a map whose keys move (a sliding surface) holds the bricks of its widest extent,
    /// not of every key it ever held.
    free: Vec<u32>,
    /// How many bricks at the start of `free` have had their values freed
    /// ([`BrickMap::release_free`]).
    released: usize,
    len: usize,
    /// (brick key, brick index) of the last brick found, for scans in key order.
    last: Option<(u64, u32)>,
}

impl<T: Copy + Default, const S: u32, const C: bool> Default for BrickMap<T, S, C> {
    fn default() -> Self {
        BrickMap::with_index(Index::Hashed(FxHashMap::default()))
    }
}

impl<T: Copy + Default, const S: u32, const C: bool> BrickMap<T, S, C> {
    fn with_index(index: Index) -> Self {
        const { assert!(S >= 1 && S <= 3, "bricks of 2³ to 8³ keys") };
        BrickMap {
            index,
            values: Vec::new(),
            meta: Vec::new(),
            chunk_maps: Vec::new(),
            free: Vec::new(),
            released: 0,
            len: 0,
            last: None,
        }
    }

    /// A map for keys whose coordinates lie below `extent` (x, y, z), which finds bricks
    /// by arithmetic instead of hashing, at 4 bytes per brick of the box (1/128 byte per
    /// key with 8³ bricks, 1/16 with 4³). Inserting a key outside the box panics; looking
    /// one up finds nothing.
    pub fn within(extent: [u32; 3]) -> Self {
        let bricks = Self::bricks_within(extent);
        let slots = vec![NO_BRICK; (bricks[0] * bricks[1] * bricks[2]) as usize];
        BrickMap::with_index(Index::Dense { bricks, slots })
    }

    /// A map for keys below `extent`: [`BrickMap::within`] when its index takes at most
    /// `index_bytes`, else one found by hashing (any keys).
    pub fn for_extent(extent: [u32; 3], index_bytes: u64) -> Self {
        if Self::dense_index_bytes(extent) <= index_bytes {
            BrickMap::within(extent)
        } else {
            BrickMap::default()
        }
    }

    /// Bytes of [`BrickMap::within`]'s index for `extent`.
    fn dense_index_bytes(extent: [u32; 3]) -> u64 {
        let [x, y, z] = Self::bricks_within(extent);
        4 * x * y * z
    }

    /// Bricks along each axis of the box `extent`.
    fn bricks_within(extent: [u32; 3]) -> [u64; 3] {
        extent.map(|n| (n as u64).div_ceil(1 << S))
    }

    /// Number of keys present.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True when no key is present.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Bytes held by the bricks (values and presence bits) and their index.
    pub fn bytes(&self) -> u64 {
        let values: usize = self.values.iter().map(|b| b.len()).sum();
        let index = match &self.index {
            Index::Hashed(map) => map.capacity() * 16,
            Index::Dense { slots, .. } => slots.len() * 4,
        };
        (values * std::mem::size_of::<T>()
            + self.meta.len() * std::mem::size_of::<Meta>()
            + self.chunk_maps.len() * CHUNKS
            + index) as u64
    }

    /// Most bytes one more brick adds to [`BrickMap::bytes`]: all its values (a chunked
    /// brick can grow to them), its meta, and a hashed index's entry counted twice for
    /// the table's growth.
    pub fn bytes_per_new_brick(&self) -> u64 {
        let chunk_map = if BrickShape::<S, C>::CHUNKED {
            CHUNKS
        } else {
            0
        };
        let index = match &self.index {
            Index::Hashed(_) => 32,
            Index::Dense { .. } => 0,
        };
        (BrickShape::<S, C>::KEYS * std::mem::size_of::<T>()
            + std::mem::size_of::<Meta>()
            + std::mem::size_of::<Box<[T]>>()
            + chunk_map
            + index) as u64
    }

    /// How many of the bricks holding the keys `orders` ([`BrickShape::order`] sort keys,
    /// ascending) are not in the map: what inserting them would add at most (fewer where
    /// emptied bricks are reused). Counted before inserting, so that a caller can refuse
    /// a batch its memory budget cannot hold instead of finding out after allocating it.
    pub fn absent_bricks_in_order(&self, orders: impl IntoIterator<Item = u64>) -> usize {
        let mut absent = 0;
        let mut last = None;
        for o in orders {
            let brick = o >> (3 * S);
            if last != Some(brick) {
                last = Some(brick);
                let key = BrickShape::<S, C>::brick_of_order(o);
                absent += usize::from(self.brick_index(key).is_none());
            }
        }
        absent
    }

    /// Frees the values of emptied bricks beyond a quarter as many as are in use: a map
    /// whose keys shrank (a surface after a jump) then holds a quarter more than its
    /// bricks, not those of its widest extent, while one whose keys move at a steady
    /// size (a few percent of its bricks emptied and refilled at a time) keeps reusing
    /// its free bricks without allocating. Returns how many bricks it freed.
    pub fn release_free(&mut self) -> usize {
        let in_use = self.meta.len() - self.free.len();
        let holding = self.free.len() - self.released;
        let extra = holding.saturating_sub((in_use / 4).max(1));
        // Bricks are reused from the end of the free list: release those nearest its
        // start, after the ones already released.
        let start = self.released;
        for &i in &self.free[start..start + extra] {
            self.values[i as usize] = Box::default();
        }
        self.released += extra;
        extra
    }

    /// Removes every key and drops the bricks (the dense index keeps its size).
    pub fn clear(&mut self) {
        match &mut self.index {
            Index::Hashed(map) => *map = FxHashMap::default(),
            Index::Dense { slots, .. } => slots.fill(NO_BRICK),
        }
        self.values = Vec::new();
        self.meta = Vec::new();
        self.chunk_maps = Vec::new();
        self.free = Vec::new();
        self.released = 0;
        self.len = 0;
        self.last = None;
    }

    /// Slot of brick key `brick` in a dense index, None outside its box.
    #[inline]
    fn dense_slot(bricks: &[u64; 3], brick: u64) -> Option<usize> {
        let [x, y, z] = VirtualGrid::coords(brick).map(u64::from);
        (x < bricks[0] && y < bricks[1] && z < bricks[2])
            .then(|| (x + bricks[0] * (y + bricks[1] * z)) as usize)
    }

    #[inline(always)]
    fn brick_index(&self, brick: u64) -> Option<u32> {
        match self.last {
            Some((b, i)) if b == brick => Some(i),
            _ => match &self.index {
                Index::Hashed(map) => map.get(&brick).copied(),
                Index::Dense { bricks, slots } => Self::dense_slot(bricks, brick)
                    .map(|s| slots[s])
                    .filter(|&i| i != NO_BRICK),
            },
        }
    }

    /// Brick `i`'s chunk map in `maps` (empty when the map is unchunked).
    #[inline(always)]
    fn chunk_map(maps: &[[u8; CHUNKS]], i: usize) -> &[u8] {
        if BrickShape::<S, C>::CHUNKED {
            &maps[i]
        } else {
            &[]
        }
    }

    /// Where key `local` of brick `i` sits in its values.
    #[inline(always)]
    fn slot(&self, i: usize, local: usize) -> usize {
        BrickShape::<S, C>::slot(Self::chunk_map(&self.chunk_maps, i), local)
    }

    /// Whether key `local` of brick `i` is present.
    #[inline(always)]
    fn present(&self, i: usize, local: usize) -> bool {
        self.meta[i].present[local / 64] >> (local % 64) & 1 == 1
    }

    /// Asks the processor to start loading the presence word and the value of `key`, so
    /// that a loop over scattered keys can overlap the cache misses of the keys ahead
    /// with the work on the current one. Only a hint: no effect on the map. In a chunked
    /// brick the value's place is read from the brick's meta first: without the value
    /// hint the slider's 1 % steps took about a tenth longer.
    #[inline]
    pub fn prefetch(&self, key: u64) {
        let (brick, local) = BrickShape::<S, C>::split(key);
        if let Some(i) = self.brick_index(brick) {
            let i = i as usize;
            let meta = &self.meta[i];
            prefetch(&meta.present[local / 64]);
            if !BrickShape::<S, C>::CHUNKED {
                prefetch(&self.values[i][local]);
            } else if self.chunk_maps[i][local / BrickShape::<S, C>::CHUNK_KEYS] != NO_CHUNK {
                // The chunk comes from the brick's chunk map: one load more before the hint.
                prefetch(&self.values[i][self.slot(i, local)]);
            }
        }
    }

    fn brick_index_or_insert(&mut self, brick: u64) -> u32 {
        self.brick_index_or_make(brick, true)
    }

    /// The index of `brick`, made when absent. A made brick's values are allocated now
    /// when `allocate`, else left empty for the caller to allocate (see
    /// [`BrickMap::insert_runs_in_brick_order`]).
    fn brick_index_or_make(&mut self, brick: u64, allocate: bool) -> u32 {
        if let Some((b, i)) = self.last {
            if b == brick {
                return i;
            }
        }
        let next = match self.free.last() {
            Some(&f) => f,
            None => self.meta.len() as u32,
        };
        let i = match &mut self.index {
            Index::Hashed(map) => *map.entry(brick).or_insert(next),
            Index::Dense { bricks, slots } => {
                let s = Self::dense_slot(bricks, brick).unwrap_or_else(|| {
                    panic!(
                        "key {:?} outside the map's box",
                        VirtualGrid::coords(brick).map(|c| c << S)
                    )
                });
                if slots[s] == NO_BRICK {
                    slots[s] = next;
                }
                slots[s]
            }
        };
        if i == next {
            if self.free.pop().is_some() {
                self.released = self.released.min(self.free.len());
                let meta = &mut self.meta[i as usize];
                meta.key = brick;
                // A chunked brick reassigns the chunks its values kept, in order.
                meta.chunks = 0;
                if BrickShape::<S, C>::CHUNKED {
                    self.chunk_maps[i as usize] = [NO_CHUNK; CHUNKS];
                }
                let values = &mut self.values[i as usize];
                if values.is_empty() && allocate {
                    *values = BrickShape::<S, C>::new_values();
                }
            } else {
                self.values.push(if allocate {
                    BrickShape::<S, C>::new_values()
                } else {
                    Box::default()
                });
                if BrickShape::<S, C>::CHUNKED {
                    self.chunk_maps.push([NO_CHUNK; CHUNKS]);
                }
                self.meta.push(Meta {
                    present: [0; MAX_WORDS],
                    count: 0,
                    chunks: 0,
                    key: brick,
                });
            }
        }
        self.last = Some((brick, i));
        i
    }

    /// Removes `key`, returning its value; a brick left empty goes to the free list.
    #[inline]
    pub fn remove(&mut self, key: u64) -> Option<T> {
        let (brick, local) = BrickShape::<S, C>::split(key);
        let i = self.brick_index(brick)?;
        let m = &mut self.meta[i as usize];
        let word = &mut m.present[local / 64];
        let bit = 1u64 << (local % 64);
        if *word & bit == 0 {
            return None;
        }
        *word &= !bit;
        m.count -= 1;
        self.len -= 1;
        let at = BrickShape::<S, C>::slot(Self::chunk_map(&self.chunk_maps, i as usize), local);
        let value = self.values[i as usize][at];
        if m.count == 0 {
            match &mut self.index {
                Index::Hashed(map) => {
                    map.remove(&brick);
                }
                Index::Dense { bricks, slots } => {
                    let s = Self::dense_slot(bricks, brick).expect("brick was found");
                    slots[s] = NO_BRICK;
                }
            }
            self.free.push(i);
            if self.last.is_some_and(|(b, _)| b == brick) {
                self.last = None;
            }
        }
        Some(value)
    }

    /// Inserts runs of `N` consecutive [`BrickShape::order`] sort keys: run `i` holds the
    /// keys from `runs[i]` · N (`runs` ascending, none repeated), and `values(i)` gives its
    /// N values with a mask of those to insert (bit l for key `runs[i]` · N + l; at least
    /// one, or the brick is made for nothing). A run lies in one brick: a row along x in
    /// an unchunked brick, in a chunked one consecutive keys of a sub-cube. The
    /// values are computed where they are stored, each brick's by one thread, so a batch
    /// needs no list of its values besides the map (a node-cache wave computes a row of
    /// nodes at a time: its values went through two lists of a million entries, which
    /// took longer to fill and insert than the nodes took to evaluate). Returns how many
    /// keys were new. Runs of one key insert a sorted list of keys (`N` = 1, mask 1).
    pub fn insert_runs_in_brick_order<const N: usize>(
        &mut self,
        runs: &[u64],
        values: impl Fn(usize) -> ([T; N], u32) + Sync,
    ) -> usize
    where
        T: Send + Sync,
    {
        const {
            assert!(
                N.is_power_of_two() && N <= 1 << S,
                "a run lies within one brick"
            )
        };
        debug_assert!(runs.windows(2).all(|w| w[0] < w[1]), "ascending, unique");
        let run_bits = N.trailing_zeros();
        let brick_of_run = |r: u64| r >> (3 * S - run_bits);
        // Bricks are found (or made) one by one, then filled in parallel.
        let mut groups: Vec<(u32, std::ops::Range<usize>)> = Vec::new();
        let mut start = 0;
        while start < runs.len() {
            let brick = brick_of_run(runs[start]);
            let end = start + runs[start..].partition_point(|&r| brick_of_run(r) == brick);
            // New bricks' values are allocated (and zeroed) by the thread that fills
            // them: one at a time here, they were the serial part of a node-cache wave
            // (a kilobyte each, tens of thousands a wave on the demo frame).
            let brick = BrickShape::<S, C>::brick_of_order(runs[start] << run_bits);
            let i = self.brick_index_or_make(brick, false);
            groups.push((i, start..end));
            start = end;
        }
        // Each group's brick borrowed mutably: in slot order, stepping the slice
        // iterators (O(1) a step) over the bricks this batch does not touch, so the cost
        // follows the batch, not the map.
        groups.sort_unstable_by_key(|&(i, _)| i);
        let (mut metas, mut boxes) = (self.meta.iter_mut(), self.values.iter_mut());
        let mut maps = self.chunk_maps.iter_mut();
        let mut next = 0;
        let jobs: Vec<(BrickMut<'_, T>, std::ops::Range<usize>)> = groups
            .into_iter()
            .map(|(i, range)| {
                let skip = i as usize - next;
                next = i as usize + 1;
                let brick = (metas.nth(skip), boxes.nth(skip));
                let (Some(meta), Some(values)) = brick else {
                    unreachable!("brick {i} was just found or made")
                };
                // Unchunked maps have no chunk maps: an empty one each.
                let map: &mut [u8] = match maps.nth(skip) {
                    Some(m) => m,
                    None => &mut [],
                };
                ((meta, values, map), range)
            })
            .collect();
        let added: usize = jobs
            .into_par_iter()
            .map(|((meta, brick, map), range)| {
                if brick.is_empty() {
                    *brick = BrickShape::<S, C>::new_values();
                }
                let mut added = 0;
                for i in range {
                    let (run, mut mask) = values(i);
                    debug_assert!(mask != 0 && mask >> N == 0, "run {i}: mask {mask:#b}");
                    while mask != 0 {
                        let l = mask.trailing_zeros();
                        mask &= mask - 1;
                        let order = runs[i] << run_bits | u64::from(l);
                        let local = BrickShape::<S, C>::local_of_order(order);
                        let word = &mut meta.present[local / 64];
                        let bit = 1u64 << (local % 64);
                        added += usize::from(*word & bit == 0);
                        *word |= bit;
                        let at =
                            BrickShape::<S, C>::slot_or_make(&mut meta.chunks, map, brick, local);
                        brick[at] = run[l as usize];
                    }
                }
                meta.count += added as u32;
                added
            })
            .sum();
        self.len += added;
        added
    }

    /// The value at `key`, if present, to change in place.
    #[inline]
    pub fn get_mut(&mut self, key: u64) -> Option<&mut T> {
        let (brick, local) = BrickShape::<S, C>::split(key);
        let i = self.brick_index(brick)? as usize;
        let slot = self.slot(i, local);
        self.present(i, local).then(|| &mut self.values[i][slot])
    }

    /// The value at `key`, to change in place, inserting `value` first when absent (one
    /// brick lookup either way).
    #[inline]
    pub fn get_or_insert(&mut self, key: u64, value: T) -> &mut T {
        let (slot, new) = self.entry(key);
        if new {
            *slot = value;
        }
        slot
    }

    /// The slot of `key`, made present (its brick, chunk and presence bit), and whether
    /// it was absent before: what `insert` and `get_or_insert` share.
    #[inline(always)]
    fn entry(&mut self, key: u64) -> (&mut T, bool) {
        let (brick, local) = BrickShape::<S, C>::split(key);
        let i = self.brick_index_or_insert(brick) as usize;
        let m = &mut self.meta[i];
        let map: &mut [u8] = match self.chunk_maps.get_mut(i) {
            Some(map) => map,
            None => &mut [],
        };
        let slot = BrickShape::<S, C>::slot_or_make(&mut m.chunks, map, &mut self.values[i], local);
        let word = &mut m.present[local / 64];
        let bit = 1u64 << (local % 64);
        let new = *word & bit == 0;
        *word |= bit;
        m.count += new as u32;
        self.len += new as usize;
        (&mut self.values[i][slot], new)
    }

    /// Every (key, value) present, brick by brick (not in key order).
    pub fn iter(&self) -> impl Iterator<Item = (u64, T)> + '_ {
        self.meta
            .iter()
            .enumerate()
            .filter(|(_, m)| m.count > 0)
            .flat_map(|(i, m)| {
                let values = &self.values[i];
                let map = Self::chunk_map(&self.chunk_maps, i);
                let brick = m.key;
                (0..BrickShape::<S, C>::WORDS)
                    .flat_map(move |w| {
                        let mut bits = m.present[w];
                        std::iter::from_fn(move || {
                            (bits != 0).then(|| {
                                let local = w * 64 + bits.trailing_zeros() as usize;
                                bits &= bits - 1;
                                local
                            })
                        })
                    })
                    .map(move |local| {
                        let key = BrickShape::<S, C>::key(brick, local);
                        (key, values[BrickShape::<S, C>::slot(map, local)])
                    })
            })
    }

    /// The value at `key`, if present.
    #[inline]
    pub fn get(&self, key: u64) -> Option<T> {
        let (brick, local) = BrickShape::<S, C>::split(key);
        let i = self.brick_index(brick)? as usize;
        self.present(i, local)
            .then(|| self.values[i][self.slot(i, local)])
    }

    /// Whether `key` is present.
    #[inline]
    pub fn contains(&self, key: u64) -> bool {
        let (brick, local) = BrickShape::<S, C>::split(key);
        self.brick_index(brick)
            .is_some_and(|i| self.present(i as usize, local))
    }

    /// Sets `key` to `value`; returns true when the key was not present before.
    #[inline]
    pub fn insert(&mut self, key: u64, value: T) -> bool {
        let (slot, new) = self.entry(key);
        *slot = value;
        new
    }

    /// The values at the eight corners of `cell`, with one brick lookup when the cell
    /// does not straddle a brick boundary. Every corner must be present.
    #[inline]
    pub fn corners(&self, cell: u64) -> [T; 8] {
        if let Some((brick, at)) = BrickShape::<S, C>::corners_in_one_brick(cell) {
            if let Some(i) = self.brick_index(brick) {
                let i = i as usize;
                let (map, values) = (Self::chunk_map(&self.chunk_maps, i), &self.values[i]);
                return at.map(|a| values[BrickShape::<S, C>::slot(map, a)]);
            }
        }
        std::array::from_fn(|k| {
            self.get(VirtualGrid::corner(cell, k))
                .expect("corner evaluated before it is read")
        })
    }

    /// The values at the eight corners of `cell`, `absent` where a corner has none, with
    /// one brick lookup when the cell does not straddle a brick boundary.
    #[inline]
    pub fn corners_or(&self, cell: u64, absent: T) -> [T; 8] {
        if let Some((brick, at)) = BrickShape::<S, C>::corners_in_one_brick(cell) {
            let Some(i) = self.brick_index(brick) else {
                return [absent; 8];
            };
            let i = i as usize;
            let (present, values) = (&self.meta[i].present, &self.values[i]);
            let map = Self::chunk_map(&self.chunk_maps, i);
            // A plain loop: `at.map` compiled to a fallible-map adapter costing a third
            // more instructions here.
            let mut out = [absent; 8];
            for (o, &a) in out.iter_mut().zip(&at) {
                if present[a / 64] >> (a % 64) & 1 == 1 {
                    *o = values[BrickShape::<S, C>::slot(map, a)];
                }
            }
            return out;
        }
        let mut found = None;
        std::array::from_fn(|k| {
            self.get_near(VirtualGrid::corner(cell, k), &mut found)
                .unwrap_or(absent)
        })
    }

    /// [`BrickMap::get`] for keys that mostly share a brick (a cell's corners across a
    /// brick face): `found` remembers the last brick looked up, so the eight corners of a
    /// cell straddling one face cost two brick lookups, not eight.
    #[inline]
    fn get_near(&self, key: u64, found: &mut Option<(u64, Option<u32>)>) -> Option<T> {
        let (brick, local) = BrickShape::<S, C>::split(key);
        let i = match *found {
            Some((b, i)) if b == brick => i,
            _ => {
                let i = self.brick_index(brick);
                *found = Some((brick, i));
                i
            }
        }?;
        let i = i as usize;
        self.present(i, local)
            .then(|| self.values[i][self.slot(i, local)])
    }

    /// Bit k set when corner k of `cell` is present, with one brick lookup when the cell
    /// does not straddle a brick boundary.
    #[inline]
    pub fn present_corners(&self, cell: u64) -> u8 {
        if let Some((brick, at)) = BrickShape::<S, C>::corners_in_one_brick(cell) {
            let Some(i) = self.brick_index(brick) else {
                return 0;
            };
            let present = &self.meta[i as usize].present;
            return (0..8).fold(0u8, |mask, k| {
                mask | ((present[at[k] / 64] >> (at[k] % 64) & 1) as u8) << k
            });
        }
        (0..8).fold(0u8, |mask, k| {
            mask | u8::from(self.contains(VirtualGrid::corner(cell, k))) << k
        })
    }
}

/// A set of grid keys, stored brick by brick.
#[derive(Default)]
pub struct BrickSet {
    map: BrickMap<()>,
}

impl BrickSet {
    /// A set for keys below `extent` (see [`BrickMap::for_extent`]).
    pub fn for_extent(extent: [u32; 3], index_bytes: u64) -> Self {
        BrickSet {
            map: BrickMap::for_extent(extent, index_bytes),
        }
    }

    /// Adds `key`; true when it was not in the set.
    #[inline]
    pub fn insert(&mut self, key: u64) -> bool {
        self.map.insert(key, ())
    }

    /// Whether `key` is in the set.
    #[inline]
    pub fn contains(&self, key: u64) -> bool {
        self.map.contains(key)
    }

    /// Bytes the set holds.
    pub fn bytes(&self) -> u64 {
        self.map.bytes()
    }

    /// Most bytes one more brick adds to [`BrickSet::bytes`].
    pub fn bytes_per_new_brick(&self) -> u64 {
        self.map.bytes_per_new_brick()
    }
}

impl FromIterator<u64> for BrickSet {
    fn from_iter<I: IntoIterator<Item = u64>>(keys: I) -> Self {
        let mut set = BrickSet::default();
        for k in keys {
            set.insert(k);
        }
        set
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    #[test]
    fn agrees_with_a_hash_map_across_brick_boundaries() {
        agrees_with_a_hash_map_across_brick_boundaries_for::<2, false>();
        agrees_with_a_hash_map_across_brick_boundaries_for::<2, true>();
        agrees_with_a_hash_map_across_brick_boundaries_for::<3, false>();
        agrees_with_a_hash_map_across_brick_boundaries_for::<3, true>();
    }

    fn agrees_with_a_hash_map_across_brick_boundaries_for<const S: u32, const C: bool>() {
        let mut next = crate::test_rng::lcg(7);
        let mut rnd = |n: u32| ((next() >> 22) % n as u64) as u32;
        let mut map = BrickMap::<u64, S, C>::default();
        let mut reference = HashMap::new();
        for _ in 0..20_000 {
            let key = VirtualGrid::key(rnd(40), rnd(40), rnd(40));
            let value = rnd(1000) as u64;
            assert_eq!(
                map.insert(key, value),
                reference.insert(key, value).is_none()
            );
        }
        assert_eq!(map.len(), reference.len());
        for x in 0..41 {
            for y in 0..41 {
                for z in 0..41 {
                    let key = VirtualGrid::key(x, y, z);
                    assert_eq!(map.get(key), reference.get(&key).copied());
                    assert_eq!(map.contains(key), reference.contains_key(&key));
                }
            }
        }
    }

    /// A map's (key, value) entries in key order, to compare two maps.
    fn sorted_entries<const S: u32, const C: bool>(map: &BrickMap<u64, S, C>) -> Vec<(u64, u64)> {
        let mut entries: Vec<_> = map.iter().collect();
        entries.sort_unstable();
        entries
    }

    /// Batches inserted brick by brick (in parallel) give the map single inserts give,
    /// for both indexes, over keys that repeat across batches; brick order round-trips
    /// at the largest coordinates too.
    #[test]
    fn inserts_in_brick_order_agree_with_single_inserts() {
        inserts_in_brick_order_agree_with_single_inserts_for::<2, false>();
        inserts_in_brick_order_agree_with_single_inserts_for::<2, true>();
        inserts_in_brick_order_agree_with_single_inserts_for::<3, false>();
        inserts_in_brick_order_agree_with_single_inserts_for::<3, true>();
    }

    fn inserts_in_brick_order_agree_with_single_inserts_for<const S: u32, const C: bool>() {
        let top = (1u32 << 20) - 1;
        for key in [
            VirtualGrid::key(top, 3, top),
            VirtualGrid::key(9, top, 17),
            0,
        ] {
            assert_eq!(
                BrickShape::<S, C>::key_of_order(BrickShape::<S, C>::order(key)),
                key
            );
        }
        let mut next = crate::test_rng::lcg(11);
        let mut rnd = |n: u32| ((next() >> 22) % n as u64) as u32;
        for mut batched in [
            BrickMap::<u64, S, C>::default(),
            BrickMap::within([40, 40, 40]),
        ] {
            let mut single = BrickMap::<u64, S, C>::default();
            for batch in 0..6 {
                let mut orders: Vec<u64> = (0..3_000)
                    .map(|_| BrickShape::<S, C>::order(VirtualGrid::key(rnd(40), rnd(40), rnd(40))))
                    .collect();
                orders.sort_unstable();
                orders.dedup();
                let values: Vec<u64> = orders.iter().map(|&o| o ^ batch).collect();
                let (bricks, absent) = (
                    batched.meta.len(),
                    batched.absent_bricks_in_order(orders.iter().copied()),
                );
                batched.insert_runs_in_brick_order::<1>(&orders, |i| ([values[i]], 1));
                assert_eq!(batched.meta.len() - bricks, absent, "bricks counted ahead");
                // The per-brick bound holds over the whole map (a hashed index grows by
                // doubling, so one batch may pay for the next ones' entries).
                assert!(
                    batched.bytes()
                        <= batched.meta.len() as u64 * batched.bytes_per_new_brick() + 64,
                    "{} bytes for {} bricks",
                    batched.bytes(),
                    batched.meta.len()
                );
                for (&o, &v) in orders.iter().zip(&values) {
                    single.insert(BrickShape::<S, C>::key_of_order(o), v);
                }
                assert_eq!(batched.len(), single.len());
            }
            assert_eq!(sorted_entries(&batched), sorted_entries(&single));
        }
    }

    /// Runs of 2 and 4 keys inserted brick by brick, each with a random mask, give the
    /// map that single inserts of the masked keys give, and count the new keys.
    #[test]
    fn runs_in_brick_order_insert_the_masked_keys_of_each_run() {
        runs_in_brick_order_insert_the_masked_keys_of_each_run_for::<2, 2, false>();
        runs_in_brick_order_insert_the_masked_keys_of_each_run_for::<4, 2, false>();
        runs_in_brick_order_insert_the_masked_keys_of_each_run_for::<4, 3, true>();
    }

    fn runs_in_brick_order_insert_the_masked_keys_of_each_run_for<
        const N: usize,
        const S: u32,
        const C: bool,
    >() {
        let mut next = crate::test_rng::lcg(23);
        let mut rnd = |n: u32| ((next() >> 22) % n as u64) as u32;
        let bits = N.trailing_zeros();
        for mut batched in [
            BrickMap::<u64, S, C>::default(),
            BrickMap::within([40, 40, 40]),
        ] {
            let mut single = BrickMap::<u64, S, C>::default();
            for batch in 0..4 {
                let mut runs: Vec<u64> = (0..1_500)
                    .map(|_| {
                        BrickShape::<S, C>::order(VirtualGrid::key(rnd(40), rnd(40), rnd(40)))
                            >> bits
                    })
                    .collect();
                runs.sort_unstable();
                runs.dedup();
                let masks: Vec<u32> = runs.iter().map(|_| 1 + rnd((1 << N) - 1)).collect();
                let value = |o: u64| o.wrapping_mul(0x9e37_79b9) ^ batch;
                let before = single.len();
                for (&r, &m) in runs.iter().zip(&masks) {
                    for l in (0..N as u32).filter(|l| m >> l & 1 == 1) {
                        let o = r << bits | u64::from(l);
                        single.insert(BrickShape::<S, C>::key_of_order(o), value(o));
                    }
                }
                let added = batched.insert_runs_in_brick_order::<N>(&runs, |i| {
                    (
                        std::array::from_fn(|l| value(runs[i] << bits | l as u64)),
                        masks[i],
                    )
                });
                assert_eq!(added, single.len() - before, "new keys counted");
                assert_eq!(batched.len(), single.len());
            }
            assert_eq!(sorted_entries(&batched), sorted_entries(&single));
        }
    }

    /// Inserts, removals and in-place changes against a hash map, for both indexes: the
    /// map agrees at every key of the box, its iteration lists exactly the reference's
    /// entries, an emptied brick is reused, and `clear` empties it.
    #[test]
    fn remove_get_mut_iter_and_clear_agree_with_a_hash_map() {
        remove_get_mut_iter_and_clear_agree_with_a_hash_map_for::<2, false>();
        remove_get_mut_iter_and_clear_agree_with_a_hash_map_for::<2, true>();
        remove_get_mut_iter_and_clear_agree_with_a_hash_map_for::<3, false>();
        remove_get_mut_iter_and_clear_agree_with_a_hash_map_for::<3, true>();
    }

    fn remove_get_mut_iter_and_clear_agree_with_a_hash_map_for<const S: u32, const C: bool>() {
        const SIDE: u32 = 27;
        for mut map in [
            BrickMap::<u64, S, C>::default(),
            BrickMap::<u64, S, C>::within([SIDE, SIDE - 3, SIDE - 7]),
        ] {
            let mut next = crate::test_rng::lcg(11);
            let mut rnd = |n: u32| ((next() >> 22) % n as u64) as u32;
            let mut reference = HashMap::new();
            for round in 0..6 {
                // Keys drift along x from round to round, as a sliding surface's do.
                for _ in 0..4_000 {
                    let x = (rnd(12) + 3 * round).min(SIDE - 1);
                    let key = VirtualGrid::key(x, rnd(SIDE - 3), rnd(SIDE - 7));
                    match rnd(5) {
                        0 => assert_eq!(map.remove(key), reference.remove(&key)),
                        4 => {
                            *map.get_or_insert(key, 50) += 1;
                            *reference.entry(key).or_insert(50) += 1;
                        }
                        1 => {
                            if let Some(v) = map.get_mut(key) {
                                *v += 5;
                            }
                            if let Some(v) = reference.get_mut(&key) {
                                *v += 5;
                            }
                        }
                        _ => {
                            let value = rnd(1000) as u64;
                            assert_eq!(
                                map.insert(key, value),
                                reference.insert(key, value).is_none()
                            );
                        }
                    }
                }
                // Remove the oldest keys, emptying whole bricks.
                let old: Vec<u64> = reference
                    .keys()
                    .copied()
                    .filter(|&k| VirtualGrid::coords(k)[0] < 3 * round)
                    .collect();
                for k in old {
                    assert_eq!(map.remove(k), reference.remove(&k));
                }
                if round % 2 == 1 {
                    // Released bricks get their values again when reused.
                    map.release_free();
                }
                assert_eq!(map.len(), reference.len());
                let mut listed: Vec<(u64, u64)> = map.iter().collect();
                listed.sort_unstable();
                let mut want: Vec<(u64, u64)> = reference.iter().map(|(&k, &v)| (k, v)).collect();
                want.sort_unstable();
                assert_eq!(listed, want, "round {round}");
                for x in 0..SIDE + 2 {
                    for y in 0..SIDE {
                        for z in 0..SIDE {
                            let key = VirtualGrid::key(x, y, z);
                            assert_eq!(map.get(key), reference.get(&key).copied());
                        }
                    }
                }
            }
            // A brick emptied is reused for the next new brick, not added to.
            map.clear();
            for x in 0..4 {
                map.insert(VirtualGrid::key(x, 1, 2), x as u64);
            }
            for x in 0..4 {
                assert_eq!(map.remove(VirtualGrid::key(x, 1, 2)), Some(x as u64));
            }
            map.insert(VirtualGrid::key(17, 9, 9), 4);
            assert_eq!(map.meta.len(), 1);
            assert_eq!(
                map.iter().collect::<Vec<_>>(),
                [(VirtualGrid::key(17, 9, 9), 4)]
            );
            // Emptied bricks beyond those in use give their values back.
            let side = 1u32 << S;
            for b in 0..3 {
                map.insert(VirtualGrid::key(b * side, 1, 2), b as u64);
            }
            let full = map.bytes();
            for b in 0..3 {
                map.remove(VirtualGrid::key(b * side, 1, 2));
            }
            // Three emptied, one in use: two freed, and nothing more on a second call.
            assert_eq!(map.release_free(), 2);
            assert_eq!(map.release_free(), 0);
            // Each brick held one key: a chunk of 64 values when chunked, else all.
            let keys = if BrickShape::<S, C>::CHUNKED {
                BrickShape::<S, C>::CHUNK_KEYS
            } else {
                BrickShape::<S, C>::KEYS
            };
            let brick = keys * 8;
            assert!(
                map.bytes() + 2 * brick as u64 <= full,
                "{} of {full}",
                map.bytes()
            );
            // Of emptied bricks, a quarter as many as are in use are kept for reuse:
            // twelve in use and six emptied keep three.
            map.clear();
            let corner = |b: u32| VirtualGrid::key(b % 3 * side, b / 3 % 3 * side, b / 9 * side);
            for b in 0..18 {
                map.insert(corner(b), b as u64);
            }
            for b in 12..18 {
                map.remove(corner(b));
            }
            assert_eq!(map.release_free(), 3);
            assert_eq!(map.release_free(), 0);
            map.clear();
            assert!(map.is_empty());
            assert_eq!(map.iter().count(), 0);
            assert_eq!(map.get(VirtualGrid::key(5, 5, 5)), None);
            assert!(map.insert(VirtualGrid::key(5, 5, 5), 1));
            assert_eq!(map.get(VirtualGrid::key(5, 5, 5)), Some(1));
        }
    }

    #[test]
    fn corners_match_single_lookups_inside_and_across_bricks() {
        corners_match_single_lookups_inside_and_across_bricks_for::<2, false>();
        corners_match_single_lookups_inside_and_across_bricks_for::<2, true>();
        corners_match_single_lookups_inside_and_across_bricks_for::<3, false>();
        corners_match_single_lookups_inside_and_across_bricks_for::<3, true>();
    }

    fn corners_match_single_lookups_inside_and_across_bricks_for<const S: u32, const C: bool>() {
        let mut map = BrickMap::<u64, S, C>::default();
        for x in 0..18 {
            for y in 0..18 {
                for z in 0..18 {
                    let key = VirtualGrid::key(x, y, z);
                    map.insert(key, key * 3 + 1);
                }
            }
        }
        for cell in [
            VirtualGrid::key(1, 2, 3),
            VirtualGrid::key(7, 2, 3),
            VirtualGrid::key(3, 7, 15),
            VirtualGrid::key(15, 15, 15),
            VirtualGrid::key(8, 0, 16),
        ] {
            let expected: [u64; 8] = std::array::from_fn(|k| VirtualGrid::corner(cell, k) * 3 + 1);
            assert_eq!(
                map.corners(cell),
                expected,
                "cell {:?}",
                VirtualGrid::coords(cell)
            );
        }
    }

    /// An 8³ brick allocates a 2³ sub-cube's values when a key in it is first set; its
    /// values survive the brick's growth, and a brick freed and reused hands its chunks
    /// to the sub-cubes it holds now.
    #[test]
    fn chunked_bricks_hold_the_sub_cubes_their_keys_lie_in() {
        let mut map = BrickMap::<u64, 3, true>::within([16, 16, 16]);
        let chunk = 8 * 8;
        let brick = std::mem::size_of::<Meta>() + CHUNKS;
        let index = map.bytes();
        let plane = |x: u32, y: u32| VirtualGrid::key(x, y, 1);
        for x in 0..4 {
            for y in 0..4 {
                map.insert(plane(x, y), (10 * x + y) as u64);
            }
        }
        // A 4×4 patch of the plane: four sub-cubes.
        assert_eq!(map.bytes() - index, (4 * chunk + brick) as u64);
        // The plane on through the brick: sixteen sub-cubes of its 64.
        for x in 0..8 {
            for y in 0..8 {
                map.insert(plane(x, y), (10 * x + y) as u64);
            }
        }
        assert_eq!(map.bytes() - index, (16 * chunk + brick) as u64);
        for x in 0..8 {
            for y in 0..8 {
                assert_eq!(map.get(plane(x, y)), Some((10 * x + y) as u64));
            }
        }
        assert_eq!(map.get(VirtualGrid::key(1, 1, 5)), None);
        for x in 0..8 {
            for y in 0..8 {
                map.remove(plane(x, y));
            }
        }
        // Reused for another brick: its one key takes the first of the kept chunks.
        let far = VirtualGrid::key(13, 14, 15);
        assert!(map.insert(far, 7));
        assert_eq!(map.meta.len(), 1, "the emptied brick is reused");
        assert_eq!(map.get(far), Some(7));
        assert_eq!(map.iter().collect::<Vec<_>>(), [(far, 7)]);
        assert_eq!(map.get(plane(1, 1)), None);
    }

    #[test]
    fn present_corners_and_corners_or_match_single_lookups_inside_and_across_bricks() {
        present_corners_and_corners_or_match_single_lookups_inside_and_across_bricks_for::<2, false>(
        );
        present_corners_and_corners_or_match_single_lookups_inside_and_across_bricks_for::<2, true>(
        );
        present_corners_and_corners_or_match_single_lookups_inside_and_across_bricks_for::<3, false>(
        );
        present_corners_and_corners_or_match_single_lookups_inside_and_across_bricks_for::<3, true>(
        );
    }

    fn present_corners_and_corners_or_match_single_lookups_inside_and_across_bricks_for<
        const S: u32,
        const C: bool,
    >() {
        // Every third key of a 20³ box, so corners are a mix of present and absent.
        let mut map = BrickMap::<u8, S, C>::default();
        for x in 0..20 {
            for y in 0..20 {
                for z in 0..20 {
                    if (x + 2 * y + 5 * z) % 3 == 0 {
                        map.insert(VirtualGrid::key(x, y, z), 1);
                    }
                }
            }
        }
        for x in 0..21 {
            for y in 0..21 {
                for z in 0..21 {
                    let cell = VirtualGrid::key(x, y, z);
                    let expected = (0..8).fold(0u8, |m, k| {
                        m | u8::from(map.contains(VirtualGrid::corner(cell, k))) << k
                    });
                    assert_eq!(map.present_corners(cell), expected, "cell {x} {y} {z}");
                    let values: [u8; 8] =
                        std::array::from_fn(|k| map.get(VirtualGrid::corner(cell, k)).unwrap_or(9));
                    assert_eq!(map.corners_or(cell, 9), values, "cell {x} {y} {z}");
                }
            }
        }
    }
}
