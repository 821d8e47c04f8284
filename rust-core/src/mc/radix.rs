//! Sorting grid keys by radix.
//!
//! An extraction sorts long lists of keys: the nodes a tracking wavefront needs (each
//! listed by up to eight cells), the next wavefront, the active cells, the cut edges (each
//! listed by up to four cells). A comparison sort spends O(n log n) steps on them and
//! mispredicts about every other comparison; on the demo frame that was a tenth of all
//! instructions. Keys pack three coordinates in fixed 20-bit fields of which a surface
//! spans only a few bits each, so a least-significant-digit radix sort over just the bits
//! that vary takes three or four passes of plain counting, with no branch on the data.
//! The order is the keys' numeric order, so results equal a comparison sort's exactly.

use rayon::prelude::*;

/// Bits per radix digit: 2,048 counters stay in L1 while a pass scatters.
const DIGIT_BITS: u32 = 11;

/// Below this many items a comparison sort is as quick and allocates nothing.
const SMALL: usize = 512;

/// Below this many items the passes run on the calling thread: handing a pass to rayon's
/// workers and waiting for them costs tens of microseconds (the slider's 5,000-pair
/// updates spent 200 µs of 1,600 in those round trips), more than counting a few
/// thousand items.
const PARALLEL_FROM: usize = 1 << 16;

/// Sorts `items` ascending by `key(item)` (stable).
pub fn sort_by_key<T, F>(items: &mut Vec<T>, key: F)
where
    T: Copy + Send + Sync,
    F: Fn(&T) -> u64 + Sync,
{
    sort_by_key_in(items, &mut Vec::new(), key);
}

/// [`sort_by_key`] with the second buffer of the passes supplied: a caller that sorts
/// again and again (the slider, once per update) keeps its capacity.
pub fn sort_by_key_in<T, F>(items: &mut Vec<T>, spare: &mut Vec<T>, key: F)
where
    T: Copy + Send + Sync,
    F: Fn(&T) -> u64 + Sync,
{
    if items.len() < SMALL {
        items.sort_by_key(|t| key(t));
        return;
    }
    let first = key(&items[0]);
    let varying = if items.len() < PARALLEL_FROM {
        items.iter().fold(0u64, |m, t| m | (key(t) ^ first))
    } else {
        items
            .par_iter()
            .fold(|| 0u64, |m, t| m | (key(t) ^ first))
            .reduce(|| 0, |a, b| a | b)
    };
    let mut from = std::mem::take(items);
    let mut to = std::mem::take(spare);
    let mut rest = varying;
    while rest != 0 {
        // The next digit starts at the lowest bit still varying; bits that never vary
        // (the unused high bits of each coordinate field) cost no pass.
        let shift = rest.trailing_zeros();
        let mask = (1u64 << DIGIT_BITS) - 1;
        scatter(&from, &mut to, |t| ((key(t) >> shift) & mask) as usize);
        std::mem::swap(&mut from, &mut to);
        // (A window reaching past bit 63 just covers fewer bits.)
        rest &= !(mask << shift);
    }
    *items = from;
    *spare = to;
}

/// Sorts `keys` ascending and removes repeats.
pub fn sort_unique(keys: &mut Vec<u64>) {
    sort_by_key(keys, |&k| k);
    keys.dedup();
}

