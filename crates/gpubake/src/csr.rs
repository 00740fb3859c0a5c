//! CSR offsets from sorted keys: where each key's run begins among them.

use rayon::prelude::*;

/// Keys per block of the offsets found in parallel.
const KEYS_PER_BLOCK: usize = 1 << 14;

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
