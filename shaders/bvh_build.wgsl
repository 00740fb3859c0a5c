// The bake's BVH over its leaves on the GPU (crates/gpubake/src/tree.rs): a linear BVH
// (Karras 2012, "Maximizing parallelism in the construction of BVHs, octrees, and k-d
// trees") over the leaves sorted by the Morton codes of their boxes' centres, written
// straight into the cache's node layout, then its boxes from the deepest inner nodes up.
//
// Layout: the inner node whose split is γ (its left child ends at leaf γ) has its children
// at slots 2γ + 1 and 2γ + 2, so children are adjacent and the root is slot 0 without a
// rewrite. Karras's inner node i ends at i when it is a left child (slot 2i + 1) and starts
// at i when it is a right child (slot 2i); a leaf takes the slot its parent gives it.

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
// Each slot's parent's slot (the root's unused).
@group(0) @binding(4) var<storage, read_write> parent: array<u32>;
// Each inner node's slot and depth (the root's 0), by Karras index.
@group(0) @binding(5) var<storage, read_write> inner: array<vec2<u32>>;
// [0]: the deepest inner node's depth; [1]: the depth whose boxes `fit_boxes` computes.
@group(0) @binding(6) var<storage, read_write> state: array<atomic<u32>>;

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

// One thread per inner node (leaves − 1 of them): its range, its split, its slot, and the
// links to its children; a child that is a leaf is copied into its slot.
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
    var slot = 0u;
    if i > 0 {
        slot = select(2u * t, 2u * t + 1u, d < 0);
    }
    let left = 2u * u32(gamma) + 1u;
    nodes[slot].count = 0u;
    nodes[slot].first = left;
    parent[left] = slot;
    parent[left + 1u] = slot;
    if min(i, j) == gamma {
        nodes[left] = leaves[gamma];
    }
    if max(i, j) == gamma + 1 {
        nodes[left + 1u] = leaves[gamma + 1];
    }
    inner[t] = vec2<u32>(slot, 0u);
}

// One thread per inner node: its depth, by walking up to the root.
@compute @workgroup_size(64)
fn measure_depths(@builtin(global_invocation_id) gid: vec3<u32>) {
    let t = thread_index(gid);
    if t + 1u >= params.leaves {
        return;
    }
    var slot = inner[t].x;
    var depth = 0u;
    while slot != 0u && depth < MAX_DEPTH {
        slot = parent[slot];
        depth = depth + 1u;
    }
    inner[t].y = depth;
    atomicMax(&state[0], depth);
}

// One thread per inner node: the box of each at the depth `state[1]` names, the union of its
// children's (leaves', or inner nodes' one depth down, which the previous dispatch made).
@compute @workgroup_size(64)
fn fit_boxes(@builtin(global_invocation_id) gid: vec3<u32>) {
    let t = thread_index(gid);
    if t + 1u >= params.leaves || inner[t].y != atomicLoad(&state[1]) {
        return;
    }
    let slot = inner[t].x;
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
