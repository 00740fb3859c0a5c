//! The BVH's tree on the GPU (`shaders/bvh_build.wgsl`): the leaves the CPU grouped, sorted
//! by the Morton codes of their boxes' centres, linked as a linear BVH, placed in the cache's
//! layout by each inner node's preorder index (children adjacent and after their parent),
//! then its boxes fitted from the deepest inner nodes up, one dispatch a depth: node for node
//! `slosh_bake::linear_bvh`, the CPU's form. The leaves are the CPU bake's; only the inner
//! nodes differ from obvhs's PLOC.

use std::sync::Arc;

use rayon::prelude::*;
use slosh_bake::{PlocTree, Stages, TreeBuild, linear_order};
use slosh_cache::{Bvh, BvhNode};

use crate::dispatch::{bind, groups, guarded, output, storage, uniform};
use crate::layout::{TREE_MAX_DEPTH, TreeNode, TreeParams};
use crate::passes::GpuStages;

/// Bytes of one node.
const NODE_BYTES: u64 = size_of::<TreeNode>() as u64;

impl GpuStages {
    /// This device's stages as a bake takes them: its neighbour search and its tree.
    pub fn stages(self: Arc<Self>) -> Stages {
        Stages {
            device_memory: self.gpu.device_memory(),
            search: self.clone(),
            in_flight: Some(self.clone()),
            turns: Some(self.turns.clone()),
            tree: self,
        }
    }

    /// Whether the nodes of a tree over that many leaves fit one binding of this device.
    fn holds(&self, leaves: usize) -> bool {
        (2 * leaves as u64 - 1) * NODE_BYTES <= self.gpu.max_binding() && leaves < 1 << 30
    }

    /// The linear BVH over `leaves` (at least two, [`GpuStages::holds`]) on the GPU, and its
    /// depth.
    fn linear_bvh(&self, leaves: &[BvhNode]) -> Result<(Vec<BvhNode>, u32), String> {
        let m = leaves.len();
        let node_bytes = (2 * m as u64 - 1) * NODE_BYTES;
        let (codes, order) = linear_order(leaves);
        let keys: Vec<[u32; 2]> = codes
            .par_iter()
            .map(|&code| [(code >> 32) as u32, code as u32])
            .collect();
        let sorted: Vec<TreeNode> = order
            .par_iter()
            .map(|&i| {
                let l = leaves[i as usize];
                TreeNode {
                    lo: l.lo,
                    count: l.count,
                    hi: l.hi,
                    first: l.first,
                }
            })
            .collect();
        let gpu = &self.gpu;
        let fault = |e: slosh_mls::SurfaceError| e.to_string();
        let (x, y, row_threads) = groups(gpu, m as u32 - 1);
        let params = uniform(
            gpu,
            &TreeParams {
                leaves: m as u32,
                row_threads,
                _pad0: 0,
                _pad1: 0,
            },
        );
        let keys = storage(&self.memory, "bvh keys", &keys).map_err(fault)?;
        let sorted = storage(&self.memory, "bvh leaves", &sorted).map_err(fault)?;
        let nodes = output(&self.memory, "bvh nodes", node_bytes);
        let links = output(&self.memory, "bvh links", (m as u64 - 1) * 16);
        let up = output(&self.memory, "bvh parents and slots", (m as u64 - 1) * 8);
        let inner = output(&self.memory, "bvh depths and preorder", (m as u64 - 1) * 8);
        let state = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("bvh depths"),
            size: 16,
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let group = bind(
            gpu,
            &self.tree_layout,
            &[
                (0, &params),
                (1, &keys),
                (2, &sorted),
                (3, &nodes),
                (4, &links),
                (5, &up),
                (6, &inner),
                (7, &state),
            ],
        );
        self.run(
            "bvh: links and depths",
            &[(&self.link_nodes, (x, y)), (&self.measure_depths, (x, y))],
            &group,
        );
        let deepest = self.read_back::<u32>(&state, 4).map_err(fault)?[0];
        if deepest >= TREE_MAX_DEPTH {
            return Err(format!(
                "an inner node {deepest} deep, where keys of 96 bits allow {TREE_MAX_DEPTH}"
            ));
        }
        // The nodes into their slots, then from the deepest inner nodes up: each depth's boxes
        // from the children the dispatch before fitted.
        gpu.queue
            .write_buffer(&state, 4, bytemuck::bytes_of(&deepest));
        let mut dispatches = Vec::with_capacity(2 * deepest as usize + 2);
        dispatches.push((&self.place_nodes, (x, y)));
        for depth in (0..=deepest).rev() {
            dispatches.push((&self.fit_boxes, (x, y)));
            if depth > 0 {
                dispatches.push((&self.next_depth, (1, 1)));
            }
        }
        self.run("bvh: nodes and boxes", &dispatches, &group);
        let nodes: Vec<TreeNode> = self.read_back(&nodes, node_bytes).map_err(fault)?;
        let nodes = nodes
            .into_par_iter()
            .map(|n| BvhNode {
                lo: n.lo,
                count: n.count,
                hi: n.hi,
                first: n.first,
            })
            .collect();
        // Inner levels, then the leaves'.
        Ok((nodes, deepest + 2))
    }
}

impl TreeBuild for GpuStages {
    fn build(&self, leaves: &[BvhNode]) -> Result<Bvh, String> {
        if leaves.len() < 2 {
            return Ok(Bvh {
                nodes: leaves.to_vec(),
            });
        }
        // More leaves than one binding holds nodes for (spray everywhere: a leaf per particle,
        // 64 bytes of nodes each, where the search needed 16): the CPU's tree, not a failed
        // step.
        if !self.holds(leaves.len()) {
            return PlocTree.build(leaves);
        }
        let (nodes, depth) = guarded(
            &self.gpu,
            || self.linear_bvh(leaves),
            |e| format!("on the GPU: {e}"),
        )?;
        // A linear BVH deeper than the tracer's stack (a rare, very uneven set): PLOC's on the
        // CPU, which pairs by distance, instead of a step the player would refuse.
        if u64::from(depth) > slosh_cache::MAX_BVH_DEPTH {
            return PlocTree.build(leaves);
        }
        Ok(Bvh { nodes })
    }

    fn describe(&self) -> String {
        format!("gpu ({}, linear BVH)", self.gpu.describe())
    }
}
