//! One point set on the GPU: in Morton order, as two f32s a coordinate, with its order.

use crate::cells::SortedPoints;
use crate::dispatch::{Pooled, bind, groups, uniform};
use crate::layout::SearchParams;
use crate::passes::GpuStages;

/// One dispatch of a search pass over a range of the sorted points: what it is given beyond
/// the points and the grid.
pub(crate) struct Dispatch<'b> {
    /// The pass's name, under which its GPU time is counted.
    pub pass: &'static str,
    pub pipeline: &'b wgpu::ComputePipeline,
    pub layout: &'b wgpu::BindGroupLayout,
    pub level: u32,
    pub cell_starts: &'b wgpu::Buffer,
    pub first: usize,
    pub count: usize,
    /// `SearchParams::wanted`.
    pub wanted: usize,
    pub flags: u32,
    pub out_base: u32,
    /// `SearchParams::shells` (the nearest-points pass).
    pub shells: u32,
    /// `SearchParams::band` (the lists pass, with `FLAG_PAIRS`).
    pub band: f32,
    /// The pass's own buffers, by binding.
    pub buffers: &'b [(u32, &'b wgpu::Buffer)],
}

/// One point set on the GPU.
pub(crate) struct GpuIndex<'a> {
    pub search: &'a GpuStages,
    /// The caller's points, in f64.
    pub points: &'a [[f64; 3]],
    pub sorted: SortedPoints,
    pub positions: Pooled,
    pub residuals: Pooled,
    pub original: Pooled,
    /// Added to every reach when the shaders pick cells: far above the f32 rounding of a
    /// cell's bounds.
    pub margin: f64,
    /// The last nearest-points query's ids where the pass wrote them, for the orientation
    /// votes (which read them in place) and no later: the lists let them go.
    pub kept_nearest: std::sync::Mutex<Option<KeptNearest>>,
}

/// A nearest-points query's ids on the GPU, in sorted order, `wanted` a point: each batch's
/// buffer with its first sorted point and its points. A point the batch's shells left
/// unfinished (`UNFINISHED` first) was found on a coarser grid, and only the host has its ids.
pub(crate) struct KeptNearest {
    pub wanted: usize,
    pub batches: Vec<(usize, usize, Pooled)>,
}

impl GpuIndex<'_> {
    /// Lets the kept nearest ids go, returning them.
    pub(crate) fn take_kept_nearest(&self) -> Option<KeptNearest> {
        self.kept_nearest
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .take()
    }
}

impl GpuIndex<'_> {
    /// The grid's low corner and cells per unit length at `level` (`SearchParams::lo`).
    pub(crate) fn lo(&self, level: u32) -> [f32; 4] {
        let lo = self.sorted.grid.lo;
        [
            lo[0] as f32,
            lo[1] as f32,
            lo[2] as f32,
            self.sorted.cells_per_unit(level) as f32,
        ]
    }

    /// Records and submits `dispatch` ([`GpuStages::run`]); returns the submission.
    pub(crate) fn submit(&self, dispatch: Dispatch<'_>) -> wgpu::SubmissionIndex {
        let gpu = self.search.gpu();
        let (x, y, row_threads) = groups(gpu, dispatch.count as u32);
        let params = uniform(
            gpu,
            &SearchParams {
                lo: self.lo(dispatch.level),
                count: dispatch.count as u32,
                first: dispatch.first as u32,
                side: 1 << dispatch.level,
                wanted: dispatch.wanted as u32,
                flags: dispatch.flags,
                out_base: dispatch.out_base,
                row_threads,
                margin: self.margin as f32,
                shells: dispatch.shells,
                band: dispatch.band,
                _pad1: 0,
                _pad2: 0,
            },
        );
        let grid = [
            (0, &params),
            (1, &self.positions),
            (2, &self.original),
            (3, dispatch.cell_starts),
            (10, &self.residuals),
        ];
        let entries: Vec<(u32, &wgpu::Buffer)> =
            grid.iter().chain(dispatch.buffers).copied().collect();
        let group = bind(gpu, dispatch.layout, &entries);
        self.search
            .run(dispatch.pass, &[(dispatch.pipeline, (x, y))], &group)
    }
}
