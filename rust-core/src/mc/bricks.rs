//! Sparse storage over virtual-grid keys in dense 8×8×8 bricks.
//!
//! A surface touches a thin shell of nodes and cells; a hash table per key spreads that
//! shell over memory, so every lookup is a cache miss and every growth a rehash of
//! everything seen so far. Bricks keep neighbouring keys together: the brick table is
//! small enough to stay in cache, a cell's eight corners lie in one brick seven times in
//! eight, and a scan in key order walks one brick at a time (the last brick is
//! remembered). Memory still follows the surface: only touched bricks exist.

use super::VirtualGrid;
use rustc_hash::FxHashMap;

/// Keys per brick edge (a power of two).
const EDGE: u32 = 8;
const SHIFT: u32 = EDGE.trailing_zeros();
const LOCAL: u32 = EDGE - 1;
/// Keys per brick.
pub(crate) const BRICK: usize = (EDGE * EDGE * EDGE) as usize;
const WORDS: usize = BRICK / 64;

/// Brick key and index within the brick of a grid key.
#[inline]
fn split(key: u64) -> (u64, usize) {
    let [x, y, z] = VirtualGrid::coords(key);
    let brick = VirtualGrid::key(x >> SHIFT, y >> SHIFT, z >> SHIFT);
    let local = (x & LOCAL) | (y & LOCAL) << SHIFT | (z & LOCAL) << (2 * SHIFT);
    (brick, local as usize)
}

/// One brick: a value and a presence bit per key.
struct Brick<T> {
    values: Box<[T; BRICK]>,
    present: [u64; WORDS],
}

/// A map from grid keys to `T`, stored brick by brick.
pub struct BrickMap<T> {
    index: FxHashMap<u64, u32>,
    bricks: Vec<Brick<T>>,
    len: usize,
    /// (brick key, brick index) of the last brick found, for scans in key order.
    last: Option<(u64, u32)>,
}

impl<T: Copy + Default> Default for BrickMap<T> {
    fn default() -> Self {
        BrickMap {
            index: FxHashMap::default(),
            bricks: Vec::new(),
            len: 0,
            last: None,
        }
    }
}

impl<T: Copy + Default> BrickMap<T> {
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
        let brick = std::mem::size_of::<[T; BRICK]>() + std::mem::size_of::<Brick<T>>();
        (self.bricks.len() * brick + self.index.capacity() * 16) as u64
    }

    fn brick_index(&self, brick: u64) -> Option<u32> {
        match self.last {
            Some((b, i)) if b == brick => Some(i),
            _ => self.index.get(&brick).copied(),
        }
    }

    fn brick_index_or_insert(&mut self, brick: u64) -> u32 {
        if let Some((b, i)) = self.last {
            if b == brick {
                return i;
            }
        }
        let next = self.bricks.len() as u32;
        let i = *self.index.entry(brick).or_insert(next);
        if i == next {
            self.bricks.push(Brick {
                values: Box::new([T::default(); BRICK]),
                present: [0; WORDS],
            });
        }
        self.last = Some((brick, i));
        i
    }

    /// The value at `key`, if present.
    #[inline]
    pub fn get(&self, key: u64) -> Option<T> {
        let (brick, local) = split(key);
        let b = &self.bricks[self.brick_index(brick)? as usize];
        (b.present[local / 64] >> (local % 64) & 1 == 1).then(|| b.values[local])
    }

    /// Whether `key` is present.
    #[inline]
    pub fn contains(&self, key: u64) -> bool {
        let (brick, local) = split(key);
        self.brick_index(brick)
            .is_some_and(|i| self.bricks[i as usize].present[local / 64] >> (local % 64) & 1 == 1)
    }

    /// Sets `key` to `value`; returns true when the key was not present before.
    #[inline]
    pub fn insert(&mut self, key: u64, value: T) -> bool {
        let (brick, local) = split(key);
        let i = self.brick_index_or_insert(brick) as usize;
        let b = &mut self.bricks[i];
        let word = &mut b.present[local / 64];
        let bit = 1u64 << (local % 64);
        let new = *word & bit == 0;
        *word |= bit;
        b.values[local] = value;
        self.len += new as usize;
        new
    }

    /// The values at the eight corners of `cell`, with one brick lookup when the cell
    /// does not straddle a brick boundary. Every corner must be present.
    #[inline]
    pub fn corners(&self, cell: u64) -> [T; 8] {
        if let Some((brick, at)) = corners_in_one_brick(cell) {
            if let Some(i) = self.brick_index(brick) {
                let values = &self.bricks[i as usize].values;
                return at.map(|a| values[a]);
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
        if let Some((brick, at)) = corners_in_one_brick(cell) {
            let Some(i) = self.brick_index(brick) else {
                return [absent; 8];
            };
            let b = &self.bricks[i as usize];
            return at.map(|a| {
                if b.present[a / 64] >> (a % 64) & 1 == 1 {
                    b.values[a]
                } else {
                    absent
                }
            });
        }
        std::array::from_fn(|k| self.get(VirtualGrid::corner(cell, k)).unwrap_or(absent))
    }

    /// Bit k set when corner k of `cell` is present, with one brick lookup when the cell
    /// does not straddle a brick boundary.
    #[inline]
    pub fn present_corners(&self, cell: u64) -> u8 {
        if let Some((brick, at)) = corners_in_one_brick(cell) {
            let Some(i) = self.brick_index(brick) else {
                return 0;
            };
            let present = &self.bricks[i as usize].present;
            return (0..8).fold(0u8, |mask, k| {
                mask | ((present[at[k] / 64] >> (at[k] % 64) & 1) as u8) << k
            });
        }
        (0..8).fold(0u8, |mask, k| {
            mask | u8::from(self.contains(VirtualGrid::corner(cell, k))) << k
        })
    }
}

/// The brick holding all eight corners of `cell` and their indices in it, unless the
/// cell straddles a brick boundary (one cell in eight along each axis).
#[inline]
fn corners_in_one_brick(cell: u64) -> Option<(u64, [usize; 8])> {
    let [x, y, z] = VirtualGrid::coords(cell);
    if (x & LOCAL) == LOCAL || (y & LOCAL) == LOCAL || (z & LOCAL) == LOCAL {
        return None;
    }
    let (brick, local) = split(cell);
    Some((
        brick,
        std::array::from_fn(|k| {
            let [dx, dy, dz] = super::corner_offset(k);
            local + (dx | dy << SHIFT | dz << (2 * SHIFT)) as usize
        }),
    ))
}

/// A set of grid keys, stored brick by brick.
#[derive(Default)]
pub struct BrickSet {
    map: BrickMap<()>,
}

impl BrickSet {
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
        let mut next = crate::test_rng::lcg(7);
        let mut rnd = |n: u32| ((next() >> 22) % n as u64) as u32;
        let mut map = BrickMap::<u64>::default();
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

    #[test]
    fn corners_match_single_lookups_inside_and_across_bricks() {
        let mut map = BrickMap::<u64>::default();
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

    #[test]
    fn present_corners_and_corners_or_match_single_lookups_inside_and_across_bricks() {
        // Every third key of a 20³ box, so corners are a mix of present and absent.
        let mut map = BrickMap::<u8>::default();
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
