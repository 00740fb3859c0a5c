//! slosh's streaming engine under `slosh play` and `slosh bench scrub`: the timeline's state
//! ([`Timeline`]), loader threads that prepare steps ahead ([`Prefetcher`]), the GPU-resident
//! steps under a byte budget ([`StepPool`]), progressive refinement ([`Refinement`]), and the
//! [`Engine`] that drives them one frame at a time. No widgets: the app draws what this holds.

#[cfg(feature = "app")]
pub mod app;
mod engine;
mod error;
pub mod export;
pub mod overlay;
pub mod pool;
pub mod prefetch;
pub mod refine;
pub mod series;
pub mod timeline;

pub use engine::{
    Engine, EngineOptions, FrameReport, FrameRequest, GpuSource, Pace, Prepared, default_budget,
    default_loaders,
};
pub use error::{Error, Result};
pub use pool::{Admission, Resident, StepPool};
pub use prefetch::{Loaded, Prefetcher, StepLoader};
pub use refine::{Progress, Refinement, ViewKey};
pub use series::{Series, SeriesStep};
pub use timeline::{Direction, Looping, Timeline};
