//! The GPU half of an upload: the step's buffers created and filled, its copies recorded,
//! its bind group made.

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use slosh_cache::{CacheFile, names};

use super::fill::{Memory, storage_buffers};
use super::host::{HostField, HostStep, Source, StepInfo};
use super::{EMPTY_BINDING, field_buffer_size, invalid};
use crate::bindings::{bind_entries, needs_split};
use crate::buffer_shelf::BufferShelf;
use crate::context::Gpu;
use crate::error::{Error, Result};
use crate::shaders::{
    EXPAND_ARRAYS, MASK_ARRAYS, RangedArray, STEP_ARRAYS, TREE_ARRAYS, WIDEN_ARRAYS, step_array,
};
use crate::staging::StagingPool;

/// The storage buffers of one step.
#[derive(Debug)]
pub struct StepBuffers {
    pub points: wgpu::Buffer,
    pub normals: wgpu::Buffer,
    pub cluster_start: wgpu::Buffer,
    /// Each cluster's first word of `cluster_ids` and whether it is wide; read by the mask
    /// pass only.
    pub cluster_base: wgpu::Buffer,
    /// The clusters' runs of candidates (`slosh_cache::candidates`); read by the mask pass
    /// only, which expands them.
    pub cluster_ids: wgpu::Buffer,
    pub balls: wgpu::Buffer,
    /// A cubic's other four coefficients (`slosh_cache::CubicWords`), or an empty binding.
    pub ball_cubic: wgpu::Buffer,
    /// Each ball's kind and degree, four bits, eight to a word (`slosh_cache::BallBits`).
    pub ball_states: wgpu::Buffer,
    /// Each ball's h, two half floats to a word, or an empty binding where h is the step's.
    pub ball_h: wgpu::Buffer,
    pub spheres: wgpu::Buffer,
    pub field: wgpu::Buffer,
    /// The baked BVH2, read by the widening pass only (the tracer widens it into the 4-wide
    /// tree of the step it draws, `widen.rs`).
    pub bvh_nodes: wgpu::Buffer,
}

impl StepBuffers {
    /// The buffers of the trace and shade passes' step bind group, in `STEP_ARRAYS`' order.
    pub fn in_binding_order(&self) -> [&wgpu::Buffer; STEP_ARRAYS.len()] {
        [
            &self.points,
            &self.normals,
            &self.cluster_start,
            &self.balls,
            &self.spheres,
            &self.field,
            &self.ball_cubic,
            &self.ball_states,
            &self.ball_h,
        ]
    }

    /// Every byte the step holds on the GPU: sections and the field.
    pub fn bytes(&self) -> u64 {
        self.in_binding_order()
            .iter()
            .map(|b| b.size())
            .sum::<u64>()
            + [&self.cluster_base, &self.cluster_ids, &self.bvh_nodes]
                .iter()
                .map(|b| b.size())
                .sum::<u64>()
    }
}

/// Where the time of an upload went.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct UploadStats {
    /// Decoded bytes placed on the GPU.
    pub bytes: u64,
    /// Bytes read from the file (compressed where the section is).
    pub stored_bytes: u64,
    /// The host half: checksums of the raw sections, the tree check and the sections it
    /// reads.
    pub host_seconds: f64,
    /// The GPU half's recording: buffers created, the staging buffer filled (compressed
    /// sections decoded into it), copies recorded.
    pub record_seconds: f64,
    /// Staging to device-local copies, from submit to completion (zero where the caller
    /// submits).
    pub gpu_seconds: f64,
    /// Open to ready, everything included.
    pub total_seconds: f64,
}

impl UploadStats {
    /// Decoded bytes per second of the whole upload, in GB/s.
    pub fn gigabytes_per_second(&self) -> f64 {
        self.bytes as f64 / self.total_seconds.max(1e-12) / 1e9
    }
}

