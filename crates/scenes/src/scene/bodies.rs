//! The closed-body family (sphere, torus, ellipsoid): Fibonacci lattices on moving, spinning
//! bodies, every particle on the surface.

use std::f64::consts::PI;

use glam::{DMat3, DVec3};
use rand::Rng;

use super::{Particles, Scene, SceneKind};
use crate::sampling::{ellipsoid_area, fibonacci_sphere, fibonacci_torus, torus_area};
use crate::truth::Truth;

const TORUS: (f64, f64) = (1.0, 0.35);
const ELLIPSOID: DVec3 = DVec3::new(1.2, 0.8, 0.5);

fn sphere_center(t: f64) -> DVec3 {
    DVec3::new(0.25 * t.sin(), 0.1 * t, 0.0)
}

fn torus_rotation(t: f64) -> DMat3 {
    DMat3::from_rotation_x(0.4 * t)
}

fn ellipsoid_rotation(t: f64) -> DMat3 {
    DMat3::from_rotation_x(0.2 * t) * DMat3::from_rotation_z(0.5 * t)
}

/// Mean spacing of `n` particles over the body's area.
pub(super) fn spacing(kind: SceneKind, n: f64) -> f64 {
    match kind {
        SceneKind::Torus => (torus_area(TORUS.0, TORUS.1) / n).sqrt(),
        SceneKind::Ellipsoid => (ellipsoid_area(ELLIPSOID) / n).sqrt(),
        _ => (4.0 * PI / n).sqrt(),
    }
}

impl Scene {
    /// The body's true surface at `time`.
    pub(super) fn body_truth(&self, time: f64) -> Truth {
        match self.spec.kind {
            SceneKind::Torus => Truth::Torus {
                center: DVec3::ZERO,
                rotation: torus_rotation(time),
                major: TORUS.0,
                minor: TORUS.1,
            },
            SceneKind::Ellipsoid => Truth::Ellipsoid {
                center: DVec3::ZERO,
                rotation: ellipsoid_rotation(time),
                radii: ELLIPSOID,
            },
            _ => Truth::Sphere {
                center: sphere_center(time),
                radius: 1.0,
            },
        }
    }

    /// The body's particles at time `t`.
    pub(super) fn body_particles(&self, t: f64, out: &mut Particles) {
        match self.spec.kind {
            SceneKind::Torus => {
                let rot = torus_rotation(t);
                for uv in fibonacci_torus(self.spec.points, TORUS.0, TORUS.1) {
                    let (su, cu) = uv.x.sin_cos();
                    let (sv, cv) = uv.y.sin_cos();
                    let n = DVec3::new(cv * cu, cv * su, sv);
                    let p = DVec3::new(
                        (TORUS.0 + TORUS.1 * cv) * cu,
                        (TORUS.0 + TORUS.1 * cv) * su,
                        TORUS.1 * sv,
                    );
                    out.push(rot * p, rot * n, 0.0, true);
                }
            }
            SceneKind::Ellipsoid => {
                let frame = ellipsoid_rotation(t);
                for d in fibonacci_sphere(self.spec.points) {
                    // Pattern on the unit sphere, mapped onto the body's ellipsoid.
                    let local = self.pattern_rotation() * d * ELLIPSOID;
                    let n = (frame * (local / (ELLIPSOID * ELLIPSOID))).normalize();
                    out.push(frame * local, n, 0.0, true);
                }
            }
            _ => {
                let c = sphere_center(t);
                let spin = DMat3::from_rotation_z(0.3 * t) * self.pattern_rotation();
                for d in fibonacci_sphere(self.spec.points) {
                    let n = spin * d;
                    out.push(c + n, n, c.z, true);
                }
            }
        }
    }

    /// A fixed random rotation of the sampling pattern (so that lattice axes do not line up
    /// with the coordinate axes), drawn from the seed.
    fn pattern_rotation(&self) -> DMat3 {
        let mut rng = self.rng(0, 7);
        let axis = DVec3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        )
        .normalize_or(DVec3::Z);
        DMat3::from_axis_angle(axis, rng.random_range(0.0..PI))
    }
}
