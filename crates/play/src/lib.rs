//! slosh's streaming engine under `slosh play` and `slosh bench scrub`: the timeline's state
//! ([`Timeline`]), loader threads that prepare steps ahead ([`Prefetcher`]), the GPU-resident
//! steps under a byte budget ([`StepPool`]), progressive refinement ([`Refinement`]) paced by a frame budget ([`FrameBudget`]), and the
//! [`Engine`] that drives them one frame at a time. No widgets: the app draws what this holds.

#[cfg(feature = "app")]
pub mod app;
mod engine;
mod error;
pub mod export;
pub mod frame_budget;
pub mod overlay;
pub mod pool;
pub mod prefetch;
mod range_mode;
pub mod refine;
pub mod series;
pub mod timeline;

pub use engine::{
    Engine, EngineOptions, FrameReport, FrameRequest, FreshBuffers, GpuSource, Pace, Prepared,
    Probe, Quality, Uploaded, default_budget, default_loaders,
};
pub use error::{Error, Result};
pub use frame_budget::FrameBudget;
pub use pool::{Admission, Resident, StepPool};
pub use prefetch::{Loaded, Prefetcher, StepLoader};
pub use range_mode::RangeMode;
pub use refine::{Draw, Pacing, Progress, Refinement, ViewKey};
pub use series::{Series, SeriesStep};
pub use timeline::{Direction, Looping, Timeline};
