//! Neighbour lists shared by clusters of consecutive points. Points in spatial order have
//! heavily overlapping neighbour lists; a cluster of `size` consecutive points stores the union
//! of its members' lists once, and each member's own list is recovered exactly by the distance
//! and normal rule that made it: neighbours j of i are the cluster's candidates with
//! |p_j − p_i| ≤ reach_i whose normal does not oppose i's (both valid), in index order.

use rayon::prelude::*;

use crate::neighbours::Neighbours;
use crate::real::{Real, V3};
use crate::runs::RunUnions;

/// Points per neighbour cluster of a bake. Measured on a 100k-point sphere at the default cap
/// of 128: clusters of 16, 32 and 64 store 16.8, 10.9 and 7.4 candidate ids per point, against
/// 128 per point for separate lists; 32 also matches a GPU subgroup of points.
pub const NEIGHBOUR_CLUSTER: u32 = 32;

/// Union of the lists of each run of `size` consecutive points: CSR offsets (one per cluster
/// plus one) and sorted candidate indices. Every point's list is in index order, so a
/// cluster's list is the merge of its members'.
pub fn cluster_lists(neighbours: &Neighbours, size: usize) -> (Vec<u32>, Vec<u32>) {
    let n = neighbours.len();
    let size = size.max(1);
    merge_clusters(n.div_ceil(size), |c| {
        (c * size..((c + 1) * size).min(n)).map(|i| neighbours.of(i))
    })
}

/// The sorted union of the lists of `points` (consecutive indices), each id once, appended
/// to `out`: one cluster's list of [`cluster_lists`], for a caller that has the others.
pub fn cluster_union(neighbours: &Neighbours, points: std::ops::Range<usize>, out: &mut Vec<u32>) {
    let (mut list, mut other, mut bits) = (Vec::new(), Vec::new(), Vec::new());
    let pieces = points.map(|i| neighbours.of(i));
    union_of(pieces, out, &mut list, &mut other, &mut bits);
}

/// The same cluster lists as [`cluster_lists`], merged from the unions of runs of
/// consecutive points (`size` a multiple of their run): each cluster's runs' unions are
/// sorted already, so a cluster's list is their merge, without reading its members' lists.
pub(crate) fn cluster_lists_from_runs(unions: &RunUnions, size: usize) -> (Vec<u32>, Vec<u32>) {
    let runs = unions.len();
    let per_cluster = (size / unions.run()).max(1);
    merge_clusters(runs.div_ceil(per_cluster), |c| {
        (c * per_cluster..((c + 1) * per_cluster).min(runs)).map(|r| unions.union(r))
    })
}

/// Each of `clusters` clusters' list: the union of the sorted lists `pieces` gives it, each
/// id once, sorted; as CSR offsets and ids. Done by blocks of clusters, each block's lists in
/// one buffer: one small buffer per cluster costs more in the allocator than the union, and a
/// stamp array per task (what this replaced) cost 4 bytes a point per task in fresh pages,
/// which at 1M points and 16 threads took longer than the unions.
fn merge_clusters<'a, P, I>(clusters: usize, pieces: P) -> (Vec<u32>, Vec<u32>)
where
    P: Fn(usize) -> I + Sync,
    I: Iterator<Item = &'a [u32]> + Clone,
{
    const CLUSTERS_PER_BLOCK: usize = 64;
    let blocks: Vec<(Vec<u32>, Vec<u32>)> = (0..clusters.div_ceil(CLUSTERS_PER_BLOCK))
        .into_par_iter()
        .map(|block| {
            let first = block * CLUSTERS_PER_BLOCK;
            let last = (first + CLUSTERS_PER_BLOCK).min(clusters);
            let (mut counts, mut ids) = (Vec::with_capacity(last - first), Vec::new());
            let (mut list, mut other, mut bits) = (Vec::new(), Vec::new(), Vec::new());
            for c in first..last {
                let before = ids.len();
                union_of(pieces(c), &mut ids, &mut list, &mut other, &mut bits);
                counts.push((ids.len() - before) as u32);
            }
            (counts, ids)
        })
        .collect();
    concatenate(blocks)
}

