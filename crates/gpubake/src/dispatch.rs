//! Buffers, bind groups and dispatches the search passes share: storage from host slices, a
//! uniform block, a two-dimensional dispatch for any count, and buffers read back.

use slosh_render::Gpu;
use wgpu::util::DeviceExt;

use crate::layout::WORKGROUP;

/// A GPU failure, as the build reports it.
pub(crate) fn gpu_error(what: impl std::fmt::Display) -> slosh_mls::SurfaceError {
    slosh_mls::SurfaceError::Index(format!("GPU neighbour search: {what}"))
}

/// `work` with the device's validation and out-of-memory errors caught (on this thread: wgpu's
/// error scopes are thread-local) and returned through `fault` as the step's error, where wgpu
/// would otherwise panic on them: a step the GPU cannot hold fails, and the batch goes on.
pub(crate) fn guarded<T, E>(
    gpu: &Gpu,
    work: impl FnOnce() -> Result<T, E>,
    fault: impl FnOnce(String) -> E,
) -> Result<T, E> {
    let memory = gpu.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
    let validation = gpu.device.push_error_scope(wgpu::ErrorFilter::Validation);
    let out = work();
    let invalid = pollster::block_on(validation.pop());
    let out_of_memory = pollster::block_on(memory.pop());
    match (out_of_memory, invalid) {
        (Some(e), _) => Err(fault(format!(
            "out of GPU memory ({e}); bake with fewer --jobs or --device cpu"
        ))),
        (None, Some(e)) => Err(fault(e.to_string())),
        (None, None) => out,
    }
}

/// The usage of the passes' storage buffers: bound, uploaded into, cleared, read back.
pub(crate) const PASS_BUFFER_USAGE: wgpu::BufferUsages = wgpu::BufferUsages::STORAGE
    .union(wgpu::BufferUsages::COPY_SRC)
    .union(wgpu::BufferUsages::COPY_DST);

/// Where the passes' buffers come from: kept from step to step on a shelf, their inputs
/// uploaded through pooled staging memory (`GpuStages::memory`, shared by the jobs).
#[derive(Debug)]
pub(crate) struct PassMemory {
    pub(crate) gpu: std::sync::Arc<Gpu>,
    pub(crate) buffers: slosh_render::BufferShelf,
    /// The most bytes `buffers` keeps while every planned step is in flight.
    pub(crate) kept_bytes: u64,
    /// Steps baked at once, as the batch planned ([`slosh_bake::StepsInFlight`]).
    pub(crate) planned: std::sync::atomic::AtomicUsize,
    pub(crate) staging: slosh_render::StagingPool,
}

/// A pass buffer from the bake's shelf, given back to it when dropped: fresh device memory
/// for every input and output of every step was allocated and freed again, step by step.
pub(crate) struct Pooled {
    buffer: wgpu::Buffer,
    shelf: slosh_render::BufferShelf,
}

impl std::ops::Deref for Pooled {
    type Target = wgpu::Buffer;

    fn deref(&self) -> &wgpu::Buffer {
        &self.buffer
    }
}

impl Drop for Pooled {
    fn drop(&mut self) {
        // Work already submitted that reads it runs before any later submission writes it.
        self.shelf.put(self.buffer.clone());
    }
}

/// A storage buffer holding `data` (one zero element where it is empty: a binding cannot be
/// empty), uploaded through the bake's staging pool and submitted before it returns.
pub(crate) fn storage<T: bytemuck::Pod>(
    memory: &PassMemory,
    label: &str,
    data: &[T],
) -> Result<Pooled, slosh_mls::SurfaceError> {
    let zero = [0u8; 16];
    let bytes: &[u8] = if data.is_empty() {
        &zero
    } else {
        bytemuck::cast_slice(data)
    };
    let size = (bytes.len() as u64).next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT);
    let buffer = memory.buffers.take(&memory.gpu, label, size);
    memory
        .staging
        .upload(&memory.gpu, bytes, &buffer)
        .map_err(gpu_error)?;
    Ok(Pooled {
        buffer,
        shelf: memory.buffers.clone(),
    })
}

