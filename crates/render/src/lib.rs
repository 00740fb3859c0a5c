//! The GPU half of slosh: a cache step streamed into wgpu storage buffers, the MLS ray tracer
//! (`shaders/trace.wgsl` over `shaders/mls.wgsl`, with the neighbour masks of the step it
//! refines derived by `shaders/expand.wgsl`, and the 4-wide tree of the step it draws widened
//! from its BVH2 by `shaders/widen.wgsl`), the shade pass (`shaders/shade.wgsl`) or the water pass with secondary
//! rays (`shaders/water.wgsl`) as compute shaders, and frames read back for files or timed
//! with GPU timestamps. The WGSL is a port of `slosh_mls`; the tests hold it to the CPU f64
//! oracle.

mod background;
mod bindings;
mod buffer_shelf;
pub mod colormap;
mod context;
pub mod cpu_shade;
mod diverging;
mod error;
mod field_map;
pub mod layout;
mod masks;
pub use masks::MaskProgress;
mod output;
mod pass;
pub mod shaders;
mod staging;
mod tracer;
mod upload;
pub mod water;
mod widen;

pub use background::{spawn as spawn_background, wait_for_background};
pub use buffer_shelf::BufferShelf;
pub use colormap::{Colormap, MISSING_FIELD_COLOUR};
pub use context::{Adapters, Gpu, MIN_BINDING_LIMIT, STORAGE_BUFFERS_NEEDED};
pub use error::{Error, Result};
pub use field_map::{FIELD_T_LIMIT, FieldMap};
pub use layout::{DEFAULT_KEY_LIGHT, ExpandSettings, GpuHit, GpuSettings, WidenSettings, status};
pub use output::{write_frame_png, write_npy, write_rgb_png};
pub use pass::checked_pipeline;
pub use staging::{StagingPool, WarmUp};
pub use tracer::{
    FRAME_TEXTURE_FORMAT, Frame, FrameTargets, PassTimes, PendingHit, ReadbackPool, RowSet,
    ShadeMode, TraceParams, Tracer, read_buffer, read_storage, settings,
};
pub use upload::{
    GpuStep, HostField, HostStep, MAX_BVH_DEPTH, MAX_LEAF_LINK_COUNT, MAX_LINK_FIRST, StepBuffers,
    StepInfo, UploadOptions, UploadStats, mask_row,
};
