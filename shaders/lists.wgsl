// Every point's neighbour list (crates/gpubake/src/lists.rs), as the CPU defines it
// (docs/algorithm.md): the nearest `cap` within reach, by (d², index), minus neighbours whose
// normal opposes the point's, in index order. Follows neighbour_grid.wgsl.
//
// `cut_lists` finds where the cap cuts each list and counts what the list keeps: one walk over
// the point's cells counts the candidates within reach in 32 bins of d²/reach² (and those
// whose normal opposes), a second gathers the bin the cut falls in and sorts it by
// (d², index). Where that bin holds more than BIN_MOST (exact ties: lattices, duplicates),
// radix selection over the squared distances' bits (then over the indices) finds the cut,
// a walk per four bits. `write_lists` walks the cells once more and writes the list where
// the counts' prefix sum says, then sorts it.

// Sorted order, like the positions.
@group(0) @binding(4) var<storage, read> reach: array<f32>;
// Unit data normals (zero where a point has none; one element without normals).
@group(0) @binding(5) var<storage, read> normals: array<vec4<f32>>;
// Squared link distances (one element without links).
@group(0) @binding(6) var<storage, read> link2: array<f32>;
// Per point of the set: the cut's distance bits and the index of the point it falls on (all
// ones: nothing cut), how many the list keeps, and whether the cap cut it (at or above the cap
// within reach) in bit 0 with the grid's level above it (DEFERRED: not yet cut).
@group(0) @binding(7) var<storage, read_write> cut: array<vec4<u32>>;
// Per point of the set: where its list begins among all lists (write only).
@group(0) @binding(8) var<storage, read> list_start: array<u32>;
// The dispatch's lists, from slot `out_base`: each id, with LINK_BIT where it is a link and
// FAR_BIT where the list was cut and its squared distance lies within NEAR_CUT of the cut's
// (those constants and ID_MASK come from crates/gpubake/src/layout.rs).
@group(0) @binding(9) var<storage, read_write> lists_out: array<u32>;
// With flag 8, the sorted positions of the dispatch's points (else first + k).
@group(0) @binding(11) var<storage, read> todo: array<u32>;
// With FLAG_PAIRS, (the caller's index of the point, the member's word) for each member within
// `band` of its list's reach (of the cut's distance where the cap cut it) or marked FAR_BIT:
// what the host measures a list's reach on where it reads no lists back. Slots past the
// buffer's end are counted but not written (the host then reads the lists).
@group(0) @binding(12) var<storage, read_write> pairs: array<vec2<u32>>;
@group(0) @binding(13) var<storage, read_write> pair_count: array<atomic<u32>>;

const ALL: u32 = 0xffffffffu;
// cut[t].w of a point whose reach spans more cells than MOST_CELLS: left to a coarser grid, so
// that no thread walks a whole sparse grid (an isolated particle's reach with h per point).
const DEFERRED: u32 = 0xffffffffu;
const MOST_CELLS: u32 = 4096u;

const BIN_COUNT: u32 = 0u;
const DISTANCE_DIGIT: u32 = 1u;
const INDEX_DIGIT: u32 = 2u;
const COUNT_KEPT: u32 = 3u;
const WRITE: u32 = 4u;
const BIN_GATHER: u32 = 5u;

const BINS: u32 = 32u;
// The most entries of the cut's bin sorted in private memory.
const BIN_MOST: u32 = 64u;

var<private> centre: vec3<f32>;
var<private> centre_low: vec3<f32>;
var<private> centre_id: u32;
var<private> reach2: f32;
var<private> own_normal: vec3<f32>;
var<private> own_link2: f32;
var<private> cut_key: u32;
// Members at or above this key are marked FAR_BIT (ALL: the list was not cut).
var<private> near_key: u32;
// Members at or above this key are appended to the pairs (ALL: none are).
var<private> pair_key: u32;
var<private> cut_id: u32;
var<private> digits: array<u32, 16>;
var<private> select_prefix: u32;
var<private> select_mask: u32;
var<private> select_shift: u32;
var<private> counted: u32;
var<private> out_at: u32;
var<private> bins: array<u32, BINS>;
var<private> opposed_bins: array<u32, BINS>;
var<private> bin_scale: f32;
var<private> cut_bin: u32;
var<private> gathered: u32;
var<private> gathered_key: array<u32, BIN_MOST>;
// The index, with LINK_BIT where the normal opposes.
var<private> gathered_id: array<u32, BIN_MOST>;

