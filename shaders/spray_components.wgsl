// Spray components on the GPU (crates/gpubake/src/components.rs): the points the lists pass
// linked (LINK_BIT: a neighbour within the point's link distance) joined by a concurrent
// union-find over each batch of lists while it is on the GPU, so that the links are never
// read back. A root is only ever hooked under the smaller of two roots (compare and swap on
// the root), so each component's root is its smallest index, as slosh_mls::component_roots
// names it; finds halve their paths as they go, storing a grandparent, which is safe since a
// point that is no root never becomes one again (ECL-CC: Jaiganesh and Burtscher, 2018).
// `join_links` runs over each batch's points, `flatten` once over every point after.
// Follows list_batch.wgsl; LINK_BIT and ID_MASK come from crates/gpubake/src/layout.rs.

struct ComponentParams {
    // The dispatch's first point and how many points it takes.
    first: u32,
    count: u32,
    // The slot among all lists of `lists`' first word.
    list_base: u32,
    row_threads: u32,
}

@group(0) @binding(0) var<uniform> params: ComponentParams;
// Each point's parent: itself at first; its component's root after `flatten`.
@group(0) @binding(3) var<storage, read_write> parent: array<atomic<u32>>;

fn find(start: u32) -> u32 {
    var x = start;
    var p = atomicLoad(&parent[x]);
    while p != x {
        let g = atomicLoad(&parent[p]);
        if g != p {
            atomicStore(&parent[x], g);
        }
        x = g;
        p = atomicLoad(&parent[x]);
    }
    return x;
}

fn unite(a: u32, b: u32) {
    var x = find(a);
    var y = find(b);
    loop {
        if x == y {
            return;
        }
        let low = min(x, y);
        let high = max(x, y);
        let swapped = atomicCompareExchangeWeak(&parent[high], high, low);
        if swapped.exchanged {
            return;
        }
        // `high` was hooked meanwhile (or the exchange failed spuriously): on from its root.
        x = find(high);
        y = find(low);
    }
}

fn thread_index(id: vec3<u32>) -> u32 {
    return id.x + id.y * params.row_threads;
}

@compute @workgroup_size(64)
fn join_links(@builtin(global_invocation_id) id: vec3<u32>) {
    let k = thread_index(id);
    if k >= params.count {
        return;
    }
    let t = params.first + k;
    let end = list_start[t + 1u] - params.list_base;
    for (var w = list_start[t] - params.list_base; w < end; w++) {
        let word = lists[w];
        if (word & LINK_BIT) != 0u {
            unite(t, word & ID_MASK);
        }
    }
}

@compute @workgroup_size(64)
fn flatten(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = thread_index(id);
    if i >= params.count {
        return;
    }
    atomicStore(&parent[i], find(i));
}