/// A storage buffer of `bytes` (at least 16), zeroed, that a pass writes and the host reads
/// back.
pub(crate) fn output(memory: &PassMemory, label: &str, bytes: u64) -> Pooled {
    let size = bytes.max(16).next_multiple_of(4);
    let buffer = memory.buffers.take(&memory.gpu, label, size);
    // A kept buffer holds its last step's bytes; passes may count into theirs.
    let mut encoder = memory
        .gpu
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("clear"),
        });
    encoder.clear_buffer(&buffer, 0, None);
    slosh_bake::device_busy();
    memory.gpu.queue.submit([encoder.finish()]);
    Pooled {
        buffer,
        shelf: memory.buffers.clone(),
    }
}

pub(crate) fn uniform<T: bytemuck::Pod>(gpu: &Gpu, params: &T) -> wgpu::Buffer {
    gpu.device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("search params"),
            contents: bytemuck::bytes_of(params),
            usage: wgpu::BufferUsages::UNIFORM,
        })
}

/// Workgroups along x and y for `count` threads, and the threads per row
/// (`SearchParams::row_threads`).
pub(crate) fn groups(gpu: &Gpu, count: u32) -> (u32, u32, u32) {
    let (x, y) = workgroup_grid(gpu, count.div_ceil(WORKGROUP));
    (x, y, x * WORKGROUP)
}

/// Workgroups along x and y for `groups` workgroups (at least one), x within the device's
/// limit per dimension.
pub(crate) fn workgroup_grid(gpu: &Gpu, groups: u32) -> (u32, u32) {
    let max = gpu
        .device
        .limits()
        .max_compute_workgroups_per_dimension
        .max(1);
    let x = groups.clamp(1, max);
    (x, groups.max(1).div_ceil(x))
}

/// Records `dispatches` (pipeline, workgroups) of one bind group in one compute pass (wgpu
/// orders each after the one before), timed into `stamps` where given.
pub(crate) fn record(
    encoder: &mut wgpu::CommandEncoder,
    dispatches: &[(&wgpu::ComputePipeline, (u32, u32))],
    bind_group: &wgpu::BindGroup,
    stamps: Option<&crate::pass_clock::Stamps>,
) {
    {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("bake stage"),
            timestamp_writes: stamps.map(|s| s.writes()),
        });
        pass.set_bind_group(0, bind_group, &[]);
        for &(pipeline, (x, y)) in dispatches {
            pass.set_pipeline(pipeline);
            pass.dispatch_workgroups(x, y, 1);
        }
    }
    if let Some(s) = stamps {
        s.resolve(encoder);
    }
}

/// A bind group of `entries` (binding, buffer) under `layout`.
pub(crate) fn bind(
    gpu: &Gpu,
    layout: &wgpu::BindGroupLayout,
    entries: &[(u32, &wgpu::Buffer)],
) -> wgpu::BindGroup {
    let entries: Vec<wgpu::BindGroupEntry<'_>> = entries
        .iter()
        .map(|&(binding, buffer)| wgpu::BindGroupEntry {
            binding,
            resource: buffer.as_entire_binding(),
        })
        .collect();
    gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("neighbour search"),
        layout,
        entries: &entries,
    })
}

/// A layout of a uniform block at 0 and storage buffers at `storage` (binding, writable).
pub(crate) fn layout(gpu: &Gpu, label: &str, storage: &[(u32, bool)]) -> wgpu::BindGroupLayout {
    let mut entries = vec![wgpu::BindGroupLayoutEntry {
        binding: 0,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }];
    entries.extend(
        storage
            .iter()
            .map(|&(binding, writable)| wgpu::BindGroupLayoutEntry {
                binding,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Storage {
                        read_only: !writable,
                    },
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            }),
    );
    gpu.device
        .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some(label),
            entries: &entries,
        })
}
