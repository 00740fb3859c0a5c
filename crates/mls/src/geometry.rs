//! Geometry every stage uses: bounding boxes, recentring, and the axis a direction points
//! along.

use rayon::prelude::*;

/// The axis-aligned bounding box (lo, hi) of `points`; infinite and empty for no points.
pub fn bounds<'a>(points: impl IntoIterator<Item = &'a [f64; 3]>) -> ([f64; 3], [f64; 3]) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in points {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    (lo, hi)
}

/// `points` moved so that their bounding box is centred on the origin (coordinates near zero
/// keep the most bits), and the centre they were moved by: the coordinates the surface's
/// build works in.
pub(crate) fn recentred(points: &[[f64; 3]]) -> (Vec<[f64; 3]>, [f64; 3]) {
    let (lo, hi) = bounds(points);
    let origin = [
        0.5 * (lo[0] + hi[0]),
        0.5 * (lo[1] + hi[1]),
        0.5 * (lo[2] + hi[2]),
    ];
    // In parallel: at 1M points a serial map is milliseconds that every other thread waits
    // for.
    let moved = points
        .par_iter()
        .map(|p| [p[0] - origin[0], p[1] - origin[1], p[2] - origin[2]])
        .collect();
    (moved, origin)
}

/// The axis `v` points along most (by |component|; the later axis on a tie).
pub fn dominant_axis(v: [f64; 3]) -> usize {
    (0..3)
        .max_by(|&a, &b| v[a].abs().total_cmp(&v[b].abs()))
        .unwrap_or(2)
}
