// The 4-wide tree's entry type: what the widening pass (widen.wgsl) writes and the trace
// walk (trace.wgsl) reads. Prepended to both modules by crates/render's shaders.rs.

// An entry of the 4-wide tree the walk descends, widened by the tracer from the baked BVH2
// (mirrors `slosh_render::layout::GpuWide`; widen.wgsl): entry i's slots hold the
// grandchildren of BVH2 node i (or a child that is a leaf), their boxes per axis across the
// four lanes and their links; an empty slot is the point (1e30, 1e30, 1e30), which no ray
// enters in time.
struct Wide {
    lo_x: vec4<f32>,
    hi_x: vec4<f32>,
    lo_y: vec4<f32>,
    hi_y: vec4<f32>,
    lo_z: vec4<f32>,
    hi_z: vec4<f32>,
    links: vec4<u32>,
    pad: vec4<u32>,
}

// A slot's link, as the trace walk stacks it: an inner node's entry (its BVH2 index), or a leaf's first item
// in the low 28 bits and its item count above, so a pop needs no read of the node itself.
// The upload refuses trees that do not fit (slosh_render::MAX_LEAF_LINK_COUNT,
// MAX_LINK_FIRST). LINK_COUNT_SHIFT and LINK_FIRST are generated from MAX_LINK_FIRST by
// shaders.rs (`shared_constants_wgsl`).
