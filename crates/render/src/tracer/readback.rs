//! GPU buffers read back to the host, and what a frame's targets hold: its pass times, its
//! hits and pixels.

use bytemuck::Zeroable;

use super::{Frame, FrameTargets, PassTimes, Tracer};
use crate::context::Gpu;
use crate::error::{Error, Result};
use crate::layout::{GpuHit, status};

/// Maps a `MAP_READ` buffer, waits, and copies its contents out as `T`s.
pub fn read_buffer<T: bytemuck::Pod>(gpu: &Gpu, buffer: &wgpu::Buffer) -> Result<Vec<T>> {
    read(gpu, buffer)
}

/// The first `size` bytes of a `COPY_SRC` buffer, copied out once the work submitted before
/// it has run (waits).
pub fn read_storage<T: bytemuck::Pod>(
    gpu: &Gpu,
    source: &wgpu::Buffer,
    size: u64,
) -> Result<Vec<T>> {
    read(gpu, &staged(gpu, source, 0, size))
}

/// The first `size` bytes of a `COPY_SRC` buffer appended to `out` once the work submitted
/// before it has run (waits): copied from the mapping straight into `out` by every thread, so
/// that hundreds of megabytes (a bake's neighbour lists) are neither copied twice nor written,
/// page by fresh page, by one thread.
pub fn read_storage_into<T: bytemuck::Pod + Send + Sync>(
    gpu: &Gpu,
    source: &wgpu::Buffer,
    size: u64,
    out: &mut Vec<T>,
) -> Result<()> {
    use rayon::prelude::*;
    mapped(
        gpu,
        &staged(gpu, source, 0, size),
        |bytes| match bytemuck::try_cast_slice::<u8, T>(bytes) {
            Ok(values) => out.par_extend(values.par_iter().copied()),
            Err(_) => out.extend(bytemuck::pod_collect_to_vec::<u8, T>(bytes)),
        },
    )
}

/// Maps a MAP_READ buffer and copies its contents out.
pub(super) fn read<T: bytemuck::Pod>(gpu: &Gpu, buffer: &wgpu::Buffer) -> Result<Vec<T>> {
    mapped(gpu, buffer, |bytes| bytemuck::pod_collect_to_vec(bytes))
}

/// Maps a MAP_READ buffer, waits, and hands its bytes to `take`.
fn mapped<R>(gpu: &Gpu, buffer: &wgpu::Buffer, take: impl FnOnce(&[u8]) -> R) -> Result<R> {
    let slice = buffer.slice(..);
    let (tx, rx) = std::sync::mpsc::channel();
    slice.map_async(wgpu::MapMode::Read, move |r| {
        let _ = tx.send(r);
    });
    gpu.wait()?;
    rx.recv()
        .map_err(|e| Error::Readback(e.to_string()))?
        .map_err(|e| Error::Readback(e.to_string()))?;
    let out = {
        let view = slice
            .get_mapped_range()
            .map_err(|e| Error::Readback(e.to_string()))?;
        take(&view)
    };
    buffer.unmap();
    Ok(out)
}

/// `size` bytes of `source` from `offset` copied into a new `MAP_READ` buffer (submitted).
fn staged(gpu: &Gpu, source: &wgpu::Buffer, offset: u64, size: u64) -> wgpu::Buffer {
    let staging = gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = gpu
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("readback"),
        });
    encoder.copy_buffer_to_buffer(source, offset, &staging, 0, size);
    gpu.queue.submit([encoder.finish()]);
    staging
}

impl Tracer {
    /// The pass times of the last frame submitted into `targets`, once the GPU has finished
    /// it (waits); `None` where the adapter has no timestamp queries.
    pub fn pass_times(&self, gpu: &Gpu, targets: &FrameTargets) -> Result<Option<PassTimes>> {
        let Some((_, _, readback)) = &targets.queries else {
            return Ok(None);
        };
        let stamps: Vec<u64> = read(gpu, readback)?;
        let period = f64::from(gpu.queue.get_timestamp_period()) * 1e-6;
        let ms = |a: usize, b: usize| stamps[b].saturating_sub(stamps[a]) as f64 * period;
        Ok(Some(PassTimes {
            trace_ms: ms(0, 1),
            shade_ms: ms(2, 3),
        }))
    }

    /// Reads the hits and pixels of the last frame submitted into `targets` (waits).
    pub fn read_frame(&self, gpu: &Gpu, targets: &FrameTargets) -> Result<Frame> {
        let whole = |b: &wgpu::Buffer| staged(gpu, b, 0, b.size());
        let mut hits: Vec<GpuHit> = read(gpu, &whole(&targets.hits))?;
        // The trace pass writes a miss's status word alone (write_miss in mls.wgsl).
        for hit in hits.iter_mut().filter(|h| h.status == status::MISS) {
            *hit = GpuHit {
                item: u32::MAX,
                ..GpuHit::zeroed()
            };
        }
        let rgba = read(gpu, &whole(&targets.image))?;
        Ok(Frame {
            width: targets.width,
            height: targets.height,
            hits,
            rgba,
        })
    }

    /// The hit at pixel (`x`, `y`) of the last frame recorded into `targets` (waits; one
    /// pixel's bytes cross): `None` for a miss or a pixel outside the frame.
    pub fn read_hit(
        &self,
        gpu: &Gpu,
        targets: &FrameTargets,
        x: u32,
        y: u32,
    ) -> Result<Option<GpuHit>> {
        if x >= targets.width || y >= targets.height {
            return Ok(None);
        }
        let size = size_of::<GpuHit>() as u64;
        let offset = (u64::from(y) * u64::from(targets.width) + u64::from(x)) * size;
        let hit: Vec<GpuHit> = read(gpu, &staged(gpu, &targets.hits, offset, size))?;
        // The trace pass writes a miss's status word alone (write_miss in mls.wgsl).
        Ok(hit.first().copied().filter(|h| h.status != status::MISS))
    }
}
