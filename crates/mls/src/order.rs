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

/// The cube that Morton codes quantise: 2²¹ steps per axis over the points' bounding box's
/// longest side, from its low corner.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MortonGrid {
    pub lo: [f64; 3],
    /// Steps per unit length: `(2²¹ − 1) / extent` (0 where every point coincides).
    pub scale: f64,
}

impl MortonGrid {
    /// Bits of a code per axis.
    pub const BITS: u32 = 21;

    pub fn new(points: &[[f64; 3]]) -> MortonGrid {
        let (lo, hi) = crate::geometry::bounds_in_parallel(points);
        let extent = (0..3).map(|a| hi[a] - lo[a]).fold(0.0, f64::max);
        let scale = if extent > 0.0 {
            ((1u64 << Self::BITS) - 1) as f64 / extent
        } else {
            0.0
        };
        MortonGrid { lo, scale }
    }

    /// The 63-bit Morton code of `p` (x in bit 0, y in bit 1, z in bit 2 of each triple):
    /// its top 3·L bits are the code of its cell in a grid of 2^L cells per axis.
    pub fn code(&self, p: &[f64; 3]) -> u64 {
        let q = |a: usize| ((p[a] - self.lo[a]) * self.scale) as u64;
        spread(q(0)) | spread(q(1)) << 1 | spread(q(2)) << 2
    }
}

/// (code, index) of every point, in input order.
pub fn morton_keys(grid: &MortonGrid, points: &[[f64; 3]]) -> Vec<(u64, u32)> {
    points
        .par_iter()
        .enumerate()
        .map(|(i, p)| (grid.code(p), i as u32))
        .collect()
}

/// The permutation that sorts `points` by 63-bit Morton code over their bounding box
/// (ties keep input order).
pub fn morton_order(points: &[[f64; 3]]) -> Vec<u32> {
    let mut keyed = morton_keys(&MortonGrid::new(points), points);
    keyed.par_sort_unstable();
    keyed.into_par_iter().map(|(_, i)| i).collect()
}
