//! Staging memory reused across uploads. Fresh host-visible memory costs a page fault per
//! page on first touch, which made the copy into a new 160 MB staging buffer several times
//! slower than the memory allows; a recycled buffer is already faulted in. A buffer goes back
//! to the pool once the GPU has finished reading it: `recycle` maps it again, and wgpu
//! completes that map only after the submitted copies, during a later device poll. The
//! first upload of a pool fills it on a thread of its own (`warm`), so that the first
//! uploads after a series opens do not each fault in a buffer of their own; the warm-up
//! stops once the pool is dropped, for the process waits for it at exit.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex, PoisonError, Weak};
use std::time::Duration;

use crate::context::Gpu;

/// Staging buffers are made in multiples of this, so that steps of similar sizes share them.
const STAGING_GRANULE: u64 = 16 << 20;

/// Buffers kept for reuse, up to a number and a total size: what [`StagingPool`] and
/// [`crate::ReadbackPool`] hold.
#[derive(Debug, Clone)]
pub(crate) struct Shelf {
    free: Arc<Mutex<Vec<wgpu::Buffer>>>,
    /// The most buffers kept; more are dropped when they come back.
    keep: usize,
    /// The most kept for now, at most `keep` ([`Shelf::keep_at_most`]).
    keep_now: Arc<AtomicUsize>,
    /// The most bytes the kept buffers hold together.
    keep_bytes: u64,
}

impl Shelf {
    pub(crate) fn new(keep: usize) -> Shelf {
        Shelf {
            free: Arc::new(Mutex::new(Vec::new())),
            keep,
            keep_now: Arc::new(AtomicUsize::new(keep)),
            keep_bytes: u64::MAX,
        }
    }

    /// Keeps at most `buffers` (never more than it was made to keep) from now on; the
    /// longest-kept of those over go now, freed after the lock is let go.
    pub(crate) fn keep_at_most(&self, buffers: usize) {
        let buffers = buffers.min(self.keep);
        self.keep_now.store(buffers, Ordering::Relaxed);
        let over: Vec<wgpu::Buffer> = {
            let mut free = self.free.lock().unwrap_or_else(PoisonError::into_inner);
            let over = free.len().saturating_sub(buffers);
            free.drain(..over).collect()
        };
        drop(over);
    }

