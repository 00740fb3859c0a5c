//! A frame budget on any adapter: what the frames recorded so far cost, per traced pixel and
//! per iteration count, decides how small a frame drawn while the view moves must be, and into
//! how many interleaved row sets a refined frame is split, one traced per UI pass, so that no
//! pass takes much longer than the budget however slow the GPU (a software one included).

/// The scales (per axis, of the frame's full size) a moving view is drawn at. Fixed steps,
/// so that the frame targets are not made again at every frame.
pub const PREVIEW_SCALES: [f32; 8] = [1.0, 0.75, 0.5, 0.375, 0.25, 0.1875, 0.125, 0.0625];

/// Weight of a new measurement in the running estimate of a frame's cost.
const SMOOTHING: f64 = 0.5;
/// A finer preview scale is taken only when it is predicted to fit this share of the
/// budget, so that the scale does not flip between two steps frame after frame.
const STEP_UP_SHARE: f64 = 0.6;
/// Before any refined frame was measured, one with `n` iterations is guessed to cost this
/// many times `n` the one-iteration cost per pixel (the fits and the refinement loop; the
/// first band measured replaces the guess).
const UNMEASURED_ITERATION_FACTOR: f64 = 3.0;
/// Iteration counts measured apart; higher counts share the last.
const MEASURED_COUNTS: usize = 9;
/// The least share of the budget left to the GPU however costly the rest of a frame.
pub const MIN_GPU_SHARE: f64 = 1.0 / 3.0;
/// A frame interval past this many budgets is a rest between frames.
const REST_FACTOR: f64 = 8.0;
/// Clusters of the first neighbour-mask part (a 300k-point step has about 9000).
pub const FIRST_MASK_CLUSTERS: u32 = 256;
/// The most rows of a row set before any frame was measured.
pub const FIRST_SET_ROWS: u32 = 8;
/// The fewest pixels a side of a preview has.
const MIN_PREVIEW_SIDE: f32 = 16.0;

/// Milliseconds a UI pass's frame may take, and what frames have cost.
#[derive(Debug, Clone)]
pub struct FrameBudget {
    budget_ms: f64,
    /// Running estimate of milliseconds per traced pixel, by iteration count.
    per_pixel_ms: [Option<f64>; MEASURED_COUNTS],
    /// Index into [`PREVIEW_SCALES`] of the scale last chosen.
    preview: usize,
    /// Running estimate of milliseconds per cluster of the neighbour-mask pass.
    per_cluster_ms: Option<f64>,
    /// Running estimate of what a frame costs besides its GPU work (the UI's own drawing,
    /// presenting): the budget left for the GPU is what remains.
    overhead_ms: f64,
}

impl FrameBudget {
    /// A budget of `budget_ms` per frame (`> 0`), nothing measured yet: the first preview is
    /// drawn small, the first band thin.
    pub fn new(budget_ms: f64) -> FrameBudget {
        FrameBudget {
            budget_ms: budget_ms.max(1.0),
            per_pixel_ms: [None; MEASURED_COUNTS],
            preview: PREVIEW_SCALES.len() - 4,
            per_cluster_ms: None,
            overhead_ms: 0.0,
        }
    }

    pub fn budget_ms(&self) -> f64 {
        self.budget_ms
    }

    /// Milliseconds of GPU work a frame may hold: the budget less the frame's other costs,
    /// but never below [`MIN_GPU_SHARE`] of it.
    pub fn gpu_ms(&self) -> f64 {
        (self.budget_ms - self.overhead_ms).max(MIN_GPU_SHARE * self.budget_ms)
    }

    /// Takes in a frame that took `frame_ms` from the one before, `gpu_ms` of it the GPU
    /// work measured. Intervals far past the budget are a rest, not a frame, and are left out.
    pub fn record_frame(&mut self, frame_ms: f64, gpu_ms: f64) {
        if !(frame_ms.is_finite() && gpu_ms.is_finite())
            || frame_ms <= 0.0
            || frame_ms > REST_FACTOR * self.budget_ms
        {
            return;
        }
        let sample = (frame_ms - gpu_ms).max(0.0);
        self.overhead_ms += SMOOTHING * (sample - self.overhead_ms);
    }

