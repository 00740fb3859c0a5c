//! Step 8 of the bake: a BVH2 over the candidates' boxes, its leaves ranges of consecutive
//! items. Candidates in index (Morton) order are grouped into leaves of up to
//! [`MAX_LEAF_ITEMS`] that lie close together and span at most [`MAX_LEAF_RANGE`] items
//! ([`leaves`], boxes rounded outward to f32); a [`TreeBuild`] links the leaves into the
//! cache's node layout: children adjacent, root first. The reference, [`PlocTree`], is
//! obvhs's (PLOC pairing each cluster among its nearest neighbours in Morton order, then
//! reinsertion, one group per leaf); a GPU may build another tree over the same leaves
//! (`slosh-gpubake`). A leaf names its items as a range, so the cache holds no item list
//! (format 6).

use std::time::Duration;

use glam::Vec3A;
use obvhs::BvhBuildParams;
use obvhs::aabb::Aabb;
use obvhs::bvh2::builder::build_bvh2;
use obvhs::ploc::PlocSearchDistance;
use rayon::prelude::*;
use slosh_cache::{Bvh, BvhNode, MAX_BVH_DEPTH, MAX_LEAF_RANGE};

/// Up to this many candidates share a leaf.
pub const MAX_LEAF_ITEMS: u32 = 8;

/// A leaf's box spans at most this many of its largest member's diameters on every axis: a
/// jump of the Morton curve starts a new leaf instead of stretching one box across it.
const LEAF_SPAN_DIAMETERS: f64 = 3.0;

fn down(v: f64) -> f32 {
    let f = v as f32;
    if f64::from(f) > v { f.next_down() } else { f }
}

fn up(v: f64) -> f32 {
    let f = v as f32;
    if f64::from(f) < v { f.next_up() } else { f }
}

/// A leaf-to-be: items `first..=last` (some of which may not be candidates) and the
/// candidates' bounds.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Group {
    first: u32,
    last: u32,
    members: u32,
    lo: [f64; 3],
    hi: [f64; 3],
    diameter: f64,
}

/// Items one thread groups on its own before the pieces are stitched ([`groups`]).
const GROUP_PIECE: usize = 1 << 14;

impl Group {
    fn new(id: u32, lo: [f64; 3], hi: [f64; 3], r: f64) -> Group {
        Group {
            first: id,
            last: id,
            members: 1,
            lo,
            hi,
            diameter: 2.0 * r,
        }
    }

    /// Takes the item in, where it fits the leaf; else says no and leaves the group as it is.
    fn take(&mut self, id: u32, lo: [f64; 3], hi: [f64; 3], r: f64) -> bool {
        let diameter = self.diameter.max(2.0 * r);
        let fits = (0..3).all(|a| {
            self.hi[a].max(hi[a]) - self.lo[a].min(lo[a]) <= LEAF_SPAN_DIAMETERS * diameter
        });
        if !(fits && self.members < MAX_LEAF_ITEMS && id - self.first < MAX_LEAF_RANGE) {
            return false;
        }
        self.last = id;
        self.members += 1;
        self.diameter = diameter;
        for a in 0..3 {
            self.lo[a] = self.lo[a].min(lo[a]);
            self.hi[a] = self.hi[a].max(hi[a]);
        }
        true
    }
}

/// `items` grouped greedily in order after `out`'s last group (which they may join): each
/// item joins the open group where it fits, else opens the next. Stops before the first item
/// that would open a group where `stop_at` says one is known already, and returns its
/// position in `items` (it and those after it not grouped); else `items.len()`.
fn group_greedily(
    items: &[(u32, [f64; 3], f64)],
    out: &mut Vec<Group>,
    stop_at: impl Fn(u32) -> bool,
) -> usize {
    for (k, &(id, c, r)) in items.iter().enumerate() {
        let (lo, hi) = (c.map(|v| v - r), c.map(|v| v + r));
        if out.last_mut().is_some_and(|g| g.take(id, lo, hi, r)) {
            continue;
        }
        if stop_at(id) {
            return k;
        }
        out.push(Group::new(id, lo, hi, r));
    }
    items.len()
}