fn opposes(j: u32) -> bool {
    return (params.flags & 1u) != 0u && dot(own_normal, normals[j].xyz) < 0.0;
}

// Monotone in d², so every bin's keys lie above the bins' before it.
fn bin_of(d2: f32) -> u32 {
    return min(u32(d2 * bin_scale), BINS - 1u);
}

fn visit(mode: u32, j: u32) {
    let d = difference(centre, centre_low, j);
    let d2 = d.x * d.x + d.y * d.y + d.z * d.z;
    if !(d2 <= reach2) {
        return;
    }
    // Non-negative floats order as their bits.
    let key = bitcast<u32>(d2);
    let id = original[j];
    switch mode {
        case BIN_COUNT: {
            counted += 1u;
            let b = bin_of(d2);
            bins[b] += 1u;
            if opposes(j) {
                opposed_bins[b] += 1u;
            }
        }
        case BIN_GATHER: {
            if bin_of(d2) == cut_bin && gathered < BIN_MOST {
                gathered_key[gathered] = key;
                gathered_id[gathered] = id | select(0u, LINK_BIT, opposes(j));
                gathered += 1u;
            }
        }
        case DISTANCE_DIGIT: {
            if (key & select_mask) == select_prefix {
                digits[(key >> select_shift) & 15u] += 1u;
            }
        }
        case INDEX_DIGIT: {
            if key == cut_key && (id & select_mask) == select_prefix {
                digits[(id >> select_shift) & 15u] += 1u;
            }
        }
        default: {
            if key > cut_key || (key == cut_key && id > cut_id) {
                return;
            }
            if opposes(j) {
                return;
            }
            if mode == COUNT_KEPT {
                counted += 1u;
                return;
            }
            var word = id;
            if (params.flags & 2u) != 0u && d2 <= own_link2 && id != centre_id {
                word |= LINK_BIT;
            }
            if key >= near_key {
                word |= FAR_BIT;
            }
            if key >= pair_key {
                let slot = atomicAdd(&pair_count[0], 1u);
                if slot < arrayLength(&pairs) {
                    pairs[slot] = vec2<u32>(centre_id, word);
                }
            }
            lists_out[out_at] = word;
            out_at += 1u;
        }
    }
}

// Visits every point of every cell the point's reach (and the margin) touches.
fn walk(mode: u32) {
    let r = sqrt(reach2) + params.margin;
    let lo = cell_of(centre - vec3<f32>(r));
    let hi = cell_of(centre + vec3<f32>(r));
    if mode == WRITE && (params.flags & 4u) != 0u {
        walk_in_order(vec3<u32>(lo), vec3<u32>(hi));
        return;
    }
    for (var z = lo.z; z <= hi.z; z += 1) {
        for (var y = lo.y; y <= hi.y; y += 1) {
            for (var x = lo.x; x <= hi.x; x += 1) {
                visit_cell(mode, cell_code(x, y, z));
            }
        }
    }
}

