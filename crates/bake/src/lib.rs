//! One particle step in, one `.slc` cache out, and the batch driver around it (rayon within a
//! step, a bounded number of steps in flight, resumable, sharded). Never touches wgpu.

mod batch;
mod bvh;
mod claim;
mod device_turns;
mod ensight_source;
mod far;
mod jobs;
mod on_demand;
mod params;
mod point_cloud;
mod reach;
mod select;
mod stages;
mod step;
mod urgency;
mod withdrawable;

pub use batch::{
    BatchOptions, BatchReport, Dropped, Event, FAR_PARTICLES, NON_FINITE_PARTICLES, Shard,
    StepOutcome, StepSource, dropped_input, files_identity, is_current, plan, run_batch,
    series_key,
};
pub use bvh::{
    MAX_LEAF_ITEMS, PlocTree, TreeBuild, leaves as bvh_leaves, linear as linear_bvh, linear_order,
};
pub use claim::{BAKE_LOCK_NAME, Claim, claim, describe as describe_series};
pub use device_turns::{DeviceTurns, TurnOrder, device_busy, device_idle};
pub use ensight_source::{EnsightSource, canonical_label};
pub use jobs::{available_memory, cores, default_jobs, viewer_jobs};
pub use on_demand::OnDemand;
pub use params::{BAKE_REVISION, BakeParams, NormalSource, SurfaceSelect};
pub use point_cloud::{PointCloud, PointCloudError, read_point_cloud};
pub use select::{
    ESTIMATE_NEIGHBOURS, ESTIMATE_THRESHOLD, StepInput, estimate_surface, estimate_surface_normals,
    estimate_surface_normals_with,
};
pub use slosh_mls::morton_order;
pub use stages::{Stages, StepsInFlight};
pub use step::{
    BakeError, BakedStep, bake_step, bake_step_parts, bake_step_parts_with,
    bake_step_unless_withdrawn, bake_step_with,
};
pub use urgency::Urgency;
pub use withdrawable::Withdrawn;
