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

/// Points whose box one task of [`bounds_in_parallel`] finds: enough to outweigh a task's
/// cost.
const BOUNDS_CHUNK: usize = 1 << 14;

/// [`bounds`] of a slice, its chunks' boxes found in parallel and merged: the same box, as
/// min and max are exact in any order. A bake takes the box of a step's points four times
/// (its recentring and the surface's, and the Morton grids of its order and the GPU's search),
/// which at 4M points was tens of milliseconds on one thread while the others waited.
pub fn bounds_in_parallel(points: &[[f64; 3]]) -> ([f64; 3], [f64; 3]) {
    points.par_chunks(BOUNDS_CHUNK).map(bounds).reduce(
        || bounds(&[]),
        |(lo, hi), (l, h)| {
            (
                std::array::from_fn(|a| lo[a].min(l[a])),
                std::array::from_fn(|a| hi[a].max(h[a])),
            )
        },
    )
}

/// `points` moved so that their bounding box is centred on the origin (coordinates near zero
/// keep the most bits), and the centre they were moved by: the coordinates the surface's
/// build works in.
pub(crate) fn recentred(points: &[[f64; 3]]) -> (Vec<[f64; 3]>, [f64; 3]) {
    let (lo, hi) = bounds_in_parallel(points);
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The parallel box is the serial one bit for bit: over several chunks, with coordinates
    /// of every sign and size and a NaN (which both ignore); and for no points.
    #[test]
    fn the_parallel_box_is_the_serial_box() {
        let count = 5 * BOUNDS_CHUNK + 123;
        // A deterministic scatter, far ends placed in different chunks.
        let mut uniform = slosh_testkit::uniform(11);
        let mut next = || 2.0 * uniform() - 1.0;
        let mut points: Vec<[f64; 3]> = (0..count)
            .map(|_| [next() * 1e3, next() * 1e-3, next()])
            .collect();
        points[3 * BOUNDS_CHUNK + 7] = [4e3, f64::NAN, -2.5];
        points[BOUNDS_CHUNK + 1] = [0.5, 0.0, 7.0];
        points[count - 1] = [-5e3, 3e-3, 0.25];
        let serial = bounds(&points);
        let parallel = bounds_in_parallel(&points);
        assert_eq!(
            serial.0.map(f64::to_bits),
            parallel.0.map(f64::to_bits),
            "lo: {:?} against {:?}",
            serial.0,
            parallel.0
        );
        assert_eq!(serial.1.map(f64::to_bits), parallel.1.map(f64::to_bits));
        assert_eq!(parallel.0, [-5e3, serial.0[1], serial.0[2]]);
        assert_eq!(parallel.1[0], 4e3);
        assert_eq!(parallel.1[2], 7.0);
        let empty = bounds_in_parallel(&[]);
        assert_eq!(empty, ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]));
    }
}