/// Appends the sorted union of the sorted `pieces` to `out`. Where the ids span few words
/// for how many there are (a cluster's neighbours in spatial order lie close together), each
/// is set in a bitset over their span, which is then read out in order: about a third of the
/// work of merging 32 lists of 128 two at a time. Otherwise the lists are merged. `list`,
/// `other` and `bits` are scratch, kept between calls (`bits` all zero between them).
fn union_of<'a>(
    pieces: impl Iterator<Item = &'a [u32]> + Clone,
    out: &mut Vec<u32>,
    list: &mut Vec<u32>,
    other: &mut Vec<u32>,
    bits: &mut Vec<u64>,
) {
    let (mut lo, mut hi, mut total) = (u32::MAX, 0u32, 0usize);
    for piece in pieces.clone() {
        if let (Some(&a), Some(&b)) = (piece.first(), piece.last()) {
            (lo, hi, total) = (lo.min(a), hi.max(b), total + piece.len());
        }
    }
    if total == 0 {
        return;
    }
    let base = lo & !63;
    let words = ((hi - base) / 64 + 1) as usize;
    if words <= total {
        if bits.len() < words {
            bits.resize(words, 0);
        }
        for &j in pieces.flat_map(|p| p.iter()) {
            let at = j - base;
            bits[(at / 64) as usize] |= 1 << (at % 64);
        }
        for (w, word) in bits[..words].iter_mut().enumerate() {
            let mut set = std::mem::take(word);
            while set != 0 {
                out.push(base + (w * 64) as u32 + set.trailing_zeros());
                set &= set - 1;
            }
        }
        return;
    }
    list.clear();
    for piece in pieces {
        merge_into(list, piece, other);
        std::mem::swap(list, other);
    }
    out.extend_from_slice(list);
}

/// `out` = the sorted union of sorted `a` and `b`, each id once.
fn merge_into(a: &[u32], b: &[u32], out: &mut Vec<u32>) {
    out.clear();
    out.reserve(a.len() + b.len());
    let (mut i, mut j) = (0, 0);
    while i < a.len() && j < b.len() {
        let (x, y) = (a[i], b[j]);
        out.push(x.min(y));
        i += usize::from(x <= y);
        j += usize::from(y <= x);
    }
    out.extend_from_slice(&a[i..]);
    out.extend_from_slice(&b[j..]);
}

/// Blocks of cluster lists (each block: its lists' lengths, and their ids one after another)
/// as CSR offsets and ids.
fn concatenate<C: IntoIterator<Item = u32>>(blocks: Vec<(C, Vec<u32>)>) -> (Vec<u32>, Vec<u32>) {
    let mut offsets = vec![0u32];
    let mut ids = Vec::with_capacity(blocks.iter().map(|b| b.1.len()).sum());
    for (counts, block_ids) in blocks {
        for count in counts {
            offsets.push(offsets[offsets.len() - 1] + count);
        }
        ids.extend_from_slice(&block_ids);
    }
    (offsets, ids)
}

/// The neighbour list of point `i` recovered from its cluster's candidates, appended to `out`.
pub fn expand_one<T: Real>(
    i: usize,
    points: &[V3<T>],
    normals: Option<&[V3<T>]>,
    reach: &[T],
    candidates: &[u32],
    out: &mut Vec<u32>,
) {
    let (p, r2) = (points[i], reach[i] * reach[i]);
    let own = normals.map(|ns| ns[i]);
    for &j in candidates {
        let Some(q) = points.get(j as usize) else {
            continue;
        };
        if !((*q - p).length_squared() <= r2) {
            continue;
        }
        // Thin sheets: a neighbour whose normal opposes the centre's is the other face.
        if let (Some(a), Some(ns)) = (own, normals) {
            let b = ns[j as usize];
            let valid = |v: V3<T>| v.length_squared() > T::zero();
            if valid(a) && valid(b) && a.dot(b) < T::zero() {
                continue;
            }
        }
        out.push(j);
    }
}

/// A step's points and their clusters' candidates (CSR over clusters of `size` consecutive
/// points): what each point's neighbour list is recovered from, by the rule of
/// [`expand_one`].
#[derive(Debug, Clone, Copy)]
pub struct ClusterCandidates<'a, T> {
    pub points: &'a [V3<T>],
    pub normals: Option<&'a [V3<T>]>,
    pub reach: &'a [T],
    pub size: usize,
    pub cluster_start: &'a [u32],
    pub cluster_ids: &'a [u32],
}