    fn slot(iterations: u32) -> usize {
        (iterations.max(1) as usize).min(MEASURED_COUNTS) - 1
    }

    /// Takes in a frame (or band) of `pixels` traced with `iterations` that took `ms`.
    pub fn record(&mut self, iterations: u32, pixels: u64, ms: f64) {
        if pixels == 0 || !ms.is_finite() || ms < 0.0 {
            return;
        }
        let sample = ms / pixels as f64;
        let slot = &mut self.per_pixel_ms[Self::slot(iterations)];
        *slot = Some(slot.map_or(sample, |old| old + SMOOTHING * (sample - old)));
    }

    /// Takes in a neighbour-mask pass over `clusters` clusters that took `ms`.
    pub fn record_masks(&mut self, clusters: u32, ms: f64) {
        if clusters == 0 || !ms.is_finite() || ms < 0.0 {
            return;
        }
        let sample = ms / f64::from(clusters);
        self.per_cluster_ms = Some(
            self.per_cluster_ms
                .map_or(sample, |old| old + SMOOTHING * (sample - old)),
        );
    }

    /// Clusters of neighbour masks one pass may derive: [`FIRST_MASK_CLUSTERS`] before any
    /// was measured.
    pub fn mask_clusters(&self) -> u32 {
        self.per_cluster_ms.map_or(FIRST_MASK_CLUSTERS, |ms| {
            (self.gpu_ms() / ms.max(1e-9)).clamp(1.0, f64::from(u32::MAX)) as u32
        })
    }

    /// Milliseconds per pixel predicted for `iterations`: measured, else guessed from the
    /// nearest measured count below it; `None` before anything was measured.
    pub fn per_pixel_ms(&self, iterations: u32) -> Option<f64> {
        let slot = Self::slot(iterations);
        if let Some(ms) = self.per_pixel_ms[slot] {
            return Some(ms);
        }
        let (known, ms) = (0..slot)
            .rev()
            .find_map(|s| self.per_pixel_ms[s].map(|ms| (s + 1, ms)))?;
        let factor = if known == 1 {
            UNMEASURED_ITERATION_FACTOR
        } else {
            1.0
        };
        Some(ms * factor * (slot + 1) as f64 / known as f64)
    }

    /// The scale a moving view of `width`×`height` is drawn at (one of [`PREVIEW_SCALES`]):
    /// the largest whose one-iteration frame is predicted within the budget.
    pub fn preview_scale(&mut self, width: u32, height: u32) -> f32 {
        let Some(per_pixel) = self.per_pixel_ms(1) else {
            return PREVIEW_SCALES[self.preview];
        };
        let pixels = f64::from(width) * f64::from(height);
        let cost = |scale: f32| per_pixel * pixels * f64::from(scale * scale);
        let smallest = PREVIEW_SCALES
            .iter()
            .rposition(|&s| s * width.min(height) as f32 >= MIN_PREVIEW_SIDE)
            .unwrap_or(0);
        // Coarser while the current one is over budget, finer while the next fits well.
        let mut at = self.preview.min(smallest);
        while at < smallest && cost(PREVIEW_SCALES[at]) > self.gpu_ms() {
            at += 1;
        }
        while at > 0 && cost(PREVIEW_SCALES[at - 1]) <= STEP_UP_SHARE * self.gpu_ms() {
            at -= 1;
        }
        self.preview = at;
        PREVIEW_SCALES[at]
    }

