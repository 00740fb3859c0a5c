// The step data types every module shares, bound from the cache's sections byte for byte or
// built by expand.wgsl; prepended to each module by crates/render's shaders.rs.

// Mirrors crates/cache/src/layout.rs: the radius of trust and the reach as half floats, the
// radius in the low half (both normal half floats, so any unpack2x16float decodes them as the
// CPU does).
struct Point {
    position: vec3<f32>,
    radii: u32,
}

fn radius_of(p: Point) -> f32 {
    return unpack2x16float(p.radii).x;
}

fn reach_of(p: Point) -> f32 {
    return unpack2x16float(p.radii).y;
}

// A data normal, or a ball's support normal: one word, the octahedral map's two signed
// 16-bit coordinates (slosh_cache::octahedral, which decodes in the same exact steps, so the
// CPU and the shaders get the same vector bit for bit). Not normalised: |x| + |y| + |z| = 1,
// or zero for no normal (a first coordinate of −32768). OCTAHEDRAL_STEP_BITS is generated
// from slosh_cache::octahedral::OCTAHEDRAL_STEP by shaders.rs.
fn octahedral(w: u32) -> vec3<f32> {
    if (w & 0xffffu) == 0x8000u {
        return vec3<f32>(0.0);
    }
    let step = bitcast<f32>(OCTAHEDRAL_STEP_BITS);
    let x = f32(bitcast<i32>(w << 16u) >> 16u) * step;
    let y = f32(bitcast<i32>(w) >> 16u) * step;
    let z = 1.0 - abs(x) - abs(y);
    if z >= 0.0 {
        return vec3<f32>(x, y, z);
    }
    return vec3<f32>((1.0 - abs(y)) * select(-1.0, 1.0, x >= 0.0), (1.0 - abs(x)) * select(-1.0, 1.0, y >= 0.0), z);
}

// Point j's data normal, decoded.
fn normal_at(j: u32) -> vec3<f32> {
    return octahedral(normals_at(j));
}

// A cluster's candidates are stored as runs of consecutive indices (slosh_cache::candidates);
// expand.wgsl expands those of the step being refined into the tracer's `candidates`, one
// index per slot, cluster c's from slot cluster_start[c]. WIDE_CLUSTER and NARROW_BIAS are
// generated from slosh_cache::candidates by shaders.rs. An empty slot, and the end of a walk
// over a neighbourhood (mls.wgsl), is NO_NEIGHBOUR.
const NO_NEIGHBOUR: u32 = 0xffffffffu;

// The neighbour masks give each cluster a block of `cluster_size` rows' worth of words: a
// member's words (its candidates over 32, rounded up) side by side, member after member.
// Cluster c's block begins at row (first + 31 c) / 32 (rows of `cluster_size` words), `first`
// being its first candidate slot (cluster_start[c]); this bound grows by at least a cluster's
// words per member from one cluster to the next, so no prefix sum is needed. Mirrors
// `slosh_render::mask_row`.
fn mask_row(cluster: u32, first: u32) -> u32 {
    return (first + 31u * cluster) / 32u;
}

// A droplet sphere (mirrors `slosh_cache::GpuSphere`).
struct Sphere {
    centre: vec3<f32>,
    radius: f32,
}
