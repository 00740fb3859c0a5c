//! Staging memory reused across uploads. Fresh host-visible memory costs a page fault per
//! page on first touch, which made the copy into a new 160 MB staging buffer several times
//! slower than the memory allows; a recycled buffer is already faulted in. A buffer goes back
//! to the pool once the GPU has finished reading it: `recycle` maps it again, and wgpu
//! completes that map only after the submitted copies, during a later device poll.

use std::sync::{Arc, Mutex, PoisonError};

use crate::context::Gpu;

/// Staging buffers are made in multiples of this, so that steps of similar sizes share them.
const STAGING_GRANULE: u64 = 16 << 20;

/// Buffers kept for reuse, up to a number: what [`StagingPool`] and
/// [`crate::ReadbackPool`] hold.
#[derive(Debug, Clone)]
pub(crate) struct Shelf {
    free: Arc<Mutex<Vec<wgpu::Buffer>>>,
    /// The most buffers kept; more are dropped when they come back.
    keep: usize,
}

impl Shelf {
    pub(crate) fn new(keep: usize) -> Shelf {
        Shelf {
            free: Arc::new(Mutex::new(Vec::new())),
            keep,
        }
    }

    pub(crate) fn len(&self) -> usize {
        self.free
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .len()
    }

    /// The smallest kept buffer of at least `size` bytes, if any.
    pub(crate) fn take(&self, size: u64) -> Option<wgpu::Buffer> {
        let mut free = self.free.lock().unwrap_or_else(PoisonError::into_inner);
        let fit = free
            .iter()
            .enumerate()
            .filter(|(_, b)| b.size() >= size)
            .min_by_key(|(_, b)| b.size())
            .map(|(i, _)| i)?;
        Some(free.swap_remove(fit))
    }

    /// Keeps `buffer` unless the shelf is full.
    pub(crate) fn put(&self, buffer: wgpu::Buffer) {
        let mut free = self.free.lock().unwrap_or_else(PoisonError::into_inner);
        if free.len() < self.keep {
            free.push(buffer);
        }
    }
}

/// Mapped staging buffers ready for the next upload.
#[derive(Debug, Clone)]
pub struct StagingPool {
    shelf: Shelf,
}

impl StagingPool {
    pub fn new(keep: usize) -> StagingPool {
        StagingPool {
            shelf: Shelf::new(keep),
        }
    }

    /// Buffers ready now.
    pub fn ready(&self) -> usize {
        self.shelf.len()
    }

    /// A mapped `MAP_WRITE | COPY_SRC` buffer of at least `size` bytes: the smallest ready
    /// one that fits, or a new one.
    pub(crate) fn take(&self, gpu: &Gpu, size: u64) -> wgpu::Buffer {
        if let Some(buffer) = self.shelf.take(size) {
            return buffer;
        }
        gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("staging (pooled)"),
            size: size.next_multiple_of(STAGING_GRANULE),
            usage: wgpu::BufferUsages::MAP_WRITE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: true,
        })
    }

    /// Takes back a buffer from [`StagingPool::take`] that is still mapped (an upload that
    /// gave up before unmapping it).
    pub(crate) fn restore(&self, buffer: wgpu::Buffer) {
        self.shelf.put(buffer);
    }

    /// Takes `buffer` back once the copies reading it, submitted before this call (or never
    /// to be submitted), are done.
    pub fn recycle(&self, buffer: wgpu::Buffer) {
        let (shelf, back) = (self.shelf.clone(), buffer.clone());
        buffer.map_async(wgpu::MapMode::Write, .., move |mapped| {
            if mapped.is_ok() {
                shelf.put(back);
            }
        });
    }
}
