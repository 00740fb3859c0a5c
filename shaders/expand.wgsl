// The neighbour-mask pass, run by the tracer before a step's first refined frame (masks.rs).
//
// `expand`: first each cluster's runs of candidates (slosh_cache::candidates) into one index
// per slot of `candidates`, then the neighbour masks: which of a point's cluster
// candidates are its neighbours (clusters.rs: expand_one, the rule docs/algorithm.md gives):
// within the point's reach, and not a point whose normal opposes the centre's (both valid).
// Bit b of word w is candidate slot 32 w + b; a cluster writes only the words its own
// candidates need, each member's side by side (step.wgsl: mask_row). The
// refinement loops in mls.wgsl then visit only the set bits.

// Mirrors `slosh_render::ExpandSettings`.
struct ExpandSettings {
    point_count: u32,
    cluster_size: u32,
    mask_words: u32,
    has_normals: u32,
    // Words of cluster_ids (the runs).
    run_words: u32,
    // The clusters this dispatch derives: first_cluster..end_cluster.
    first_cluster: u32,
    end_cluster: u32,
    // Candidate slots of all clusters (the last cluster_start).
    candidate_count: u32,
}

// The arrays (shaders.rs: EXPAND_ARRAYS) are read and written through accessors that
// crates/render's shaders.rs generates over the ranges they are bound in.
@group(0) @binding(100) var<uniform> expand_settings: ExpandSettings;

// One workgroup per cluster: its candidates' positions and normals are read once into
// workgroup memory, a tile of MASK_TILE at a time, and every (member, word) pair of the tile
// tests them there (a member reads each candidate from memory 32 times fewer). The tests are
// the same expressions as clusters.rs, so the bits are too.
const MASK_TILE: u32 = 256u;
const TILE_WORDS: u32 = 8u; // MASK_TILE / 32
var<workgroup> tile_positions: array<vec4<f32>, MASK_TILE>;
var<workgroup> tile_normals: array<vec4<f32>, MASK_TILE>;
var<workgroup> cluster_first: u32;
var<workgroup> cluster_count: u32;
var<workgroup> cluster_base_word: u32;
var<workgroup> cluster_end_word: u32;
// A tile of runs' lengths, scanned into their first slots.
var<workgroup> run_slots: array<u32, MASK_TILE>;

// Writes cluster c's candidates, one per slot from `first`, from its runs: a tile of runs at
// a time, each thread one run, placed by an exclusive scan of the tile's lengths. Slots no
// run reaches keep NO_NEIGHBOUR, and a run never writes past the cluster's `count` slots,
// whatever the file holds.
fn expand_runs(c: u32, first: u32, count: u32, lid: u32) {
    let cfg = expand_settings;
    let size = max(cfg.cluster_size, 1u);
    for (var k = lid; k < count; k += MASK_TILE) {
        candidates_set(first + k, NO_NEIGHBOUR);
    }
    // Another thread's run may write a slot this thread emptied: the fill lands first.
    storageBarrier();
    let base = workgroupUniformLoad(&cluster_base_word);
    let wide = (base & WIDE_CLUSTER) != 0u;
    let at = base & ~WIDE_CLUSTER;
    let end = workgroupUniformLoad(&cluster_end_word);
    let per_run = select(1u, 2u, wide);
    let runs = select(0u, (end - at) / per_run, end > at);
    var placed = 0u;
    for (var tile = 0u; tile < runs; tile += MASK_TILE) {
        let r = tile + lid;
        var start = 0u;
        var len = 0u;
        if r < runs {
            if wide {
                start = cluster_ids_at(at + 2u * r);
                len = cluster_ids_at(at + 2u * r + 1u);
            } else {
                let word = cluster_ids_at(at + r);
                start = c * size + (word & 0xffffu) - NARROW_BIAS;
                len = word >> 16u;
            }
        }
        // Inclusive scan (Hillis–Steele), saturating so that a hostile length cannot wrap.
        run_slots[lid] = min(len, count);
        workgroupBarrier();
        for (var d = 1u; d < MASK_TILE; d <<= 1u) {
            var add = 0u;
            if lid >= d {
                add = run_slots[lid - d];
            }
            workgroupBarrier();
            run_slots[lid] = min(run_slots[lid] + add, count);
            workgroupBarrier();
        }
        let at_slot = min(placed + run_slots[lid] - min(len, count), count);
        for (var m = 0u; m < len && at_slot + m < count; m++) {
            candidates_set(first + at_slot + m, start + m);
        }
        placed = min(placed + workgroupUniformLoad(&run_slots[MASK_TILE - 1u]), count);
    }
    storageBarrier();
}

