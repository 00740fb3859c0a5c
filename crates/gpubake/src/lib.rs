//! The bake's stages on the GPU, in wgpu compute over a device someone else made
//! ([`slosh_render::Gpu`]). Each stage implements a `slosh_mls` interface whose CPU form is
//! the reference, and returns what it returns where no two distances tie
//! (`docs/algorithm.md`, "Neighbour search"): the nearest points of every point and every
//! point's neighbour list ([`GpuStages`], a [`slosh_mls::NeighbourSearch`]), on a grid of
//! Morton cells (`shaders/neighbour_grid.wgsl`, `nearest.wgsl`, `lists.wgsl`), and the initial
//! fits over those lists while they are on the GPU (`shaders/bake_fit.wgsl` over the tracer's
//! `fit.wgsl`), equal to the CPU's f64 fits within f32; and the BVH's tree over the CPU's
//! leaves ([`slosh_bake::TreeBuild`]: a linear BVH, `shaders/bvh_build.wgsl`). [`GpuStages::stages`]
//! hands both to a bake.

mod cells;
mod components;
mod csr;
mod dispatch;
mod fits;
mod host_memory;
mod index;
mod layout;
mod lists;
mod nearest;
mod orient;
mod pass_clock;
mod passes;
mod search;
mod tree;
mod unions;

pub use layout::{
    ComponentParams, FitSettings, NEAREST_MAX, SearchParams, TreeNode, TreeParams,
    UNION_SPAN_WORDS, UnionParams, components_source, fits_source, lists_source, nearest_source,
    orient_votes_source, tree_source, unions_source,
};
pub use passes::{GpuStages, KeptBuffers};
