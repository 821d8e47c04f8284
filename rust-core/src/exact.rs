//! Parallel flat maps into a list sized exactly beforehand.
//!
//! rayon's `flat_map_iter(..).collect()` cannot know the length: each thread grows a list
//! of its own by doubling, and the lists are then copied into the result. For the
//! extractors' largest lists (every triangle, every cut edge of a million-particle frame,
//! a hundred megabytes and more) the doubling copies and the pages they touch for the first
//! time cost more than the items: each page of fresh memory is a fault in the kernel.
//! Where an item's output count is cheap to know (a table lookup), counting first lets
//! every thread write straight into its part of one list, allocated zeroed (fresh pages
//! from the system, each touched once, by the thread that fills it).

use rayon::prelude::*;

/// Items per task: a task counts, then fills, a run of this many.
const CHUNK: usize = 1 << 12;

/// The outputs of `fill` for each of `items`, in item order, where `count(item)` is the
/// number of outputs `fill(item, out)` writes into `out`: it is given exactly that many
/// and must write every one. The list starts as `vec![T::default(); n]`, which std
/// allocates zeroed (`calloc`, fresh pages for a large list) only for the types it knows
/// to be zero there: primitive numbers and short arrays of them; other types are written
/// once on the calling thread first.
pub fn flat_map<I, T>(
    items: &[I],
    count: impl Fn(&I) -> usize + Sync,
    fill: impl Fn(&I, &mut [T]) + Sync,
) -> Vec<T>
where
    I: Sync,
    T: Send + Copy + Default,
{
    let counts: Vec<usize> = items
        .par_chunks(CHUNK)
        .map(|run| run.iter().map(&count).sum())
        .collect();
    let mut out = vec![T::default(); counts.iter().sum()];
    let mut parts = Vec::with_capacity(counts.len());
    let mut rest = out.as_mut_slice();
    for &n in &counts {
        let (part, tail) = rest.split_at_mut(n);
        parts.push(part);
        rest = tail;
    }
    items
        .par_chunks(CHUNK)
        .zip(parts)
        .for_each(|(run, mut part)| {
            for item in run {
                let (mine, tail) = part.split_at_mut(count(item));
                fill(item, mine);
                part = tail;
            }
            debug_assert!(part.is_empty(), "`count` gave an item two different counts");
        });
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against the sequential flat map, across chunk boundaries, with items that write
    /// nothing.
    #[test]
    fn equals_the_sequential_flat_map() {
        let items: Vec<u32> = (0..3 * CHUNK as u32 + 17).map(|i| i * 7919 % 13).collect();
        let out = flat_map(
            &items,
            |&i| (i % 4) as usize,
            |&i, out: &mut [[u32; 2]]| {
                for (k, o) in out.iter_mut().enumerate() {
                    *o = [i, k as u32];
                }
            },
        );
        let expected: Vec<[u32; 2]> = items
            .iter()
            .flat_map(|&i| (0..i % 4).map(move |k| [i, k]))
            .collect();
        assert_eq!(out, expected);
        assert!(flat_map(&[] as &[u32], |_| 1, |_, _: &mut [u8]| {}).is_empty());
    }
}
