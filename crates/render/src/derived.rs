//! What the tracer derives from the step it draws (`shaders/expand.wgsl`): each BVH item
//! slot's sphere (`leaves`, so the walk reads a leaf's spheres beside its items instead of
//! through them) and the neighbour masks (`expand`: a bit per cluster candidate saying
//! whether it is in the point's neighbour list, so the refinement loops visit the list itself
//! instead of filtering every candidate each time).
//!
//! No step holds them: the masks alone are about a third of what a step would hold, and a
//! step is drawn far less often than it sits in the pool. The tracer keeps one set, for the
//! step it drew last, and derives it again, in the same submission as the frame, when a
//! frame is of another step: the leaf spheres for any frame, the masks only for a refined
//! one (scrubbing at one iteration never runs the mask pass).

use std::sync::{Mutex, OnceLock};

use crate::bindings::{bind_entries, layout_entries};
use crate::context::Gpu;
use crate::error::{Error, Result};
use crate::layout::ExpandSettings;
use crate::shaders::{DERIVED_ARRAYS, EXPAND_ARRAYS, expand_wgsl};
use crate::upload::{EMPTY_BINDING, GpuStep};

/// The leaf pass's threads per workgroup and per row of its 2D dispatch.
const LEAF_GROUP: u32 = 64;

/// The derived arrays the tracer holds: whose, and the trace passes' group over them.
#[derive(Debug)]
struct Held {
    step: u64,
    leaf_spheres: wgpu::Buffer,
    masks: wgpu::Buffer,
    /// Whether `masks` are the step's (else an earlier step's, or empty: never read by the
    /// frames that do not refine).
    masks_valid: bool,
    group: wgpu::BindGroup,
}

/// The passes' pipelines (per split, on first use), the trace passes' group-2 layout, and
/// the one set held.
#[derive(Debug)]
pub(crate) struct DerivedArrays {
    /// The storage binding limit the passes are compiled for (the tracer's).
    limit: u64,
    expand_layout: wgpu::BindGroupLayout,
    expand_pipeline_layout: wgpu::PipelineLayout,
    /// `leaves` and `expand`, by split.
    pipelines: [OnceLock<(wgpu::ComputePipeline, wgpu::ComputePipeline)>; 2],
    /// Group 2 of the trace and shade passes.
    pub(crate) layout: wgpu::BindGroupLayout,
    /// Bound where a pass or a frame does not use an output.
    empty: wgpu::Buffer,
    held: Mutex<Option<Held>>,
}

/// A storage buffer of `size` bytes a pass writes (readable back for tests).
pub(crate) fn derived_buffer(gpu: &Gpu, label: &str, size: u64) -> wgpu::Buffer {
    gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: size.max(EMPTY_BINDING),
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    })
}

/// `held` where it is at least `needed` bytes (a pass writes every element a step reads),
/// else a new buffer.
fn reuse(gpu: &Gpu, held: Option<wgpu::Buffer>, label: &str, needed: u64) -> wgpu::Buffer {
    match held {
        Some(b) if b.size() >= needed => b,
        _ => derived_buffer(gpu, label, needed),
    }
}

