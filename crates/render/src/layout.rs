//! `#[repr(C)]` Pod structs mirroring the WGSL uniform and output structs of the same names
//! (the cache's section types are in `slosh_cache::layout`). A test checks every size and
//! offset against naga's reflection of the shaders.

use bytemuck::{Pod, Zeroable};

/// `struct Settings` in mls.wgsl: the camera in the cache's local coordinates and the tracing
/// and shading parameters.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct GpuSettings {
    pub eye: [f32; 3],
    pub width: u32,
    /// Camera right vector × tan(fov/2) × aspect.
    pub right: [f32; 3],
    pub height: u32,
    /// Camera up vector × tan(fov/2).
    pub up: [f32; 3],
    pub iterations: u32,
    pub forward: [f32; 3],
    pub degree: u32,
    pub epsilon: f32,
    pub h_factor: f32,
    /// 0 mean data normals (covariance when they cancel), 1 covariance.
    pub normals_mode: u32,
    pub has_normals: u32,
    pub point_count: u32,
    pub sphere_count: u32,
    pub cluster_size: u32,
    pub mode: u32,
    /// The shown field range's minimum and 1 / span, scaled by 2^`field_exponent`
    /// ([`crate::FieldMap`]).
    pub field_low: f32,
    pub field_inverse_span: f32,
    pub has_field: u32,
    /// Words of neighbour mask of the largest cluster.
    pub mask_words: u32,
    /// Nodes of the BVH2 (entries of the 4-wide tree widened from it), and the items its
    /// leaves range over (balls, then droplet spheres).
    pub node_count: u32,
    pub item_count: u32,
    /// The field's colour map (`Colormap as u32`).
    pub colormap: u32,
    /// The rows this dispatch covers: every `row_stride`-th from `first_row`. A slow adapter
    /// traces a frame as several such sets, one per submission (`Tracer::record_rows`), so
    /// it never holds the UI for a whole frame.
    pub first_row: u32,
    /// Unit direction towards the key light.
    pub key_light: [f32; 3],
    pub row_stride: u32,
    /// How far outside the MLS surface the drawn surface lies along its normal, in local
    /// units (the step's `surface_offset`).
    pub surface_offset: f32,
    /// The step's h (a half float), and whether each ball has its own instead (`ball_h`).
    pub h: f32,
    pub per_point_h: u32,
    /// The degree every ball was fitted at (0–3) where the step has no degraded fits, so the
    /// trace reads no ball's state; 4 where it has.
    pub ball_degree: u32,
    /// The rest of [`crate::FieldMap`]: the power of two that brings the shown range within
    /// [−1, 1], and the values beyond which a field value counts as lying there.
    pub field_exponent: i32,
    pub field_clamp_low: f32,
    pub field_clamp_high: f32,
    pub pad: u32,
}

/// The key light's direction by default, normalize(0.4, −0.3, 0.85): from the front left,
/// high above a z-up scene. One source for the GPU passes and the CPU shading.
#[allow(clippy::excessive_precision)]
pub const DEFAULT_KEY_LIGHT: [f32; 3] = [0.40561610, -0.30421208, 0.86193422];

/// `struct ExpandSettings` in expand.wgsl: the uniforms of the neighbour-mask pass.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct ExpandSettings {
    pub point_count: u32,
    pub cluster_size: u32,
    pub mask_words: u32,
    pub has_normals: u32,
    /// Words of cluster_ids: the clusters' runs of candidates.
    pub run_words: u32,
    /// The clusters this dispatch derives: `first_cluster..end_cluster` (a step's masks may
    /// be derived in parts, one per submission, on a slow adapter).
    pub first_cluster: u32,
    pub end_cluster: u32,
    /// Candidate slots of all clusters (the last `cluster_start`).
    pub candidate_count: u32,
}

/// `struct WidenSettings` in widen.wgsl: the uniforms of the widening pass.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct WidenSettings {
    /// The grid the nodes' boxes are stored on (`slosh_cache::BvhGrid`).
    pub origin: [f32; 3],
    pub node_count: u32,
    pub step: [f32; 3],
    /// Threads per row of the dispatch's grid (workgroups in x × the workgroup size).
    pub row_threads: u32,
}

/// `struct Wide` in step.wgsl: an entry of the 4-wide tree the trace walk descends, widened
/// by the tracer from a BVH2 node (`shaders/widen.wgsl`): slot i's box per axis across the
/// four lanes, and its link (an inner grandchild's node index, or a leaf's packed items); an
/// empty slot is the point [`EMPTY_SLOT`] with link 0.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct GpuWide {
    pub lo_x: [f32; 4],
    pub hi_x: [f32; 4],
    pub lo_y: [f32; 4],
    pub hi_y: [f32; 4],
    pub lo_z: [f32; 4],
    pub hi_z: [f32; 4],
    pub links: [u32; 4],
    pub pad: [u32; 4],
}

/// Where an empty slot of a [`GpuWide`] sits on every axis: a unit ray (|1 / d| ≥ 1 per
/// axis) would enter it beyond any t the walk accepts, or behind its origin.
pub const EMPTY_SLOT: f32 = 1e30;

/// `struct Hit` in trace.wgsl: one pixel of the hit buffer, in the cache's local coordinates.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct GpuHit {
    pub position: [f32; 3],
    pub t: f32,
    pub normal: [f32; 3],
    /// 0 miss, 1 converged, 2 iteration limit, 3 no support, 4 degenerate fit, 5 droplet.
    pub status: u32,
    /// The ball (point index) or droplet item (points + sphere index) that was hit.
    pub item: u32,
    pub iterations: u32,
    pub degree: u32,
    pub degraded: u32,
}

/// Hit statuses as the shaders number them (also the `.npy` status channel).
pub mod status {
    pub const MISS: u32 = 0;
    pub const CONVERGED: u32 = 1;
    pub const ITERATION_LIMIT: u32 = 2;
    pub const NO_SUPPORT: u32 = 3;
    pub const DEGENERATE_FIT: u32 = 4;
    pub const DROPLET: u32 = 5;
}
