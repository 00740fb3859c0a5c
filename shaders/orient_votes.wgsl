// The orientation check's first-pass votes (crates/mls/src/orient.rs, `repair_orientation`)
// of every point on the GPU (crates/gpubake/src/orient.rs): each neighbour with a normal
// counts its tangent weight w = 1 − (n·d)²/|d|² to the 4th power, for or against the point's
// normal by the sign of their normals' dot product; a neighbour within 60° of the tangent plane is a patch edge.
// A neighbour at the place of one before it makes no edge, nor one farther than EDGE_REACH
// times the point's EDGE_RANK-th nearest place (none where it has fewer). In f32, so every test that rounding
// could have decided (a weight near 0 or the patch weight, a dot product near 0, a vote near
// the threshold, a neighbour at the point's place or at an earlier neighbour's) marks the
// point VOTE_RECAST, and the host casts its votes in f64. The constants are prepended from
// Rust (`slosh_mls::vote_word_wgsl`), then the grid's module (neighbour_grid.wgsl).

// The votes (slosh_mls::vote_word) of the dispatch's points, from sorted position
// params.first: patch edges in the low ORIENT_NEIGHBOURS bits.
@group(0) @binding(4) var<storage, read_write> votes: array<u32>;
// The dispatch's points' nearest as the nearest-points pass (nearest.wgsl) wrote them:
// params.wanted ids each, nearest first, by the caller's index, which is the sorted position
// here; the point itself among them or not. A point's neighbours for the check are its first
// ORIENT_NEIGHBOURS others. UNFINISHED (NO_POINT's value) first: the pass left the point to a
// coarser grid, whose ids only the host has.
@group(0) @binding(5) var<storage, read> nearest_ids: array<u32>;
// Each point's unit normal as f32, w 1; all zero where it has none.
@group(0) @binding(6) var<storage, read> normals: array<vec4<f32>>;

@compute @workgroup_size(64)
fn orient_votes(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k_point = thread_index(gid);
    if k_point >= params.count {
        return;
    }
    let i = params.first + k_point;
    let own = normals[i];
    // No normal: no votes and no edges.
    if own.w == 0.0 {
        votes[k_point] = 0u;
        return;
    }
    let base = k_point * params.wanted;
    if nearest_ids[base] == NO_POINT {
        votes[k_point] = VOTE_RECAST;
        return;
    }
    let p = positions[i].xyz;
    let p_low = residuals[i].xyz;
    var vote = 0.0;
    var total = 0.0;
    var word = 0u;
    // Places (neighbours not at the point's) met so far, and once the EDGE_RANK-th is met,
    // how far its edges reach, squared; nearest first, the places before it lie within.
    // (Twins count here each, where the host counts one place once; but a twin, like a
    // neighbour at the point's place, makes the point VOTE_RECAST.)
    var places = 0u;
    var reach2 = 0.0;
    // Each slot's neighbour and squared distance, for the twins below.
    var slot_ids: array<u32, ORIENT_NEIGHBOURS>;
    var slot_distance2: array<f32, ORIENT_NEIGHBOURS>;
    // k: the slot among the point's others, which names its patch edge's bit.
    var k = 0u;
    for (var s = 0u; s < params.wanted && k < ORIENT_NEIGHBOURS; s += 1u) {
        let j = nearest_ids[base + s];
        if j == i {
            continue;
        }
        k += 1u;
        slot_ids[k - 1u] = j;
        if j == NO_POINT {
            continue;
        }
        let d = difference(p, p_low, j);
        let dd = dot(d, d);
        slot_distance2[k - 1u] = dd;
        // A neighbour at the place of one before it makes no edge (a particle written twice
        // votes once). Points at one place are at one distance, in f32 too, and have one
        // split position; points with one split position may still differ in f64, which
        // decides.
        for (var m = 0u; m + 1u < k; m += 1u) {
            let before = slot_ids[m];
            if before != NO_POINT && slot_distance2[m] == dd
                && all(positions[before].xyz == positions[j].xyz)
                && all(residuals[before].xyz == residuals[j].xyz) {
                word |= VOTE_RECAST;
            }
        }
        if dd > 0.0 {
            places += 1u;
            if places == EDGE_RANK {
                reach2 = EDGE_REACH * EDGE_REACH * dd;
            }
        }
        // Points that coincide in f32 may not in f64, where the host counts a place that
        // this pass does not (with a normal or without).
        if dd <= 0.0 {
            word |= VOTE_RECAST;
            continue;
        }
        let other = normals[j];
        if other.w == 0.0 {
            continue;
        }
        if places > EDGE_RANK {
            if abs(dd - reach2) <= WEIGHT_MARGIN * reach2 {
                word |= VOTE_RECAST;
            }
            if dd > reach2 {
                continue;
            }
        }
        let along = dot(own.xyz, d);
        let w = 1.0 - along * along / dd;
        if w <= WEIGHT_MARGIN {
            // Along the normal: no edge, unless f64 would find a sliver of weight.
            if w > -WEIGHT_MARGIN {
                word |= VOTE_RECAST;
            }
            continue;
        }
        if abs(w - PATCH_WEIGHT) <= WEIGHT_MARGIN {
            word |= VOTE_RECAST;
        }
        let agreement = dot(own.xyz, other.xyz);
        if abs(agreement) <= WEIGHT_MARGIN {
            word |= VOTE_RECAST;
        }
        if w >= PATCH_WEIGHT {
            word |= 1u << (k - 1u);
            if agreement < 0.0 {
                word |= VOTE_CONTRADICTED;
            }
        }
        // Its vote weighs w to the power 2^VOTE_SQUARINGS (slosh_mls::VOTE_SQUARINGS).
        var weight = w;
        for (var e = 0u; e < VOTE_SQUARINGS; e += 1u) {
            weight *= weight;
        }
        vote += weight * sign(agreement);
        total += weight;
    }
    // Fewer places than EDGE_RANK: no stretch of surface, no edges.
    if places < EDGE_RANK {
        word &= VOTE_RECAST;
        total = 0.0;
    }
    if total > 0.0 {
        if vote < -REVERSE_BELOW * total {
            word |= VOTE_REVERSE;
        }
        if abs(vote + REVERSE_BELOW * total) <= VOTE_MARGIN {
            word |= VOTE_RECAST;
        }
    }
    votes[k_point] = word;
}
