//! GPU buffers read back to the host, and what a frame's targets hold: its pass times, its
//! hits and pixels.

use std::sync::{Arc, OnceLock};

use bytemuck::Zeroable;

use super::{Frame, FrameTargets, PassTimes, Tracer};
use crate::context::Gpu;
use crate::error::{Error, Result};
use crate::layout::{GpuHit, status};
use crate::staging::Shelf;

/// Maps a `MAP_READ` buffer, waits, and copies its contents out as `T`s.
pub fn read_buffer<T: bytemuck::Pod>(gpu: &Gpu, buffer: &wgpu::Buffer) -> Result<Vec<T>> {
    read(gpu, buffer, None)
}

/// The first `size` bytes of a `COPY_SRC` buffer, copied out once the work submitted before
/// it has run (waits).
pub fn read_storage<T: bytemuck::Pod>(
    gpu: &Gpu,
    source: &wgpu::Buffer,
    size: u64,
) -> Result<Vec<T>> {
    read_range(gpu, source, 0, size)
}

/// `size` bytes of `source` from `offset`, copied out once that copy has run (waits for it
/// alone).
fn read_range<T: bytemuck::Pod>(
    gpu: &Gpu,
    source: &wgpu::Buffer,
    offset: u64,
    size: u64,
) -> Result<Vec<T>> {
    let (staging, copied) = staged(gpu, source, offset, size);
    read(gpu, &staging, Some(copied))
}

/// Read-back buffers reused across reads: fresh host-visible memory costs a page fault (and a
/// page cleared) per page on first touch, which a bake's hundreds of megabytes of lists paid
/// again in every batch of every step. A buffer returns to the pool once its read is done.
#[derive(Debug, Clone)]
pub struct ReadbackPool {
    shelf: Shelf,
}

/// Read-back buffers are made in multiples of this (or the power of two above a smaller
/// size), so that reads of similar sizes share them.
const READBACK_GRANULE: u64 = 16 << 20;

impl ReadbackPool {
    pub fn new(keep: usize) -> ReadbackPool {
        ReadbackPool {
            shelf: Shelf::new(keep),
        }
    }

    /// The same pool, keeping no more than `bytes` of buffers in all.
    pub fn within(self, bytes: u64) -> ReadbackPool {
        ReadbackPool {
            shelf: self.shelf.within(bytes),
        }
    }

    /// Keeps at most `buffers` for the next reads from now on (never more than it was made
    /// to keep); those over go now.
    pub fn keep_at_most(&self, buffers: usize) {
        self.shelf.keep_at_most(buffers);
    }

    /// Buffers kept for the next reads.
    pub fn kept(&self) -> usize {
        self.shelf.len()
    }

    /// The first `size` bytes of a `COPY_SRC` buffer, once the work submitted before it has
    /// run (waits).
    pub fn read<T: bytemuck::Pod>(
        &self,
        gpu: &Gpu,
        source: &wgpu::Buffer,
        size: u64,
    ) -> Result<Vec<T>> {
        self.with_staged(gpu, source, &[(0, size)], |bytes| {
            bytemuck::pod_collect_to_vec(bytes)
        })
    }

    /// The first `size` bytes of a `COPY_SRC` buffer appended to `out`, once the work
    /// submitted before it has run (waits): copied from the mapping straight into `out` by
    /// every thread, so that hundreds of megabytes (a bake's neighbour lists) are neither
    /// copied twice nor written, page by fresh page, by one thread.
    pub fn read_into<T: bytemuck::Pod + Send + Sync>(
        &self,
        gpu: &Gpu,
        source: &wgpu::Buffer,
        size: u64,
        out: &mut Vec<T>,
    ) -> Result<()> {
        use rayon::prelude::*;
        self.with_staged(
            gpu,
            source,
            &[(0, size)],
            |bytes| match bytemuck::try_cast_slice::<u8, T>(bytes) {
                Ok(values) => out.par_extend(values.par_iter().copied()),
                Err(_) => out.extend(bytemuck::pod_collect_to_vec::<u8, T>(bytes)),
            },
        )
    }

