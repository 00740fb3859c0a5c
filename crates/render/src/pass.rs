//! What the tracer's per-step passes (the neighbour masks, the widening) make alike: their
//! layouts, a compute pipeline from a WGSL source with validation errors caught, a uniform
//! block, and the storage buffers they write.

use std::sync::OnceLock;

use crate::bindings::layout_entries;
use crate::context::Gpu;
use crate::error::{Error, Result};
use crate::shaders::RangedArray;
use crate::upload::EMPTY_BINDING;

/// The pipeline of `source`'s `entry` under `layout`, its override `constants` set,
/// validation errors caught.
pub fn checked_pipeline(
    gpu: &Gpu,
    layout: &wgpu::PipelineLayout,
    label: &str,
    source: String,
    entry: &str,
    constants: &[(&str, f64)],
) -> Result<wgpu::ComputePipeline> {
    let device = &gpu.device;
    let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(label),
        layout: Some(layout),
        module: &module,
        entry_point: Some(entry),
        compilation_options: wgpu::PipelineCompilationOptions {
            constants,
            ..Default::default()
        },
        cache: None,
    });
    match pollster::block_on(scope.pop()) {
        Some(e) => Err(Error::Validation(e.to_string())),
        None => Ok(pipeline),
    }
}

/// A uniform buffer holding `value`.
pub(crate) fn uniform_buffer<T: bytemuck::Pod>(
    gpu: &Gpu,
    label: &str,
    value: &T,
) -> Result<wgpu::Buffer> {
    let buffer = gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: size_of::<T>() as u64,
        usage: wgpu::BufferUsages::UNIFORM,
        mapped_at_creation: true,
    });
    buffer
        .slice(..)
        .get_mapped_range_mut()
        .map_err(|e| Error::Readback(e.to_string()))?
        .copy_from_slice(bytemuck::bytes_of(value));
    buffer.unmap();
    Ok(buffer)
}

/// A per-step pass's layouts: its own group's (`arrays` and a uniform block) and pipeline
/// layout, and the layout of the group the trace passes bind its output in (`output`).
#[derive(Debug)]
pub(crate) struct PassLayouts {
    pub(crate) pass: wgpu::BindGroupLayout,
    pub(crate) pipeline: wgpu::PipelineLayout,
    pub(crate) output: wgpu::BindGroupLayout,
}

impl PassLayouts {
    pub(crate) fn new(
        gpu: &Gpu,
        label: &str,
        arrays: &[RangedArray],
        output_label: &str,
        output: &[RangedArray],
    ) -> PassLayouts {
        let device = &gpu.device;
        let pass = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some(label),
            entries: &layout_entries(arrays, true),
        });
        let pipeline = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(label),
            bind_group_layouts: &[Some(&pass)],
            immediate_size: 0,
        });
        let output = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some(output_label),
            entries: &layout_entries(output, false),
        });
        PassLayouts {
            pass,
            pipeline,
            output,
        }
    }
}

/// A storage buffer of `size` bytes (at least [`EMPTY_BINDING`]) that a pass writes,
/// readable back for tests.
pub(crate) fn storage_buffer(gpu: &Gpu, label: &str, size: u64) -> wgpu::Buffer {
    gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: size.max(EMPTY_BINDING),
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    })
}

/// The storage buffer a pass writes for the step drawn last (the wide tree, the neighbour
/// masks): `held` while it holds `needed` bytes (the pass writes every word the step reads),
/// else a new one a quarter larger than asked (never past the device's largest buffer).
/// Steps of one series differ a little in size, and a new buffer costs an allocation and its
/// first clear, on the path of a frame: on lavapipe, 27 MB of masks for a 300k-point step a
/// few hundred bytes larger than the last took 80 ms more than its later parts.
pub(crate) fn held_storage(
    gpu: &Gpu,
    label: &str,
    held: Option<wgpu::Buffer>,
    needed: u64,
) -> wgpu::Buffer {
    held.filter(|b| b.size() >= needed).unwrap_or_else(|| {
        let align = wgpu::COPY_BUFFER_ALIGNMENT;
        let largest = (gpu.device.limits().max_buffer_size / align * align).max(needed);
        let size = (needed + needed / 4).next_multiple_of(align).min(largest);
        storage_buffer(gpu, label, size)
    })
}

/// A per-step pass: its layouts and its pipelines, one per split, built on first use from
/// `source(limit, split)`.
#[derive(Debug)]
pub(crate) struct StepPass {
    pub(crate) layouts: PassLayouts,
    label: &'static str,
    source: fn(u64, bool) -> String,
    /// The storage binding limit the pass is compiled for (the tracer's).
    pub(crate) limit: u64,
    pipelines: [OnceLock<wgpu::ComputePipeline>; 2],
}

impl StepPass {
    /// `label` is also the entry point's name.
    pub(crate) fn new(
        layouts: PassLayouts,
        label: &'static str,
        source: fn(u64, bool) -> String,
        limit: u64,
    ) -> StepPass {
        StepPass {
            layouts,
            label,
            source,
            limit,
            pipelines: Default::default(),
        }
    }

    pub(crate) fn pipeline(&self, gpu: &Gpu, split: bool) -> Result<&wgpu::ComputePipeline> {
        let slot = &self.pipelines[usize::from(split)];
        if let Some(pipeline) = slot.get() {
            return Ok(pipeline);
        }
        let source = (self.source)(self.limit, split);
        let pipeline = checked_pipeline(
            gpu,
            &self.layouts.pipeline,
            self.label,
            source,
            self.label,
            &[],
        )?;
        Ok(slot.get_or_init(|| pipeline))
    }
}