/// Consecutive candidates grouped into leaves (`items` ascending by id), the same groups as
/// one greedy pass in order. Pieces are grouped in parallel, each from its first item; then,
/// in order, the pass goes on from the previous piece's groups into each piece only until it
/// opens a group at an item where the piece's own grouping opened one: from there on the two
/// agree (a group's fate depends only on where it opens), so the rest of the piece's groups
/// are taken as they are. (One thread's pass over a 1M step's items took 10-20 ms beside the
/// fits.)
fn groups(items: &[(u32, [f64; 3], f64)]) -> Vec<Group> {
    let pieces: Vec<Vec<Group>> = items
        .par_chunks(GROUP_PIECE)
        .map(|piece| {
            let mut own = Vec::with_capacity(piece.len() / 4 + 1);
            group_greedily(piece, &mut own, |_| false);
            own
        })
        .collect();
    let mut out: Vec<Group> = Vec::with_capacity(items.len() / 4 + 1);
    for (piece, own) in items.chunks(GROUP_PIECE).zip(pieces) {
        let opens = |id: u32| own.binary_search_by_key(&id, |g| g.first).is_ok();
        let k = group_greedily(piece, &mut out, opens);
        if k < piece.len() {
            let at = own.partition_point(|g| g.first < piece[k].0);
            out.extend_from_slice(&own[at..]);
        }
    }
    out
}

/// The leaves of the BVH over `items` ((item id, centre, radius) spheres in local
/// coordinates, ids ascending): each a range of items and its box, rounded outward to f32.
pub fn leaves(items: &[(u32, [f64; 3], f64)]) -> Vec<BvhNode> {
    debug_assert!(items.windows(2).all(|w| w[0].0 < w[1].0));
    groups(items)
        .par_iter()
        .map(|g| BvhNode {
            lo: g.lo.map(down),
            count: g.last - g.first + 1,
            hi: g.hi.map(up),
            first: g.first,
        })
        .collect()
}

/// What links a step's leaves into its BVH: the CPU's [`PlocTree`], or a GPU's.
pub trait TreeBuild: Send + Sync + std::fmt::Debug {
    /// The tree over `leaves` (from [`leaves`]), in the cache's layout: root first, an inner
    /// node's children adjacent, every leaf once, every inner box the union of its
    /// children's. An error is the step's (a device that fails).
    fn build(&self, leaves: &[BvhNode]) -> Result<Bvh, String>;

    /// What it runs on, for reports.
    fn describe(&self) -> String;
}

/// The reference tree: obvhs's PLOC on the CPU, or where that is deeper than the tracer walks
/// (PLOC chains leaves whose boxes coincide: a pile of particles on the surface), the linear
/// BVH, which splits them by position in Morton order.
#[derive(Debug, Clone, Copy, Default)]
pub struct PlocTree;

impl TreeBuild for PlocTree {
    fn build(&self, leaves: &[BvhNode]) -> Result<Bvh, String> {
        [ploc, linear]
            .iter()
            .map(|build| build(leaves))
            .find(|bvh| bvh.depth().is_some_and(|d| d as u64 <= MAX_BVH_DEPTH))
            .ok_or_else(|| {
                format!(
                    "{} leaves make a tree deeper than the tracer's {MAX_BVH_DEPTH} levels, \
                     paired by distance or by Morton code",
                    leaves.len()
                )
            })
    }

    fn describe(&self) -> String {
        "cpu (obvhs PLOC)".into()
    }
}

/// The leaves' order in a linear BVH: by the 63-bit Morton code of their boxes' centres (over
/// the centres' bounds), ties by index. Returns the codes, ascending, and the leaves' indices
/// in that order.
pub fn linear_order(leaves: &[BvhNode]) -> (Vec<u64>, Vec<u32>) {
    let centres: Vec<[f64; 3]> = leaves
        .par_iter()
        .map(|l| std::array::from_fn(|a| 0.5 * (f64::from(l.lo[a]) + f64::from(l.hi[a]))))
        .collect();
    let mut keyed = slosh_mls::morton_keys(&slosh_mls::MortonGrid::new(&centres), &centres);
    keyed.par_sort_unstable();
    keyed.into_par_iter().unzip()
}

