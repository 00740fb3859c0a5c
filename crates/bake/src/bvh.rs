//! Step 8 of the bake: a BVH2 over the candidates' boxes, built by obvhs (PLOC pairing each
//! cluster among its nearest neighbours in Morton order, then reinsertion) and rewritten into
//! the cache's node layout: children adjacent, root first, boxes rounded outward to f32.

use std::time::Duration;

use glam::Vec3A;
use obvhs::BvhBuildParams;
use obvhs::aabb::Aabb;
use obvhs::bvh2::builder::build_bvh2;
use obvhs::ploc::PlocSearchDistance;
use rayon::prelude::*;
use slosh_cache::{Bvh, GpuBvhNode};

/// Up to this many items share a leaf (obvhs collapses by SAH cost below it).
pub const MAX_LEAF_ITEMS: u32 = 8;

fn down(v: f64) -> f32 {
    let f = v as f32;
    if f64::from(f) > v { f.next_down() } else { f }
}

fn up(v: f64) -> f32 {
    let f = v as f32;
    if f64::from(f) < v { f.next_up() } else { f }
}

/// Builds the BVH over `items`: (item id, centre, radius) spheres in local coordinates.
pub fn build(items: &[(u32, [f64; 3], f64)]) -> Bvh {
    if items.is_empty() {
        return Bvh::default();
    }
    let boxes: Vec<Aabb> = items
        .par_iter()
        .map(|(_, c, r)| {
            Aabb::new(
                Vec3A::new(down(c[0] - r), down(c[1] - r), down(c[2] - r)),
                Vec3A::new(up(c[0] + r), up(c[1] + r), up(c[2] + r)),
            )
        })
        .collect();
    // obvhs's fast preset, but PLOC searching one neighbour either side at every depth (its
    // fast path) instead of a wider search near the root: balls of about one size tiling a
    // surface gain nothing from the wider search. On the H200 host at 1M points the build
    // took 218–274 ms on 16 threads (470–595 ms on 2) against 256–326 ms (560–736 ms), with
    // 5 % more nodes; frames traced within a few per cent either way (docs/bake.md).
    let params = BvhBuildParams {
        max_prims_per_leaf: MAX_LEAF_ITEMS,
        ploc_search_distance: PlocSearchDistance::Minimum,
        search_depth_threshold: 0,
        ..BvhBuildParams::fast_build()
    };
    let built = build_bvh2(&boxes, params, &mut Duration::default());
    // Rewrite breadth first from the root so that the layout is ours whatever obvhs keeps
    // internally: every inner node's two children sit in consecutive slots.
    let mut nodes: Vec<GpuBvhNode> = Vec::with_capacity(built.nodes.len());
    let mut leaf_items: Vec<u32> = Vec::with_capacity(items.len());
    let mut queue = std::collections::VecDeque::from([(0usize, 0usize)]);
    nodes.push(bytemuck::Zeroable::zeroed());
    while let Some((src, dst)) = queue.pop_front() {
        let node = &built.nodes[src];
        let lo = node.aabb().min;
        let hi = node.aabb().max;
        let mut out = GpuBvhNode {
            lo: [lo.x, lo.y, lo.z],
            count: 0,
            hi: [hi.x, hi.y, hi.z],
            first: 0,
        };
        if node.is_leaf() {
            out.first = leaf_items.len() as u32;
            out.count = node.prim_count;
            let first = node.first_index as usize;
            for p in &built.primitive_indices[first..first + node.prim_count as usize] {
                leaf_items.push(items[*p as usize].0);
            }
        } else {
            out.first = nodes.len() as u32;
            let child = node.first_index as usize;
            for c in 0..2 {
                queue.push_back((child + c, nodes.len()));
                nodes.push(bytemuck::Zeroable::zeroed());
            }
        }
        nodes[dst] = out;
    }
    Bvh {
        nodes,
        items: leaf_items,
    }
}
