// The nearest points of every point (crates/gpubake/src/nearest.rs): shells of cells around
// the point's own, until no unvisited cell can hold a nearer point, or `shells` of them: a
// point that needs more (an outlier far from the rest) is marked and searched again on a
// coarser grid, so that no thread walks a whole sparse grid. Follows neighbour_grid.wgsl.
// NEAREST_MAX is prepended from Rust.

// The caller's indices of each point's nearest, nearest first, for the dispatch's points;
// UNFINISHED first where the shells ran out.
@group(0) @binding(4) var<storage, read_write> nearest_out: array<u32>;
// With flag 8, the sorted positions of the dispatch's points (else first + k).
@group(0) @binding(5) var<storage, read> todo: array<u32>;

const UNFINISHED: u32 = 0xffffffffu;

// (d², id) ordered by distance, then index.
fn before(d2: f32, id: u32, other_d2: f32, other_id: u32) -> bool {
    return d2 < other_d2 || (d2 == other_d2 && id < other_id);
}

@compute @workgroup_size(64)
fn nearest(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = thread_index(gid);
    if k >= params.count {
        return;
    }
    var t = params.first + k;
    if (params.flags & 8u) != 0u {
        t = todo[k];
    }
    let p = positions[t].xyz;
    let p_low = residuals[t].xyz;
    let wanted = params.wanted;
    var best_d2: array<f32, NEAREST_MAX>;
    var best_id: array<u32, NEAREST_MAX>;
    var found = 0u;
    let c = cell_of(p);
    let side = i32(params.side);
    let cell_size = 1.0 / params.lo.w;
    let last_shell = min(side, i32(params.shells));
    var finished = false;
    for (var s = 0; s <= last_shell; s += 1) {
        for (var dz = -s; dz <= s; dz += 1) {
            let z = c.z + dz;
            if z < 0 || z >= side {
                continue;
            }
            for (var dy = -s; dy <= s; dy += 1) {
                let y = c.y + dy;
                if y < 0 || y >= side {
                    continue;
                }
                // Inside the shell's faces in z and y, only its two x faces are new.
                let whole_row = abs(dz) == s || abs(dy) == s;
                var dx = -s;
                loop {
                    if dx > s {
                        break;
                    }
                    let x = c.x + dx;
                    if x >= 0 && x < side {
                        let code = cell_code(x, y, z);
                        let end = cell_start[code + 1u];
                        for (var j = cell_start[code]; j < end; j += 1u) {
                            let d = difference(p, p_low, j);
                            let d2 = d.x * d.x + d.y * d.y + d.z * d.z;
                            let id = original[j];
                            if found < wanted || before(d2, id, best_d2[wanted - 1u], best_id[wanted - 1u]) {
                                var at = min(found, wanted - 1u);
                                while at > 0u && before(d2, id, best_d2[at - 1u], best_id[at - 1u]) {
                                    best_d2[at] = best_d2[at - 1u];
                                    best_id[at] = best_id[at - 1u];
                                    at -= 1u;
                                }
                                best_d2[at] = d2;
                                best_id[at] = id;
                                found = min(found + 1u, wanted);
                            }
                        }
                    }
                    if whole_row || s == 0 {
                        dx += 1;
                    } else {
                        dx += 2 * s;
                    }
                }
            }
        }
        // Every unvisited cell lies at least s cells beyond the point's own; past the grid's
        // side there is none.
        let clear = f32(s) * cell_size - params.margin;
        if found == wanted && ((clear > 0.0 && best_d2[wanted - 1u] <= clear * clear) || s >= side) {
            finished = true;
            break;
        }
    }
    let base = k * wanted;
    if !finished {
        nearest_out[base] = UNFINISHED;
        return;
    }
    for (var i = 0u; i < wanted; i += 1u) {
        nearest_out[base + i] = best_id[i];
    }
}
