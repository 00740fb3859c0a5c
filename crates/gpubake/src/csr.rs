//! CSR from keys: where each key's run begins among sorted keys, and (key, word) pairs grouped
//! by key.

use rayon::prelude::*;

/// Keys per block of the offsets found in parallel.
const KEYS_PER_BLOCK: usize = 1 << 14;

/// Keys per piece of the runs sorted in parallel ([`grouped`]).
const KEYS_PER_PIECE: usize = 1 << 12;

/// `pairs` of (key, word), keys below `keys`, grouped by key: the `keys + 1` offsets and the
/// words, each key's run in ascending order of (`rank(word)`, word). A count, a prefix sum and
/// a scatter, then each run's few words sorted: linear in the pairs, where a sort of the pairs
/// themselves (a 1M step has a million near its lists' reaches) took 15.8 ms on two cores.
/// `None` where a key is `keys` or above.
pub(crate) fn grouped(
    pairs: &[[u32; 2]],
    keys: usize,
    rank: impl Fn(u32) -> u32 + Sync,
) -> Option<(Vec<u32>, Vec<u32>)> {
    use std::sync::atomic::{AtomicU32, Ordering::Relaxed};
    let atomics = |len: usize| -> Vec<AtomicU32> {
        (0..len)
            .into_par_iter()
            .map(|_| AtomicU32::new(0))
            .collect()
    };
    if !pairs.par_iter().all(|&[key, _]| (key as usize) < keys) {
        return None;
    }
    let counts = atomics(keys + 1);
    pairs.par_iter().for_each(|&[key, _]| {
        counts[key as usize + 1].fetch_add(1, Relaxed);
    });
    let mut start: Vec<u32> = counts.into_iter().map(AtomicU32::into_inner).collect();
    for k in 1..start.len() {
        start[k] += start[k - 1];
    }
    // Each pair into the next free place of its key's run (in no particular order within it:
    // the runs are sorted next).
    let cursor: Vec<AtomicU32> = start[..keys]
        .par_iter()
        .map(|&s| AtomicU32::new(s))
        .collect();
    let placed = atomics(pairs.len());
    pairs.par_iter().for_each(|&[key, word]| {
        let at = cursor[key as usize].fetch_add(1, Relaxed);
        placed[at as usize].store(word, Relaxed);
    });
    let mut words: Vec<u32> = placed.into_iter().map(AtomicU32::into_inner).collect();
    slosh_mls::csr_pieces(&start, &mut words, KEYS_PER_PIECE)
        .into_par_iter()
        .for_each(|(range, piece)| {
            let base = start[range.start];
            for k in range {
                piece[(start[k] - base) as usize..(start[k + 1] - base) as usize]
                    .sort_unstable_by_key(|&w| (rank(w), w));
            }
        });
    Some((start, words))
}

/// The `keys + 1` offsets of the runs of `len` items whose keys (`key(i)`, below `keys`) are
/// sorted: key k's items are `offsets[k]..offsets[k + 1]`. By blocks of keys in parallel, each
/// block's first found by binary search and the rest by a walk (a count and a prefix sum over
/// millions of keys on one thread took milliseconds of every step).
pub(crate) fn sorted_starts(
    len: usize,
    keys: usize,
    key: impl Fn(usize) -> usize + Sync,
) -> Vec<u32> {
    let mut start = vec![0u32; keys + 1];
    start
        .par_chunks_mut(KEYS_PER_BLOCK)
        .enumerate()
        .for_each(|(b, block)| {
            let first = b * KEYS_PER_BLOCK;
            // The first item whose key is `first` or above.
            let (mut lo, mut hi) = (0, len);
            while lo < hi {
                let mid = lo + (hi - lo) / 2;
                if key(mid) < first {
                    lo = mid + 1;
                } else {
                    hi = mid;
                }
            }
            let mut i = lo;
            for (k, s) in block.iter_mut().enumerate() {
                while i < len && key(i) < first + k {
                    i += 1;
                }
                *s = i as u32;
            }
        });
    start
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against a sort of the pairs: keys with runs, gaps and none at all, words with marks
    /// above the rank's bits (ranked without them, then by the whole word), over several
    /// pieces; a key out of range is refused.
    #[test]
    fn grouped_pairs_are_the_sorted_pairs_as_csr() {
        let mark = 1u32 << 31;
        let rank = |w: u32| w & !mark;
        for keys in [1, 7, 3 * KEYS_PER_PIECE + 5] {
            let pairs: Vec<[u32; 2]> = (0..5 * keys as u32)
                .filter(|i| i % 7 != 3)
                .map(|i| {
                    let key = i.wrapping_mul(2_654_435_761) % keys as u32;
                    let word = (i.wrapping_mul(40_503) % 97) | if i % 5 == 0 { mark } else { 0 };
                    [key, word]
                })
                .collect();
            let mut want = pairs.clone();
            want.sort_unstable_by_key(|&[k, w]| (k, rank(w), w));
            let (start, words) = grouped(&pairs, keys, rank).expect("keys in range");
            assert_eq!(start.len(), keys + 1);
            assert_eq!(start[keys] as usize, pairs.len());
            let got: Vec<[u32; 2]> = (0..keys)
                .flat_map(|k| {
                    words[start[k] as usize..start[k + 1] as usize]
                        .iter()
                        .map(move |&w| [k as u32, w])
                })
                .collect();
            assert_eq!(got, want, "{keys} keys");
        }
        assert_eq!(grouped(&[[0, 1], [3, 2]], 3, |w| w), None);
    }

    /// Against a count and a prefix sum: keys with runs, gaps and none at all, over several
    /// blocks.
    #[test]
    fn offsets_count_the_items_of_the_keys_before() {
        for keys in [0, 1, 5, KEYS_PER_BLOCK, 3 * KEYS_PER_BLOCK + 7] {
            let items: Vec<usize> = (0..keys)
                .flat_map(|k| std::iter::repeat_n(k, (k * 7 + 3) % 5))
                .collect();
            let mut want = vec![0u32; keys + 1];
            for &k in &items {
                want[k + 1] += 1;
            }
            for k in 1..want.len() {
                want[k] += want[k - 1];
            }
            assert_eq!(
                sorted_starts(items.len(), keys, |i| items[i]),
                want,
                "{keys} keys"
            );
        }
    }
}