/// The linear BVH over `leaves` (Karras 2012), as `shaders/bvh_build.wgsl` builds it on the
/// GPU, node for node (`docs/algorithm.md`): the inner node p-th in preorder has its children
/// at slots 2p + 1 and 2p + 2, after it.
pub fn linear(leaves: &[BvhNode]) -> Bvh {
    let m = leaves.len();
    if m < 2 {
        return Bvh {
            nodes: leaves.to_vec(),
        };
    }
    let (keys, order) = linear_order(leaves);
    // The common prefix of keys i and j, their indices breaking ties; −1 outside.
    let delta = |i: i64, j: i64| -> i64 {
        if j < 0 || j >= m as i64 {
            return -1;
        }
        let (a, b) = (keys[i as usize], keys[j as usize]);
        if a != b {
            i64::from((a ^ b).leading_zeros())
        } else {
            64 + i64::from(((i as u32) ^ (j as u32)).leading_zeros())
        }
    };
    // Each inner node: its range's first leaf, its split, whether each child is a leaf, and
    // whether it is its parent's left child.
    let inner: Vec<(usize, usize, [bool; 2], bool)> = (0..m as i64 - 1)
        .into_par_iter()
        .map(|i| {
            let d = if delta(i, i + 1) > delta(i, i - 1) {
                1
            } else {
                -1
            };
            let shortest = delta(i, i - d);
            let mut reach = 2;
            while delta(i, i + reach * d) > shortest {
                reach *= 2;
            }
            let mut length = 0;
            let mut step = reach / 2;
            while step >= 1 {
                if delta(i, i + (length + step) * d) > shortest {
                    length += step;
                }
                step /= 2;
            }
            let j = i + length * d;
            let prefix = delta(i, j);
            let mut split = 0;
            let mut divisor = 2;
            loop {
                let s = (length + divisor - 1) / divisor;
                if delta(i, i + (split + s) * d) > prefix {
                    split += s;
                }
                if s <= 1 {
                    break;
                }
                divisor *= 2;
            }
            let gamma = i + split * d + d.min(0);
            (
                i.min(j) as usize,
                gamma as usize,
                [i.min(j) == gamma, i.max(j) == gamma + 1],
                d < 0,
            )
        })
        .collect();
    // Each inner node's preorder index among inner nodes: its first leaf plus the left turns
    // on its path from the root. Its children go to slots 2p + 1 and 2p + 2.
    let mut parent = vec![0usize; m - 1];
    for (i, &(_, gamma, leaf, _)) in inner.iter().enumerate() {
        for side in 0..2 {
            if !leaf[side] {
                parent[gamma + side] = i;
            }
        }
    }
    let preorder: Vec<usize> = (0..m - 1)
        .into_par_iter()
        .map(|i| {
            let (mut node, mut left_turns) = (i, 0);
            while node != 0 {
                left_turns += usize::from(inner[node].3);
                node = parent[node];
            }
            inner[i].0 + left_turns
        })
        .collect();
    let empty = BvhNode {
        lo: [0.0; 3],
        count: 0,
        hi: [0.0; 3],
        first: 0,
    };
    let mut nodes = vec![empty; 2 * m - 1];
    nodes[0].first = 2 * preorder[0] as u32 + 1;
    for (i, &(_, gamma, leaf, _)) in inner.iter().enumerate() {
        let base = 2 * preorder[i] + 1;
        for side in 0..2 {
            nodes[base + side] = if leaf[side] {
                leaves[order[gamma + side] as usize]
            } else {
                BvhNode {
                    first: 2 * preorder[gamma + side] as u32 + 1,
                    ..empty
                }
            };
        }
    }
    // Boxes from the leaves up, children before parents.
    let mut stack = vec![(0usize, false)];
    while let Some((slot, children_done)) = stack.pop() {
        let node = nodes[slot];
        if node.count > 0 {
            continue;
        }
        let c = node.first as usize;
        if children_done {
            let (a, b) = (nodes[c], nodes[c + 1]);
            nodes[slot].lo = std::array::from_fn(|k| a.lo[k].min(b.lo[k]));
            nodes[slot].hi = std::array::from_fn(|k| a.hi[k].max(b.hi[k]));
        } else {
            stack.extend([(slot, true), (c, false), (c + 1, false)]);
        }
    }
    Bvh { nodes }
}