// Writes the lists of the cells in [lo, hi] in Morton order: depth first through the octree
// of cells, children in code order, skipping every node outside the box. The points then come
// in sorted order, which is index order where the caller's points came in Morton order (the
// bake's): the list needs no sort. Slower than the plain loop where order does not matter.
fn walk_in_order(lo: vec3<u32>, hi: vec3<u32>) {
    let level = countTrailingZeros(params.side);
    if level == 0u {
        visit_cell(WRITE, 0u);
        return;
    }
    // At depth d: the node's coordinates at level d, and the next of its children to try.
    var node: array<vec3<u32>, 11>;
    var next_child: array<u32, 11>;
    node[0] = vec3<u32>(0u);
    next_child[0] = 0u;
    var depth = 0u;
    loop {
        if next_child[depth] == 8u {
            if depth == 0u {
                break;
            }
            depth -= 1u;
            continue;
        }
        let c = next_child[depth];
        next_child[depth] = c + 1u;
        let child = node[depth] * 2u + vec3<u32>(c & 1u, (c >> 1u) & 1u, c >> 2u);
        let shift = level - (depth + 1u);
        let first = child << vec3<u32>(shift);
        let last = first + vec3<u32>((1u << shift) - 1u);
        if any(last < lo) || any(first > hi) {
            continue;
        }
        if shift == 0u {
            visit_cell(WRITE, cell_code(i32(child.x), i32(child.y), i32(child.z)));
            continue;
        }
        depth += 1u;
        node[depth] = child;
        next_child[depth] = 0u;
    }
}

fn visit_cell(mode: u32, code: u32) {
    let end = cell_start[code + 1u];
    for (var j = cell_start[code]; j < end; j += 1u) {
        visit(mode, j);
    }
}

struct Selected {
    // The need-th smallest value.
    value: u32,
    // How many equal to it the first `need` take.
    take: u32,
    // How many equal to it there are.
    equal: u32,
};

// The need-th smallest distance bits (DISTANCE_DIGIT) or index among the cut's distance
// (INDEX_DIGIT), four bits a walk, from the top.
fn select_value(mode: u32, need_first: u32) -> Selected {
    var need = need_first;
    select_prefix = 0u;
    select_mask = 0u;
    var equal = 0u;
    for (var shift = 28; shift >= 0; shift -= 4) {
        select_shift = u32(shift);
        for (var d = 0u; d < 16u; d += 1u) {
            digits[d] = 0u;
        }
        walk(mode);
        var d = 0u;
        loop {
            if need <= digits[d] || d == 15u {
                break;
            }
            need -= digits[d];
            d += 1u;
        }
        select_prefix |= d << select_shift;
        select_mask |= 15u << select_shift;
        equal = digits[d];
    }
    return Selected(select_prefix, need, equal);
}

// The sorted position of the dispatch's k-th point.
fn point_of(k: u32) -> u32 {
    if (params.flags & 8u) != 0u {
        return todo[k];
    }
    return params.first + k;
}

fn begin(t: u32) {
    centre = positions[t].xyz;
    centre_low = residuals[t].xyz;
    centre_id = original[t];
    let r = reach[t];
    reach2 = r * r;
    if (params.flags & 1u) != 0u {
        own_normal = normals[t].xyz;
    }
    if (params.flags & 2u) != 0u {
        own_link2 = link2[t];
    }
}

// The cut within bin `cut_bin` (at most BIN_MOST entries): its `need`-th entry by (d², index),
// and how many of the first `need` oppose.
fn cut_in_bin(need: u32) -> u32 {
    gathered = 0u;
    walk(BIN_GATHER);
    for (var i = 1u; i < gathered; i += 1u) {
        let key = gathered_key[i];
        let id = gathered_id[i];
        var at = i;
        loop {
            if at == 0u {
                break;
            }
            let kb = gathered_key[at - 1u];
            let ib = gathered_id[at - 1u] & ~LINK_BIT;
            if !(key < kb || (key == kb && (id & ~LINK_BIT) < ib)) {
                break;
            }
            gathered_key[at] = kb;
            gathered_id[at] = gathered_id[at - 1u];
            at -= 1u;
        }
        gathered_key[at] = key;
        gathered_id[at] = id;
    }
    cut_key = gathered_key[need - 1u];
    cut_id = gathered_id[need - 1u] & ~LINK_BIT;
    var opposed = 0u;
    for (var i = 0u; i < need; i += 1u) {
        opposed += select(0u, 1u, (gathered_id[i] & LINK_BIT) != 0u);
    }
    return opposed;
}

