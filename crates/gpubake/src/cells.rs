//! The CPU's half of the grid: the points in Morton order, as f32 and the residual f32 leaves
//! off, and for a level L the first point of every cell of 2^L per axis (a cell is the top
//! 3·L bits of its points' codes, so its points are consecutive).

use rayon::prelude::*;
use slosh_mls::{MortonGrid, morton_keys};

/// The most cells per axis a grid has: 2^10, the bits the shaders spread.
const MAX_LEVEL: u32 = 10;

/// A point set in Morton order.
#[derive(Debug)]
pub(crate) struct SortedPoints {
    pub grid: MortonGrid,
    /// Sorted position → the caller's index.
    pub order: Vec<u32>,
    /// Whether `order` is the identity (the bake's points come in this order).
    pub identity: bool,
    /// The sorted points' codes.
    pub codes: Vec<u64>,
    /// xyz as f32, w 0.
    pub high: Vec<[f32; 4]>,
    /// The f64 coordinate minus `high`, as f32.
    pub low: Vec<[f32; 4]>,
}

impl SortedPoints {
    pub fn new(points: &[[f64; 3]]) -> SortedPoints {
        let grid = MortonGrid::new(points);
        let mut keyed = morton_keys(&grid, points);
        let identity = keyed.par_windows(2).all(|w| w[0].0 <= w[1].0);
        if !identity {
            keyed.par_sort_unstable();
        }
        let (codes, order): (Vec<u64>, Vec<u32>) = keyed.into_par_iter().unzip();
        let split: Vec<([f32; 4], [f32; 4])> = order
            .par_iter()
            .map(|&i| {
                let p = points[i as usize];
                let high = p.map(|c| c as f32);
                let low: [f32; 3] = std::array::from_fn(|a| (p[a] - f64::from(high[a])) as f32);
                (
                    [high[0], high[1], high[2], 0.0],
                    [low[0], low[1], low[2], 0.0],
                )
            })
            .collect();
        let (high, low) = split.into_par_iter().unzip();
        SortedPoints {
            grid,
            order,
            identity,
            codes,
            high,
            low,
        }
    }

    pub fn len(&self) -> usize {
        self.order.len()
    }

    /// The sorted position of each caller's index (the inverse of `order`).
    pub fn rank(&self) -> Vec<u32> {
        let mut rank = vec![0u32; self.len()];
        for (t, &i) in self.order.iter().enumerate() {
            rank[i as usize] = t as u32;
        }
        rank
    }

    /// Per-point values in sorted order, back in the caller's order.
    pub fn unsort<T: Copy + Default>(&self, sorted: Vec<T>) -> Vec<T> {
        if self.identity {
            return sorted;
        }
        let mut out = vec![T::default(); sorted.len()];
        for (t, &i) in self.order.iter().enumerate() {
            out[i as usize] = sorted[t];
        }
        out
    }

    /// The side of the cube the codes quantise.
    pub fn extent(&self) -> f64 {
        if self.grid.scale > 0.0 {
            ((1u64 << MortonGrid::BITS) - 1) as f64 / self.grid.scale
        } else {
            0.0
        }
    }

    /// The finest level whose table fits: at most 8 cells per point (4096 at least), within
    /// `max_bytes`, and no more than the shaders spread.
    pub fn max_level(&self, max_bytes: u64) -> u32 {
        let cells_cap = (8 * self.len() as u64).max(4096);
        (1..=MAX_LEVEL)
            .take_while(|&l| {
                let cells = 1u64 << (3 * l);
                cells <= cells_cap && (cells + 1) * 4 <= max_bytes
            })
            .last()
            .unwrap_or(1)
    }

    /// The cell side at `level`, in the points' units.
    pub fn cell_size(&self, level: u32) -> f64 {
        1.0 / self.cells_per_unit(level)
    }

    /// The finest level (up to `max`) whose occupied cells hold at least `per_cell` points
    /// on average.
    pub fn level_for_occupancy(&self, per_cell: f64, max: u32) -> u32 {
        (1..=max)
            .take_while(|&l| {
                let shift = 3 * (MortonGrid::BITS - l);
                let occupied = 1 + self
                    .codes
                    .par_windows(2)
                    .filter(|w| w[0] >> shift != w[1] >> shift)
                    .count();
                self.len() as f64 / occupied as f64 >= per_cell
            })
            .last()
            .unwrap_or(1)
    }

    /// The finest level (up to `max`) whose cells are at least `size` wide.
    pub fn level_for_size(&self, size: f64, max: u32) -> u32 {
        (1..=max)
            .take_while(|&l| self.cell_size(l) >= size)
            .last()
            .unwrap_or(1)
    }

    /// Where each cell's points begin (2^(3·level) + 1 entries, by the cells' Morton codes).
    pub fn cell_starts(&self, level: u32) -> Vec<u32> {
        let shift = 3 * (MortonGrid::BITS - level);
        let cells = 1usize << (3 * level);
        let mut start = vec![0u32; cells + 1];
        for &code in &self.codes {
            start[(code >> shift) as usize + 1] += 1;
        }
        for c in 0..cells {
            start[c + 1] += start[c];
        }
        start
    }

    /// Cells per unit length at `level` (the shaders' `lo.w`).
    pub fn cells_per_unit(&self, level: u32) -> f64 {
        self.grid.scale / f64::from(1u32 << (MortonGrid::BITS - level))
    }
}
