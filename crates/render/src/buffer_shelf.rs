//! Device-local step buffers kept for reuse. Creating a buffer is usually a sub-allocation,
//! but where the allocator has no room left it allocates a new block of device memory, and
//! it frees a block once its last buffer is dropped: a series streaming through a full pool
//! did both again and again, some milliseconds each, on the path of a jump. A step dropped
//! from the pool gives its section buffers here, and the next upload takes them.

use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, PoisonError};

use crate::context::Gpu;

/// The usage of every buffer on the shelf: a step's sections.
pub(crate) const SECTION_USAGE: wgpu::BufferUsages =
    wgpu::BufferUsages::STORAGE.union(wgpu::BufferUsages::COPY_DST);

/// Kept section buffers, up to a number of bytes.
#[derive(Debug, Clone, Default)]
pub struct BufferShelf {
    free: Arc<Mutex<Vec<wgpu::Buffer>>>,
    /// The most bytes kept; a buffer that would pass it is dropped when it comes back.
    limit: Arc<AtomicU64>,
    /// Buffers an upload made because none on the shelf fitted.
    fresh: Arc<AtomicUsize>,
}

impl BufferShelf {
    /// A shelf that keeps nothing until [`BufferShelf::set_limit`].
    pub fn new() -> BufferShelf {
        BufferShelf::default()
    }

    /// Keeps at most `bytes`; what is over goes now.
    pub fn set_limit(&self, bytes: u64) {
        self.limit.store(bytes, Ordering::Relaxed);
        let mut free = self.lock();
        while free.iter().map(wgpu::Buffer::size).sum::<u64>() > bytes {
            free.remove(0);
        }
    }

    /// Bytes held.
    pub fn bytes(&self) -> u64 {
        self.lock().iter().map(wgpu::Buffer::size).sum()
    }

    /// Buffers uploads made because none on the shelf fitted.
    pub fn fresh(&self) -> usize {
        self.fresh.load(Ordering::Relaxed)
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Vec<wgpu::Buffer>> {
        self.free.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// A section buffer of at least `size` bytes and at most a sixteenth more: the smallest
    /// kept one, or a new one of `size` bytes.
    pub(crate) fn take(&self, gpu: &Gpu, label: &str, size: u64) -> wgpu::Buffer {
        let mut free = self.lock();
        let fit = free
            .iter()
            .enumerate()
            .filter(|(_, b)| b.size() >= size && b.size() <= size + size / 16)
            .min_by_key(|(_, b)| b.size())
            .map(|(i, _)| i);
        if let Some(i) = fit {
            return free.swap_remove(i);
        }
        drop(free);
        self.fresh.fetch_add(1, Ordering::Relaxed);
        new_section(gpu, label, size)
    }

    /// Keeps `buffer` (of [`SECTION_USAGE`]; others are dropped) within the limit, dropping
    /// the longest-kept buffers to make room.
    pub(crate) fn put(&self, buffer: wgpu::Buffer) {
        let limit = self.limit.load(Ordering::Relaxed);
        if buffer.usage() != SECTION_USAGE || buffer.size() > limit {
            return;
        }
        let mut free = self.lock();
        free.push(buffer);
        while free.iter().map(wgpu::Buffer::size).sum::<u64>() > limit {
            free.remove(0);
        }
    }
}

/// A new section buffer of `size` bytes.
pub(crate) fn new_section(gpu: &Gpu, label: &str, size: u64) -> wgpu::Buffer {
    gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size,
        usage: SECTION_USAGE,
        mapped_at_creation: false,
    })
}
