// The neighbour masks of a step, run once after its upload: which of a point's cluster
// candidates are its neighbours (clusters.rs: expand_one, the rule docs/algorithm.md gives):
// within the point's reach, and not a point whose normal opposes the centre's (both valid).
// One thread per (point, word): bit b of word w is candidate slot 32 w + b. The refinement
// loops in mls.wgsl then visit only the set bits.

struct Point {
    position: vec3<f32>,
    radius: f32,
}

struct Normal {
    normal: vec3<f32>,
    pad: f32,
}

// Mirrors `slosh_render::ExpandSettings`.
struct ExpandSettings {
    point_count: u32,
    cluster_size: u32,
    mask_words: u32,
    has_normals: u32,
    // Threads per row of the 2D dispatch (a 1D one would exceed the workgroup count limit).
    row_threads: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<storage, read> points: array<Point>;
@group(0) @binding(1) var<storage, read> normals: array<Normal>;
@group(0) @binding(2) var<storage, read> reach: array<f32>;
@group(0) @binding(3) var<storage, read> cluster_start: array<u32>;
@group(0) @binding(4) var<storage, read> cluster_ids: array<u32>;
@group(0) @binding(5) var<storage, read_write> neighbour_masks: array<u32>;
@group(0) @binding(6) var<uniform> expand_settings: ExpandSettings;

@compute @workgroup_size(64, 1, 1)
fn expand(@builtin(global_invocation_id) gid: vec3<u32>) {
    let cfg = expand_settings;
    let slot = gid.y * cfg.row_threads + gid.x;
    if cfg.mask_words == 0u || slot >= cfg.point_count * cfg.mask_words {
        return;
    }
    let centre = slot / cfg.mask_words;
    let word = slot % cfg.mask_words;
    let c = centre / max(cfg.cluster_size, 1u);
    let first = cluster_start[c] + word * 32u;
    let last = min(cluster_start[c + 1u], arrayLength(&cluster_ids));
    let position = points[centre].position;
    let r = reach[centre];
    let reach2 = r * r;
    var own_normal = vec3<f32>(0.0);
    if cfg.has_normals != 0u {
        own_normal = normals[centre].normal;
    }
    let check_normals = dot(own_normal, own_normal) > 0.0;
    var bits = 0u;
    for (var b = 0u; b < 32u; b++) {
        let k = first + b;
        if k >= last {
            break;
        }
        let j = cluster_ids[k];
        if j >= cfg.point_count {
            continue;
        }
        let d = points[j].position - position;
        if !(d.x * d.x + d.y * d.y + d.z * d.z <= reach2) {
            continue;
        }
        if check_normals {
            let n = normals[j].normal;
            if dot(n, n) > 0.0 && dot(own_normal, n) < 0.0 {
                continue;
            }
        }
        bits |= 1u << b;
    }
    neighbour_masks[slot] = bits;
}
