//! Cluster candidate lists stored as runs (format 5): in Morton order a cluster's candidates
//! come in runs of consecutive indices (about 36 runs of 10 for a cluster of 32 with 350
//! candidates), so each cluster stores its runs, not its candidates. A narrow cluster, whose
//! runs all begin near its first point, stores each run in one word: the start as a 16-bit
//! offset from the cluster's first point (low half), the length in the high half. A wide
//! cluster stores two words per run: the start as a 32-bit index, then the length.
//! `cluster_base` gives each cluster's first word and, in its top bit, which of the two it
//! is; a cluster's words end where the next one's begin. `cluster_start` still counts
//! candidates (the neighbour masks' slots). expand.wgsl expands the runs of the step it
//! refines into one candidate per slot, the same way.

/// The top bit of a `cluster_base` entry: the cluster stores 32-bit run starts.
pub const WIDE_CLUSTER: u32 = 1 << 31;

/// A narrow run starting at candidate j, in a cluster whose first point is `first`, stores
/// j + NARROW_BIAS − first, which must lie in 0..=u16::MAX.
pub const NARROW_BIAS: u32 = 32768;

/// The longest run one narrow word holds (a longer one is split).
const NARROW_RUN: u32 = u16::MAX as u32;

/// The narrow offset of a run starting at `j` in a cluster whose first point is `first`, if
/// it has one.
fn narrow(j: u32, first: u32) -> Option<u32> {
    u16::try_from((i64::from(j) + i64::from(NARROW_BIAS) - i64::from(first)).max(-1))
        .ok()
        .map(u32::from)
}

/// The runs of consecutive indices of a sorted `list`: (start, length), found as they are
/// read (no list of them is made: a 1M-point step has 31k clusters).
fn runs_of(list: &[u32]) -> impl Iterator<Item = (u32, u32)> + '_ {
    let mut at = 0;
    std::iter::from_fn(move || {
        let first = *list.get(at)?;
        let mut len = 1;
        while list
            .get(at + len)
            .is_some_and(|&j| u64::from(first) + len as u64 == u64::from(j))
        {
            len += 1;
        }
        at += len;
        Some((first, len as u32))
    })
}

/// Appends a narrow cluster's words for the runs of `list` to `words`: each run cut into
/// parts of at most [`NARROW_RUN`], one word per part; `false`, with `words` as it was,
/// where a part starts outside the narrow range of `first`.
fn push_narrow(words: &mut Vec<u32>, list: &[u32], first: u32) -> bool {
    let before = words.len();
    for (mut j, mut left) in runs_of(list) {
        while left > 0 {
            let part = left.min(NARROW_RUN);
            let Some(offset) = narrow(j, first) else {
                words.truncate(before);
                return false;
            };
            words.push(offset | (part << 16));
            (j, left) = (j + part, left - part);
        }
    }
    true
}

/// The `cluster_base` entries and words of cluster lists (`start`, CSR over `ids`, each
/// cluster's list sorted ascending) of clusters of `size` points; `None` if the words would
/// not be addressable by 31 bits. A cluster is narrow where every part of its runs starts in
/// the narrow range, else wide.
pub fn pack(start: &[u32], ids: &[u32], size: u32) -> Option<(Vec<u32>, Vec<u32>)> {
    use rayon::prelude::*;
    let clusters = start.len().saturating_sub(1);
    // Each block of clusters packed on its own (its clusters' word counts, whether wide, and
    // words), then placed one after another: at 1M points a single pass took 80 ms.
    const CLUSTERS_PER_BLOCK: usize = 256;
    // Per block: each cluster's word count and whether it is wide; the block's words.
    type Block = (Vec<(u32, bool)>, Vec<u32>);
    let blocks: Vec<Block> = (0..clusters.div_ceil(CLUSTERS_PER_BLOCK))
        .into_par_iter()
        .map(|block| {
            let (first_cluster, last) = (
                block * CLUSTERS_PER_BLOCK,
                ((block + 1) * CLUSTERS_PER_BLOCK).min(clusters),
            );
            let (mut counts, mut words) = (Vec::with_capacity(last - first_cluster), Vec::new());
            for c in first_cluster..last {
                let list = &ids[start[c] as usize..start[c + 1] as usize];
                let before = words.len();
                let first = (c as u32).checked_mul(size)?;
                let wide = !push_narrow(&mut words, list, first);
                if wide {
                    words.extend(runs_of(list).flat_map(|(j, len)| [j, len]));
                }
                counts.push((u32::try_from(words.len() - before).ok()?, wide));
            }
            Some((counts, words))
        })
        .collect::<Option<_>>()?;
    let (mut base, mut words) = (
        Vec::with_capacity(clusters),
        Vec::with_capacity(blocks.iter().map(|b| b.1.len()).sum()),
    );
    let mut at = 0u32;
    for (counts, block_words) in blocks {
        for (count, wide) in counts {
            if at >= WIDE_CLUSTER {
                return None;
            }
            base.push(if wide { at | WIDE_CLUSTER } else { at });
            at = at.checked_add(count)?;
        }
        words.extend_from_slice(&block_words);
    }
    (at <= WIDE_CLUSTER).then_some((base, words))
}

