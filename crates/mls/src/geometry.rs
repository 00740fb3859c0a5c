//! Geometry every stage uses: bounding boxes and the axis a direction points along.

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

/// The axis `v` points along most (by |component|; the later axis on a tie).
pub fn dominant_axis(v: [f64; 3]) -> usize {
    (0..3)
        .max_by(|&a, &b| v[a].abs().total_cmp(&v[b].abs()))
        .unwrap_or(2)
}