/// How [`GpuStep::create_in`] records and where it takes its memory from.
#[derive(Default)]
pub struct UploadOptions<'a> {
    /// Takes the staging memory from this pool; hand it back with
    /// [`GpuStep::take_staging`] and [`StagingPool::recycle`] once the copies are submitted.
    pub staging: Option<&'a StagingPool>,
    /// Takes the section buffers from this shelf where it has some of the right sizes; the
    /// step gives them back to it when dropped.
    pub shelf: Option<&'a BufferShelf>,
    /// Asked between pieces of the staging fill: `true` abandons the upload with
    /// [`Error::Cancelled`] (a prefetch that a jump made stale).
    pub cancelled: Option<&'a (dyn Fn() -> bool + Sync)>,
}

impl std::fmt::Debug for UploadOptions<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("UploadOptions")
            .field("staging", &self.staging)
            .field("shelf", &self.shelf)
            .field("cancelled", &self.cancelled.is_some())
            .finish()
    }
}

/// A step on the GPU, with what the passes need to know about it and its bind group.
#[derive(Debug)]
pub struct GpuStep {
    /// Unique among the process's steps: what the tracer's held masks belong to.
    id: u64,
    pub buffers: StepBuffers,
    pub info: StepInfo,
    /// Whether an array spans more than one storage binding (see shaders.rs).
    pub split: bool,
    /// The shaded field's name and its finite range.
    pub field: Option<(String, f32, f32)>,
    /// Points whose value of the shaded field is missing (`HostField::missing`).
    pub field_missing: usize,
    pub upload: UploadStats,
    /// The trace and shade passes' group 0, made for `binding_limit`.
    bind_group: wgpu::BindGroup,
    binding_limit: u64,
    /// The pooled staging buffer of the upload, until taken back.
    staging: Option<wgpu::Buffer>,
    /// Where the section buffers go when the step is dropped.
    shelf: Option<BufferShelf>,
}

impl Drop for GpuStep {
    fn drop(&mut self) {
        if let Some(shelf) = &self.shelf {
            let b = &self.buffers;
            for buffer in b.in_binding_order() {
                shelf.put(buffer.clone());
            }
            for buffer in [&b.cluster_base, &b.cluster_ids, &b.bvh_nodes] {
                shelf.put(buffer.clone());
            }
        }
    }
}

/// How the passes bind each array of [`HostStep::gpu_arrays`]: the candidate runs and their
/// offsets are read only by the mask pass, the BVH2 only by the widening pass; a name that
/// is no array is an error, never a guess.
fn array_of(file: &CacheFile, name: &str) -> Result<&'static RangedArray> {
    Ok(match name {
        names::POINTS => &step_array::POINTS,
        names::NORMALS => &step_array::NORMALS,
        names::CLUSTER_START => &step_array::CLUSTER_START,
        names::CLUSTER_NEIGHBOURS => &EXPAND_ARRAYS[3],
        names::CLUSTER_BASE => &EXPAND_ARRAYS[5],
        names::BALLS => &step_array::BALLS,
        names::BALL_CUBIC => &step_array::BALL_CUBIC,
        names::BALL_STATES => &step_array::BALL_STATES,
        names::BALL_H => &step_array::BALL_H,
        names::SPHERES => &step_array::SPHERES,
        names::BVH_NODES => &WIDEN_ARRAYS[0],
        other => {
            return Err(invalid(
                file,
                format!("no GPU binding for section '{other}'"),
            ));
        }
    })
}

/// Whether an array of `bytes` needs more than one binding (split into ranges); an error
/// naming it where it cannot be bound at all.
fn needs_ranges(
    gpu: &Gpu,
    file: &CacheFile,
    what: &str,
    array: &RangedArray,
    bytes: u64,
) -> Result<bool> {
    needs_split(
        &gpu.device,
        &gpu.describe(),
        gpu.max_binding(),
        array,
        what,
        bytes,
    )
    .map_err(|problem| invalid(file, problem))
}

/// An empty field's binding.
fn no_field(gpu: &Gpu) -> wgpu::Buffer {
    gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("no field"),
        size: EMPTY_BINDING,
        usage: wgpu::BufferUsages::STORAGE,
        mapped_at_creation: false,
    })
}

