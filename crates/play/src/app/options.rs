//! How `slosh play` was asked to run, and why it could not start.

use std::path::PathBuf;

use crate::engine::EngineOptions;

/// How `slosh play` was asked to run.
#[derive(Debug, Clone)]
pub struct PlayOptions {
    /// The cache directory played (a raw case's: where its steps are baked).
    pub dir: PathBuf,
    /// A raw case, baked into `dir` as its steps are needed.
    pub bake: Option<std::sync::Arc<slosh_bake::OnDemand>>,
    pub adapter: Option<String>,
    pub engine: EngineOptions,
    /// Viewport pixels traced per physical pixel, per axis (0.25–2).
    pub render_scale: f32,
    /// The up axis; `None`: z.
    pub up: Option<[f64; 3]>,
    /// Iterations refined to once the view is still.
    pub iterations: u32,
    /// How the surface is shown at the start.
    pub mode: slosh_render::ShadeMode,
    /// Milliseconds a frame may take on the GPU (`FrameRequest::frame_budget_ms`).
    pub frame_budget_ms: Option<f64>,
    /// Window inner size in logical points.
    pub window: (f32, f32),
    /// Where screenshots and exported frames go.
    pub output: PathBuf,
    /// Print a line per UI frame and per failure (for tests driving the window).
    pub log_frames: bool,
    /// How the field's values span the colour map to start with.
    pub range_mode: crate::RangeMode,
    /// The field's colour map to start with.
    pub colormap: slosh_render::Colormap,
}

/// Why the player could not start.
#[derive(Debug, thiserror::Error)]
pub enum AppError {
    #[error(
        "no Vulkan adapter for the player: {0}\n  install a Vulkan driver: your GPU vendor's, or Mesa's software one (Debian/Ubuntu: apt install mesa-vulkan-drivers libvulkan1)"
    )]
    NoGpu(slosh_render::Error),
    #[error(transparent)]
    Engine(#[from] crate::Error),
    #[error("the window could not open: {0}")]
    Window(String),
}