    /// The byte ranges (offset, size) of a `COPY_SRC` buffer, one after another, once the
    /// work submitted before them has run (waits): one copy submission and one mapping for
    /// all of them. Offsets and sizes are multiples of 4.
    pub fn read_ranges<T: bytemuck::Pod>(
        &self,
        gpu: &Gpu,
        source: &wgpu::Buffer,
        ranges: &[(u64, u64)],
    ) -> Result<Vec<T>> {
        if ranges.iter().all(|r| r.1 == 0) {
            return Ok(Vec::new());
        }
        self.with_staged(gpu, source, ranges, |bytes| {
            bytemuck::pod_collect_to_vec(bytes)
        })
    }

    /// The `ranges` (offset, size) of `source` copied one after another into a pooled
    /// `MAP_READ` buffer, mapped and handed to `take`; the buffer goes back to the pool.
    fn with_staged<R>(
        &self,
        gpu: &Gpu,
        source: &wgpu::Buffer,
        ranges: &[(u64, u64)],
        take: impl FnOnce(&[u8]) -> R,
    ) -> Result<R> {
        let size: u64 = ranges.iter().map(|r| r.1).sum();
        let buffer = self.take(gpu, size);
        let mut encoder = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("readback"),
            });
        let mut at = 0;
        for &(offset, bytes) in ranges.iter().filter(|r| r.1 > 0) {
            encoder.copy_buffer_to_buffer(source, offset, &buffer, at, bytes);
            at += bytes;
        }
        let copied = gpu.queue.submit([encoder.finish()]);
        let out = mapped(gpu, &buffer, size, Some(copied), take);
        if out.is_ok() {
            self.shelf.put(buffer);
        }
        out
    }

    /// An unmapped `MAP_READ | COPY_DST` buffer of at least `size` bytes: the smallest free
    /// one that fits, or a new one.
    fn take(&self, gpu: &Gpu, size: u64) -> wgpu::Buffer {
        if let Some(buffer) = self.shelf.take(size) {
            return buffer;
        }
        let rounded = if size >= READBACK_GRANULE {
            size.next_multiple_of(READBACK_GRANULE)
        } else {
            size.next_power_of_two().max(wgpu::COPY_BUFFER_ALIGNMENT)
        };
        gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback (pooled)"),
            size: rounded,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    }
}

/// Maps a MAP_READ buffer and copies its contents out, once the submission `written` that
/// last wrote it has run (or every submission, where that is not known).
pub(super) fn read<T: bytemuck::Pod>(
    gpu: &Gpu,
    buffer: &wgpu::Buffer,
    written: Option<wgpu::SubmissionIndex>,
) -> Result<Vec<T>> {
    mapped(gpu, buffer, buffer.size(), written, |bytes| {
        bytemuck::pod_collect_to_vec(bytes)
    })
}

/// Maps the first `size` bytes of a MAP_READ buffer, waits (for the submission `written`,
/// or for every submission), and hands them to `take`.
fn mapped<R>(
    gpu: &Gpu,
    buffer: &wgpu::Buffer,
    size: u64,
    written: Option<wgpu::SubmissionIndex>,
    take: impl FnOnce(&[u8]) -> R,
) -> Result<R> {
    let slice = buffer.slice(..size);
    let (tx, rx) = std::sync::mpsc::channel();
    slice.map_async(wgpu::MapMode::Read, move |r| {
        let _ = tx.send(r);
    });
    match written {
        Some(index) => gpu.wait_for(index)?,
        None => gpu.wait()?,
    }
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

/// `size` bytes of `source` from `offset` copied into a new `MAP_READ` buffer, and the
/// copy's submission.
fn staged(
    gpu: &Gpu,
    source: &wgpu::Buffer,
    offset: u64,
    size: u64,
) -> (wgpu::Buffer, wgpu::SubmissionIndex) {
    let staging = gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let copied = copy_out(gpu, source, offset, &staging, size);
    (staging, copied)
}

/// Submits a copy of `size` bytes of `source` from `offset` to the start of `staging`;
/// returns the submission.
fn copy_out(
    gpu: &Gpu,
    source: &wgpu::Buffer,
    offset: u64,
    staging: &wgpu::Buffer,
    size: u64,
) -> wgpu::SubmissionIndex {
    let mut encoder = gpu
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("readback"),
        });
    encoder.copy_buffer_to_buffer(source, offset, staging, 0, size);
    gpu.queue.submit([encoder.finish()])
}