    /// Whether `rows` rows of a `width`-pixel-wide frame with `iterations` are predicted
    /// within the budget.
    pub fn fits(&self, iterations: u32, width: u32, rows: u32) -> bool {
        match self.per_pixel_ms(iterations) {
            Some(per_pixel) => {
                per_pixel * f64::from(width.max(1)) * f64::from(rows) <= self.gpu_ms()
            }
            None => rows <= FIRST_SET_ROWS,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn previews_shrink_until_they_fit_and_grow_back_when_cheap() {
        let mut b = FrameBudget::new(33.0);
        // Nothing measured: a small first guess.
        assert_eq!(b.preview_scale(1600, 1000), 0.25);
        // 1 µs a pixel: 1.6 s for the whole frame; 33 ms fits 33000 pixels, a scale of at most
        // 0.144: 0.125.
        b.record(1, 100_000, 100.0);
        assert_eq!(b.preview_scale(1600, 1000), 0.125);
        // Asked again with nothing new: the same scale.
        assert_eq!(b.preview_scale(1600, 1000), 0.125);
        // A fast adapter: the whole frame fits well, the full size.
        for _ in 0..20 {
            b.record(1, 1_000_000, 1.0);
        }
        assert_eq!(b.preview_scale(1600, 1000), 1.0);
        // Never below 16 pixels a side.
        let mut slow = FrameBudget::new(1.0);
        slow.record(1, 1, 1000.0);
        assert_eq!(slow.preview_scale(256, 128), 0.125);
    }

    #[test]
    fn rows_fit_as_measured() {
        let mut b = FrameBudget::new(33.0);
        // Unmeasured: 8 rows.
        assert!(b.fits(3, 1600, 8) && !b.fits(3, 1600, 9));
        b.record(1, 1_000, 1.0);
        // 3 iterations guessed at 3 × 3 µs a pixel: 2 rows of 1600 fit in 33 ms, 3 do not.
        assert!(b.fits(3, 1600, 2) && !b.fits(3, 1600, 3));
        // Measured at 1 µs a pixel: 20 rows.
        b.per_pixel_ms[2] = Some(1e-3);
        assert!(b.fits(3, 1600, 20) && !b.fits(3, 1600, 21));
        // Never a negative or NaN measurement.
        b.record(3, 100, f64::NAN);
        b.record(3, 100, -1.0);
        assert_eq!(b.per_pixel_ms(3), Some(1e-3));
    }

    #[test]
    fn the_rest_of_a_frame_leaves_the_gpu_less() {
        let mut b = FrameBudget::new(33.0);
        assert_eq!(b.gpu_ms(), 33.0);
        b.record(1, 1000, 1.0);
        assert!(b.fits(1, 100, 330) && !b.fits(1, 100, 331));
        // Frames of 40 ms of which 10 on the GPU: 30 ms of UI; 3 ms left, but never below a
        // third of the budget.
        for _ in 0..30 {
            b.record_frame(40.0, 10.0);
        }
        assert!((b.gpu_ms() - 11.0).abs() < 1e-9, "{}", b.gpu_ms());
        assert!(b.fits(1, 100, 110) && !b.fits(1, 100, 111));
        // A rest of a second is no frame; cheaper frames give the GPU its share back.
        b.record_frame(1000.0, 0.0);
        assert!((b.gpu_ms() - 11.0).abs() < 1e-9);
        for _ in 0..60 {
            b.record_frame(20.0, 15.0);
        }
        assert!((b.gpu_ms() - 28.0).abs() < 1e-6, "{}", b.gpu_ms());
    }

    #[test]
    fn mask_parts_fit_as_measured() {
        let mut b = FrameBudget::new(30.0);
        assert_eq!(b.mask_clusters(), FIRST_MASK_CLUSTERS);
        b.record_masks(256, 512.0);
        assert_eq!(b.mask_clusters(), 15);
        b.record_masks(0, 1.0);
        b.record_masks(10, f64::NAN);
        assert_eq!(b.mask_clusters(), 15);
        b.record_masks(100, 0.0);
        assert_eq!(b.mask_clusters(), 30);
    }
}
