//! Neighbour lists with one spatial query per run of consecutive (spatially ordered) points.
//! Each point's list is "the nearest ≤ cap points within its reach, ties at the cut broken by
//! index, minus opposing normals, in index order" (`docs/algorithm.md`). A run's members share
//! most of their neighbours, so the run asks the tree once, for every point within reach of
//! any member, and each member filters that set by its own distances: the tree is walked and
//! its results allocated once per run instead of once per point, and a set kept in index order
//! gives every list in index order without a sort.

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;

use crate::found::NeighbourLists;
use crate::neighbours::Neighbours;
use crate::runs::{LIST_BLOCK, RUN, RUNS_PER_BLOCK, RunUnions};

/// kiddo's squared Euclidean distance, summed in its order, so that a list is the set its
/// `within` query would return.
#[inline(always)]
pub fn distance2(a: [f64; 3], b: [f64; 3]) -> f64 {
    let d = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
}

pub(crate) fn neighbour_lists(
    tree: &ImmutableKdTree<f64, 3>,
    points: &[[f64; 3]],
    reach: &[f64],
    cap: usize,
    normals: Option<&[Option<[f64; 3]>]>,
    link_distance2: Option<&(dyn Fn(usize) -> f64 + Sync)>,
) -> NeighbourLists {
    let n = points.len();
    let cap = cap.max(1);
    /// The output of one block of runs, each list and union in one buffer.
    struct Block {
        counts: Vec<u32>,
        ids: Vec<u32>,
        reach: Vec<f64>,
        capped: usize,
        /// Every id some member of each run kept, in index order (CSR over the block's runs).
        union_start: Vec<u32>,
        union_ids: Vec<u32>,
        links: Vec<(u32, u32)>,
    }
    struct Scratch {
        /// kiddo's traversal stack, reused by every query of the thread.
        query:
            kiddo::QueryScratch<kiddo::stem_strategies::eytzinger::EytzingerFlexPf<0, 1>, f64, 3>,
        /// The run's candidates: every point within the run's query ball, in index order.
        found: Vec<u32>,
        /// The run's candidates' coordinates, one array per axis (the distance loop vectorises).
        axes: [Vec<f64>; 3],
        /// Their unit normals, zero where a point has none (a zero normal opposes nothing).
        normal_axes: [Vec<f64>; 3],
        /// One member's squared distance to each candidate.
        d2: Vec<f64>,
        /// The bits of the d² within reach (non-negative floats order as their bits).
        keys: Vec<u64>,
        /// Which candidates some member kept.
        kept: Vec<bool>,
        /// Positions in `found` of one member's candidates within reach, ascending.
        near: Vec<u32>,
    }
    // Runs of consecutive points in space, whatever order the points come in (a bake's are
    // already in this order, and then the runs are consecutive indices).
    let order = crate::order::morton_order(points);
    let blocks: Vec<Block> = order
        .par_chunks(LIST_BLOCK)
        .map_init(
            || Scratch {
                query: tree.create_scratch::<SquaredEuclidean<f64>>(),
                found: Vec::new(),
                axes: Default::default(),
                normal_axes: Default::default(),
                d2: Vec::new(),
                keys: Vec::new(),
                kept: Vec::new(),
                near: Vec::new(),
            },
            |scratch, block_points| {
                let size = block_points.len();
                let mut block = Block {
                    counts: Vec::with_capacity(size),
                    ids: Vec::with_capacity(size * cap.min(256)),
                    reach: Vec::with_capacity(size),
                    capped: 0,
                    union_start: Vec::with_capacity(RUNS_PER_BLOCK + 1),
                    union_ids: Vec::new(),
                    links: Vec::new(),
                };
                block.union_start.push(0);
                for run_points in block_points.chunks(RUN) {
                    let members = run_points.iter().map(|&i| i as usize);
                    // The run's box centre, and a radius holding every member's reach (with
                    // slack far above rounding, so that no point within reach is missed).
                    let (lo, hi) = crate::geometry::bounds(members.clone().map(|i| &points[i]));
                    let centre: [f64; 3] = std::array::from_fn(|a| 0.5 * (lo[a] + hi[a]));
                    let radius = members
                        .clone()
                        .map(|i| distance2(points[i], centre).sqrt() + reach[i])
                        .fold(0.0, f64::max)
                        * (1.0 + 1e-9);
                    let Scratch {
                        query,
                        found,
                        axes,
                        normal_axes,
                        d2,
                        keys,
                        kept,
                        near,
                    } = scratch;
                    // Visited into the thread's buffer: no result vector per run.
                    found.clear();
                    tree.query(&centre)
                        .within::<SquaredEuclidean<f64>>(radius * radius)
                        .unsorted()
                        .without_distances()
                        .with_scratch(query)
                        .visit(|f| found.push(f.item));
                    // Index order: a position in `found` orders as the index it holds.
                    found.sort_unstable();
                    for (a, axis) in axes.iter_mut().enumerate() {
                        axis.clear();
                        axis.extend(found.iter().map(|&j| points[j as usize][a]));
                    }
                    let normal_of = |i: usize| normals.and_then(|ns| ns[i]).unwrap_or([0.0; 3]);
                    for (a, axis) in normal_axes.iter_mut().enumerate() {
                        axis.clear();
                        axis.extend(found.iter().map(|&j| normal_of(j as usize)[a]));
                    }
                    kept.clear();
                    kept.resize(found.len(), false);
                    for i in members {
                        let p = points[i];
                        let r2 = reach[i] * reach[i];
                        d2.clear();
                        d2.extend(
                            axes[0]
                                .iter()
                                .zip(&axes[1])
                                .zip(&axes[2])
                                .map(|((x, y), z)| distance2(p, [*x, *y, *z])),
                        );
                        // The candidates within reach, compacted without a branch (whether a
                        // candidate is within reach is a coin toss the predictor loses): every
                        // slot is written, and the length moves on only past those within.
                        keys.resize(d2.len(), 0);
                        near.resize(d2.len(), 0);
                        let mut within = 0;
                        {
                            // Local slices: through the scratch's vectors, every store made
                            // the compiler load their pointers and lengths again.
                            let (keys, near) = (keys.as_mut_slice(), near.as_mut_slice());
                            for (k, &d) in d2.iter().enumerate() {
                                keys[within] = d.to_bits();
                                near[within] = k as u32;
                                within += usize::from(d <= r2);
                            }
                        }
                        keys.truncate(within);
                        near.truncate(within);
                        let capped = keys.len() >= cap;
                        // Kept: d² below `limit`, and d² equal to it while `ties` last (in
                        // index order): within reach, or the nearest `cap` by (d², index) where
                        // the cap cuts.
                        let (limit, mut ties) = if keys.len() > cap {
                            let (below, &mut last, _) = keys.select_nth_unstable(cap - 1);
                            let less = below.iter().filter(|&&k| k < last).count();
                            (f64::from_bits(last), cap - less)
                        } else {
                            (r2, usize::MAX)
                        };
                        let own = normal_of(i);
                        // No link is asked for: nothing is within a negative d².
                        let link2 = link_distance2.map_or(-1.0, |f| f(i));
                        let mut far = 0.0f64;
                        let before = block.ids.len();
                        let (d2, found, kept) =
                            (d2.as_slice(), found.as_slice(), kept.as_mut_slice());
                        let [nx, ny, nz] = [&normal_axes[0], &normal_axes[1], &normal_axes[2]]
                            .map(|axis| axis.as_slice());
                        // Only those within reach, in index order.
                        for &k in near.iter() {
                            let (k, d) = (k as usize, d2[k as usize]);
                            if d > limit || (d == limit && ties == 0) {
                                continue;
                            }
                            if d == limit {
                                ties -= 1;
                            }
                            far = far.max(d);
                            // Thin sheets: a neighbour whose normal opposes the centre's is the
                            // other side.
                            let dot = own[0] * nx[k] + own[1] * ny[k] + own[2] * nz[k];
                            if dot < 0.0 {
                                continue;
                            }
                            block.ids.push(found[k]);
                            kept[k] = true;
                            if d <= link2 && found[k] as usize != i {
                                block.links.push((i as u32, found[k]));
                            }
                        }
                        // A cut list reaches only as far as its farthest member: the radius
                        // that reproduces it as a distance filter (clusters' `expand`),
                        // rounded up so that squaring it again cannot fall below the farthest d².
                        let list_reach = if capped {
                            far.sqrt().next_up().next_up()
                        } else {
                            reach[i]
                        };
                        block.counts.push((block.ids.len() - before) as u32);
                        block.reach.push(list_reach);
                        block.capped += usize::from(capped);
                    }
                    block.union_ids.extend(
                        found
                            .iter()
                            .zip(kept.iter())
                            .filter_map(|(&j, &k)| k.then_some(j)),
                    );
                    block.union_start.push(block.union_ids.len() as u32);
                }
                block
            },
        )
        .collect();
    // Runs of consecutive indices (the points came in spatial order): each block's buffer holds
    // the lists of consecutive points, in order, and becomes a piece of the lists as it is.
    let index_runs = order.iter().enumerate().all(|(k, &i)| i as usize == k);
    let mut start = vec![0u32; n + 1];
    let mut reach_out = vec![0.0; n];
    // (block, offset into its ids) of each point's list, where they must be copied.
    let mut source = vec![(0u32, 0u32); if index_runs { 0 } else { n }];
    let mut capped = 0;
    // Block b's members are `order`'s b-th chunk.
    for (b, (block, members)) in blocks.iter().zip(order.chunks(LIST_BLOCK)).enumerate() {
        let mut from = 0;
        for ((&i, &count), &reach) in members.iter().zip(&block.counts).zip(&block.reach) {
            let i = i as usize;
            start[i + 1] = count;
            reach_out[i] = reach;
            if let Some(slot) = source.get_mut(i) {
                *slot = (b as u32, from);
            }
            from += count;
        }
        capped += block.capped;
    }
    for i in 0..n {
        start[i + 1] += start[i];
    }
    let mut links = Vec::with_capacity(blocks.len());
    let mut unions = Vec::with_capacity(blocks.len());
    let mut pieces = Vec::with_capacity(blocks.len());
    for block in blocks {
        links.push(block.links);
        unions.push((block.union_start, block.union_ids));
        pieces.push(block.ids);
    }
    let lists = if index_runs {
        Neighbours::from_pieces(start, LIST_BLOCK, pieces)
    } else {
        // Back to point order, copied by blocks of points in parallel: the lists of a
        // 1M-point step are half a gigabyte, which one thread would take longer to zero and
        // fault in than the runs took to find.
        let total = start[n] as usize;
        let mut ids: Vec<u32> = Vec::with_capacity(total);
        ids.par_extend(rayon::iter::repeat_n(0, total));
        const POINTS_PER_COPY: usize = 1024;
        crate::neighbours::csr_pieces(&start, &mut ids, POINTS_PER_COPY)
            .into_par_iter()
            .for_each(|(points, piece)| {
                let mut at = 0;
                for i in points {
                    let (b, from) = (source[i].0 as usize, source[i].1 as usize);
                    let len = (start[i + 1] - start[i]) as usize;
                    piece[at..at + len].copy_from_slice(&pieces[b][from..from + len]);
                    at += len;
                }
            });
        Neighbours::from_csr(start, ids)
    }
    .expect("the blocks hold exactly the lists their counts say");
    let run_unions = index_runs.then_some(RunUnions {
        run: RUN,
        runs: n.div_ceil(RUN),
        per_block: RUNS_PER_BLOCK,
        blocks: unions,
    });
    NeighbourLists {
        lists: crate::found::KeptLists::Whole(lists),
        reach: reach_out,
        capped,
        run_unions,
        links,
        components: None,
        fits: None,
        fit_seconds: 0.0,
        parts: Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The definition, point by point: kiddo's `within` at the point, the nearest `cap` by
    /// (d², index), minus opposing normals, in index order.
    fn reference(
        tree: &ImmutableKdTree<f64, 3>,
        points: &[[f64; 3]],
        reach: &[f64],
        cap: usize,
        normals: &[Option<[f64; 3]>],
    ) -> Vec<Vec<u32>> {
        (0..points.len())
            .map(|i| {
                let mut found: Vec<(f64, u32)> = tree
                    .query(&points[i])
                    .within::<SquaredEuclidean<f64>>(reach[i] * reach[i])
                    .unsorted()
                    .execute()
                    .into_iter()
                    .map(|f| (f.distance, f.item))
                    .collect();
                found.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
                found.truncate(cap);
                let mut list: Vec<u32> = found
                    .iter()
                    .map(|f| f.1)
                    .filter(|&j| match (normals[i], normals[j as usize]) {
                        (Some(a), Some(b)) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2] >= 0.0,
                        _ => true,
                    })
                    .collect();
                list.sort_unstable();
                list
            })
            .collect()
    }

    /// A lattice (every distance tied many times, so the cap cuts through ties), shuffled so
    /// that the runs are not index runs, with duplicates, opposing normals and a point whose
    /// normal is unusable; scattered points in index order; and the same in Morton order,
    /// whose runs are consecutive indices.
    #[test]
    fn lists_equal_point_by_point_queries() {
        let shuffled = slosh_scenes::tied_lattice(12, 12, 6, 40);
        let mut scattered: Vec<[f64; 3]> = Vec::new();
        let mut s = 12345u64;
        let mut rand = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..3000 {
            scattered.push([rand(), rand(), 0.1 * rand()]);
        }
        // The scattered points in Morton order: every run is consecutive indices, as in a bake.
        let in_order: Vec<[f64; 3]> = crate::order::morton_order(&scattered)
            .iter()
            .map(|&i| scattered[i as usize])
            .collect();
        assert!(
            crate::order::morton_order(&in_order)
                .iter()
                .enumerate()
                .all(|(k, &i)| i as usize == k)
        );
        for (points, base_reach, cap, index_runs) in [
            (shuffled, 2.2, 40, false),
            (scattered, 0.06, 24, false),
            (in_order, 0.06, 24, true),
        ] {
            let n = points.len();
            let normals: Vec<Option<[f64; 3]>> = (0..n)
                .map(|i| match i % 11 {
                    0 => None,
                    3 => Some([0.0, 0.0, -1.0]),
                    _ => Some([0.0, 0.0, 1.0]),
                })
                .collect();
            let reach: Vec<f64> = (0..n)
                .map(|i| base_reach * (1.0 + (i % 5) as f64 * 0.1))
                .collect();
            let tree: ImmutableKdTree<f64, 3> = ImmutableKdTree::new_from_slice(&points).unwrap();
            let link = 0.5 * base_reach;
            let lists = neighbour_lists(
                &tree,
                &points,
                &reach,
                cap,
                Some(&normals),
                Some(&|_| link * link),
            );
            let want = reference(&tree, &points, &reach, cap, &normals);
            let whole = lists.lists.whole().expect("the CPU keeps every list");
            let mut capped = 0;
            for i in 0..n {
                assert_eq!(whole.of(i), want[i].as_slice(), "point {i}");
                capped += usize::from(lists.reach[i] < reach[i]);
            }
            assert!(
                capped > n / 4,
                "the cap must cut lists here ({capped} of {n})"
            );
            assert!(lists.capped >= capped);
            // Links: every j ≠ i in i's list within the link distance, each once.
            let mut links: Vec<(u32, u32)> = lists.links.concat();
            links.sort_unstable();
            let mut want_links: Vec<(u32, u32)> = (0..n)
                .flat_map(|i| want[i].iter().map(move |&j| (i as u32, j)))
                .filter(|&(i, j)| {
                    let (p, q) = (points[i as usize], points[j as usize]);
                    i != j && distance2(p, q) <= link * link
                })
                .collect();
            want_links.sort_unstable();
            assert!(want_links.len() > n, "links must be found here");
            assert_eq!(links, want_links);
            // Clusters merged from the runs' unions are the unions of their members' lists.
            assert_eq!(lists.run_unions.is_some(), index_runs);
            if let Some(unions) = &lists.run_unions {
                for size in [RUN, 2 * RUN, 4 * RUN] {
                    assert_eq!(
                        crate::clusters::cluster_lists_from_runs(unions, size),
                        crate::clusters::cluster_lists(whole, size),
                        "clusters of {size}"
                    );
                }
            }
        }
    }
}