/// obvhs's PLOC over `leaves`, rewritten into the cache's layout.
fn ploc(leaves: &[BvhNode]) -> Bvh {
    if leaves.is_empty() {
        return Bvh::default();
    }
    let boxes: Vec<Aabb> = leaves
        .par_iter()
        .map(|leaf| Aabb::new(Vec3A::from(leaf.lo), Vec3A::from(leaf.hi)))
        .collect();
    // obvhs's fast preset, but PLOC searching one neighbour either side at every depth (its
    // fast path) instead of a wider search near the root: balls of about one size tiling a
    // surface gain nothing from the wider search (docs/bake.md). One group per leaf: a leaf
    // must be one range of items.
    let params = BvhBuildParams {
        max_prims_per_leaf: 1,
        ploc_search_distance: PlocSearchDistance::Minimum,
        search_depth_threshold: 0,
        ..BvhBuildParams::fast_build()
    };
    let built = build_bvh2(&boxes, params, &mut Duration::default());
    // Rewrite breadth first from the root so that the layout is ours whatever obvhs keeps
    // internally: every inner node's two children sit in consecutive slots.
    let empty = BvhNode {
        lo: [0.0; 3],
        count: 0,
        hi: [0.0; 3],
        first: 0,
    };
    let mut nodes: Vec<BvhNode> = Vec::with_capacity(built.nodes.len());
    let mut queue = std::collections::VecDeque::from([(0usize, 0usize)]);
    nodes.push(empty);
    while let Some((src, dst)) = queue.pop_front() {
        let node = &built.nodes[src];
        let lo = node.aabb().min;
        let hi = node.aabb().max;
        let mut out = BvhNode {
            lo: [lo.x, lo.y, lo.z],
            count: 0,
            hi: [hi.x, hi.y, hi.z],
            first: 0,
        };
        if node.is_leaf() {
            debug_assert_eq!(node.prim_count, 1);
            out = leaves[built.primitive_indices[node.first_index as usize] as usize];
        } else {
            out.first = nodes.len() as u32;
            let child = node.first_index as usize;
            for c in 0..2 {
                queue.push_back((child + c, nodes.len()));
                nodes.push(empty);
            }
        }
        nodes[dst] = out;
    }
    Bvh { nodes }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn leaves_are_ranges_that_hold_every_item_once_and_close_together() {
        // A line of unit balls with gaps in the ids (non-candidates) and a jump in space.
        let mut items = Vec::new();
        for i in 0..40u32 {
            if i % 7 == 3 {
                continue;
            }
            let x = if i < 20 {
                f64::from(i)
            } else {
                1000.0 + f64::from(i)
            };
            items.push((i, [x, 0.0, 0.0], 1.0));
        }
        let bvh = ploc(&leaves(&items));
        let mut seen = vec![0; 40];
        for leaf in bvh.nodes.iter().filter(|n| n.count > 0) {
            assert!(leaf.count <= MAX_LEAF_RANGE);
            let members: Vec<&(u32, [f64; 3], f64)> = items
                .iter()
                .filter(|(id, ..)| (leaf.first..leaf.first + leaf.count).contains(id))
                .collect();
            assert!(!members.is_empty() && members.len() as u32 <= MAX_LEAF_ITEMS);
            for (id, c, r) in &members {
                seen[*id as usize] += 1;
                assert!(
                    (0..3)
                        .all(|a| f64::from(leaf.lo[a]) <= c[a] - r
                            && f64::from(leaf.hi[a]) >= c[a] + r),
                    "leaf {leaf:?} does not hold item {id}"
                );
            }
            // Never across the jump: a leaf's box spans at most three diameters.
            assert!(leaf.hi[0] - leaf.lo[0] <= 6.0, "{leaf:?}");
        }
        for (id, &count) in seen.iter().enumerate() {
            let candidate = items.iter().any(|(i, ..)| *i as usize == id);
            assert_eq!(count, usize::from(candidate), "item {id}");
        }
    }

    #[test]
    fn pieces_grouped_in_parallel_give_one_passs_groups() {
        // A random walk of balls of random sizes, some ids skipped, across several pieces:
        // groups run across the pieces' edges, and the walk's jumps open groups anywhere.
        let mut next = slosh_testkit::uniform(0x9e37_79b9_7f4a_7c15);
        let mut items = Vec::new();
        let mut at = [0.0f64; 3];
        let mut id = 0u32;
        while items.len() < 5 * GROUP_PIECE + 123 {
            id += 1 + u32::from(next() < 0.2);
            let jump = if next() < 0.05 { 50.0 } else { 1.0 };
            for c in &mut at {
                *c += jump * (next() - 0.5);
            }
            items.push((id, at, 0.05 + next()));
        }
        let mut one_pass = Vec::new();
        group_greedily(&items, &mut one_pass, |_| false);
        assert!(one_pass.len() > 3 * GROUP_PIECE / MAX_LEAF_ITEMS as usize);
        assert_eq!(groups(&items), one_pass);
        // Where the pieces' first groups all differ from the pass's.
        let line: Vec<(u32, [f64; 3], f64)> = (0..3 * GROUP_PIECE as u32 + 5)
            .map(|i| (i + i / 1000, [f64::from(i), 0.0, 0.0], 1.0))
            .collect();
        let mut one_pass = Vec::new();
        group_greedily(&line, &mut one_pass, |_| false);
        assert_eq!(groups(&line), one_pass);
    }

    #[test]
    fn a_pile_of_coincident_balls_stays_within_the_tracers_depth() {
        // PLOC chains equal boxes one per level (63 leaves made a tree 63 deep); the
        // reference then takes the linear BVH, which splits them by position.
        let items: Vec<(u32, [f64; 3], f64)> = (0..2000).map(|i| (i, [0.5; 3], 0.01)).collect();
        let leaves = leaves(&items);
        assert!(ploc(&leaves).depth().unwrap() as u64 > MAX_BVH_DEPTH);
        let bvh = PlocTree.build(&leaves).unwrap();
        let depth = bvh.depth().unwrap();
        assert!(depth <= 10, "depth {depth}");
        assert_eq!(bvh.nodes, linear(&leaves).nodes);
        assert_eq!(
            bvh.nodes.iter().filter(|n| n.count > 0).count(),
            leaves.len()
        );
    }
}
