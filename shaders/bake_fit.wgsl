// The bake's initial fits on the GPU (crates/gpubake/src/fits.rs): at each point, over its
// neighbour list as the lists pass wrote it, the support plane and polynomial that
// `initial_fit_with` (crates/mls/src/intersect.rs) computes, in f32: the same fit.wgsl the
// tracer refines with, which follows this file. FIT_DEGREE is the bake's degree.

struct Settings {
    // Points in this dispatch, from sorted position `first`.
    count: u32,
    first: u32,
    row_threads: u32,
    // The first slot of this dispatch's lists among all lists.
    list_base: u32,
    has_normals: u32,
    // 0: the weighted mean of the data normals; 1: the covariance (NormalsMode).
    normals_mode: u32,
    _pad0: u32,
    _pad1: u32,
};

@group(0) @binding(0) var<uniform> settings: Settings;
// Sorted positions and residuals (neighbour_grid.wgsl's), and the data normals.
@group(0) @binding(1) var<storage, read> positions: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> residuals: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> data_normals: array<vec4<f32>>;
// Per sorted point: where its list begins among all lists, and its smoothing length.
@group(0) @binding(4) var<storage, read> list_start: array<u32>;
@group(0) @binding(5) var<storage, read> smoothing: array<f32>;
// This dispatch's lists (lists.wgsl's words: the caller's indices, with LINK_BIT and FAR_BIT;
// those constants and ID_MASK come from crates/gpubake/src/layout.rs).
@group(0) @binding(6) var<storage, read> lists: array<u32>;
// Sorted position of each caller's index (the lists hold the caller's indices).
@group(0) @binding(7) var<storage, read> rank: array<u32>;
// Per point of the dispatch: (normal, status), then the ten coefficients and the degree.
@group(0) @binding(8) var<storage, read_write> fits_out: array<vec4<f32>>;

const NO_NEIGHBOUR: u32 = 0xffffffffu;

// The point being fitted, as two f32s a coordinate: the fits run in coordinates centred on
// it (r = 0), where a neighbour's offset is as accurate as f32 allows of the offset itself.
var<private> centre_high: vec3<f32>;
var<private> centre_low: vec3<f32>;

struct Position {
    position: vec3<f32>,
}

// Neighbour j's offset from the centre.
fn points_at(j: u32) -> Position {
    return Position((positions[j].xyz - centre_high) + (residuals[j].xyz - centre_low));
}

fn normal_at(j: u32) -> vec3<f32> {
    return data_normals[j].xyz;
}

// A point's list: slots [first, end) of `lists`, holding the caller's indices.
struct Neighbourhood {
    first: u32,
    end: u32,
}

struct Cursor {
    at: u32,
}

fn first_neighbours(nb: Neighbourhood) -> Cursor {
    return Cursor(nb.first);
}

// The next neighbour's sorted position, or NO_NEIGHBOUR after the last.
fn next_neighbour(nb: Neighbourhood, cursor: ptr<function, Cursor>) -> u32 {
    if (*cursor).at >= nb.end {
        return NO_NEIGHBOUR;
    }
    let id = lists[(*cursor).at] & ID_MASK;
    (*cursor).at += 1u;
    return rank[id];
}

@compute @workgroup_size(64)
fn initial_fits(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = gid.y * settings.row_threads + gid.x;
    if k >= settings.count {
        return;
    }
    let t = settings.first + k;
    centre_high = positions[t].xyz;
    centre_low = residuals[t].xyz;
    let nb = Neighbourhood(list_start[t] - settings.list_base, list_start[t + 1u] - settings.list_base);
    let h = smoothing[t];
    // Without data normals the plane faces away from the set's centre (surface.rs: toward
    // 2·centre, which is the centre itself from the centre).
    let origin = vec3<f32>(0.0);
    let support = support_normal(origin, nb, h, centre_high);
    var status = 0.0;
    var normal = vec3<f32>(0.0);
    var poly: Poly;
    poly.degree = 0u;
    if support.ok {
        let f = fit(origin, frame_from_normal(support.normal), nb, h);
        if f.ok {
            status = select(1.0, 2.0, f.degraded);
            normal = support.normal;
            poly = f.poly;
        }
    }
    let at = k * 4u;
    fits_out[at] = vec4<f32>(normal, status);
    fits_out[at + 1u] = vec4<f32>(poly.c[0], poly.c[1], poly.c[2], poly.c[3]);
    fits_out[at + 2u] = vec4<f32>(poly.c[4], poly.c[5], poly.c[6], poly.c[7]);
    fits_out[at + 3u] = vec4<f32>(poly.c[8], poly.c[9], f32(poly.degree), 0.0);
}
