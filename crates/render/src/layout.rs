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
    pub field_min: f32,
    pub field_max: f32,
    pub has_field: u32,
    /// Words of neighbour mask of the largest cluster.
    pub mask_words: u32,
    /// Entries of bvh_nodes on the GPU (the blank lead node included) and of bvh_items.
    pub node_count: u32,
    pub item_count: u32,
    pub pad0: u32,
    pub pad1: u32,
    /// Unit direction towards the key light.
    pub key_light: [f32; 3],
    pub pad2: f32,
}

/// The key light's direction by default, normalize(0.4, −0.3, 0.85): from the front left,
/// high above a z-up scene. One source for the GPU passes and the CPU shading.
#[allow(clippy::excessive_precision)]
pub const DEFAULT_KEY_LIGHT: [f32; 3] = [0.40561610, -0.30421208, 0.86193422];

/// `struct ExpandSettings` in expand.wgsl: the uniforms of the per-step passes (neighbour
/// masks and leaf spheres).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct ExpandSettings {
    pub point_count: u32,
    pub cluster_size: u32,
    pub mask_words: u32,
    pub has_normals: u32,
    /// Threads per row of the 2D dispatches.
    pub row_threads: u32,
    pub sphere_count: u32,
    /// Entries of the BVH's item list.
    pub item_count: u32,
    /// Entries of cluster_ids.
    pub cluster_id_count: u32,
    /// Nodes of the baked BVH2.
    pub node_count: u32,
    pub pad0: u32,
    pub pad1: u32,
    pub pad2: u32,
}

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
