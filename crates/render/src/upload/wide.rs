//! The 4-wide tree the trace walk descends, made from the baked BVH2 by the host half: an
//! entry per BVH2 inner node the walk stops at (the root, and every inner grandchild of an
//! entry), its slots that node's grandchildren (or a child that is a leaf). Only those nodes
//! get entries, so the tree takes about a third of the BVH2's node count in 128-byte
//! entries, and the BVH2 itself stays on the host.

use slosh_cache::GpuBvhNode;

use super::checks::MAX_LINK_FIRST;
use crate::layout::{EMPTY_SLOT, GpuWide};

/// A leaf as the walk stacks it: `first | count << 28` (step.wgsl: `link`).
fn leaf_link(node: &GpuBvhNode) -> u32 {
    node.first | (node.count << MAX_LINK_FIRST.count_ones())
}

/// Node `i` of a `bvh_nodes` section's bytes.
fn node_at(nodes: &[u8], i: u32) -> GpuBvhNode {
    let at = i as usize * size_of::<GpuBvhNode>();
    bytemuck::pod_read_unaligned(&nodes[at..at + size_of::<GpuBvhNode>()])
}

fn empty() -> GpuWide {
    GpuWide {
        lo_x: [EMPTY_SLOT; 4],
        hi_x: [EMPTY_SLOT; 4],
        lo_y: [EMPTY_SLOT; 4],
        hi_y: [EMPTY_SLOT; 4],
        lo_z: [EMPTY_SLOT; 4],
        hi_z: [EMPTY_SLOT; 4],
        links: [0; 4],
        pad: [0; 4],
    }
}

fn set_slot(wide: &mut GpuWide, slot: usize, node: &GpuBvhNode, link: u32) {
    wide.lo_x[slot] = node.lo[0];
    wide.hi_x[slot] = node.hi[0];
    wide.lo_y[slot] = node.lo[1];
    wide.hi_y[slot] = node.hi[1];
    wide.lo_z[slot] = node.lo[2];
    wide.hi_z[slot] = node.hi[2];
    wide.links[slot] = link;
}

/// The wide tree of a BVH2 that `check_tree` accepted (children after their parent, inside
/// the array), entries in the order the walk's descent reaches them; entry 0 is the root (a
/// lone leaf root is entry 0's one slot). An error where the entries would not fit a link.
pub(super) fn wide_tree(nodes: &[u8]) -> Result<Vec<GpuWide>, String> {
    let count = (nodes.len() / size_of::<GpuBvhNode>()) as u32;
    if count == 0 {
        return Ok(Vec::new());
    }
    let root = node_at(nodes, 0);
    if root.count > 0 {
        let mut lone = empty();
        set_slot(&mut lone, 0, &root, leaf_link(&root));
        return Ok(vec![lone]);
    }
    // The BVH2 node behind each entry, appended as the slots above them link them.
    let mut behind = vec![0u32];
    let mut out = Vec::with_capacity(count as usize / 3 + 1);
    while let Some(&parent) = behind.get(out.len()) {
        let parent = node_at(nodes, parent);
        let mut wide = empty();
        let mut slot = 0;
        for c in [parent.first, parent.first + 1] {
            let child = node_at(nodes, c);
            if child.count > 0 {
                set_slot(&mut wide, slot, &child, leaf_link(&child));
                slot += 1;
                continue;
            }
            for g in [child.first, child.first + 1] {
                let grandchild = node_at(nodes, g);
                let link = if grandchild.count > 0 {
                    leaf_link(&grandchild)
                } else {
                    behind.push(g);
                    (behind.len() - 1) as u32
                };
                set_slot(&mut wide, slot, &grandchild, link);
                slot += 1;
            }
        }
        out.push(wide);
    }
    if out.len() as u64 > u64::from(MAX_LINK_FIRST) {
        return Err(format!(
            "the BVH widens into {} nodes; the tracer links at most {MAX_LINK_FIRST}",
            out.len()
        ));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn node(count: u32, first: u32, lo: f32) -> GpuBvhNode {
        GpuBvhNode {
            lo: [lo; 3],
            count,
            hi: [lo + 1.0; 3],
            first,
        }
    }

    fn bytes(nodes: &[GpuBvhNode]) -> Vec<u8> {
        bytemuck::cast_slice(nodes).to_vec()
    }

    #[test]
    fn entries_are_the_root_and_inner_grandchildren_with_every_leaf_in_one_slot() {
        // 0 → (1, 2); 1 → (3, 4) leaves; 2 → (5, 6): 5 a leaf, 6 → (7, 8) leaves.
        let tree = [
            node(0, 1, 0.0),
            node(0, 3, 1.0),
            node(0, 5, 2.0),
            node(2, 0, 3.0),
            node(1, 2, 4.0),
            node(3, 3, 5.0),
            node(0, 7, 6.0),
            node(1, 6, 7.0),
            node(1, 7, 8.0),
        ];
        let wide = wide_tree(&bytes(&tree)).unwrap();
        assert_eq!(wide.len(), 2, "the root and node 6");
        let root = &wide[0];
        let link = |n: &GpuBvhNode| leaf_link(n);
        assert_eq!(
            root.links,
            [link(&tree[3]), link(&tree[4]), link(&tree[5]), 1]
        );
        assert_eq!(root.lo_x, [3.0, 4.0, 5.0, 6.0]);
        assert_eq!(wide[1].links, [link(&tree[7]), link(&tree[8]), 0, 0]);
        assert_eq!(wide[1].lo_y[2], EMPTY_SLOT);
        // A lone leaf root is one slot of entry 0; no nodes, no entries.
        let lone = wide_tree(&bytes(&[node(4, 0, 0.0)])).unwrap();
        assert_eq!((lone.len(), lone[0].links[0]), (1, 4 << 28));
        assert!(wide_tree(&[]).unwrap().is_empty());
    }
}