/// An id no step has (ids count up from 0): what held per-step buffers say once forgotten.
pub(crate) const NO_STEP: u64 = u64::MAX;

/// The next step id.
fn next_id() -> u64 {
    static NEXT: AtomicU64 = AtomicU64::new(0);
    NEXT.fetch_add(1, Ordering::Relaxed)
}

impl GpuStep {
    /// The shaded field's finite range; `None` where no field is shaded or none of its
    /// values is finite (whose range reads (0, 0)).
    pub fn field_range(&self) -> Option<(f32, f32)> {
        let none_finite =
            self.field_missing > 0 && self.field_missing as u64 >= u64::from(self.info.point_count);
        self.field
            .as_ref()
            .filter(|_| !none_finite)
            .map(|f| (f.1, f.2))
    }

    /// Opens, uploads and waits: both halves in one call, `file`'s GPU sections and `field`'s
    /// values, if named.
    pub fn upload(gpu: &Gpu, file: &CacheFile, field: Option<&str>) -> Result<GpuStep> {
        let start = Instant::now();
        let host = HostStep::read(file, field)?;
        let mut encoder = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("upload"),
            });
        let mut step = GpuStep::create(gpu, &host, &mut encoder)?;
        let submitted = Instant::now();
        let scope = gpu.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let copied = gpu.queue.submit([encoder.finish()]);
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(Error::Validation(e.to_string()));
        }
        gpu.wait_for(copied)?;
        step.upload.gpu_seconds = submitted.elapsed().as_secs_f64();
        step.upload.total_seconds = start.elapsed().as_secs_f64();
        Ok(step)
    }

    /// The GPU half: buffers created and filled through staging, the copies recorded into
    /// `encoder`. Nothing is submitted or waited for; the step is ready for frames recorded
    /// after it in the same or a later submission.
    pub fn create(
        gpu: &Gpu,
        host: &HostStep<'_>,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<GpuStep> {
        GpuStep::create_in(gpu, host, encoder, UploadOptions::default())
    }

    /// [`GpuStep::create`] with the copies recorded into `copies`, and `options`.
    pub fn create_in(
        gpu: &Gpu,
        host: &HostStep<'_>,
        encoder: &mut wgpu::CommandEncoder,
        options: UploadOptions<'_>,
    ) -> Result<GpuStep> {
        let UploadOptions {
            staging,
            shelf,
            cancelled,
        } = options;
        let start = Instant::now();
        let file = host.file();
        let info = host.info.clone();
        // Every array, sections, the wide tree and the masks the tracer derives, within
        // RANGES bindings: one split decides how every pass of the step's frames reads.
        let mut split = false;
        let gpu_arrays = host.gpu_arrays();
        for (name, source) in &gpu_arrays {
            split |= needs_ranges(gpu, file, name, array_of(file, name)?, source.len())?;
        }
        if let Some(field) = &host.field {
            split |= needs_ranges(
                gpu,
                file,
                "field",
                &step_array::FIELD,
                field.bytes.len() as u64,
            )?;
        }
        let mask_bytes = info.mask_bytes();
        split |= needs_ranges(gpu, file, "neighbour masks", &MASK_ARRAYS[0], mask_bytes)?;
        split |= needs_ranges(gpu, file, "wide tree", &TREE_ARRAYS[0], info.wide_bytes())?;
        let candidate_bytes = info.candidate_bytes();
        split |= needs_ranges(gpu, file, "candidates", &MASK_ARRAYS[1], candidate_bytes)?;
        let mut stats = UploadStats {
            stored_bytes: host.stored_bytes,
            host_seconds: host.host_seconds,
            ..UploadStats::default()
        };
        let mut arrays = gpu_arrays;
        if let Some(f) = &host.field {
            arrays.push(("field", Source::Bytes(&f.bytes)));
        }
        stats.bytes = arrays.iter().map(|(_, b)| b.len()).sum();
        let memory = Memory {
            staging,
            shelf,
            cancelled,
        };
        let (mut sections, staging) = storage_buffers(gpu, file, &arrays, encoder, memory)?;
        let field_values = match &host.field {
            Some(_) => sections
                .pop()
                .ok_or_else(|| Error::Validation("upload produced too few buffers".into()))?,
            None => no_field(gpu),
        };
        let mut it = sections.into_iter();
        let mut next = || {
            it.next()
                .ok_or_else(|| Error::Validation("upload produced too few buffers".into()))
        };
        let (points, normals) = (next()?, next()?);
        let (cluster_start, cluster_base, cluster_ids) = (next()?, next()?, next()?);
        let (balls, ball_cubic) = (next()?, next()?);
        let (ball_states, ball_h) = (next()?, next()?);
        let (spheres, bvh_nodes) = (next()?, next()?);
        let buffers = StepBuffers {
            points,
            normals,
            cluster_start,
            cluster_base,
            cluster_ids,
            balls,
            ball_cubic,
            ball_states,
            ball_h,
            spheres,
            field: field_values,
            bvh_nodes,
        };
        let binding_limit = gpu.max_binding();
        let bind_group = step_group(gpu, &buffers, binding_limit);
        stats.record_seconds = start.elapsed().as_secs_f64();
        stats.total_seconds = stats.host_seconds + stats.record_seconds;
        Ok(GpuStep {
            id: next_id(),
            buffers,
            info,
            split,
            field: host.field.as_ref().map(|f| (f.name.clone(), f.min, f.max)),
            field_missing: host.field.as_ref().map_or(0, |f| f.missing),
            upload: stats,
            bind_group,
            binding_limit,
            staging,
            shelf: shelf.cloned(),
        })
    }

    /// The pooled staging buffer the upload's copies read, to recycle once they are
    /// submitted.
    pub fn take_staging(&mut self) -> Option<wgpu::Buffer> {
        self.staging.take()
    }

    /// Replaces the colour field (or drops it with `None`): only the field's buffer is
    /// uploaded (through `queue.write_buffer`, ordered before the next submission) and the
    /// bind group remade.
    pub fn set_field(&mut self, gpu: &Gpu, field: Option<&HostField>) -> Result<()> {
        let buffer = match field {
            Some(f) => {
                if f.bytes.len() as u64 != u64::from(self.info.point_count) * 4 {
                    return Err(Error::Validation(format!(
                        "field '{}' has {} bytes for a step of {} points",
                        f.name,
                        f.bytes.len(),
                        self.info.point_count
                    )));
                }
                needs_split(
                    &gpu.device,
                    &gpu.describe(),
                    self.binding_limit,
                    &step_array::FIELD,
                    "field",
                    f.bytes.len() as u64,
                )
                .map_err(Error::Validation)?;
                let buffer = gpu.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("field"),
                    size: field_buffer_size(&f.bytes),
                    usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                });
                gpu.queue.write_buffer(&buffer, 0, &f.bytes);
                buffer
            }
            None => no_field(gpu),
        };
        self.buffers.field = buffer;
        self.field = field.map(|f| (f.name.clone(), f.min, f.max));
        self.field_missing = field.map_or(0, |f| f.missing);
        self.bind_group = step_group(gpu, &self.buffers, self.binding_limit);
        Ok(())
    }

    /// Unique among this process's steps.
    pub fn id(&self) -> u64 {
        self.id
    }

    /// The trace and shade passes' group 0 for this step.
    pub fn bind_group(&self) -> &wgpu::BindGroup {
        &self.bind_group
    }

    /// The binding limit the step's bind group was made for.
    pub fn binding_limit(&self) -> u64 {
        self.binding_limit
    }

    /// Every byte the step holds on the GPU.
    pub fn gpu_bytes(&self) -> u64 {
        self.buffers.bytes()
    }
}

/// The step bind group of `buffers`, under the device's shared layout.
fn step_group(gpu: &Gpu, buffers: &StepBuffers, limit: u64) -> wgpu::BindGroup {
    let entries = bind_entries(&STEP_ARRAYS, &buffers.in_binding_order(), None, limit);
    gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("step"),
        layout: gpu.step_layout(),
        entries: &entries,
    })
}
