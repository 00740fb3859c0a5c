// The widening pass, run by the tracer when a frame draws a step other than the one whose
// tree it holds (crates/render's widen.rs): the step's baked BVH2 (bvh_nodes, as the cache
// stores it: boxes on a grid) into the 4-wide tree the trace walk descends (wide_nodes,
// wide.wgsl: Wide, boxes in f32).
//
// One thread per BVH2 node, and entry i of the wide tree is node i's: its slots are node i's
// grandchildren (or a child that is a leaf), each with its box and its link, a leaf's packed
// items or an inner grandchild's node index. Every inner node gets its entry, whether or not
// the walk reaches it (from the root it meets every other level), so no thread needs another's
// result and the links need no numbering pass; a lone leaf root is entry 0's one slot.
// Entries of other leaves are never read and never written. The upload's host half refused
// trees whose links would not fit (slosh_render::MAX_LINK_FIRST, checks.rs).

// Mirrors `slosh_cache::GpuBvhNode`: the box's six grid coordinates two to a word (lo x |
// lo y << 16, lo z | hi x << 16, hi y | hi z << 16), and the link, packed as the walk stacks
// it: count 0 is an inner node with children first and first + 1, otherwise a leaf over
// items first .. first + count.
struct BvhNode {
    bounds: vec3<u32>,
    link: u32,
}

// Mirrors `slosh_render::WidenSettings`: the grid (slosh_cache::BvhGrid) and the dispatch.
struct WidenSettings {
    origin: vec3<f32>,
    node_count: u32,
    step: vec3<f32>,
    // Threads per row of the dispatch's grid (workgroups in x × WIDEN_GROUP).
    row_threads: u32,
}

@group(0) @binding(100) var<uniform> widen_settings: WidenSettings;

fn is_leaf(n: BvhNode) -> bool {
    return (n.link >> LINK_COUNT_SHIFT) != 0u;
}

fn first_of(n: BvhNode) -> u32 {
    return n.link & LINK_FIRST;
}

// The link a slot holding node `index` gets: a leaf's own (already packed as the walk stacks
// it), or the inner node's index, its entry.
fn link_of(n: BvhNode, index: u32) -> u32 {
    return select(index, n.link, is_leaf(n));
}

// A box's corners: origin + q × step per axis, the step a power of two, so one rounding as
// slosh_cache::BvhGrid::decode does.
fn low_corner(n: BvhNode) -> vec3<f32> {
    let q = vec3<u32>(n.bounds.x & 0xffffu, n.bounds.x >> 16u, n.bounds.y & 0xffffu);
    return widen_settings.origin + vec3<f32>(q) * widen_settings.step;
}

fn high_corner(n: BvhNode) -> vec3<f32> {
    let q = vec3<u32>(n.bounds.y >> 16u, n.bounds.z & 0xffffu, n.bounds.z >> 16u);
    return widen_settings.origin + vec3<f32>(q) * widen_settings.step;
}

// WIDEN_GROUP is generated from slosh_render's shaders.rs.
@compute @workgroup_size(WIDEN_GROUP)
fn widen(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x + gid.y * widen_settings.row_threads;
    if i >= widen_settings.node_count {
        return;
    }
    let node = bvh_nodes_at(i);
    if is_leaf(node) && i != 0u {
        return;
    }
    // Up to four slots; the unused stay the empty point with link 0.
    var lo = array<vec3<f32>, 4>(vec3<f32>(EMPTY_SLOT), vec3<f32>(EMPTY_SLOT), vec3<f32>(EMPTY_SLOT), vec3<f32>(EMPTY_SLOT));
    var hi = lo;
    var links = vec4<u32>(0u);
    var slot = 0u;
    if is_leaf(node) {
        lo[0] = low_corner(node);
        hi[0] = high_corner(node);
        links[0] = node.link;
    } else {
        for (var c = 0u; c < 2u; c++) {
            let child = bvh_nodes_at(first_of(node) + c);
            if is_leaf(child) {
                lo[slot] = low_corner(child);
                hi[slot] = high_corner(child);
                links[slot] = child.link;
                slot++;
                continue;
            }
            for (var g = 0u; g < 2u; g++) {
                let index = first_of(child) + g;
                let grandchild = bvh_nodes_at(index);
                lo[slot] = low_corner(grandchild);
                hi[slot] = high_corner(grandchild);
                links[slot] = link_of(grandchild, index);
                slot++;
            }
        }
    }
    var w: Wide;
    w.lo_x = vec4<f32>(lo[0].x, lo[1].x, lo[2].x, lo[3].x);
    w.hi_x = vec4<f32>(hi[0].x, hi[1].x, hi[2].x, hi[3].x);
    w.lo_y = vec4<f32>(lo[0].y, lo[1].y, lo[2].y, lo[3].y);
    w.hi_y = vec4<f32>(hi[0].y, hi[1].y, hi[2].y, hi[3].y);
    w.lo_z = vec4<f32>(lo[0].z, lo[1].z, lo[2].z, lo[3].z);
    w.hi_z = vec4<f32>(hi[0].z, hi[1].z, hi[2].z, hi[3].z);
    w.links = links;
    w.pad = vec4<u32>(0u);
    wide_nodes_set(i, w);
}
