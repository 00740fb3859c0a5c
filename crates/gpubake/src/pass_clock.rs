//! The passes' GPU time, from timestamps the device writes, read without waiting: each pass's
//! pair of ticks is copied out in the pass's own submission and read once the GPU has run it
//! and a later wait has polled the device. A read that waited for its own 16 bytes after every
//! pass put a round trip through the queue the bake's jobs share behind every pass (some two
//! dozen a step), where the bake itself reads back only what it needs.

use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::{Arc, Mutex};

use slosh_render::Gpu;

/// A pass's start and end timestamps, resolved and copied into a buffer the host maps.
pub(crate) struct Stamps {
    set: wgpu::QuerySet,
    resolved: wgpu::Buffer,
    readable: wgpu::Buffer,
}

impl Stamps {
    fn new(gpu: &Gpu) -> Stamps {
        let buffer = |label, usage| {
            gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: 16,
                usage,
                mapped_at_creation: false,
            })
        };
        Stamps {
            set: gpu.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("bake pass times"),
                ty: wgpu::QueryType::Timestamp,
                count: 2,
            }),
            resolved: buffer(
                "bake pass times",
                wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            ),
            readable: buffer(
                "bake pass times (read)",
                wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            ),
        }
    }

    /// The timestamp writes of a compute pass timed by these stamps.
    pub(crate) fn writes(&self) -> wgpu::ComputePassTimestampWrites<'_> {
        wgpu::ComputePassTimestampWrites {
            query_set: &self.set,
            beginning_of_pass_write_index: Some(0),
            end_of_pass_write_index: Some(1),
        }
    }

    /// Records, after the timed pass, the copy of its ticks to where the host can map them.
    pub(crate) fn resolve(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.resolve_query_set(&self.set, 0..2, &self.resolved, 0);
        encoder.copy_buffer_to_buffer(&self.resolved, 0, &self.readable, 0, 16);
    }
}

/// Where a pending pass's mapping stands: asked for, done (its ticks readable), or failed.
const MAPPING: u8 = 0;
const MAPPED: u8 = 1;
const FAILED: u8 = 2;

/// A submitted pass whose ticks are on their way.
struct Pending {
    pass: &'static str,
    stamps: Stamps,
    submission: wgpu::SubmissionIndex,
    state: Arc<AtomicU8>,
}

/// GPU nanoseconds of every pass timed so far, in all and by the pass's name, and the passes
/// whose ticks have not been read yet.
pub(crate) struct PassClock {
    /// The device's nanoseconds a tick.
    period_ns: f64,
    counted: Mutex<Counted>,
}

#[derive(Default)]
struct Counted {
    total_nanos: u64,
    by_pass: Vec<(&'static str, u64)>,
    pending: Vec<Pending>,
    /// Stamps read and free for another pass.
    free: Vec<Stamps>,
}

/// Stamps kept for reuse, about as many as the jobs sharing a device have in flight.
const FREE_STAMPS_KEPT: usize = 64;

impl std::fmt::Debug for PassClock {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PassClock").finish_non_exhaustive()
    }
}

impl PassClock {
    pub(crate) fn new(gpu: &Gpu) -> PassClock {
        PassClock {
            period_ns: f64::from(gpu.queue.get_timestamp_period()),
            counted: Mutex::default(),
        }
    }

    /// Stamps for a pass about to be recorded, where the device writes timestamps.
    pub(crate) fn stamps(&self, gpu: &Gpu) -> Option<Stamps> {
        if !gpu.timestamps {
            return None;
        }
        let free = self.counted.lock().ok().and_then(|mut c| c.free.pop());
        Some(free.unwrap_or_else(|| Stamps::new(gpu)))
    }

    /// Asks for `stamps`' ticks once `submission`, which recorded the pass `pass` and
    /// [`Stamps::resolve`], has run; counts those of earlier passes that have arrived.
    pub(crate) fn submitted(
        &self,
        pass: &'static str,
        stamps: Stamps,
        submission: wgpu::SubmissionIndex,
    ) {
        let state = Arc::new(AtomicU8::new(MAPPING));
        let told = state.clone();
        stamps
            .readable
            .slice(..)
            .map_async(wgpu::MapMode::Read, move |r| {
                told.store(if r.is_ok() { MAPPED } else { FAILED }, Ordering::Release);
            });
        if let Ok(mut c) = self.counted.lock() {
            c.pending.push(Pending {
                pass,
                stamps,
                submission,
                state,
            });
            c.count_arrived(self.period_ns);
        }
    }

    /// Waits for every pass submitted so far to have run, and counts their ticks: what is read
    /// before and after a bake for that bake's GPU time.
    pub(crate) fn settle(&self, gpu: &Gpu) {
        let Ok(mut c) = self.counted.lock() else {
            return;
        };
        for p in &c.pending {
            // A wait that fails (a lost device) leaves those passes uncounted.
            let _ = gpu.wait_for(p.submission.clone());
        }
        c.count_arrived(self.period_ns);
    }

    /// GPU seconds of every pass counted so far.
    pub(crate) fn seconds(&self) -> f64 {
        self.counted
            .lock()
            .map_or(0.0, |c| c.total_nanos as f64 * 1e-9)
    }

    /// [`PassClock::seconds`] by pass, in the order the passes were first counted.
    pub(crate) fn seconds_by_pass(&self) -> Vec<(&'static str, f64)> {
        self.counted.lock().map_or(Vec::new(), |c| {
            c.by_pass
                .iter()
                .map(|&(pass, ns)| (pass, ns as f64 * 1e-9))
                .collect()
        })
    }
}

impl Counted {
    /// Counts the ticks of every pending pass whose mapping has completed.
    fn count_arrived(&mut self, period_ns: f64) {
        let mut k = 0;
        while k < self.pending.len() {
            match self.pending[k].state.load(Ordering::Acquire) {
                MAPPING => k += 1,
                state => {
                    let p = self.pending.swap_remove(k);
                    if state != MAPPED {
                        continue;
                    }
                    let ticks: Option<[u64; 2]> = p
                        .stamps
                        .readable
                        .slice(..)
                        .get_mapped_range()
                        .ok()
                        .map(|view| bytemuck::pod_read_unaligned(&view[..16]));
                    p.stamps.readable.unmap();
                    // Ticks that cannot be read leave the pass uncounted.
                    if let Some([start, end]) = ticks {
                        let nanos = (end.saturating_sub(start) as f64 * period_ns).round() as u64;
                        self.total_nanos += nanos;
                        match self.by_pass.iter_mut().find(|(q, _)| *q == p.pass) {
                            Some((_, total)) => *total += nanos,
                            None => self.by_pass.push((p.pass, nanos)),
                        }
                        if self.free.len() < FREE_STAMPS_KEPT {
                            self.free.push(p.stamps);
                        }
                    }
                }
            }
        }
    }
}