impl<T: Real> ClusterCandidates<'_, T> {
    /// Every point's neighbour list (CSR).
    pub fn expand(&self) -> (Vec<u32>, Vec<u32>) {
        let per_cluster = self.expand_each(true);
        let n = self.points.len();
        let mut start = Vec::with_capacity(n + 1);
        let mut ids = Vec::with_capacity(per_cluster.iter().map(|(_, v)| v.len()).sum());
        start.push(0u32);
        for (counts, list) in per_cluster {
            for c in counts {
                let last = start.last().copied().unwrap_or(0);
                start.push(last + c);
            }
            ids.extend_from_slice(&list);
        }
        (start, ids)
    }

    /// Every point's neighbour count, without keeping the lists (a 1M-point step's would
    /// take half a gigabyte).
    pub fn neighbour_counts(&self) -> Vec<u32> {
        self.expand_each(false)
            .into_iter()
            .flat_map(|(counts, _)| counts)
            .collect()
    }

    /// Each cluster's members' neighbour counts and, where `keep`, their lists one after
    /// another; clusters are independent, so they are expanded in parallel.
    fn expand_each(&self, keep: bool) -> Vec<(Vec<u32>, Vec<u32>)> {
        let size = self.size.max(1);
        let n = self.points.len();
        (0..n.div_ceil(size))
            .into_par_iter()
            .map(|c| {
                let candidates = match (self.cluster_start.get(c), self.cluster_start.get(c + 1)) {
                    (Some(&a), Some(&b)) => {
                        self.cluster_ids.get(a as usize..b as usize).unwrap_or(&[])
                    }
                    _ => &[],
                };
                let mut counts = Vec::with_capacity(size);
                let mut ids = Vec::with_capacity(candidates.len() * if keep { 4 } else { 1 });
                for i in c * size..((c + 1) * size).min(n) {
                    let before = ids.len();
                    expand_one(
                        i,
                        self.points,
                        self.normals,
                        self.reach,
                        candidates,
                        &mut ids,
                    );
                    counts.push((ids.len() - before) as u32);
                    if !keep {
                        ids.clear();
                    }
                }
                (counts, ids)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeSet;

    /// Against a set union, on lists of every shape a step has: empty, one id, the point's
    /// own neighbourhood overlapping the next point's, and far ids (spray, a wrapped Morton
    /// curve); cluster sizes that do and do not divide the point count.
    #[test]
    fn cluster_lists_are_the_sorted_unions_of_their_members_lists() {
        let n = 1000usize;
        let mut x = 12345u32;
        let mut next = move || {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            x
        };
        let lists: Vec<Vec<u32>> = (0..n)
            .map(|i| {
                let set: BTreeSet<u32> = match i % 7 {
                    0 => BTreeSet::new(),
                    1 => [i as u32].into(),
                    2 => (0..5).map(|_| next() % n as u32).collect(),
                    _ => (0..20)
                        .map(|_| {
                            (i as u32 + next() % 40)
                                .saturating_sub(20)
                                .min(n as u32 - 1)
                        })
                        .collect(),
                };
                set.into_iter().collect()
            })
            .collect();
        check_unions(&lists);
        // Ids spread far apart (a cluster's span many words for its few ids): merged.
        let spread: Vec<Vec<u32>> = lists
            .iter()
            .map(|l| l.iter().map(|&j| j * 4099).collect())
            .collect();
        check_unions(&spread);
        // Both in one cluster's members.
        let mixed: Vec<Vec<u32>> = (0..n)
            .map(|i| {
                if i % 5 == 0 {
                    spread[i].clone()
                } else {
                    lists[i].clone()
                }
            })
            .collect();
        check_unions(&mixed);
    }

    fn check_unions(lists: &[Vec<u32>]) {
        let n = lists.len();
        let mut start = vec![0u32];
        for l in lists {
            start.push(start[start.len() - 1] + l.len() as u32);
        }
        let neighbours = Neighbours::from_csr(start, lists.concat()).unwrap();
        for size in [1, 7, 32, 1000, 4096] {
            let (offsets, ids) = cluster_lists(&neighbours, size);
            assert_eq!(offsets.len(), n.div_ceil(size) + 1);
            for c in 0..n.div_ceil(size) {
                let want: Vec<u32> = lists[c * size..((c + 1) * size).min(n)]
                    .iter()
                    .flatten()
                    .copied()
                    .collect::<BTreeSet<u32>>()
                    .into_iter()
                    .collect();
                let got = &ids[offsets[c] as usize..offsets[c + 1] as usize];
                assert_eq!(got, want.as_slice(), "cluster {c} of {size}");
            }
        }
    }
}