@compute @workgroup_size(256, 1, 1)
fn expand(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let cfg = expand_settings;
    let size = max(cfg.cluster_size, 1u);
    let c = cfg.first_cluster + wid.y * groups.x + wid.x;
    if cfg.mask_words == 0u || c >= min(cfg.end_cluster, (cfg.point_count + size - 1u) / size) {
        return;
    }
    if lid == 0u {
        let first = cluster_start_at(c);
        let last = min(cluster_start_at(c + 1u), cfg.candidate_count);
        cluster_first = first;
        cluster_count = select(0u, last - first, last > first);
        cluster_base_word = cluster_base_at(c);
        var end = cfg.run_words;
        if c + 1u < (cfg.point_count + size - 1u) / size {
            end = min(cluster_base_at(c + 1u) & ~WIDE_CLUSTER, cfg.run_words);
        }
        cluster_end_word = end;
    }
    let first = workgroupUniformLoad(&cluster_first);
    // Candidates past the largest cluster's words are never tested.
    let count = min(workgroupUniformLoad(&cluster_count), cfg.mask_words * 32u);
    expand_runs(c, first, count, lid);
    let members = min(size, cfg.point_count - c * size);
    let block = mask_row(c, first) * size;
    let words = (count + 31u) / 32u;
    for (var base = 0u; base < count; base += MASK_TILE) {
        let k = base + lid;
        var position = vec4<f32>(0.0);
        var normal = vec4<f32>(0.0);
        if k < count {
            let j = candidates_at(first + k);
            // w = 1 marks a candidate inside the point list.
            if j < cfg.point_count {
                position = vec4<f32>(points_at(j).position, 1.0);
                if cfg.has_normals != 0u {
                    normal = vec4<f32>(normal_at(j), 0.0);
                }
            }
        }
        tile_positions[lid] = position;
        tile_normals[lid] = normal;
        workgroupBarrier();
        // Neighbouring threads take neighbouring members of one word: they read the same
        // tile entry at each step (a broadcast, no bank conflicts) and neighbouring points.
        for (var pair = lid; pair < members * TILE_WORDS; pair += MASK_TILE) {
            let word = base / 32u + pair / members;
            let centre = c * size + pair % members;
            if word * 32u >= count {
                continue;
            }
            let own_point = points_at(centre);
            let own = own_point.position;
            let r = reach_of(own_point);
            let reach2 = r * r;
            var own_normal = vec3<f32>(0.0);
            if cfg.has_normals != 0u {
                own_normal = normal_at(centre);
            }
            let check_normals = dot(own_normal, own_normal) > 0.0;
            var bits = 0u;
            for (var b = 0u; b < 32u; b++) {
                let slot = word * 32u + b;
                if slot >= count {
                    break;
                }
                let q = tile_positions[slot - base];
                if q.w == 0.0 {
                    continue;
                }
                let d = q.xyz - own;
                if !(d.x * d.x + d.y * d.y + d.z * d.z <= reach2) {
                    continue;
                }
                if check_normals {
                    let n = tile_normals[slot - base].xyz;
                    if dot(n, n) > 0.0 && dot(own_normal, n) < 0.0 {
                        continue;
                    }
                }
                bits |= 1u << b;
            }
            neighbour_masks_set(block + (pair % members) * words + word, bits);
        }
        workgroupBarrier();
    }
}
