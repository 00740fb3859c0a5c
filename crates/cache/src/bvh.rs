//! The baked BVH2 read on the CPU: the reference traversal of the node layout the WGSL
//! tracer walks (stack based, nearer child first, pruned by the best hit so far).

use slosh_mls::BallIndex;

/// A BVH2 node with its box in f32, as the bake builds it and as the CPU walks it once
/// decoded from the cache's grid ([`crate::BvhGrid`]). `count == 0`: inner node, children at
/// `first` and `first + 1`. `count > 0`: leaf over items `first .. first + count` (balls, then
/// droplet spheres). Node 0 is the root.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BvhNode {
    pub lo: [f32; 3],
    pub count: u32,
    pub hi: [f32; 3],
    pub first: u32,
}

/// The nodes of a step's BVH. Items number balls `0..n` and droplet spheres
/// `n..n + spheres`, as [`BallIndex`] expects; a leaf holds items `first..first + count`,
/// which may include balls that are not candidates (the walk's visitor skips those).
#[derive(Debug, Clone, Default)]
pub struct Bvh {
    pub nodes: Vec<BvhNode>,
}

/// The most items one leaf's range spans (format 6): the trace walk packs a leaf's count in
/// four bits of its stack link.
pub const MAX_LEAF_RANGE: u32 = 15;

/// The deepest BVH a step may hold: what the trace shader's largest traversal stack (96
/// entries) holds, the wide tree having 31 levels, each stacking up to three slots. The bake
/// builds within it and the verifier refuses deeper trees.
pub const MAX_BVH_DEPTH: u64 = 62;

/// Entry parameter of the ray into the box for t ≥ 0, if it enters at all.
fn enter(node: &BvhNode, origin: [f64; 3], inv_dir: [f64; 3]) -> Option<f64> {
    let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
    for a in 0..3 {
        let (lo, hi) = (f64::from(node.lo[a]), f64::from(node.hi[a]));
        if inv_dir[a].is_infinite() {
            // Parallel to the slab: inside it or never.
            if origin[a] < lo || origin[a] > hi {
                return None;
            }
            continue;
        }
        let (ta, tb) = ((lo - origin[a]) * inv_dir[a], (hi - origin[a]) * inv_dir[a]);
        t0 = t0.max(ta.min(tb));
        t1 = t1.min(ta.max(tb));
    }
    (t0 <= t1).then_some(t0)
}

impl BallIndex for Bvh {
    fn walk(&self, origin: [f64; 3], dir: [f64; 3], visit: &mut dyn FnMut(&[u32]) -> f64) {
        let Some(root) = self.nodes.first() else {
            return;
        };
        let inv_dir = dir.map(|d| 1.0 / d);
        let Some(t_root) = enter(root, origin, inv_dir) else {
            return;
        };
        let mut best = f64::INFINITY;
        let mut stack: Vec<(u32, f64)> = vec![(0, t_root)];
        while let Some((index, t_near)) = stack.pop() {
            // Equal is not pruned: a tie goes to the lower item, which may lie here.
            if t_near > best {
                continue;
            }
            let node = &self.nodes[index as usize];
            if node.count > 0 {
                let mut ids = [0u32; MAX_LEAF_RANGE as usize];
                let (first, end) = (node.first, node.first.saturating_add(node.count));
                // A longer range (which no bake writes, and the verifier refuses) is visited
                // in parts.
                for start in (first..end).step_by(ids.len()) {
                    let part = (end - start).min(MAX_LEAF_RANGE) as usize;
                    for (k, id) in ids[..part].iter_mut().enumerate() {
                        *id = start + k as u32;
                    }
                    best = visit(&ids[..part]);
                }
                continue;
            }
            let (a, b) = (node.first, node.first + 1);
            let ta = self
                .nodes
                .get(a as usize)
                .and_then(|n| enter(n, origin, inv_dir));
            let tb = self
                .nodes
                .get(b as usize)
                .and_then(|n| enter(n, origin, inv_dir));
            // Push the farther child first so the nearer one is walked first.
            match (ta, tb) {
                (Some(ta), Some(tb)) if ta <= tb => stack.extend([(b, tb), (a, ta)]),
                (Some(ta), Some(tb)) => stack.extend([(a, ta), (b, tb)]),
                (Some(ta), None) => stack.push((a, ta)),
                (None, Some(tb)) => stack.push((b, tb)),
                (None, None) => {}
            }
        }
    }
}

impl Bvh {
    /// Depth of the tree (1 for a lone root), or `None` if a child index leaves the node array
    /// or the links are not a tree.
    pub fn depth(&self) -> Option<usize> {
        if self.nodes.is_empty() {
            return Some(0);
        }
        let mut seen = vec![false; self.nodes.len()];
        let mut stack = vec![(0usize, 1usize)];
        let mut depth = 0;
        while let Some((i, d)) = stack.pop() {
            if std::mem::replace(seen.get_mut(i)?, true) {
                return None;
            }
            depth = depth.max(d);
            let node = &self.nodes[i];
            if node.count == 0 {
                let a = node.first as usize;
                stack.push((a, d + 1));
                stack.push((a.checked_add(1)?, d + 1));
            }
        }
        Some(depth)
    }
}