/// Cluster `c`'s words: from its base to the next cluster's, or to `words` for the last.
fn words_of(base: &[u32], c: usize, words: usize) -> std::ops::Range<usize> {
    let at = (base[c] & !WIDE_CLUSTER) as usize;
    let end = base
        .get(c + 1)
        .map_or(words, |&b| (b & !WIDE_CLUSTER) as usize);
    at..end.max(at)
}

/// Checks that each cluster's words begin where the previous cluster's end, inside `words`
/// words, and that a wide cluster's words pair up: the structure a reader relies on before
/// it reads the runs.
pub fn check_layout(start: &[u32], base: &[u32], words: usize) -> Result<(), String> {
    let clusters = start.len().saturating_sub(1);
    if base.len() != clusters {
        return Err(format!(
            "{} cluster bases for {clusters} clusters",
            base.len()
        ));
    }
    if base.first().is_some_and(|&b| b & !WIDE_CLUSTER != 0) {
        return Err("the first cluster's words do not begin at word 0".into());
    }
    let mut next = 0usize;
    for c in 0..clusters {
        let at = (base[c] & !WIDE_CLUSTER) as usize;
        let end = base
            .get(c + 1)
            .map_or(words, |&b| (b & !WIDE_CLUSTER) as usize);
        if at != next || end < at || end > words {
            return Err(format!(
                "cluster {c}'s runs (words {at}..{end}) do not follow the previous cluster's (which end at word {next}) inside the {words} words"
            ));
        }
        if base[c] & WIDE_CLUSTER != 0 && !(end - at).is_multiple_of(2) {
            return Err(format!(
                "wide cluster {c} has {} words, not pairs of start and length",
                end - at
            ));
        }
        next = end;
    }
    Ok(())
}

/// Cluster lists stored as runs: `cluster_start`, `cluster_base` and the words of clusters
/// of `size` points, read where they lie.
#[derive(Debug, Clone, Copy)]
pub struct PackedLists<'a> {
    pub start: &'a [u32],
    pub base: &'a [u32],
    pub words: &'a [u32],
    pub size: u32,
}

