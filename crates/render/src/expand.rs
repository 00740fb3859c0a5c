//! The per-step pass of `shaders/expand.wgsl`, run once inside each upload: the neighbour
//! masks (a bit per cluster candidate saying whether it is in the point's neighbour list, so
//! the refinement loops visit the list itself instead of filtering every candidate each time).

use std::sync::OnceLock;

use crate::bindings::{bind_entries, layout_entries};
use crate::context::Gpu;
use crate::error::{Error, Result};
use crate::layout::ExpandSettings;
use crate::shaders::{EXPAND_ARRAYS, expand_wgsl};

/// The pass's pipeline for one module (arrays split in ranges or not).
#[derive(Debug)]
struct Passes {
    masks: wgpu::ComputePipeline,
}

/// The per-step passes' pipelines, compiled for one device and its binding limit (per split,
/// on first use): made by whoever uploads steps (a loader, `slosh render`, a test) beside
/// its [`Tracer`](crate::Tracer), and handed to every [`GpuStep`](crate::GpuStep) upload.
/// Made after [`Gpu::limit_bindings`](crate::Gpu::limit_bindings), which they are compiled
/// for.
#[derive(Debug)]
pub struct StepPasses {
    /// The storage binding limit the passes are compiled for.
    max_binding: u64,
    layout: wgpu::BindGroupLayout,
    pipeline_layout: wgpu::PipelineLayout,
    passes: [OnceLock<Passes>; 2],
}

/// The buffers the pass reads and the one it writes (`masks`), in the order of
/// `EXPAND_ARRAYS`.
pub(crate) struct ExpandInputs<'a> {
    pub points: &'a wgpu::Buffer,
    pub normals: &'a wgpu::Buffer,
    pub reach: &'a wgpu::Buffer,
    pub cluster_start: &'a wgpu::Buffer,
    pub cluster_ids: &'a wgpu::Buffer,
    pub masks: &'a wgpu::Buffer,
    pub cluster_base: &'a wgpu::Buffer,
}

impl StepPasses {
    /// The passes for `gpu` at its current binding limit.
    pub fn new(gpu: &Gpu) -> StepPasses {
        StepPasses::for_device(&gpu.device, gpu.max_binding())
    }

    /// The storage binding limit the passes were compiled for.
    pub fn max_binding(&self) -> u64 {
        self.max_binding
    }

    fn for_device(device: &wgpu::Device, max_binding: u64) -> StepPasses {
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("expand"),
            entries: &layout_entries(&EXPAND_ARRAYS, true),
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("expand"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        StepPasses {
            max_binding,
            layout,
            pipeline_layout,
            passes: Default::default(),
        }
    }

    fn passes(&self, device: &wgpu::Device, split: bool) -> &Passes {
        self.passes[usize::from(split)].get_or_init(|| {
            let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("expand"),
                source: wgpu::ShaderSource::Wgsl(expand_wgsl(self.max_binding, split).into()),
            });
            Passes {
                masks: device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some("expand"),
                    layout: Some(&self.pipeline_layout),
                    module: &module,
                    entry_point: Some("expand"),
                    compilation_options: wgpu::PipelineCompilationOptions::default(),
                    cache: None,
                }),
            }
        })
    }

    /// Records the pass that fills `inputs.masks` (rows of words, `mask_row`); `split` when
    /// an array spans several ranges.
    pub(crate) fn encode(
        &self,
        device: &wgpu::Device,
        inputs: &ExpandInputs,
        settings: ExpandSettings,
        split: bool,
        encoder: &mut wgpu::CommandEncoder,
        timestamps: Option<&wgpu::QuerySet>,
    ) -> Result<()> {
        let max_groups = device.limits().max_compute_workgroups_per_dimension;
        let uniform = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("expand settings"),
            size: size_of::<ExpandSettings>() as u64,
            usage: wgpu::BufferUsages::UNIFORM,
            mapped_at_creation: true,
        });
        uniform
            .slice(..)
            .get_mapped_range_mut()
            .map_err(|e| Error::Readback(e.to_string()))?
            .copy_from_slice(bytemuck::bytes_of(&settings));
        uniform.unmap();
        let buffers = [
            inputs.points,
            inputs.normals,
            inputs.reach,
            inputs.cluster_start,
            inputs.cluster_ids,
            inputs.masks,
            inputs.cluster_base,
        ];
        let entries = bind_entries(&EXPAND_ARRAYS, &buffers, Some(&uniform), self.max_binding);
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("expand"),
            layout: &self.layout,
            entries: &entries,
        });
        let passes = self.passes(device, split);
        // One workgroup per cluster.
        let clusters = settings.point_count.div_ceil(settings.cluster_size.max(1));
        let groups = if settings.mask_words == 0 {
            0
        } else {
            clusters
        };
        let timestamp_writes = timestamps.map(|set| wgpu::ComputePassTimestampWrites {
            query_set: set,
            beginning_of_pass_write_index: Some(0),
            end_of_pass_write_index: Some(1),
        });
        // A timed pass runs even with nothing to do, so that its stamps are written.
        if groups == 0 && timestamp_writes.is_none() {
            return Ok(());
        }
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("per-step"),
            timestamp_writes,
        });
        if groups > 0 {
            pass.set_pipeline(&passes.masks);
            pass.set_bind_group(0, &group, &[]);
            pass.dispatch_workgroups(groups.min(max_groups), groups.div_ceil(max_groups), 1);
        }
        Ok(())
    }
}
