//! The player (`slosh play`): an eframe/egui window over the engine. Kept apart from the
//! engine, behind the `app` feature, so the engine builds and tests without a window toolkit.

mod camera;
mod player;
mod timeline_panel;

pub use camera::OrbitCamera;
pub use player::{AppError, PlayOptions, run};
