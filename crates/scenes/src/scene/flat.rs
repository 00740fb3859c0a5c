//! The flat family (sheet, plane): jittered grid points over a square, or over two squares
//! closer than the smoothing length with opposing normals.

use glam::DVec3;
use rand::Rng;
use rand_chacha::ChaCha8Rng;

use super::{Particles, Scene, SceneKind};
use crate::sampling::grid;
use crate::truth::Truth;

/// Mean spacing of `n` particles over the square (the sheet's two).
pub(super) fn spacing(kind: SceneKind, n: f64) -> f64 {
    match kind {
        SceneKind::Sheet => (2.0 * 4.0 / n).sqrt(),
        _ => (4.0 / n).sqrt(),
    }
}

impl Scene {
    /// Gap of the thin sheet: half the mean spacing, well inside any smoothing length.
    pub fn sheet_gap(&self) -> f64 {
        0.5 * self.spacing
    }

    /// The squares' true surface at `time`.
    pub(super) fn flat_truth(&self, time: f64) -> Truth {
        match self.spec.kind {
            SceneKind::Sheet => {
                let gap = self.sheet_gap();
                let c = DVec3::new(0.0, 0.0, 0.1 * time);
                Truth::Union {
                    parts: vec![
                        Truth::Square {
                            center: c + DVec3::Z * gap / 2.0,
                            normal: DVec3::Z,
                            half: 1.0,
                        },
                        Truth::Square {
                            center: c - DVec3::Z * gap / 2.0,
                            normal: -DVec3::Z,
                            half: 1.0,
                        },
                    ],
                }
            }
            _ => Truth::Square {
                center: DVec3::new(0.05 * time, 0.0, 0.0),
                normal: DVec3::Z,
                half: 1.0,
            },
        }
    }

    /// The squares' particles at time `t`.
    pub(super) fn flat_particles(&self, t: f64, rng: &mut ChaCha8Rng, out: &mut Particles) {
        match self.spec.kind {
            SceneKind::Sheet => {
                let gap = self.sheet_gap();
                let c = DVec3::new(0.0, 0.0, 0.1 * t);
                let half_n = self.spec.points / 2;
                for (side, normal) in [(1.0, DVec3::Z), (-1.0, -DVec3::Z)] {
                    for q in square_points(half_n, self.spacing, rng) {
                        out.push(
                            c + DVec3::new(q.x, q.y, side * gap / 2.0),
                            normal,
                            c.z,
                            true,
                        );
                    }
                }
            }
            _ => {
                let c = DVec3::new(0.05 * t, 0.0, 0.0);
                for q in square_points(self.spec.points, self.spacing, rng) {
                    out.push(c + DVec3::new(q.x, q.y, 0.0), DVec3::Z, 0.0, true);
                }
            }
        }
    }
}

/// About `n` jittered grid points over [−1, 1]².
fn square_points(n: usize, s: f64, rng: &mut ChaCha8Rng) -> Vec<glam::DVec2> {
    let jitter = 0.15 * s;
    grid(2.0, 2.0, s)
        .into_iter()
        .take(n.max(1))
        .map(|q| {
            glam::DVec2::new(
                (q.x - 1.0 + rng.random_range(-jitter..=jitter)).clamp(-1.0, 1.0),
                (q.y - 1.0 + rng.random_range(-jitter..=jitter)).clamp(-1.0, 1.0),
            )
        })
        .collect()
}