impl DerivedArrays {
    pub(crate) fn new(gpu: &Gpu, limit: u64) -> DerivedArrays {
        let device = &gpu.device;
        let expand_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("expand"),
            entries: &layout_entries(&EXPAND_ARRAYS, true),
        });
        let expand_pipeline_layout =
            device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("expand"),
                bind_group_layouts: &[Some(&expand_layout)],
                immediate_size: 0,
            });
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("derived"),
            entries: &layout_entries(&DERIVED_ARRAYS, false),
        });
        DerivedArrays {
            limit,
            expand_layout,
            expand_pipeline_layout,
            pipelines: Default::default(),
            layout,
            empty: derived_buffer(gpu, "empty", EMPTY_BINDING),
            held: Mutex::new(None),
        }
    }

    fn pipelines(
        &self,
        gpu: &Gpu,
        split: bool,
    ) -> Result<&(wgpu::ComputePipeline, wgpu::ComputePipeline)> {
        let slot = &self.pipelines[usize::from(split)];
        if let Some(pipelines) = slot.get() {
            return Ok(pipelines);
        }
        let device = &gpu.device;
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("expand"),
            source: wgpu::ShaderSource::Wgsl(expand_wgsl(self.limit, split).into()),
        });
        let pipeline = |entry: &str| {
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: Some(&self.expand_pipeline_layout),
                module: &module,
                entry_point: Some(entry),
                compilation_options: wgpu::PipelineCompilationOptions::default(),
                cache: None,
            })
        };
        let pipelines = (pipeline("leaves"), pipeline("expand"));
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(Error::Validation(e.to_string()));
        }
        Ok(slot.get_or_init(|| pipelines))
    }

    /// The trace passes' group 2 for a frame of `step`: the held arrays, derived first
    /// (recorded into `encoder`) where they are another step's, the masks only where the
    /// frame `refines`.
    pub(crate) fn group_for(
        &self,
        gpu: &Gpu,
        step: &GpuStep,
        refines: bool,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<wgpu::BindGroup> {
        let mut held = self
            .held
            .lock()
            .map_err(|_| Error::Validation("the derived arrays' lock was poisoned".into()))?;
        let same_step = held.as_ref().is_some_and(|h| h.step == step.id());
        if let Some(h) = held
            .as_ref()
            .filter(|h| same_step && (!refines || h.masks_valid))
        {
            return Ok(h.group.clone());
        }
        let (leaf_spheres, masks, masks_valid) = match held.take() {
            Some(h) => (
                Some(h.leaf_spheres),
                Some(h.masks),
                same_step && h.masks_valid,
            ),
            None => (None, None, false),
        };
        let leaf_spheres = reuse(gpu, leaf_spheres, "leaf spheres", step.info.leaf_bytes());
        if !same_step {
            self.record_leaves(gpu, step, &leaf_spheres, encoder)?;
        }
        let (masks, masks_valid) = if refines && !masks_valid {
            let masks = reuse(gpu, masks, "neighbour masks", step.info.mask_bytes());
            self.record_masks(gpu, step, &masks, encoder, None)?;
            (masks, true)
        } else {
            (masks.unwrap_or_else(|| self.empty.clone()), masks_valid)
        };
        let group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("derived"),
            layout: &self.layout,
            entries: &bind_entries(&DERIVED_ARRAYS, &[&leaf_spheres, &masks], None, self.limit),
        });
        *held = Some(Held {
            step: step.id(),
            leaf_spheres,
            masks,
            masks_valid,
            group: group.clone(),
        });
        Ok(group)
    }

    /// Bytes of the derived arrays held now.
    pub(crate) fn held_bytes(&self) -> u64 {
        self.held.lock().map_or(0, |h| {
            h.as_ref()
                .map_or(0, |h| h.leaf_spheres.size() + h.masks.size())
        })
    }

    /// Bytes of neighbour masks held now that are some step's (0 before the first refined
    /// frame).
    pub(crate) fn mask_bytes(&self) -> u64 {
        self.held.lock().map_or(0, |h| {
            h.as_ref()
                .filter(|h| h.masks_valid)
                .map_or(0, |h| h.masks.size())
        })
    }

    /// The passes' bind group over `step` and the two outputs.
    fn expand_group(
        &self,
        gpu: &Gpu,
        step: &GpuStep,
        leaf_spheres: &wgpu::Buffer,
        masks: &wgpu::Buffer,
    ) -> Result<wgpu::BindGroup> {
        let device = &gpu.device;
        let info = &step.info;
        let settings = ExpandSettings {
            point_count: info.point_count,
            cluster_size: info.cluster_size,
            mask_words: info.mask_words,
            has_normals: u32::from(info.has_normals),
            cluster_id_count: info.cluster_id_count,
            row_threads: self.leaf_rows(info.item_count).0 * LEAF_GROUP,
            sphere_count: info.sphere_count,
            item_count: info.item_count,
        };
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
        let b = &step.buffers;
        let buffers = [
            &b.points,
            &b.normals,
            &b.reach,
            &b.cluster_start,
            &b.cluster_ids,
            masks,
            &b.cluster_base,
            &b.bvh_items,
            &b.spheres,
            leaf_spheres,
        ];
        let entries = bind_entries(&EXPAND_ARRAYS, &buffers, Some(&uniform), self.limit);
        Ok(device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("expand"),
            layout: &self.expand_layout,
            entries: &entries,
        }))
    }

    /// Workgroups per row and rows of the leaf pass over `items` slots.
    fn leaf_rows(&self, items: u32) -> (u32, u32) {
        let groups = items.div_ceil(LEAF_GROUP).max(1);
        let per_row = groups.min(1 << 15);
        (per_row, groups.div_ceil(per_row))
    }

    fn record_leaves(
        &self,
        gpu: &Gpu,
        step: &GpuStep,
        leaf_spheres: &wgpu::Buffer,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<()> {
        let group = self.expand_group(gpu, step, leaf_spheres, &self.empty)?;
        let (leaves, _) = self.pipelines(gpu, step.split)?;
        let (per_row, rows) = self.leaf_rows(step.info.item_count);
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("leaf spheres"),
            timestamp_writes: None,
        });
        pass.set_pipeline(leaves);
        pass.set_bind_group(0, &group, &[]);
        pass.dispatch_workgroups(per_row, rows, 1);
        Ok(())
    }

    /// Records the pass that fills `masks` for `step` (rows of words, `mask_row`), timed
    /// into `timestamps` (2 queries) where given.
    pub(crate) fn record_masks(
        &self,
        gpu: &Gpu,
        step: &GpuStep,
        masks: &wgpu::Buffer,
        encoder: &mut wgpu::CommandEncoder,
        timestamps: Option<&wgpu::QuerySet>,
    ) -> Result<()> {
        let group = self.expand_group(gpu, step, &self.empty, masks)?;
        let (_, expand) = self.pipelines(gpu, step.split)?;
        let max_groups = gpu.device.limits().max_compute_workgroups_per_dimension;
        // One workgroup per cluster.
        let info = &step.info;
        let clusters = info.point_count.div_ceil(info.cluster_size.max(1));
        let groups = if info.mask_words == 0 { 0 } else { clusters };
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
            label: Some("neighbour masks"),
            timestamp_writes,
        });
        if groups > 0 {
            pass.set_pipeline(expand);
            pass.set_bind_group(0, &group, &[]);
            pass.dispatch_workgroups(groups.min(max_groups), groups.div_ceil(max_groups), 1);
        }
        Ok(())
    }
}
