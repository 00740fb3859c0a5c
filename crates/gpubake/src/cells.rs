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
        // Straight into the two arrays: a pairs' array between was 128 MB of fresh memory at
        // 4M points.
        let (high, low): (Vec<[f32; 4]>, Vec<[f32; 4]>) = order
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
            .unzip();
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
        if self.identity {
            return self.order.clone();
        }
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
        let occupied = self.occupied_cells();
        (1..=max.min(MortonGrid::BITS))
            .take_while(|&l| self.len() as f64 / occupied[l as usize] as f64 >= per_cell)
            .last()
            .unwrap_or(1)
    }

    /// Occupied cells at every level 0..=BITS, in one pass over the codes (a pass per level
    /// took 40 ms at 1M points): two consecutive codes fall in different cells from the
    /// level that their highest differing bit's axis triple belongs to, and at every finer
    /// level.
    fn occupied_cells(&self) -> Vec<usize> {
        const LEVELS: usize = MortonGrid::BITS as usize + 1;
        // Pairs (i, i + 1) counted by chunks of i, each into a histogram of its own (one
        // carried through a fold by value was copied at every pair).
        const CHUNK: usize = 1 << 14;
        let codes = &self.codes;
        let pairs = codes.len().saturating_sub(1);
        let first_differing = (0..pairs.div_ceil(CHUNK))
            .into_par_iter()
            .map(|c| {
                let mut count = [0usize; LEVELS];
                for i in c * CHUNK..((c + 1) * CHUNK).min(pairs) {
                    let d = codes[i] ^ codes[i + 1];
                    if d != 0 {
                        let high = 63 - d.leading_zeros();
                        count[(MortonGrid::BITS - high / 3) as usize] += 1;
                    }
                }
                count
            })
            .reduce(
                || [0usize; LEVELS],
                |a, b| std::array::from_fn(|l| a[l] + b[l]),
            );
        let mut occupied = vec![1usize; LEVELS];
        let mut boundaries = 0;
        for l in 0..LEVELS {
            boundaries += first_differing[l];
            occupied[l] = 1 + boundaries;
        }
        occupied
    }

    /// The finest level (up to `max`) whose cells are at least `size` wide.
    pub fn level_for_size(&self, size: f64, max: u32) -> u32 {
        (1..=max)
            .take_while(|&l| self.cell_size(l) >= size)
            .last()
            .unwrap_or(1)
    }

    /// Where each cell's points begin (2^(3·level) + 1 entries, by the cells' Morton codes),
    /// from the sorted codes.
    pub fn cell_starts(&self, level: u32) -> Vec<u32> {
        let shift = 3 * (MortonGrid::BITS - level);
        let codes = &self.codes;
        crate::csr::sorted_starts(codes.len(), 1 << (3 * level), |i| {
            (codes[i] >> shift) as usize
        })
    }

    /// Occupied cells at `level`, counted one level at a time (the reference the one-pass
    /// count is tested against).
    #[cfg(test)]
    fn occupied_at(&self, level: u32) -> usize {
        let shift = 3 * (MortonGrid::BITS - level);
        1 + self
            .codes
            .windows(2)
            .filter(|w| w[0] >> shift != w[1] >> shift)
            .count()
    }

    /// Cells per unit length at `level` (the shaders' `lo.w`).
    pub fn cells_per_unit(&self, level: u32) -> f64 {
        self.grid.scale / f64::from(1u32 << (MortonGrid::BITS - level))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `count` points scattered over a flat box (uniform from `seed`), the first 500 of them
    /// again (duplicates share cells) and one far from the rest (an outlier).
    fn scattered(seed: u64, count: usize) -> Vec<[f64; 3]> {
        let mut next = slosh_testkit::uniform(seed);
        let mut points: Vec<[f64; 3]> =
            (0..count).map(|_| [next(), next(), 0.1 * next()]).collect();
        points.extend_from_within(0..500);
        points.push([1e3, -1e3, 5.0]);
        points
    }

    /// The one-pass count against a count per level, on points that fill some cells, share
    /// others (duplicates) and lie far apart (an outlier).
    #[test]
    fn occupied_cells_at_every_level_match_a_count_per_level() {
        let points = scattered(7, 5000);
        let sorted = SortedPoints::new(&points);
        let occupied = sorted.occupied_cells();
        for level in 0..=MortonGrid::BITS {
            assert_eq!(
                occupied[level as usize],
                sorted.occupied_at(level),
                "level {level}"
            );
        }
        assert_eq!(occupied[0], 1);
        assert!(
            occupied[MortonGrid::BITS as usize] < points.len(),
            "duplicates share cells"
        );
    }

    /// Each cell's start, from the sorted codes, is a count of the points in the cells before
    /// it, at every level a grid uses (cells empty, full and shared by duplicates).
    #[test]
    fn cell_starts_count_the_points_of_the_cells_before() {
        let sorted = SortedPoints::new(&scattered(11, 20000));
        for level in 1..=7 {
            let shift = 3 * (MortonGrid::BITS - level);
            let mut want = vec![0u32; (1usize << (3 * level)) + 1];
            for &code in &sorted.codes {
                want[(code >> shift) as usize + 1] += 1;
            }
            for c in 1..want.len() {
                want[c] += want[c - 1];
            }
            assert_eq!(sorted.cell_starts(level), want, "level {level}");
        }
    }
}
