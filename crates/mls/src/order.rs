//! Spatial order: points sorted by their Morton (Z-order) code, so that neighbours in space
//! are near in memory (coherent GPU reads) and neighbour indices are small deltas.

use rayon::prelude::*;

/// Spreads the low 21 bits of `v` to every third bit.
fn spread(v: u64) -> u64 {
    let mut x = v & 0x1f_ffff;
    x = (x | x << 32) & 0x1f00000000ffff;
    x = (x | x << 16) & 0x1f0000ff0000ff;
    x = (x | x << 8) & 0x100f00f00f00f00f;
    x = (x | x << 4) & 0x10c30c30c30c30c3;
    (x | x << 2) & 0x1249249249249249
}

/// The permutation that sorts `points` by 63-bit Morton code over their bounding box
/// (ties keep input order).
pub fn morton_order(points: &[[f64; 3]]) -> Vec<u32> {
    let (lo, hi) = crate::geometry::bounds(points);
    let extent = (0..3).map(|a| hi[a] - lo[a]).fold(0.0, f64::max);
    let scale = if extent > 0.0 {
        ((1u64 << 21) - 1) as f64 / extent
    } else {
        0.0
    };
    let mut keyed: Vec<(u64, u32)> = points
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let q = |a: usize| ((p[a] - lo[a]) * scale) as u64;
            (
                spread(q(0)) | spread(q(1)) << 1 | spread(q(2)) << 2,
                i as u32,
            )
        })
        .collect();
    keyed.par_sort_unstable();
    keyed.into_par_iter().map(|(_, i)| i).collect()
}
