// Every point's neighbour list (crates/gpubake/src/lists.rs), as the CPU defines it
// (docs/algorithm.md): the nearest `cap` within reach, by (d², index), minus neighbours whose
// normal opposes the point's, in index order. Follows neighbour_grid.wgsl.
//
// `cut` finds where the cap cuts each list, by radix selection over the squared distances'
// bits (then over the indices, where the cut falls among equal distances), walking the
// point's cells once per digit, and counts what the list keeps; `write` walks them once more
// and writes the list where the counts' prefix sum says, then sorts it.

// Sorted order, like the positions.
@group(0) @binding(4) var<storage, read> reach: array<f32>;
// Unit data normals (zero where a point has none; one element without normals).
@group(0) @binding(5) var<storage, read> normals: array<vec4<f32>>;
// Squared link distances (one element without links).
@group(0) @binding(6) var<storage, read> link2: array<f32>;
// Per point of the set: the cut's distance bits and index (all ones: nothing cut), how many
// the list keeps, and whether the cap cut it (at or above the cap within reach).
@group(0) @binding(7) var<storage, read_write> cut: array<vec4<u32>>;
// Per point of the set: where its list begins among all lists (write only).
@group(0) @binding(8) var<storage, read> list_start: array<u32>;
// The dispatch's lists, from slot `out_base`: each id, with LINK_BIT where it is a link.
@group(0) @binding(9) var<storage, read_write> lists_out: array<u32>;

const LINK_BIT: u32 = 0x80000000u;
const ALL: u32 = 0xffffffffu;

const COUNT_WITHIN: u32 = 0u;
const DISTANCE_DIGIT: u32 = 1u;
const INDEX_DIGIT: u32 = 2u;
const COUNT_KEPT: u32 = 3u;
const WRITE: u32 = 4u;

var<private> centre: vec3<f32>;
var<private> centre_low: vec3<f32>;
var<private> centre_id: u32;
var<private> reach2: f32;
var<private> own_normal: vec3<f32>;
var<private> own_link2: f32;
var<private> cut_key: u32;
var<private> cut_id: u32;
var<private> digits: array<u32, 16>;
var<private> select_prefix: u32;
var<private> select_mask: u32;
var<private> select_shift: u32;
var<private> counted: u32;
var<private> out_at: u32;

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
        case COUNT_WITHIN: {
            counted += 1u;
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
            if (params.flags & 1u) != 0u && dot(own_normal, normals[j].xyz) < 0.0 {
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
    for (var z = lo.z; z <= hi.z; z += 1) {
        for (var y = lo.y; y <= hi.y; y += 1) {
            for (var x = lo.x; x <= hi.x; x += 1) {
                let code = cell_code(x, y, z);
                let end = cell_start[code + 1u];
                for (var j = cell_start[code]; j < end; j += 1u) {
                    visit(mode, j);
                }
            }
        }
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
fn select(mode: u32, need_first: u32) -> Selected {
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

@compute @workgroup_size(64)
fn cut_lists(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = thread_index(gid);
    if k >= params.count {
        return;
    }
    let t = params.first + k;
    begin(t);
    cut_key = ALL;
    cut_id = ALL;
    counted = 0u;
    walk(COUNT_WITHIN);
    let cap = params.wanted;
    let capped = counted >= cap;
    if capped {
        let by_distance = select(DISTANCE_DIGIT, cap);
        cut_key = by_distance.value;
        if by_distance.equal > by_distance.take {
            cut_id = select(INDEX_DIGIT, by_distance.take).value;
        }
    }
    counted = 0u;
    walk(COUNT_KEPT);
    cut[t] = vec4<u32>(cut_key, cut_id, counted, u32(capped));
}

@compute @workgroup_size(64)
fn write_lists(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = thread_index(gid);
    if k >= params.count {
        return;
    }
    let t = params.first + k;
    begin(t);
    cut_key = cut[t].x;
    cut_id = cut[t].y;
    let first = list_start[t] - params.out_base;
    out_at = first;
    walk(WRITE);
    // Index order (lists hold up to the cap: an insertion sort in place).
    for (var i = first + 1u; i < out_at; i += 1u) {
        let word = lists_out[i];
        var at = i;
        while at > first && (lists_out[at - 1u] & ~LINK_BIT) > (word & ~LINK_BIT) {
            lists_out[at] = lists_out[at - 1u];
            at -= 1u;
        }
        lists_out[at] = word;
    }
}
