//! The search passes, compiled once for a device and shared by every step in flight.

use std::sync::Arc;

use slosh_render::Gpu;

use crate::dispatch::layout;
use crate::layout::{lists_source, nearest_source};

/// The bytes one dispatch's output may take, at most (with the adapter's binding limit):
/// larger outputs go in several dispatches, so that a 4M-point step's lists (about 2 GB)
/// never sit on the GPU whole.
pub(crate) const OUTPUT_BATCH_BYTES: u64 = 256 << 20;

/// A [`NeighbourSearch`] on a GPU: the passes built once, shared by every step in flight.
#[derive(Debug)]
pub struct GpuSearch {
    pub(crate) gpu: Arc<Gpu>,
    pub(crate) nearest_layout: wgpu::BindGroupLayout,
    pub(crate) nearest: wgpu::ComputePipeline,
    pub(crate) lists_layout: wgpu::BindGroupLayout,
    pub(crate) cut: wgpu::ComputePipeline,
    pub(crate) write: wgpu::ComputePipeline,
}

/// Bindings every pass reads: positions, original indices, cell starts, residuals.
const GRID_BINDINGS: [(u32, bool); 4] = [(1, false), (2, false), (3, false), (10, false)];

impl GpuSearch {
    /// The passes, compiled for `gpu`; an error where the adapter refuses them.
    pub fn new(gpu: Arc<Gpu>) -> Result<GpuSearch, slosh_render::Error> {
        let nearest_layout = layout(
            &gpu,
            "nearest points",
            &[GRID_BINDINGS.as_slice(), &[(4, true)]].concat(),
        );
        let lists_layout = layout(
            &gpu,
            "neighbour lists",
            &[
                GRID_BINDINGS.as_slice(),
                &[
                    (4, false),
                    (5, false),
                    (6, false),
                    (7, true),
                    (8, false),
                    (9, true),
                ],
            ]
            .concat(),
        );
        let pipeline_layout = |layout: &wgpu::BindGroupLayout| {
            gpu.device
                .create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                    label: Some("neighbour search"),
                    bind_group_layouts: &[Some(layout)],
                    immediate_size: 0,
                })
        };
        let nearest_pipeline_layout = pipeline_layout(&nearest_layout);
        let lists_pipeline_layout = pipeline_layout(&lists_layout);
        let nearest = slosh_render::checked_pipeline(
            &gpu,
            &nearest_pipeline_layout,
            "nearest",
            nearest_source(),
            "nearest",
        )?;
        let cut = slosh_render::checked_pipeline(
            &gpu,
            &lists_pipeline_layout,
            "cut_lists",
            lists_source(),
            "cut_lists",
        )?;
        let write = slosh_render::checked_pipeline(
            &gpu,
            &lists_pipeline_layout,
            "write_lists",
            lists_source(),
            "write_lists",
        )?;
        Ok(GpuSearch {
            gpu,
            nearest_layout,
            nearest,
            lists_layout,
            cut,
            write,
        })
    }

    pub fn gpu(&self) -> &Gpu {
        &self.gpu
    }

    /// The most bytes one output of a dispatch takes.
    pub(crate) fn output_limit(&self) -> u64 {
        OUTPUT_BATCH_BYTES.min(self.gpu.max_binding())
    }
}
