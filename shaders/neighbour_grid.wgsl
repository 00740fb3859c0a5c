// The grid a neighbour search on the GPU walks (crates/gpubake): the points sorted by Morton
// code, and for each cell of 2^level per axis (by the Morton code of its coordinates) where its
// points begin. The cells are the top bits of the codes the CPU gave the points, in f64; the
// shaders only pick which cells to visit, with a margin far above f32 rounding, and then test
// distances, so a point near a cell's face is never missed.

struct SearchParams {
    // xyz: the grid's low corner; w: cells per unit length.
    lo: vec4<f32>,
    // Points in this dispatch, from sorted position `first`.
    count: u32,
    first: u32,
    // Cells per axis, 2^level.
    side: u32,
    // nearest: how many per point; lists: the cap.
    wanted: u32,
    // 1: data normals, 2: links, 4: the caller's points came in Morton order, 8: the points
    // are todo's, 16 (FLAG_PAIRS): lists: each member near its list's reach is appended to
    // the pairs.
    flags: u32,
    // The first output slot of this dispatch (lists).
    out_base: u32,
    // Threads per row of the dispatch (dispatches are two-dimensional past 65535 groups).
    row_threads: u32,
    // Added to every reach when picking cells.
    margin: f32,
    // nearest: the most shells of cells a point searches before it is left to a coarser grid.
    shells: u32,
    // lists, with FLAG_PAIRS: how near its list's reach (or cut) a member is appended.
    band: f32,
    _pad1: u32,
    _pad2: u32,
};

@group(0) @binding(0) var<uniform> params: SearchParams;
// Sorted positions as f32 (w unused), and what f32 left off (the f64 coordinate minus it):
// a difference of nearby points is then as accurate as f32 allows of the difference itself,
// not of the coordinates (Dekker's double-float split).
@group(0) @binding(1) var<storage, read> positions: array<vec4<f32>>;
@group(0) @binding(10) var<storage, read> residuals: array<vec4<f32>>;
// Sorted position → the caller's index.
@group(0) @binding(2) var<storage, read> original: array<u32>;
// side³ + 1 entries: cell c's points are [cell_start[c], cell_start[c + 1]).
@group(0) @binding(3) var<storage, read> cell_start: array<u32>;

// The low 10 bits of v to every third bit.
fn spread(v: u32) -> u32 {
    var x = v & 0x3ffu;
    x = (x | (x << 16u)) & 0x030000ffu;
    x = (x | (x << 8u)) & 0x0300f00fu;
    x = (x | (x << 4u)) & 0x030c30c3u;
    x = (x | (x << 2u)) & 0x09249249u;
    return x;
}

fn cell_code(x: i32, y: i32, z: i32) -> u32 {
    return spread(u32(x)) | (spread(u32(y)) << 1u) | (spread(u32(z)) << 2u);
}

// The cell holding x, clamped to the grid.
fn cell_of(x: vec3<f32>) -> vec3<i32> {
    let c = floor((x - params.lo.xyz) * params.lo.w);
    let top = f32(params.side - 1u);
    return vec3<i32>(clamp(c, vec3<f32>(0.0), vec3<f32>(top)));
}

// (a point at `high` + `low`) − point j.
fn difference(high: vec3<f32>, low: vec3<f32>, j: u32) -> vec3<f32> {
    return (high - positions[j].xyz) + (low - residuals[j].xyz);
}

fn thread_index(gid: vec3<u32>) -> u32 {
    return gid.y * params.row_threads + gid.x;
}
