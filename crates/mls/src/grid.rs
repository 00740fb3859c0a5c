//! A uniform grid over the balls' bounding boxes, walked front to back along a ray
//! (Amanatides & Woo), and the index trait every tracer walks. The in-memory tracer's index;
//! caches carry a BVH instead.

/// A spatial index over a surface's candidates: ball i is item i, droplet sphere d is item
/// `len + d`.
pub trait BallIndex: Sync {
    /// Calls `visit` with batches of items whose bounds the ray (t ≥ 0) enters, roughly nearest
    /// first. `visit` returns the nearest hit so far (∞ if none); the walk ends once nothing
    /// unvisited can be nearer (or as near: ties go to the lower item).
    fn walk(&self, origin: [f64; 3], dir: [f64; 3], visit: &mut dyn FnMut(&[u32]) -> f64);
}

#[derive(Debug, Clone)]
pub(crate) struct Grid {
    lo: [f64; 3],
    cell: f64,
    dims: [usize; 3],
    start: Vec<u32>,
    items: Vec<u32>,
}

impl Grid {
    /// Cells of about two mean radii, coarser if that would make more than 8 cells per ball
    /// (sparse scenes with outliers).
    pub fn build(centres: &[[f64; 3]], radii: &[f64], mean_radius: f64) -> Grid {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for (c, &r) in centres.iter().zip(radii) {
            for a in 0..3 {
                lo[a] = lo[a].min(c[a] - r);
                hi[a] = hi[a].max(c[a] + r);
            }
        }
        let extent = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
        let mut cell = (2.0 * mean_radius)
            .max(extent.iter().copied().fold(0.0, f64::max) * 1e-6)
            .max(f64::MIN_POSITIVE);
        let budget = 8 * centres.len().max(1);
        let dims_for = |cell: f64| extent.map(|e| ((e / cell).ceil() as usize).max(1));
        while dims_for(cell).iter().product::<usize>() > budget {
            cell *= 1.5;
        }
        let dims = dims_for(cell);
        let cell_of =
            |v: f64, a: usize| (((v - lo[a]) / cell).floor().max(0.0) as usize).min(dims[a] - 1);
        let range = |c: &[f64; 3], r: f64| -> [(usize, usize); 3] {
            std::array::from_fn(|a| (cell_of(c[a] - r, a), cell_of(c[a] + r, a)))
        };
        let index = |x: usize, y: usize, z: usize| (z * dims[1] + y) * dims[0] + x;
        let mut counts = vec![0u32; dims.iter().product::<usize>() + 1];
        for (c, &r) in centres.iter().zip(radii) {
            let [(x0, x1), (y0, y1), (z0, z1)] = range(c, r);
            for z in z0..=z1 {
                for y in y0..=y1 {
                    for x in x0..=x1 {
                        counts[index(x, y, z) + 1] += 1;
                    }
                }
            }
        }
        for i in 1..counts.len() {
            counts[i] += counts[i - 1];
        }
        let mut fill = counts.clone();
        let mut items = vec![0u32; *counts.last().unwrap_or(&0) as usize];
        for (b, (c, &r)) in centres.iter().zip(radii).enumerate() {
            let [(x0, x1), (y0, y1), (z0, z1)] = range(c, r);
            for z in z0..=z1 {
                for y in y0..=y1 {
                    for x in x0..=x1 {
                        let slot = &mut fill[index(x, y, z)];
                        items[*slot as usize] = b as u32;
                        *slot += 1;
                    }
                }
            }
        }
        Grid {
            lo,
            cell,
            dims,
            start: counts,
            items,
        }
    }
}

impl BallIndex for Grid {
    /// Visits the cells the ray crosses for t in [0, ∞), nearest first; stops at the first
    /// cell the ray leaves beyond the best hit so far.
    fn walk(&self, origin: [f64; 3], dir: [f64; 3], visit: &mut dyn FnMut(&[u32]) -> f64) {
        let hi: [f64; 3] = std::array::from_fn(|a| self.lo[a] + self.dims[a] as f64 * self.cell);
        let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
        for a in 0..3 {
            if dir[a] == 0.0 {
                if origin[a] < self.lo[a] || origin[a] > hi[a] {
                    return;
                }
                continue;
            }
            let (ta, tb) = (
                (self.lo[a] - origin[a]) / dir[a],
                (hi[a] - origin[a]) / dir[a],
            );
            t0 = t0.max(ta.min(tb));
            t1 = t1.min(ta.max(tb));
        }
        if !(t0 <= t1) {
            return;
        }
        let mut cell = [0usize; 3];
        let mut step = [0isize; 3];
        let mut t_next = [f64::INFINITY; 3];
        let mut t_delta = [f64::INFINITY; 3];
        for a in 0..3 {
            let p = origin[a] + dir[a] * t0;
            cell[a] =
                (((p - self.lo[a]) / self.cell).floor().max(0.0) as usize).min(self.dims[a] - 1);
            if dir[a] > 0.0 {
                step[a] = 1;
                t_next[a] = (self.lo[a] + (cell[a] + 1) as f64 * self.cell - origin[a]) / dir[a];
                t_delta[a] = self.cell / dir[a];
            } else if dir[a] < 0.0 {
                step[a] = -1;
                t_next[a] = (self.lo[a] + cell[a] as f64 * self.cell - origin[a]) / dir[a];
                t_delta[a] = -self.cell / dir[a];
            }
        }
        loop {
            let i = (cell[2] * self.dims[1] + cell[1]) * self.dims[0] + cell[0];
            let items = &self.items[self.start[i] as usize..self.start[i + 1] as usize];
            let axis = if t_next[0] <= t_next[1] && t_next[0] <= t_next[2] {
                0
            } else if t_next[1] <= t_next[2] {
                1
            } else {
                2
            };
            let exit = t_next[axis].min(t1);
            // Any hit nearer than the best (or tied with it) lies in a cell not yet left.
            if !(exit <= visit(items)) || t_next[axis] > t1 {
                return;
            }
            let next = cell[axis] as isize + step[axis];
            if next < 0 || next >= self.dims[axis] as isize {
                return;
            }
            cell[axis] = next as usize;
            t_next[axis] += t_delta[axis];
        }
    }
}
