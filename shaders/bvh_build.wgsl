// The bake's BVH over its leaves on the GPU (crates/gpubake/src/tree.rs): a linear BVH
// (Karras 2012, "Maximizing parallelism in the construction of BVHs, octrees, and k-d
// trees") over the leaves sorted by the Morton codes of their boxes' centres, written
// straight into the cache's node layout, then its boxes from the deepest inner nodes up.
//
// Layout: the root is slot 0, and the inner node that comes p-th in preorder among inner
// nodes has its children at slots 2p + 1 and 2p + 2: children adjacent and after their
// parent (whose own slot, 2q + 1 or 2q + 2, has q < p). An inner node's preorder index is
// the first leaf of its range plus the left turns on its path from the root: the inner nodes
// before it in preorder are its ancestors and those of the subtrees left of its path.

struct TreeParams {
    leaves: u32,
    row_threads: u32,
    _pad0: u32,
    _pad1: u32,
}

// As slosh_cache::BvhNode: count 0 is an inner node whose children are `first`, `first + 1`.
struct TreeNode {
    lo: vec3<f32>,
    count: u32,
    hi: vec3<f32>,
    first: u32,
}

@group(0) @binding(0) var<uniform> params: TreeParams;
// Each leaf's Morton code (high word, low word), ascending.
@group(0) @binding(1) var<storage, read> keys: array<vec2<u32>>;
// The leaves in the keys' order.
@group(0) @binding(2) var<storage, read> leaves: array<TreeNode>;
// 2·leaves − 1 slots.
@group(0) @binding(3) var<storage, read_write> nodes: array<TreeNode>;
// Each inner node (by Karras index): its range's first leaf, its split, and flags (1: the
// left child is a leaf, 2: the right child is a leaf, 4: it is its parent's left child).
@group(0) @binding(4) var<storage, read_write> links: array<vec4<u32>>;
// Each inner node's parent and slot, both written by the parent.
@group(0) @binding(5) var<storage, read_write> up: array<vec2<u32>>;
// Each inner node's depth (the root's 0) and preorder index among inner nodes.
@group(0) @binding(6) var<storage, read_write> inner: array<vec2<u32>>;
// [0]: the deepest inner node's depth; [1]: the depth whose boxes `fit_boxes` computes.
@group(0) @binding(7) var<storage, read_write> state: array<atomic<u32>>;

// MAX_DEPTH (the longest chain of inner nodes a build can make) is prepended from Rust.

fn thread_index(gid: vec3<u32>) -> u32 {
    return gid.y * params.row_threads + gid.x;
}

// Length of the common prefix of keys i and j, their indices breaking ties; −1 outside.
fn delta(i: i32, j: i32) -> i32 {
    if j < 0 || j >= i32(params.leaves) {
        return -1;
    }
    let a = keys[i];
    let b = keys[j];
    if a.x != b.x {
        return i32(countLeadingZeros(a.x ^ b.x));
    }
    if a.y != b.y {
        return 32 + i32(countLeadingZeros(a.y ^ b.y));
    }
    return 64 + i32(countLeadingZeros(u32(i) ^ u32(j)));
}

// One thread per inner node (leaves − 1 of them): its range and its split, and its parent
// link to the children that are inner nodes.
@compute @workgroup_size(64)
fn link_nodes(@builtin(global_invocation_id) gid: vec3<u32>) {
    let t = thread_index(gid);
    if t + 1u >= params.leaves {
        return;
    }
    let i = i32(t);
    let d = select(-1, 1, delta(i, i + 1) > delta(i, i - 1));
    // The range's other end: double the step while the prefix stays longer than the
    // neighbour's on the other side, then bisect.
    let shortest = delta(i, i - d);
    var reach = 2;
    while delta(i, i + reach * d) > shortest {
        reach = reach * 2;
    }
    var length = 0;
    var step = reach / 2;
    while step >= 1 {
        if delta(i, i + (length + step) * d) > shortest {
            length = length + step;
        }
        step = step / 2;
    }
    let j = i + length * d;
    // The split: the last leaf whose prefix with i is longer than the range's.
    let prefix = delta(i, j);
    var split = 0;
    var divisor = 2;
    loop {
        let s = (length + divisor - 1) / divisor;
        if delta(i, i + (split + s) * d) > prefix {
            split = split + s;
        }
        if s <= 1 {
            break;
        }
        divisor = divisor * 2;
    }
    let gamma = i + split * d + min(d, 0);
    var flags = 0u;
    if min(i, j) == gamma {
        flags = flags | 1u;
    } else {
        up[gamma].x = t;
    }
    if max(i, j) == gamma + 1 {
        flags = flags | 2u;
    } else {
        up[gamma + 1].x = t;
    }
    // Karras's node i ends at i when it is a left child.
    if d < 0 {
        flags = flags | 4u;
    }
    links[t] = vec4<u32>(u32(min(i, j)), u32(gamma), flags, 0u);
}

// One thread per inner node: its depth and its preorder index, by walking up to the root.
@compute @workgroup_size(64)
fn measure_depths(@builtin(global_invocation_id) gid: vec3<u32>) {
    let t = thread_index(gid);
    if t + 1u >= params.leaves {
        return;
    }
    var node = t;
    var depth = 0u;
    var left_turns = 0u;
    while node != 0u && depth < MAX_DEPTH {
        left_turns = left_turns + ((links[node].z >> 2u) & 1u);
        node = up[node].x;
        depth = depth + 1u;
    }
    inner[t] = vec2<u32>(depth, links[t].x + left_turns);
    atomicMax(&state[0], depth);
}

// One thread per inner node: its children into the slots its preorder index gives them.
@compute @workgroup_size(64)
fn place_nodes(@builtin(global_invocation_id) gid: vec3<u32>) {
    let t = thread_index(gid);
    if t + 1u >= params.leaves {
        return;
    }
    let base = 2u * inner[t].y + 1u;
    let gamma = links[t].y;
    let flags = links[t].z;
    if t == 0u {
        nodes[0].count = 0u;
        nodes[0].first = base;
    }
    for (var side = 0u; side < 2u; side = side + 1u) {
        let child = gamma + side;
        if (flags & (1u << side)) != 0u {
            nodes[base + side] = leaves[child];
        } else {
            nodes[base + side].count = 0u;
            nodes[base + side].first = 2u * inner[child].y + 1u;
            up[child].y = base + side;
        }
    }
}

// One thread per inner node: the box of each at the depth `state[1]` names, the union of its
// children's (leaves', or inner nodes' one depth down, which the previous dispatch made).
@compute @workgroup_size(64)
fn fit_boxes(@builtin(global_invocation_id) gid: vec3<u32>) {
    let t = thread_index(gid);
    if t + 1u >= params.leaves || inner[t].x != atomicLoad(&state[1]) {
        return;
    }
    var slot = 0u;
    if t != 0u {
        slot = up[t].y;
    }
    let a = nodes[nodes[slot].first];
    let b = nodes[nodes[slot].first + 1u];
    nodes[slot].lo = min(a.lo, b.lo);
    nodes[slot].hi = max(a.hi, b.hi);
}

// One thread: the next depth up.
@compute @workgroup_size(1)
fn next_depth() {
    atomicSub(&state[1], 1u);
}