@compute @workgroup_size(64)
fn cut_lists(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = thread_index(gid);
    if k >= params.count {
        return;
    }
    let t = point_of(k);
    begin(t);
    let level = countTrailingZeros(params.side);
    let r = sqrt(reach2) + params.margin;
    let box = cell_of(centre + vec3<f32>(r)) - cell_of(centre - vec3<f32>(r)) + vec3<i32>(1);
    if u32(box.x) * u32(box.y) * u32(box.z) > MOST_CELLS && level > 1u {
        cut[t] = vec4<u32>(ALL, ALL, 0u, DEFERRED);
        return;
    }
    cut_key = ALL;
    cut_id = ALL;
    counted = 0u;
    for (var b = 0u; b < BINS; b += 1u) {
        bins[b] = 0u;
        opposed_bins[b] = 0u;
    }
    bin_scale = select(0.0, f32(BINS) / reach2, reach2 > 0.0);
    walk(BIN_COUNT);
    let cap = params.wanted;
    let capped = counted >= cap;
    var kept = 0u;
    if !capped {
        var opposed = 0u;
        for (var b = 0u; b < BINS; b += 1u) {
            opposed += opposed_bins[b];
        }
        kept = counted - opposed;
    } else {
        var below = 0u;
        var opposed_below = 0u;
        var b = 0u;
        loop {
            if below + bins[b] >= cap || b == BINS - 1u {
                break;
            }
            below += bins[b];
            opposed_below += opposed_bins[b];
            b += 1u;
        }
        let need = cap - below;
        if bins[b] <= BIN_MOST {
            cut_bin = b;
            let opposed_in = cut_in_bin(need);
            kept = below - opposed_below + need - opposed_in;
        } else {
            let by_distance = select_value(DISTANCE_DIGIT, cap);
            cut_key = by_distance.value;
            // The index too where no other shares the distance: the host measures the cut
            // point's distance in f64.
            cut_id = select_value(INDEX_DIGIT, by_distance.take).value;
            counted = 0u;
            walk(COUNT_KEPT);
            kept = counted;
        }
    }
    cut[t] = vec4<u32>(cut_key, cut_id, kept, u32(capped) | (level << 1u));
}

@compute @workgroup_size(64)
fn write_lists(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = thread_index(gid);
    if k >= params.count {
        return;
    }
    let t = point_of(k);
    // Points cut on another grid are written by that grid's dispatch.
    if (cut[t].w >> 1u) != countTrailingZeros(params.side) {
        return;
    }
    begin(t);
    cut_key = cut[t].x;
    cut_id = cut[t].y;
    near_key = ALL;
    if (cut[t].w & 1u) != 0u {
        near_key = bitcast<u32>(bitcast<f32>(cut_key) * (1.0 - NEAR_CUT));
    }
    pair_key = ALL;
    if (params.flags & FLAG_PAIRS) != 0u {
        // The list reaches its reach, or where the cap cut it, the cut's distance.
        var far = sqrt(reach2);
        if (cut[t].w & 1u) != 0u {
            far = sqrt(bitcast<f32>(cut_key));
        }
        let inner = max(far - params.band, 0.0);
        pair_key = min(bitcast<u32>(inner * inner), near_key);
    }
    let first = list_start[t] - params.out_base;
    out_at = first;
    walk(WRITE);
    // Index order: as walked where the points came sorted, else an insertion sort in place
    // (lists hold up to the cap).
    if (params.flags & 4u) != 0u {
        return;
    }
    for (var i = first + 1u; i < out_at; i += 1u) {
        let word = lists_out[i];
        var at = i;
        while at > first && (lists_out[at - 1u] & ID_MASK) > (word & ID_MASK) {
            lists_out[at] = lists_out[at - 1u];
            at -= 1u;
        }
        lists_out[at] = word;
    }
}