impl Tracer {
    /// The pass times of the last frame submitted into `targets`, once the GPU has finished
    /// it (waits); `None` where the adapter has no timestamp queries.
    pub fn pass_times(&self, gpu: &Gpu, targets: &FrameTargets) -> Result<Option<PassTimes>> {
        let Some((_, _, readback)) = &targets.queries else {
            return Ok(None);
        };
        let stamps: Vec<u64> = read(gpu, readback, None)?;
        let period = f64::from(gpu.queue.get_timestamp_period()) * 1e-6;
        let ms = |a: usize, b: usize| stamps[b].saturating_sub(stamps[a]) as f64 * period;
        Ok(Some(PassTimes {
            trace_ms: ms(0, 1),
            shade_ms: ms(2, 3),
        }))
    }

    /// Reads the hits and pixels of the last frame submitted into `targets` (waits).
    pub fn read_frame(&self, gpu: &Gpu, targets: &FrameTargets) -> Result<Frame> {
        let mut hits: Vec<GpuHit> = read_range(gpu, &targets.hits, 0, targets.hits.size())?;
        // The trace pass writes a miss's status word alone (write_miss in mls.wgsl).
        for hit in hits.iter_mut().filter(|h| h.status == status::MISS) {
            *hit = GpuHit {
                item: u32::MAX,
                ..GpuHit::zeroed()
            };
        }
        let rgba = read_range(gpu, &targets.image, 0, targets.image.size())?;
        Ok(Frame {
            width: targets.width,
            height: targets.height,
            hits,
            rgba,
        })
    }

    /// Asks for the hit at pixel (`x`, `y`) of the last frame recorded into `targets`, one
    /// pixel's bytes copied back without waiting: taken with [`PendingHit::poll`] once the GPU
    /// has run the copy (a software adapter may run it behind the window's paint and present).
    /// `None` for a pixel outside the frame.
    pub fn request_hit(
        &self,
        gpu: &Gpu,
        targets: &FrameTargets,
        x: u32,
        y: u32,
    ) -> Option<PendingHit> {
        if x >= targets.width || y >= targets.height {
            return None;
        }
        let size = size_of::<GpuHit>() as u64;
        let offset = (u64::from(y) * u64::from(targets.width) + u64::from(x)) * size;
        let (staging, _) = staged(gpu, &targets.hits, offset, size);
        let mapped = Arc::new(OnceLock::new());
        let set = mapped.clone();
        staging.slice(..).map_async(wgpu::MapMode::Read, move |r| {
            let _ = set.set(r);
        });
        Some(PendingHit { staging, mapped })
    }
}

/// A pixel's hit being copied back ([`Tracer::request_hit`]).
#[derive(Debug)]
pub struct PendingHit {
    staging: wgpu::Buffer,
    /// Set by the mapping's callback, on whichever thread polls the device.
    mapped: Arc<OnceLock<std::result::Result<(), wgpu::BufferAsyncError>>>,
}

impl PendingHit {
    /// The hit once the copy has run (`Some(None)` for a miss), `None` while it has not:
    /// checks the device once, without waiting.
    pub fn poll(&self, gpu: &Gpu) -> Result<Option<Option<GpuHit>>> {
        gpu.device
            .poll(wgpu::PollType::Poll)
            .map_err(|e| Error::Readback(e.to_string()))?;
        match self.mapped.get() {
            None => Ok(None),
            Some(Err(e)) => Err(Error::Readback(e.to_string())),
            Some(Ok(())) => {
                let hit: GpuHit = {
                    let view = self
                        .staging
                        .slice(..)
                        .get_mapped_range()
                        .map_err(|e| Error::Readback(e.to_string()))?;
                    bytemuck::pod_read_unaligned(&view)
                };
                // The trace pass writes a miss's status word alone (write_miss in mls.wgsl).
                Ok(Some((hit.status != status::MISS).then_some(hit)))
            }
        }
    }
}
