//! Synthetic particle scenes whose true surface is known in closed form, moving in time, and
//! scenes built to break naive MLS. Pure maths: no files, no formats.

mod ray;
mod sampling;
mod scene;
mod truth;

pub use glam::{DMat3, DVec3};
pub use ray::{Hit, TrueRay};
pub use sampling::{fibonacci_sphere, fibonacci_torus, jittered_block, tied_lattice};
pub use scene::{
    DENSITY, Droplet, Extra, GRAVITY, HardCases, MAX_POINTS, Particles, Scene, SceneError,
    SceneKind, SceneSpec,
};
pub use truth::{Truth, Wave, height, height_gradient};