/// One counting pass: `to` becomes `from` ordered stably by `digit`. Each thread counts
/// and then places its own chunk of `from`; a chunk's items of one digit go after the
/// earlier chunks' items of that digit, so the pass stays stable.
fn scatter<T, F>(from: &[T], to: &mut Vec<T>, digit: F)
where
    T: Copy + Send + Sync,
    F: Fn(&T) -> usize + Sync,
{
    const BUCKETS: usize = 1 << DIGIT_BITS;
    let count = |part: &[T]| {
        let mut counts = Box::new([0usize; BUCKETS]);
        for t in part {
            counts[digit(t) & (BUCKETS - 1)] += 1;
        }
        counts
    };
    let parallel = from.len() >= PARALLEL_FROM;
    let chunk = from.len().div_ceil(rayon::current_num_threads()).max(SMALL);
    // Digits are masked to BUCKETS - 1 at each use, so no index needs a bounds check.
    let mut starts: Vec<Box<[usize; BUCKETS]>> = if parallel {
        from.par_chunks(chunk).map(count).collect()
    } else {
        vec![count(from)]
    };
    let mut total = 0;
    for d in 0..BUCKETS {
        for counts in starts.iter_mut() {
            let n = counts[d];
            counts[d] = total;
            total += n;
        }
    }
    to.clear();
    to.reserve(from.len());
    let out = Out(to.as_mut_ptr());
    let place = |part: &[T], first: &[usize; BUCKETS]| {
        // A local copy of the cursors: the compiler then knows the writes through
        // `out` cannot change them, and keeps them out of memory round trips.
        let mut next = *first;
        for t in part {
            let d = digit(t) & (BUCKETS - 1);
            // SAFETY: `next[d]` walks this chunk's own slots for digit d, which no
            // other chunk writes, and every slot is below from.len() <= capacity.
            unsafe { out.at(next[d]).write(*t) };
            next[d] += 1;
        }
    };
    if parallel {
        from.par_chunks(chunk)
            .zip(starts.par_iter())
            .for_each(|(part, first)| place(part, first));
    } else {
        place(from, &starts[0]);
    }
    // SAFETY: the counts give each item of `from` exactly one distinct slot, so every
    // index of 0..from.len() was written above.
    unsafe { to.set_len(from.len()) };
}

/// The output buffer, shared by the threads of a scatter (each writes its own slots).
struct Out<T>(*mut T);

// SAFETY: threads write disjoint slots of one buffer that outlives the scatter.
unsafe impl<T: Send> Send for Out<T> {}
unsafe impl<T: Send> Sync for Out<T> {}

impl<T> Out<T> {
    /// # Safety
    /// `i` must be within the buffer's capacity.
    unsafe fn at(&self, i: usize) -> *mut T {
        self.0.add(i)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mc::{edge_key, VirtualGrid};

    #[test]
    fn equals_a_comparison_sort_on_grid_keys_edge_keys_and_full_width_numbers() {
        let mut next = crate::test_rng::lcg(7);
        let grid_keys: Vec<u64> = (0..20_000)
            .map(|_| {
                let c = [0, 1, 2].map(|_| (next() % 300) as u32 + 5);
                VirtualGrid::key(c[0], c[1], c[2])
            })
            .collect();
        let edges: Vec<u64> = grid_keys
            .iter()
            .map(|&k| edge_key(k, (k % 3) as usize))
            .collect();
        let wide: Vec<u64> = (0..5_000).map(|_| next() << 11 ^ next()).collect();
        let top_bit: Vec<u64> = (0..3_000).map(|i| (i % 7) << 61 | i).collect();
        for keys in [grid_keys, edges, wide, top_bit] {
            let mut expected = keys.clone();
            expected.sort_unstable();
            let mut sorted = keys.clone();
            sort_by_key(&mut sorted, |&k| k);
            assert_eq!(sorted, expected);
            expected.dedup();
            let mut unique = keys;
            sort_unique(&mut unique);
            assert_eq!(unique, expected);
        }
    }

    #[test]
    fn is_stable_and_keeps_every_item() {
        // Items with equal keys keep their input order: the payload is the input index.
        let mut next = crate::test_rng::lcg(3);
        for n in [10_000, PARALLEL_FROM + 1_000] {
            let mut items: Vec<(u64, u32)> = (0..n)
                .map(|i| (VirtualGrid::key(0, (next() % 40) as u32, 9), i as u32))
                .collect();
            let mut expected = items.clone();
            expected.sort_by_key(|t| t.0);
            // Uneven chunks across three threads (the long list): each chunk's share of
            // a digit must land after the earlier chunks' share.
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(3)
                .build()
                .unwrap();
            let mut threaded = items.clone();
            pool.install(|| sort_by_key(&mut threaded, |t| t.0));
            assert_eq!(threaded, expected);
            sort_by_key(&mut items, |t| t.0);
            assert_eq!(items, expected);
        }
    }

    #[test]
    fn small_equal_and_empty_lists() {
        for keys in [vec![], vec![5u64], vec![9; 2_000], vec![3, 1, 2]] {
            let mut expected = keys.clone();
            expected.sort_unstable();
            expected.dedup();
            let mut got = keys;
            sort_unique(&mut got);
            assert_eq!(got, expected);
        }
    }
}
