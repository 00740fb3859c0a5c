//! The checks a step's sections pass before the GPU sees them: a tree the trace walk can
//! finish, neighbour-mask offsets the shaders can index, and a field's finite range.

use rayon::prelude::*;
use slosh_cache::{GpuBvhNode, names};

pub use slosh_cache::MAX_BVH_DEPTH;

/// The traversal stack packs a node as `first | count << 28` (trace.wgsl: `link`), so a
/// leaf holds at most this many items, and `first` and an inner node's index (its wide
/// entry, widen.wgsl) stay below 2^28.
pub const MAX_LINK_FIRST: u32 = (1 << slosh_cache::LINK_FIRST_BITS) - 1;
pub const MAX_LEAF_LINK_COUNT: u32 = u32::MAX >> MAX_LINK_FIRST.count_ones();

// Every leaf a bake writes (format 6: a range of at most `MAX_LEAF_RANGE` items) packs into a
// stack link.
const _: () = assert!(slosh_cache::MAX_LEAF_RANGE <= MAX_LEAF_LINK_COUNT);

/// Checks that the `bvh_nodes` section is a tree the trace pass can walk, and returns its
/// node count: every node packs into a stack link, a leaf's items lie in the item list, and
/// an inner node's children come after it (so every descent ends: trace.wgsl is compiled
/// without loop guards, `Tracer`'s `trace_module`). Each node is checked alone, so the
/// nodes are checked in parallel; the first bad one is named.
pub(super) fn check_tree(nodes: &[u8], items: u64) -> Result<u32, String> {
    const NODE: usize = size_of::<GpuBvhNode>();
    let node_count = (nodes.len() / NODE) as u64;
    if node_count > u64::from(MAX_LINK_FIRST) + 1 {
        return Err(format!(
            "section '{}' holds {node_count} nodes; the tracer links at most {}",
            names::BVH_NODES,
            u64::from(MAX_LINK_FIRST) + 1
        ));
    }
    let bad = nodes.par_chunks_exact(NODE).enumerate().find_map_first(|(i, node)| {
        let node: GpuBvhNode = bytemuck::pod_read_unaligned(node);
        let (count, first) = (node.count(), node.first());
        let (wide, first64) = (u64::from(count), u64::from(first));
        // A stored link packs as a stack link does (`slosh_cache::LINK_FIRST_BITS`).
        let problem = if count > 0 && first64 + wide > items {
            format!(
                "holds items {first}..{} of a list of {items}",
                first64 + wide
            )
        } else if count == 0 && (first64 <= i as u64 || first64 + 1 >= node_count) {
            format!(
                "has children {first} and {} in a tree of {node_count} nodes (children must follow their parent)",
                first64 + 1
            )
        } else {
            return None;
        };
        Some(format!(
            "BVH node {i} (byte {} of section '{}') {problem}",
            i * NODE,
            names::BVH_NODES
        ))
    });
    match bad {
        Some(problem) => Err(problem),
        None => Ok(node_count as u32),
    }
}

/// The first row of cluster `cluster`'s neighbour-mask words, `first` being its first
/// candidate slot: `mask_row` in shaders/step.wgsl, which explains the layout.
pub fn mask_row(cluster: u64, first: u64) -> u64 {
    (first + 31 * cluster) / 32
}

fn words(bytes: &[u8]) -> Vec<u32> {
    bytes
        .chunks_exact(4)
        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

/// The neighbour masks' layout and the candidates': the most mask words any cluster needs,
/// the rows of `cluster_size` words that hold every cluster's, and the candidate count. An
/// error where the cluster offsets are not monotone from 0, the clusters' candidate words do
/// not follow each other to the end of `cluster_neighbours` (`candidate_words` words), or
/// the masks would not be indexable by u32: the shaders rely on all three.
pub(super) fn mask_layout(
    cluster_start: &[u8],
    cluster_base: &[u8],
    candidate_words: u64,
    cluster_size: u32,
) -> Result<(u32, u64, u32), String> {
    let start32 = words(cluster_start);
    let starts: Vec<u64> = start32.iter().map(|&s| u64::from(s)).collect();
    if starts.first().is_some_and(|&s| s != 0) || starts.windows(2).any(|w| w[0] > w[1]) {
        return Err(format!(
            "section '{}' is not monotone from 0",
            names::CLUSTER_START
        ));
    }
    slosh_cache::candidates::check_layout(&start32, &words(cluster_base), candidate_words as usize)
        .map_err(|problem| format!("section '{}': {problem}", names::CLUSTER_BASE))?;
    let most = starts.windows(2).map(|w| w[1] - w[0]).max().unwrap_or(0);
    let clusters = starts.len().saturating_sub(1) as u64;
    let rows = mask_row(clusters, starts.last().copied().unwrap_or(0));
    if rows * u64::from(cluster_size) > u64::from(u32::MAX) {
        return Err(format!(
            "{rows} rows of neighbour masks exceed the tracer's 32-bit indices"
        ));
    }
    let candidates = starts.last().copied().unwrap_or(0) as u32;
    Ok((most.div_ceil(32) as u32, rows, candidates))
}

/// Writes [`slosh_cache::FIELD_MISSING`] over every missing value of `bytes` (little-endian
/// f32s), which the shade pass can test for where it cannot test for NaN, in the same pass
/// that finds the other values' range: how many were missing, and the others' minimum and
/// maximum (0, 0 when there are none).
pub(super) fn mark_missing(bytes: &mut [u8]) -> (usize, (f32, f32)) {
    let (mut missing, mut lo, mut hi) = (0, f32::INFINITY, f32::NEG_INFINITY);
    for c in bytes.chunks_exact_mut(4) {
        let v = f32::from_le_bytes([c[0], c[1], c[2], c[3]]);
        if slosh_cache::field_missing(v) {
            c.copy_from_slice(&slosh_cache::FIELD_MISSING.to_le_bytes());
            missing += 1;
        } else {
            (lo, hi) = (lo.min(v), hi.max(v));
        }
    }
    (missing, if lo <= hi { (lo, hi) } else { (0.0, 0.0) })
}

#[cfg(test)]
mod tests {
    use super::check_tree;
    use slosh_cache::{BvhGrid, BvhNode};

    /// A node as the `bvh_nodes` section stores it.
    fn node(count: u32, first: u32) -> Vec<u8> {
        let node = BvhNode {
            lo: [0.0; 3],
            count,
            hi: [1.0; 3],
            first,
        };
        bytemuck::bytes_of(&BvhGrid::default().encode(&node).unwrap()).to_vec()
    }

    #[test]
    fn trees_the_walk_could_not_finish_are_refused() {
        let tree = |nodes: &[(u32, u32)]| -> Vec<u8> {
            nodes.iter().flat_map(|&(c, f)| node(c, f)).collect()
        };
        // Root with two leaves of 3 and 2 items.
        assert_eq!(check_tree(&tree(&[(0, 1), (3, 0), (2, 3)]), 5), Ok(3));
        let cycle = check_tree(&tree(&[(0, 1), (0, 0), (2, 3)]), 5).unwrap_err();
        assert!(
            cycle.contains("BVH node 1 (byte 16") && cycle.contains("follow"),
            "{cycle}"
        );
        let outside = check_tree(&tree(&[(0, 1), (3, 0), (2, 4)]), 5).unwrap_err();
        assert!(outside.contains("items 4..6 of a list of 5"), "{outside}");
        let dangling = check_tree(&tree(&[(0, 1), (3, 0)]), 5).unwrap_err();
        assert!(
            dangling.contains("children 1 and 2 in a tree of 2 nodes"),
            "{dangling}"
        );
    }
}
