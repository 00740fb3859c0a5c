//! Neighbour lists shared by clusters of consecutive points. Points in spatial order have
//! heavily overlapping neighbour lists; a cluster of `size` consecutive points stores the union
//! of its members' lists once, and each member's own list is recovered exactly by the distance
//! and normal rule that made it: neighbours j of i are the cluster's candidates with
//! |p_j − p_i| ≤ reach_i whose normal does not oppose i's (both valid), in index order.

use rayon::prelude::*;

use crate::neighbours::Neighbours;
use crate::real::{Real, V3};
use crate::runs::{LIST_RUN, RunUnions};

/// Union of the lists of each run of `size` consecutive points: CSR offsets (one per cluster
/// plus one) and sorted candidate indices.
pub fn cluster_lists(neighbours: &Neighbours, size: usize) -> (Vec<u32>, Vec<u32>) {
    let n = neighbours.len();
    let size = size.max(1);
    // Members' lists overlap by most of their length: mark each index once per cluster (a
    // per-thread stamp array), then sort only the union.
    let unions: Vec<Vec<u32>> = (0..n.div_ceil(size))
        .into_par_iter()
        .map_init(
            || vec![u32::MAX; n],
            |stamp, c| {
                let (first, last) = (c * size, ((c + 1) * size).min(n));
                let mut union = Vec::new();
                for &j in (first..last).flat_map(|i| neighbours.of(i)) {
                    if let Some(s) = stamp.get_mut(j as usize)
                        && *s != c as u32
                    {
                        *s = c as u32;
                        union.push(j);
                    }
                }
                union.sort_unstable();
                union
            },
        )
        .collect();
    concatenate(unions.into_iter().map(|u| ([u.len() as u32], u)).collect())
}

/// The same cluster lists as [`cluster_lists`], merged from the unions of runs of
/// [`LIST_RUN`] consecutive points (`size` a multiple of it): each cluster's runs' unions are
/// sorted already, so a cluster's list is their merge, without reading its members' lists.
pub(crate) fn cluster_lists_from_runs(unions: &RunUnions, size: usize) -> (Vec<u32>, Vec<u32>) {
    let runs = unions.len();
    let per_cluster = (size / LIST_RUN).max(1);
    let union = |r: usize| unions.union(r);
    let clusters = runs.div_ceil(per_cluster);
    // Clusters merged by blocks, each block's lists in one buffer (one small buffer per
    // cluster costs more in the allocator than the merge).
    const CLUSTERS_PER_BLOCK: usize = 64;
    let blocks: Vec<(Vec<u32>, Vec<u32>)> = (0..clusters.div_ceil(CLUSTERS_PER_BLOCK))
        .into_par_iter()
        .map(|block| {
            let first = block * CLUSTERS_PER_BLOCK;
            let last = (first + CLUSTERS_PER_BLOCK).min(clusters);
            let (mut counts, mut ids) = (Vec::with_capacity(last - first), Vec::new());
            let mut list: Vec<u32> = Vec::new();
            let mut other: Vec<u32> = Vec::new();
            for c in first..last {
                list.clear();
                for r in c * per_cluster..((c + 1) * per_cluster).min(runs) {
                    let (mut a, b) = (list.iter().peekable(), union(r));
                    other.clear();
                    other.reserve(list.len() + b.len());
                    let mut b = b.iter().peekable();
                    // A two-way merge of sorted lists, each id once.
                    loop {
                        let next = match (a.peek(), b.peek()) {
                            (Some(&&x), Some(&&y)) if x < y => a.next(),
                            (Some(&&x), Some(&&y)) if y < x => b.next(),
                            (Some(_), Some(_)) => {
                                b.next();
                                a.next()
                            }
                            (Some(_), None) => a.next(),
                            (None, Some(_)) => b.next(),
                            (None, None) => break,
                        };
                        other.extend(next);
                    }
                    std::mem::swap(&mut list, &mut other);
                }
                counts.push(list.len() as u32);
                ids.extend_from_slice(&list);
            }
            (counts, ids)
        })
        .collect();
    concatenate(blocks)
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

/// Every point's neighbour list (CSR) from the cluster lists.
pub fn expand<T: Real>(
    points: &[V3<T>],
    normals: Option<&[V3<T>]>,
    reach: &[T],
    size: usize,
    cluster_start: &[u32],
    cluster_ids: &[u32],
) -> (Vec<u32>, Vec<u32>) {
    let size = size.max(1);
    let n = points.len();
    // Clusters are independent: expand them in parallel, then concatenate in order.
    let per_cluster: Vec<(Vec<u32>, Vec<u32>)> = (0..n.div_ceil(size))
        .into_par_iter()
        .map(|c| {
            let candidates = match (cluster_start.get(c), cluster_start.get(c + 1)) {
                (Some(&a), Some(&b)) => cluster_ids.get(a as usize..b as usize).unwrap_or(&[]),
                _ => &[],
            };
            let mut counts = Vec::with_capacity(size);
            let mut ids = Vec::with_capacity(candidates.len() * 4);
            for i in c * size..((c + 1) * size).min(n) {
                let before = ids.len();
                expand_one(i, points, normals, reach, candidates, &mut ids);
                counts.push((ids.len() - before) as u32);
            }
            (counts, ids)
        })
        .collect();
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
