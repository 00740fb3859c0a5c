//! The flat family (sheet, plane): jittered grid points over a square.

use rand::Rng;
use rand_chacha::ChaCha8Rng;

use crate::sampling::grid;

/// About `n` jittered grid points over [−1, 1]².
pub(super) fn square_points(n: usize, s: f64, rng: &mut ChaCha8Rng) -> Vec<glam::DVec2> {
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