impl PackedLists<'_> {
    /// Cluster `c`'s candidates.
    fn count(&self, c: usize) -> u64 {
        u64::from(self.start[c + 1].saturating_sub(self.start[c]))
    }

    /// Cluster `c`'s runs as (first index, length), read from its words (a layout
    /// [`check_layout`] accepts).
    fn runs(&self, c: usize) -> impl Iterator<Item = (u64, u64)> + '_ {
        let own = &self.words[words_of(self.base, c, self.words.len())];
        let first = u64::from(c as u32) * u64::from(self.size);
        let wide = self.base[c] & WIDE_CLUSTER != 0;
        let (step, pairs) = if wide {
            (2, own.len() / 2)
        } else {
            (1, own.len())
        };
        (0..pairs).map(move |r| {
            let w = &own[r * step..];
            if wide {
                (u64::from(w[0]), u64::from(w[1]))
            } else {
                let j = (first + u64::from(w[0] & 0xffff)).wrapping_sub(u64::from(NARROW_BIAS));
                (j, u64::from(w[0] >> 16))
            }
        })
    }

    /// What is wrong with the lists, if anything: a layout [`check_layout`] refuses, an empty
    /// run, runs whose lengths do not add up to the cluster's candidates, or an index past
    /// u32; the first cluster in cluster order that fails is named, as a scan would (clusters
    /// are checked in parallel: one scan took most of a 4M-point verify).
    pub fn check(&self) -> Result<(), String> {
        use rayon::prelude::*;
        check_layout(self.start, self.base, self.words.len())?;
        let problem = (0..self.base.len()).into_par_iter().find_map_first(|c| {
            let count = self.count(c);
            let mut held = 0u64;
            for (r, (j, len)) in self.runs(c).enumerate() {
                if len == 0 {
                    return Some(format!("cluster {c}'s run {r} is empty"));
                }
                if j.checked_add(len).is_none_or(|end| end > 1 << 32) {
                    return Some(format!("cluster {c}'s run {r} lies outside u32"));
                }
                if held + len > count {
                    return Some(format!(
                        "cluster {c}'s runs hold more than its {count} candidates"
                    ));
                }
                held += len;
            }
            (held != count)
                .then(|| format!("cluster {c}'s runs hold {held} of its {count} candidates"))
        });
        problem.map_or(Ok(()), Err)
    }

    /// The first cluster (in cluster order) whose candidates are not sorted, distinct and
    /// below `points`, read from the runs of lists [`Self::check`] accepts: each run must
    /// start past the previous one's end, and the last end at `points` or before.
    pub fn first_unsorted(&self, points: usize) -> Option<usize> {
        use rayon::prelude::*;
        (0..self.base.len()).into_par_iter().find_first(|&c| {
            let mut end: Option<u64> = None;
            for (j, len) in self.runs(c) {
                if end.is_some_and(|e| j < e) {
                    return true;
                }
                end = Some(j + len);
            }
            end.is_some_and(|e| e > points as u64)
        })
    }

    /// The lists back as 32-bit indices (CSR over `start`), or what [`Self::check`] finds
    /// wrong.
    pub fn unpack(&self) -> Result<Vec<u32>, String> {
        use rayon::prelude::*;
        self.check()?;
        // Each block of clusters expanded into its own part of the output.
        const CLUSTERS_PER_BLOCK: usize = 256;
        let clusters = self.base.len();
        let total: u64 = (0..clusters).map(|c| self.count(c)).sum();
        let mut out = vec![0u32; total as usize];
        let mut parts = Vec::with_capacity(clusters.div_ceil(CLUSTERS_PER_BLOCK));
        let mut rest = out.as_mut_slice();
        for first in (0..clusters).step_by(CLUSTERS_PER_BLOCK) {
            let block = first..(first + CLUSTERS_PER_BLOCK).min(clusters);
            let len: u64 = block.clone().map(|c| self.count(c)).sum();
            let (part, tail) = rest.split_at_mut(len as usize);
            parts.push((block, part));
            rest = tail;
        }
        parts.into_par_iter().for_each(|(block, part)| {
            let mut at = 0;
            for c in block {
                for (j, len) in self.runs(c) {
                    for (slot, id) in part[at..at + len as usize].iter_mut().zip(j..j + len) {
                        *slot = id as u32;
                    }
                    at += len as usize;
                }
            }
        });
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The cluster lists back as 32-bit indices, or what is wrong ([`PackedLists::unpack`]).
    fn unpack(start: &[u32], base: &[u32], words: &[u32], size: u32) -> Result<Vec<u32>, String> {
        PackedLists {
            start,
            base,
            words,
            size,
        }
        .unpack()
    }

    #[test]
    fn runs_pack_narrow_near_and_wide_far_and_come_back() {
        // Three clusters of 32: runs near their first point, one 40000 points away, and an
        // empty one.
        let start = vec![0, 6, 9, 9];
        let ids = vec![0, 1, 2, 5, 40, 41, 1, 2, 40_032];
        let (base, words) = pack(&start, &ids, 32).unwrap();
        assert_eq!(base, vec![0, 3 | WIDE_CLUSTER, 7]);
        assert_eq!(
            words.len(),
            7,
            "three narrow runs, two wide ones of two words"
        );
        // A narrow run: its start biased from the cluster's first point, its length above.
        assert_eq!(words[0], NARROW_BIAS | (3 << 16));
        assert_eq!(&words[3..7], &[1, 2, 40_032, 1]);
        assert_eq!(unpack(&start, &base, &words, 32).unwrap(), ids);
        // A base that skips words, an odd wide cluster, runs that miss or pass the count,
        // and an empty run are refused.
        assert!(unpack(&start, &[0, 4 | WIDE_CLUSTER, 7], &words, 32).is_err());
        assert!(unpack(&start, &[0, 3 | WIDE_CLUSTER, 6], &words, 32).is_err());
        let mut short = words.clone();
        short[0] = NARROW_BIAS | (2 << 16);
        assert!(unpack(&start, &base, &short, 32).is_err());
        let mut long = words.clone();
        long[0] = NARROW_BIAS | (4 << 16);
        assert!(unpack(&start, &base, &long, 32).is_err());
        let mut empty = words.clone();
        empty[2] = NARROW_BIAS;
        assert!(unpack(&start, &base, &empty, 32).is_err());
        // The bias's edges: a run starting at first − 32768 is narrow, first + 32767 too,
        // one more is wide.
        let start = vec![0, 0, 2];
        let (base, _) = pack(&start, &[0, 32767 + 32], 32).unwrap();
        assert_eq!(base[1] & WIDE_CLUSTER, 0);
        let (base, _) = pack(&start, &[0, 32768 + 32], 32).unwrap();
        assert_ne!(base[1] & WIDE_CLUSTER, 0);
    }

    #[test]
    fn a_run_longer_than_a_narrow_word_is_split_or_stored_wide() {
        // Cluster 1024 (first point 32768) with 65545 consecutive candidates from 0: a
        // narrow word of 65535 at offset 0, then one of 10 at offset 65535.
        let mut start = vec![0u32; 1025];
        start.push(65_545);
        let ids: Vec<u32> = (0..65_545).collect();
        let (base, words) = pack(&start, &ids, 32).unwrap();
        assert_eq!(base[1024], 0);
        assert_eq!(words, vec![u32::from(u16::MAX) << 16, 65_535 | (10 << 16)]);
        assert_eq!(unpack(&start, &base, &words, 32).unwrap(), ids);
        // From cluster 0, the second part would start past the narrow range: wide.
        let (base, words) = pack(&[0, 70_000], &(0..70_000).collect::<Vec<_>>(), 32).unwrap();
        assert_eq!((base, words.clone()), (vec![WIDE_CLUSTER], vec![0, 70_000]));
    }

    /// The lists' order and range are read from their runs: a run that starts before the
    /// previous one ends (out of order, or a candidate twice) or ends past the points names
    /// its cluster, the first in cluster order.
    #[test]
    fn runs_out_of_order_twice_or_past_the_points_name_their_cluster() {
        let lists: [&[u32]; 5] = [&[0, 1, 2], &[7, 9], &[3, 3], &[40, 41, 40], &[60]];
        let pack_all = |lists: &[&[u32]]| {
            let mut start = vec![0u32];
            let mut ids = Vec::new();
            for l in lists {
                ids.extend_from_slice(l);
                start.push(ids.len() as u32);
            }
            let (base, words) = pack(&start, &ids, 32).unwrap();
            (start, base, words)
        };
        let first_unsorted = |lists: &[&[u32]], points: usize| {
            let (start, base, words) = pack_all(lists);
            let packed = PackedLists {
                start: &start,
                base: &base,
                words: &words,
                size: 32,
            };
            packed.check().unwrap();
            packed.first_unsorted(points)
        };
        assert_eq!(first_unsorted(&lists, 100), Some(2), "a candidate twice");
        assert_eq!(
            first_unsorted(&[lists[0], lists[1], lists[3]], 100),
            Some(2)
        );
        assert_eq!(first_unsorted(&[lists[0], lists[1], lists[4]], 60), Some(2));
        assert_eq!(first_unsorted(&[lists[0], lists[1], lists[4]], 61), None);
        assert_eq!(first_unsorted(&[lists[1], &[], lists[0]], 10), None);
    }

    /// Many clusters (packed and unpacked by blocks, in parallel): narrow and wide ones, empty
    /// ones, runs of one; back exactly, and a damaged cluster past the first blocks is named
    /// as a scan would name it (the first in cluster order).
    #[test]
    fn thousands_of_clusters_round_trip_and_the_first_bad_one_is_named() {
        let clusters = 3000u32;
        let mut start = vec![0u32];
        let mut ids = Vec::new();
        for c in 0..clusters {
            let first = c * 32;
            let list: Vec<u32> = match c % 5 {
                0 => Vec::new(),
                1 => (first..first + 40).collect(),
                2 => (0..30).map(|k| first + 3 * k).collect(),
                3 => vec![first, first + 1, 1_000_000 + c],
                _ => (first.saturating_sub(20)..first + 60)
                    .chain([5_000_000])
                    .collect(),
            };
            ids.extend(&list);
            start.push(ids.len() as u32);
        }
        let (base, words) = pack(&start, &ids, 32).unwrap();
        assert!(base.iter().any(|b| b & WIDE_CLUSTER != 0));
        assert!(base.iter().any(|b| b & WIDE_CLUSTER == 0));
        assert_eq!(unpack(&start, &base, &words, 32).unwrap(), ids);
        // Cluster 2001 (a run of 40) and 2501 claim one candidate fewer than their runs hold.
        let mut short = start.clone();
        for c in [2501usize, 2001] {
            short[c + 1] -= 1;
            for s in &mut short[c + 2..] {
                *s -= 1;
            }
        }
        let err = unpack(&short, &base, &words, 32).unwrap_err();
        assert_eq!(err, "cluster 2001's runs hold more than its 39 candidates");
    }
}
