//! The neighbour-mask pass (`shaders/expand.wgsl`), run once per step inside its upload: a bit
//! per cluster candidate saying whether it is in the point's neighbour list, so the
//! refinement loops visit the list itself instead of filtering every candidate each time.

use crate::bindings::{bind_in_order, buffer_entry, storage_entry};
use crate::context::Gpu;
use crate::error::{Error, Result};
use crate::layout::ExpandSettings;
use crate::shaders::EXPAND_WGSL;

const WORKGROUP: u32 = 64;

/// The compiled pass, built once per device.
#[derive(Debug)]
pub(crate) struct Expander {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
}

/// The buffers the pass reads and the one it writes.
pub(crate) struct ExpandInputs<'a> {
    pub points: &'a wgpu::Buffer,
    pub normals: &'a wgpu::Buffer,
    pub reach: &'a wgpu::Buffer,
    pub cluster_start: &'a wgpu::Buffer,
    pub cluster_ids: &'a wgpu::Buffer,
    pub masks: &'a wgpu::Buffer,
}

impl Expander {
    pub(crate) fn new(device: &wgpu::Device) -> Expander {
        let mut entries: Vec<_> = (0..5).map(|b| storage_entry(b, true)).collect();
        entries.push(storage_entry(5, false));
        entries.push(buffer_entry(6, wgpu::BufferBindingType::Uniform));
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("expand"),
            entries: &entries,
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("expand"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("expand"),
            source: wgpu::ShaderSource::Wgsl(EXPAND_WGSL.into()),
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("expand"),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some("expand"),
            compilation_options: wgpu::PipelineCompilationOptions::default(),
            cache: None,
        });
        Expander { pipeline, layout }
    }

    /// Records the pass that fills `inputs.masks` (`mask_words` u32s per point).
    pub(crate) fn encode(
        &self,
        gpu: &Gpu,
        inputs: &ExpandInputs,
        settings: ExpandSettings,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<()> {
        let threads = settings.point_count * settings.mask_words;
        if threads == 0 {
            return Ok(());
        }
        let max_groups = gpu.device.limits().max_compute_workgroups_per_dimension;
        let groups = threads.div_ceil(WORKGROUP);
        let (groups_x, groups_y) = (groups.min(max_groups), groups.div_ceil(max_groups));
        let settings = ExpandSettings {
            row_threads: groups_x * WORKGROUP,
            ..settings
        };
        let uniform = gpu.device.create_buffer(&wgpu::BufferDescriptor {
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
            &uniform,
        ];
        let entries = bind_in_order(&buffers);
        let group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("expand"),
            layout: &self.layout,
            entries: &entries,
        });
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("expand"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &group, &[]);
        pass.dispatch_workgroups(groups_x, groups_y, 1);
        Ok(())
    }
}