    /// The same shelf, keeping no more than `bytes` in all.
    pub(crate) fn within(self, bytes: u64) -> Shelf {
        Shelf {
            keep_bytes: bytes,
            ..self
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

    /// The shelf without its buffers kept alive: [`WeakShelf::upgrade`] gives it back while
    /// an owner holds it.
    fn downgrade(&self) -> WeakShelf {
        WeakShelf {
            free: Arc::downgrade(&self.free),
            keep: self.keep,
            keep_now: self.keep_now.clone(),
            keep_bytes: self.keep_bytes,
        }
    }

    /// Keeps `buffer` unless the shelf is full, by count or by bytes; else it is freed after
    /// the lock is let go.
    pub(crate) fn put(&self, buffer: wgpu::Buffer) {
        let mut free = self.free.lock().unwrap_or_else(PoisonError::into_inner);
        let held: u64 = free.iter().map(wgpu::Buffer::size).sum();
        let keep = self.keep.min(self.keep_now.load(Ordering::Relaxed));
        if free.len() < keep && held.saturating_add(buffer.size()) <= self.keep_bytes {
            free.push(buffer);
        } else {
            drop(free);
            drop(buffer);
        }
    }
}

/// A [`Shelf`] that does not keep its buffers alive: what a warm-up holds.
struct WeakShelf {
    free: Weak<Mutex<Vec<wgpu::Buffer>>>,
    keep: usize,
    keep_now: Arc<AtomicUsize>,
    keep_bytes: u64,
}

impl WeakShelf {
    fn upgrade(&self) -> Option<Shelf> {
        Some(Shelf {
            free: self.free.upgrade()?,
            keep: self.keep,
            keep_now: self.keep_now.clone(),
            keep_bytes: self.keep_bytes,
        })
    }
}

/// What a pool's warm-up did: the buffers it made, once it has ended.
#[derive(Debug, Default)]
pub struct WarmUp {
    made: AtomicUsize,
    ended: Mutex<bool>,
    ended_signal: Condvar,
}

impl WarmUp {
    fn end(&self) {
        *self.ended.lock().unwrap_or_else(PoisonError::into_inner) = true;
        self.ended_signal.notify_all();
    }

    /// The buffers the warm-up made, once it has ended (or never started), or `None` where it
    /// is still running after `timeout`.
    pub fn wait(&self, timeout: Duration) -> Option<usize> {
        let ended = self.ended.lock().unwrap_or_else(PoisonError::into_inner);
        let (ended, _) = self
            .ended_signal
            .wait_timeout_while(ended, timeout, |ended| !*ended)
            .unwrap_or_else(PoisonError::into_inner);
        (*ended).then(|| self.made.load(Ordering::Relaxed))
    }
}

/// Mapped staging buffers ready for the next upload.
#[derive(Debug, Clone)]
pub struct StagingPool {
    shelf: Shelf,
    /// Buffers an upload had to make because none was ready.
    fresh: Arc<AtomicUsize>,
    /// Whether the pool was filled once (see [`StagingPool::take`]).
    warmed: Arc<AtomicBool>,
    /// The most buffers the warm-up makes ([`StagingPool::warm_at_most`]).
    warm_limit: Arc<AtomicUsize>,
    warm_up: Arc<WarmUp>,
}

impl StagingPool {
    pub fn new(keep: usize) -> StagingPool {
        StagingPool {
            shelf: Shelf::new(keep),
            fresh: Arc::new(AtomicUsize::new(0)),
            warmed: Arc::new(AtomicBool::new(false)),
            warm_limit: Arc::new(AtomicUsize::new(usize::MAX)),
            warm_up: Arc::default(),
        }
    }

    /// Has the warm-up make at most `buffers`, the caller's own first included: as many as
    /// the uploads in flight together, where they are few. It runs once, at the first upload,
    /// so a limit set after that changes nothing. Where the device has memory that
    /// the host can write (a large BAR), staging buffers live in the device's memory, and a
    /// warm-up sized for many jobs filled gigabytes of it for a bake of one step at a time.
    pub fn warm_at_most(&self, buffers: usize) {
        self.warm_limit.store(buffers, Ordering::Relaxed);
    }

    /// Keeps at most `buffers` ready from now on (never more than it was made to keep);
    /// those over go now.
    pub fn keep_at_most(&self, buffers: usize) {
        self.shelf.keep_at_most(buffers);
    }

    /// The same pool, keeping no more than `bytes` of buffers in all.
    pub fn within(self, bytes: u64) -> StagingPool {
        StagingPool {
            shelf: self.shelf.within(bytes),
            ..self
        }
    }

    /// Buffers uploads had to make because none was ready (the warm-up's excluded).
    pub fn fresh(&self) -> usize {
        self.fresh.load(Ordering::Relaxed)
    }

    /// Buffers ready now.
    pub fn ready(&self) -> usize {
        self.shelf.len()
    }

    /// What the warm-up (started by the first upload) did, to be watched after the pool is
    /// gone.
    pub fn warm_up(&self) -> Arc<WarmUp> {
        self.warm_up.clone()
    }

    /// A mapped `MAP_WRITE | COPY_SRC` buffer of at least `size` bytes: the smallest ready
    /// one that fits, or a new one. The first call also fills the pool on a thread of its
    /// own, with buffers an eighth larger than `size` (a series' steps are of about one
    /// size), their pages written once so that they are faulted in.
    pub(crate) fn take(&self, gpu: &Gpu, size: u64) -> wgpu::Buffer {
        if !self.warmed.swap(true, Ordering::Relaxed) {
            self.warm(gpu, size + size / 8);
        }
        if let Some(buffer) = self.shelf.take(size) {
            return buffer;
        }
        self.fresh.fetch_add(1, Ordering::Relaxed);
        new_staging(&gpu.device, size)
    }

    /// Fills the shelf, but for the buffer the caller is about to make, with buffers of
    /// `size` on a thread of its own, until it is full or the pool is dropped: the process
    /// waits for the thread at exit, and a bake of one step ended long before its pool's
    /// warm-up (a 1,000-point bake on lavapipe waited 0.6 s for it).
    fn warm(&self, gpu: &Gpu, size: u64) {
        let (device, shelf) = (gpu.device.clone(), self.shelf.downgrade());
        let fit = self.shelf.keep_bytes / staging_size(size);
        let count = self
            .shelf
            .keep
            .min(usize::try_from(fit).unwrap_or(usize::MAX))
            .min(self.warm_limit.load(Ordering::Relaxed));
        let count = count.saturating_sub(1);
        let watch = self.warm_up.clone();
        let spawned = crate::background::spawn("staging warm-up".into(), move || {
            for _ in 0..count {
                let Some(shelf) = shelf.upgrade() else { break };
                let buffer = new_staging(&device, size);
                // A view that cannot be had leaves the buffer unfaulted, not unusable.
                if let Ok(mut view) = buffer.slice(..).get_mapped_range_mut() {
                    view.slice(..).fill(0);
                }
                shelf.put(buffer);
                watch.made.fetch_add(1, Ordering::Relaxed);
            }
            watch.end();
        });
        // Without a thread the pool fills as uploads go, as it did before.
        if spawned.is_err() {
            self.warm_up.end();
        }
    }

    /// `bytes` copied into the start of `target` (a `COPY_DST` buffer) through a staging
    /// buffer of the pool, submitted: work submitted after reads them. The staging buffer
    /// comes back to the pool once the copy is done.
    pub fn upload(
        &self,
        gpu: &Gpu,
        bytes: &[u8],
        target: &wgpu::Buffer,
    ) -> Result<wgpu::SubmissionIndex, crate::Error> {
        let size = (bytes.len() as u64).next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT);
        let staging = self.take(gpu, size);
        {
            use rayon::prelude::*;
            // Copied by every thread, a mapped piece each: one thread's copy of a step's
            // positions (tens of megabytes) took milliseconds of every bake's step.
            let views = bytes
                .chunks(UPLOAD_PIECE)
                .enumerate()
                .map(|(k, piece)| {
                    let at = (k * UPLOAD_PIECE) as u64;
                    let end = at + (piece.len() as u64).next_multiple_of(4);
                    staging
                        .slice(at..end)
                        .get_mapped_range_mut()
                        .map_err(|e| crate::Error::Readback(e.to_string()))
                })
                .collect::<Result<Vec<_>, _>>()?;
            views
                .into_par_iter()
                .zip(bytes.par_chunks(UPLOAD_PIECE))
                .for_each(|(mut to, from)| to.slice(..from.len()).copy_from_slice(from));
        }
        staging.unmap();
        let mut encoder = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("upload"),
            });
        encoder.copy_buffer_to_buffer(&staging, 0, target, 0, size);
        let submitted = gpu.queue.submit([encoder.finish()]);
        self.recycle(staging);
        Ok(submitted)
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

/// Bytes of an upload each thread copies at a time.
const UPLOAD_PIECE: usize = 1 << 20;

/// The size of a staging buffer made for `size` bytes: whole granules.
fn staging_size(size: u64) -> u64 {
    size.max(1).next_multiple_of(STAGING_GRANULE)
}

/// A mapped `MAP_WRITE | COPY_SRC` buffer of at least `size` bytes, in whole granules.
fn new_staging(device: &wgpu::Device, size: u64) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("staging (pooled)"),
        size: staging_size(size),
        usage: wgpu::BufferUsages::MAP_WRITE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: true,
    })
}
