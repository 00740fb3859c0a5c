//! The player (`slosh play`): an eframe/egui window over the engine. Kept apart from the
//! engine, behind the `app` feature, so the engine builds and tests without a window toolkit.

mod camera;
mod export_panel;
mod fit;
mod frame_stats;
mod launch;
mod options;
mod player;
mod run_queue;
mod timeline_panel;
mod view;

pub use camera::OrbitCamera;
pub use launch::run;
pub use options::{AppError, PlayOptions};
