//! Device-local buffers kept for reuse: a step's sections (the player's), or a bake's
//! inputs and outputs (the GPU bake's). Creating a buffer is usually a sub-allocation,
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

/// Kept buffers of one usage, up to a number of bytes.
#[derive(Debug, Clone)]
pub struct BufferShelf {
    free: Arc<Mutex<Vec<wgpu::Buffer>>>,
    /// The usage of every buffer it makes and keeps.
    usage: wgpu::BufferUsages,
    /// Whether a new buffer is made a sixteenth larger than asked, so that the next,
    /// slightly larger, request finds it.
    headroom: bool,
    /// The most bytes kept; a buffer that would pass it is dropped when it comes back.
    limit: Arc<AtomicU64>,
    /// Buffers an upload made because none on the shelf fitted.
    fresh: Arc<AtomicUsize>,
}

impl Default for BufferShelf {
    fn default() -> BufferShelf {
        BufferShelf::new()
    }
}

impl BufferShelf {
    /// A shelf of step sections (storage and copy destination, made as large as asked) that
    /// keeps nothing until [`BufferShelf::set_limit`].
    pub fn new() -> BufferShelf {
        BufferShelf::of(SECTION_USAGE, false)
    }

    /// A shelf of buffers of `usage`, each made a sixteenth larger than asked where
    /// `headroom`, that keeps nothing until [`BufferShelf::set_limit`].
    pub fn of(usage: wgpu::BufferUsages, headroom: bool) -> BufferShelf {
        BufferShelf {
            free: Arc::default(),
            usage,
            headroom,
            limit: Arc::default(),
            fresh: Arc::default(),
        }
    }

    /// Keeps at most `bytes`; what is over goes now.
    pub fn set_limit(&self, bytes: u64) {
        self.limit.store(bytes, Ordering::Relaxed);
        let over = trim(&mut self.lock(), bytes);
        // Freed after the lock is let go: other threads take and give buffers meanwhile.
        drop(over);
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

    /// A buffer of at least `size` bytes and at most a sixteenth more (an eighth with
    /// headroom, or what the shelf makes for `size` where that is more): the smallest kept
    /// one, or a new one. Its bytes are what its last user left.
    pub fn take(&self, gpu: &Gpu, label: &str, size: u64) -> wgpu::Buffer {
        let made = self.made_size(gpu, size);
        let most = if self.headroom {
            size + size / 8
        } else {
            size + size / 16
        }
        // A small buffer's rounding can pass the headroom (16 bytes are made 20): the
        // buffer made for a size always serves that size again.
        .max(made);
        let mut free = self.lock();
        let fit = free
            .iter()
            .enumerate()
            .filter(|(_, b)| b.size() >= size && b.size() <= most)
            .min_by_key(|(_, b)| b.size())
            .map(|(i, _)| i);
        if let Some(i) = fit {
            return free.swap_remove(i);
        }
        drop(free);
        self.fresh.fetch_add(1, Ordering::Relaxed);
        create(gpu, label, made, self.usage)
    }

    /// The bytes of a buffer made for `size`: a sixteenth more with headroom, aligned for
    /// copies, but never past what one binding holds (passes bind their buffers whole).
    fn made_size(&self, gpu: &Gpu, size: u64) -> u64 {
        if self.headroom {
            (size + size / 16)
                .min(gpu.max_binding().max(size))
                .next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT)
        } else {
            size
        }
    }

    /// Keeps `buffer` (of the shelf's usage; others are dropped) within the limit, dropping
    /// the longest-kept buffers to make room.
    pub fn put(&self, buffer: wgpu::Buffer) {
        let limit = self.limit.load(Ordering::Relaxed);
        if buffer.usage() != self.usage || buffer.size() > limit {
            return;
        }
        let over = {
            let mut free = self.lock();
            free.push(buffer);
            trim(&mut free, limit)
        };
        drop(over);
    }
}

/// The longest-kept buffers taken off `free` until it holds at most `bytes`.
fn trim(free: &mut Vec<wgpu::Buffer>, bytes: u64) -> Vec<wgpu::Buffer> {
    let mut held: u64 = free.iter().map(wgpu::Buffer::size).sum();
    let mut over = 0;
    while held > bytes {
        held -= free[over].size();
        over += 1;
    }
    free.drain(..over).collect()
}

/// A new section buffer of `size` bytes.
pub(crate) fn new_section(gpu: &Gpu, label: &str, size: u64) -> wgpu::Buffer {
    create(gpu, label, size, SECTION_USAGE)
}

fn create(gpu: &Gpu, label: &str, size: u64, usage: wgpu::BufferUsages) -> wgpu::Buffer {
    gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size,
        usage,
        mapped_at_creation: false,
    })
}
