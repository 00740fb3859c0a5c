//! The streaming engine: a cache series on a timeline, steps prepared ahead by loader threads
//! (host half and GPU half both off the frame thread), a GPU-resident pool under a byte
//! budget, and frames recorded into the caller's encoder with progressive refinement. It
//! holds no widget state: an app or a benchmark drives it one frame at a time.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;
use std::sync::{Arc, Mutex, PoisonError};

use slosh_mls::Camera;
use slosh_render::{
    BufferShelf, FrameTargets, Gpu, GpuStep, HostField, MaskProgress, RowSet, StagingPool,
    TraceParams, Tracer,
};

mod gpu_source;
mod probe;
mod wait;

pub use gpu_source::{GpuSource, Prepared};
pub use probe::Probe;
pub use wait::Pace;

use crate::error::{Error, Result};
use crate::frame_budget::FrameBudget;
use crate::pool::{Admission, StepPool};
use crate::prefetch::Prefetcher;
use crate::refine::{Draw, Pacing, Progress, Refinement, ViewKey};
use crate::series::Series;
use crate::timeline::{Direction, Looping, Timeline};

/// The span over which the rate of motion is measured.
const RATE_WINDOW_SECONDS: f64 = 0.5;
/// Steps one frame may count towards that rate (a jump is not motion).
const MAX_STEPS_PER_FRAME: f64 = 4.0;
/// Steps in flight beyond the loaders' own, one each: the staging buffers kept, and the
/// steps' worth of section buffers kept beyond the budget for the uploads that replace the
/// steps dropped from the pool. Every loader may be uploading a step before any step leaves
/// the pool: with two steps' worth kept, 6 loaders on the H100 host created 268 section
/// buffers during 100 page-cache jumps through a 100k-point series, and 521 at 1M.
const SPARE_STEPS: usize = 2;

/// Buffers the engine's uploads had to create (none being kept that fitted), since it
/// opened.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FreshBuffers {
    /// Staging buffers (host-visible), the warm-up's excluded.
    pub staging: usize,
    /// Device-local section buffers.
    pub sections: usize,
}

/// How the engine streams.
#[derive(Debug, Clone, PartialEq)]
pub struct EngineOptions {
    /// Bytes of GPU memory the resident steps may hold; `None`: [`default_budget`].
    pub budget: Option<u64>,
    /// Loader threads.
    pub loaders: usize,
    /// Seconds of playback or scrubbing to keep loaded ahead, at the rate seen.
    pub lookahead_seconds: f64,
    /// Fewest and most steps requested ahead of the current one.
    pub min_ahead: usize,
    pub max_ahead: usize,
    /// The field to colour by, if any.
    pub field: Option<String>,
    /// A pause before every load: an instrumented slow source, for tests of a frame loop
    /// that must not wait on loads.
    pub load_delay: Option<std::time::Duration>,
}

impl Default for EngineOptions {
    fn default() -> EngineOptions {
        EngineOptions {
            budget: None,
            loaders: default_loaders(),
            lookahead_seconds: 0.5,
            min_ahead: 4,
            max_ahead: 64,
            field: None,
            load_delay: None,
        }
    }
}

/// Loader threads by default: three eighths of the cores, 2 to 6 (each load decodes and
/// copies on rayon's threads too). On the H200 host's 16 cores, cache format 6, 4 and 6
/// loaders alternated in one call: 1M-point steps streamed at 94.8, 90.4, 93.7 steps/s with
/// 4 and 99.9, 99.1, 104.8 with 6; 8 gave 120.9 beside 6's 124.1 in another
/// (`docs/results-scrub.md`).
pub fn default_loaders() -> usize {
    std::thread::available_parallelism().map_or(2, |n| (n.get() * 3 / 8).clamp(2, 6))
}

/// The default budget: half the adapter's device-local memory where it can be read (the
/// rest for the frame, other apps and the driver), else 2 GiB.
pub fn default_budget(gpu: &Gpu) -> u64 {
    gpu.device_memory().map_or(2 << 30, |bytes| bytes / 2)
}

/// What a frame asks for.
#[derive(Debug, Clone)]
pub struct FrameRequest {
    /// Seconds since the last frame (drives playback).
    pub seconds: f64,
    pub camera: Camera,
    /// `iterations` is the refinement target once still.
    pub params: TraceParams,
    /// Whether the camera is being moved (refinement restarts at one iteration).
    pub camera_moving: bool,
    /// Milliseconds a frame may take on the GPU: a moving view is drawn smaller and a refined
    /// frame in bands of rows, one per call, as the frames measured so far say fits
    /// ([`Engine::finish_frame`] measures them). `None`: every frame whole at full size.
    pub frame_budget_ms: Option<f64>,
}

/// What a frame recorded, to be measured once it ran.
#[derive(Debug, Clone, Copy)]
enum Recorded {
    /// A frame or a set of its rows: its iterations and pixels, and whether it went into
    /// the preview targets.
    Trace {
        iterations: u32,
        pixels: u64,
        preview: bool,
    },
    /// A part of a step's neighbour masks, in clusters.
    Masks { clusters: u32 },
}

/// The quality of the picture on screen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Quality {
    /// Its size per axis against the full size.
    pub scale: f32,
    pub iterations: u32,
}

/// What a frame did.
#[derive(Debug, Default)]
pub struct FrameReport {
    /// The series position asked for.
    pub wanted: usize,
    /// The position drawn (or still on screen): the one asked for, or the nearest resident
    /// stand-in; `None` until any step is resident.
    pub shown: Option<usize>,
    pub stand_in: bool,
    /// Iterations drawn this frame; `None` when the targets already hold this view.
    pub drawn: Option<u32>,
    /// What was drawn this frame: a whole frame, a preview or a band of rows.
    pub draw: Option<Draw>,
    /// The quality of the picture on screen after this frame.
    pub quality: Option<Quality>,
    /// Neighbour masks derived this frame ahead of a refined one, under a frame budget.
    pub masks: Option<MaskProgress>,
    pub progress: Option<Progress>,
    /// Steps made resident this frame, with the ms of their upload's halves.
    pub uploaded: Vec<Uploaded>,
    /// Steps that failed this frame, by position, with why.
    pub failures: Vec<(usize, String)>,
}

/// A step made resident: its position, the ms of its host half (open, checks, decoding) and
/// of its record half (buffers filled, copies recorded), both run by a loader.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Uploaded {
    pub position: usize,
    pub host_ms: f64,
    pub record_ms: f64,
}

/// The streaming engine over one cache directory.
#[derive(Debug)]
pub struct Engine {
    gpu: Arc<Gpu>,
    tracer: Tracer,
    series: Series,
    source: Arc<GpuSource>,
    timeline: Timeline,
    pool: StepPool<GpuStep>,
    prefetch: Prefetcher<Prepared>,
    targets: Option<FrameTargets>,
    /// The smaller targets a moving view is drawn into under a frame budget.
    preview_targets: Option<FrameTargets>,
    /// The picture on screen is the preview's (else the full targets').
    showing_preview: bool,
    quality: Option<Quality>,
    refinement: Refinement,
    /// The frame budget and what frames have cost, once a request asked for one.
    frame_budget: Option<FrameBudget>,
    /// What the last frame recorded, and when it handed the encoder back, for
    /// [`Engine::finish_frame`].
    unmeasured: Option<(Recorded, std::time::Instant)>,
    options: EngineOptions,
    /// Failed steps by bake index, with why.
    failed: BTreeMap<usize, String>,
    /// Failures found outside a frame (a file removed or unreadable), by bake index, for the
    /// next frame's report.
    unreported: Vec<(usize, String)>,
    /// The field each resident step holds, by bake index.
    step_fields: HashMap<usize, Option<String>>,
    field: Option<String>,
    revision: u64,
    /// Steps moved in the recent frames, with the engine clock at each (seconds), for the
    /// rate the position moves at.
    moves: std::collections::VecDeque<(f64, f64)>,
    /// Seconds of frames handed to the engine so far.
    clock: f64,
    last_position: usize,
    scrub_direction: Direction,
    /// The positions the last frame asked for.
    last_window: Vec<usize>,
    /// A position jumped to (outside the last window) and not yet resident: it alone is
    /// loaded, and loads in flight for other steps are withdrawn, until it arrives.
    urgent: Option<usize>,
    /// The bake index drawn last.
    shown: Option<usize>,
    /// Mean bytes of a resident step, for how many fit.
    step_bytes: u64,
    /// The shown step's surface, once a pixel of it was probed.
    probed: Option<probe::HeldProbe>,
    /// What a probe of a step not yet probed asked for, being prepared.
    probing: Option<probe::PreparingProbe>,
    /// Traced frames recorded so far: a hit read back belongs to the frame it came from.
    frames_recorded: u64,
    /// The hit a probe asked for, being read back, and the last one read.
    hit: probe::HitReadback,
    /// The GPU time [`Engine::finish_frame`] measured of the last frame.
    last_gpu_ms: Option<f64>,
}

impl Engine {
    /// An engine over the cache directory `dir`, on `gpu` (made here or from a device
    /// someone else created, [`Gpu::from_parts`]).
    pub fn open(gpu: Arc<Gpu>, dir: &Path, options: EngineOptions) -> Result<Engine> {
        Engine::over(gpu, Series::open(dir)?, None, options)
    }

    /// An engine over a raw case's steps, each baked into `bake`'s directory by the loader
    /// that first needs it (the next run finds it baked); a step that fails to bake is a
    /// failed step like any other.
    pub fn open_baking(
        gpu: Arc<Gpu>,
        bake: Arc<slosh_bake::OnDemand>,
        options: EngineOptions,
    ) -> Result<Engine> {
        let series = Series::planned(bake.dir(), bake.steps(), bake.key().clone())?;
        Engine::over(gpu, series, Some(bake), options)
    }

    fn over(
        gpu: Arc<Gpu>,
        series: Series,
        bake: Option<Arc<slosh_bake::OnDemand>>,
        mut options: EngineOptions,
    ) -> Result<Engine> {
        if bake.is_some() {
            // A step baked as it is needed takes hundreds of milliseconds, not the few of a
            // load: every loader bakes a step of the window ahead at once, where a window of
            // the rate's half second held four (a 1M-point case played at 4.5 steps/s with
            // most loaders idle).
            options.min_ahead = options.min_ahead.max(options.loaders);
        }
        let tracer = Tracer::new(&gpu)?;
        let budget = options.budget.unwrap_or_else(|| default_budget(&gpu));
        let source = Arc::new(GpuSource {
            gpu: gpu.clone(),
            belongs: Mutex::new((None, None)),
            staging: StagingPool::new(options.loaders + SPARE_STEPS),
            shelf: BufferShelf::new(),
            delay: options.load_delay,
            paths: Mutex::new(HashMap::new()),
            field: Mutex::new(options.field.clone()),
            bake,
        });
        let prefetch = Prefetcher::new(source.clone(), options.loaders);
        let mut engine = Engine {
            gpu,
            tracer,
            timeline: Timeline::new(Vec::new()),
            series,
            source,
            pool: StepPool::new(budget),
            prefetch,
            targets: None,
            preview_targets: None,
            showing_preview: false,
            quality: None,
            refinement: Refinement::default(),
            frame_budget: None,
            unmeasured: None,
            field: options.field.clone(),
            options,
            failed: BTreeMap::new(),
            unreported: Vec::new(),
            step_fields: HashMap::new(),
            revision: 0,
            moves: std::collections::VecDeque::new(),
            clock: 0.0,
            last_position: 0,
            scrub_direction: Direction::Forward,
            last_window: Vec::new(),
            urgent: None,
            shown: None,
            step_bytes: 0,
            probed: None,
            probing: None,
            frames_recorded: 0,
            hit: probe::HitReadback::default(),
            last_gpu_ms: None,
        };
        engine.adopt_series();
        Ok(engine)
    }

    fn adopt_series(&mut self) {
        let current = self.bake_index(self.timeline.current());
        let mut paths = self
            .source
            .paths
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        paths.clear();
        paths.extend(
            self.series
                .steps()
                .iter()
                .map(|s| (s.index, s.path.clone())),
        );
        drop(paths);
        *self
            .source
            .belongs
            .lock()
            .unwrap_or_else(PoisonError::into_inner) =
            (self.series.manifest().cloned(), self.series.key().cloned());
        // Steps whose files are gone or unreadable are failed steps, said like any other.
        let problems: Vec<(usize, String)> = self
            .series
            .problems()
            .map(|(i, why)| (i, why.to_string()))
            .collect();
        for (index, why) in problems {
            self.pool.remove(index);
            self.step_fields.remove(&index);
            if self.failed.get(&index) != Some(&why) {
                self.unreported.push((index, why.clone()));
            }
            self.failed.insert(index, why);
        }
        self.timeline.set_times(self.series.times());
        // The step shown stays shown where the series grew before it.
        if let Some(index) = current
            && let Some(position) = self.position(index)
        {
            self.timeline.set_current(position);
        }
        self.last_position = self.timeline.current();
    }

    /// Looks again at the series' directory: steps a running bake added, files copied over,
    /// restored or removed, a manifest written. Returns whether anything changed. What was
    /// loaded from or concluded about a changed file is dropped, so it loads again.
    pub fn refresh_series(&mut self) -> Result<bool> {
        let change = self.series.refresh()?;
        for index in &change.changed {
            self.pool.remove(*index);
            self.step_fields.remove(index);
            self.failed.remove(index);
        }
        if change.manifest {
            // Steps failed against the old manifest (or none) are judged again.
            self.failed.clear();
        }
        if change.any() {
            self.adopt_series();
        }
        Ok(change.any())
    }

    pub fn gpu(&self) -> &Arc<Gpu> {
        &self.gpu
    }

    pub fn tracer(&self) -> &Tracer {
        &self.tracer
    }

    pub fn series(&self) -> &Series {
        &self.series
    }

    pub fn timeline(&self) -> &Timeline {
        &self.timeline
    }

    /// The timeline, for a widget or key handler to move.
    pub fn timeline_mut(&mut self) -> &mut Timeline {
        &mut self.timeline
    }

    pub fn budget(&self) -> u64 {
        self.pool.budget()
    }

    pub fn used_bytes(&self) -> u64 {
        self.pool.used()
    }

    /// Buffers the uploads had to create so far.
    pub fn fresh_buffers(&self) -> FreshBuffers {
        FreshBuffers {
            staging: self.source.staging.fresh(),
            sections: self.source.shelf.fresh(),
        }
    }

    /// Bytes of section buffers kept for the next uploads, beyond the budget.
    pub fn shelved_bytes(&self) -> u64 {
        self.source.shelf.bytes()
    }

    /// Series positions resident on the GPU.
    pub fn resident(&self) -> Vec<usize> {
        let mut v: Vec<usize> = self
            .pool
            .indices()
            .filter_map(|i| self.position(i))
            .collect();
        v.sort_unstable();
        v
    }

    /// Series positions whose step is baked, in a raw case's series (every one of a cache
    /// directory's is); as of the last look at the directory.
    pub fn baked(&self) -> Vec<usize> {
        let steps = self.series.steps();
        (0..steps.len())
            .filter(|&p| !self.series.is_planned() || steps[p].stamp.is_some())
            .collect()
    }

    /// Series positions being loaded or queued.
    pub fn prefetching(&self) -> Vec<usize> {
        let mut v: Vec<usize> = self
            .prefetch
            .in_flight()
            .into_iter()
            .chain(self.prefetch.queued())
            .filter_map(|i| self.position(i))
            .collect();
        v.sort_unstable();
        v
    }

    /// Failed steps by series position, with why.
    pub fn failures(&self) -> Vec<(usize, String)> {
        self.failed
            .iter()
            .filter_map(|(i, why)| self.position(*i).map(|p| (p, why.clone())))
            .collect()
    }

    pub fn field(&self) -> Option<&str> {
        self.field.as_deref()
    }

    /// The frame targets whose texture holds the picture on screen: the full-size ones, or a
    /// moving view's preview under a frame budget.
    pub fn targets(&self) -> Option<&FrameTargets> {
        if self.showing_preview {
            self.preview_targets.as_ref()
        } else {
            self.targets.as_ref()
        }
    }

    /// Waits for the frame last recorded and submitted, and takes its GPU time (timestamp
    /// queries where the adapter has them, else from its recording to the end of the wait) into
    /// the frame budget. Returns that time in ms where a frame was recorded.
    pub fn finish_frame(&mut self) -> Result<Option<f64>> {
        let Some((recorded, start)) = self.unmeasured.take() else {
            return Ok(None);
        };
        let targets = match recorded {
            Recorded::Trace { preview: true, .. } => self.preview_targets.as_ref(),
            Recorded::Trace { preview: false, .. } => self.targets.as_ref(),
            // The mask pass has no timestamps: its time is from the end of the recording to
            // the end of the wait (a software adapter may run the work inside the submit).
            Recorded::Masks { .. } => None,
        };
        let stamped = match targets {
            Some(t) => self.tracer.pass_times(&self.gpu, t)?,
            None => None,
        };
        self.gpu.wait()?;
        let ms = stamped.map_or(start.elapsed().as_secs_f64() * 1e3, |t| {
            t.trace_ms + t.shade_ms
        });
        self.last_gpu_ms = Some(ms);
        if let Some(budget) = &mut self.frame_budget {
            match recorded {
                Recorded::Trace {
                    iterations, pixels, ..
                } => budget.record(iterations, pixels, ms),
                Recorded::Masks { clusters } => budget.record_masks(clusters, ms),
            }
        }
        Ok(Some(ms))
    }

    /// The step drawn last, if any (series position, and the step itself).
    pub fn shown_step(&self) -> Option<(usize, &GpuStep)> {
        let index = self.shown?;
        let position = self.position(index)?;
        // Looked up without marking it used: reading is not displaying.
        self.pool.peek(index).map(|s| (position, s))
    }

    /// Colours by `field` from now on: loaders load it, resident steps switch when shown.
    pub fn set_field(&mut self, field: Option<String>) {
        if field == self.field {
            return;
        }
        self.field = field.clone();
        *self
            .source
            .field
            .lock()
            .unwrap_or_else(PoisonError::into_inner) = field;
        self.revision += 1;
    }

    /// The bake index (the step's number everywhere: file names, `slosh render --step`) of
    /// the step at timeline position `position`.
    pub fn bake_index(&self, position: usize) -> Option<usize> {
        self.series.steps().get(position).map(|s| s.index)
    }

    /// The timeline position of the step with bake index `index`.
    pub fn position(&self, index: usize) -> Option<usize> {
        self.series
            .steps()
            .binary_search_by_key(&index, |s| s.index)
            .ok()
    }

    /// Steps per second the position has moved at over the last `RATE_WINDOW_SECONDS`.
    fn rate(&self) -> f64 {
        let steps: f64 = self.moves.iter().map(|(_, m)| m).sum();
        let span = self
            .moves
            .front()
            .map_or(0.0, |(t, _)| self.clock - t)
            .max(RATE_WINDOW_SECONDS / 4.0);
        steps / span
    }

    /// Positions to have resident, most urgent first: the current one, then ahead in the
    /// direction of motion (as many as the rate and the budget allow), then one behind.
    fn window(&self) -> Vec<usize> {
        let len = self.timeline.len();
        if len == 0 {
            return Vec::new();
        }
        let current = self.timeline.current();
        let direction = if self.timeline.is_playing() {
            self.timeline.direction()
        } else {
            self.scrub_direction
        };
        let rate = if self.timeline.is_playing() {
            self.timeline.speed().max(self.rate())
        } else {
            self.rate()
        };
        let mut ahead = ((rate * self.options.lookahead_seconds).ceil() as usize)
            .clamp(self.options.min_ahead, self.options.max_ahead.max(1));
        if let Some(fit) = self.pool.budget().checked_div(self.step_bytes) {
            ahead = ahead.min((fit as usize).saturating_sub(2));
        }
        let wraps = self.timeline.is_playing() && self.timeline.looping() != Looping::Off;
        let (first, last) = self.timeline.bounds();
        let mut out = vec![current];
        let mut at = current as i64;
        for _ in 0..ahead {
            at += direction.sign();
            if at < first as i64 || at > last as i64 {
                if !wraps {
                    break;
                }
                at = if at < first as i64 { last } else { first } as i64;
            }
            out.push(at as usize);
        }
        let behind = current as i64 - direction.sign();
        if (0..len as i64).contains(&behind) {
            out.push(behind as usize);
        }
        out.dedup();
        out
    }

    /// Prepared steps that arrived, made resident (window steps may evict, background fill
    /// only takes free room).
    fn admit(&mut self, window: &[usize], report: &mut FrameReport) {
        let keep = self.shown;
        let mut commands = Vec::new();
        let mut staging = Vec::new();
        for loaded in self.prefetch.poll() {
            let Some(position) = self.position(loaded.index) else {
                continue;
            };
            match loaded.result {
                Err(why) => {
                    report.failures.push((position, why.clone()));
                    self.failed.insert(loaded.index, why);
                }
                Ok(mut prepared) => {
                    staging.extend(prepared.step.take_staging());
                    let bytes = prepared.step.gpu_bytes();
                    let urgent = window.contains(&position);
                    let free = self.pool.used() + bytes <= self.pool.budget();
                    if !urgent && !free {
                        continue;
                    }
                    let upload = prepared.step.upload;
                    if bytes > self.pool.budget() {
                        // It would never fit: said once, not loaded again and again.
                        let why = format!(
                            "step {} needs {:.1} MB of GPU memory, more than the whole budget \
                             of {:.1} MB (--budget sets it)",
                            loaded.index,
                            bytes as f64 / 1e6,
                            self.pool.budget() as f64 / 1e6
                        );
                        report.failures.push((position, why.clone()));
                        self.failed.insert(loaded.index, why);
                        continue;
                    }
                    self.failed.remove(&loaded.index);
                    // The step asked for may take the shown one's room when only one fits.
                    let keep = if position == self.timeline.current()
                        && !self.pool.could_hold(bytes, keep)
                    {
                        None
                    } else {
                        keep
                    };
                    if let Admission::Stored { evicted } =
                        self.pool.insert(loaded.index, prepared.step, keep)
                    {
                        for gone in evicted {
                            self.step_fields.remove(&gone);
                        }
                        self.step_fields.insert(loaded.index, prepared.field);
                        commands.push(prepared.commands);
                        report.uploaded.push(Uploaded {
                            position,
                            host_ms: upload.host_seconds * 1e3,
                            record_ms: upload.record_seconds * 1e3,
                        });
                        let n = self.pool.len() as u64;
                        self.step_bytes = (self.step_bytes * (n - 1) + bytes) / n.max(1);
                        // Room for the buffers of the steps the next uploads replace.
                        let shelved = (self.options.loaders + SPARE_STEPS) as u64;
                        self.source.shelf.set_limit(shelved * self.step_bytes);
                    }
                }
            }
        }
        if !commands.is_empty() {
            self.gpu.queue.submit(commands);
        }
        // After the submission: their copies are done before the buffers map again.
        for buffer in staging {
            self.source.staging.recycle(buffer);
        }
    }

    /// Asks the loaders for the window's missing steps, then, while the pool has room, the
    /// rest of the series nearest first (a series that fits ends up wholly resident).
    fn request(&mut self, window: &[usize]) {
        let missing = |p: &usize| {
            self.bake_index(*p)
                .is_some_and(|i| !self.pool.contains(i) && !self.failed.contains_key(&i))
        };
        let mut wanted: Vec<usize> = window.iter().copied().filter(missing).collect();
        if wanted.is_empty() && self.step_bytes > 0 {
            let room = self.pool.budget().saturating_sub(self.pool.used()) / self.step_bytes;
            let room = (room as usize).min(self.options.loaders * 2);
            if room > 0 {
                let current = self.timeline.current();
                let mut rest: Vec<usize> = (0..self.timeline.len()).filter(missing).collect();
                rest.sort_by_key(|&p| p.abs_diff(current));
                wanted.extend(rest.into_iter().take(room));
            }
        }
        let indices: Vec<usize> = wanted
            .into_iter()
            .filter_map(|p| self.bake_index(p))
            .collect();
        self.prefetch.request(indices);
    }

    /// Plays the timeline on, takes in prepared steps (their uploads submitted here, ahead of
    /// the caller's frame), asks for the next ones, and records the frame into `encoder`
    /// (unless the targets already hold this view). Never waits on disk: a step not yet
    /// resident is drawn by its nearest resident stand-in.
    pub fn frame(
        &mut self,
        request: &FrameRequest,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<FrameReport> {
        let time_moved = self.timeline.advance(request.seconds);
        let position = self.timeline.current();
        // How fast the position moves, by play or by scrub.
        let moved = position.abs_diff(self.last_position) as f64;
        if position != self.last_position {
            self.scrub_direction = if position > self.last_position {
                Direction::Forward
            } else {
                Direction::Backward
            };
        }
        self.clock += request.seconds.max(0.0);
        // A jump is not motion: a frame counts at most a few steps.
        self.moves
            .push_back((self.clock, moved.min(MAX_STEPS_PER_FRAME)));
        while self
            .moves
            .front()
            .is_some_and(|(t, _)| self.clock - t > RATE_WINDOW_SECONDS)
        {
            self.moves.pop_front();
        }
        let scrubbed = position != self.last_position;
        self.last_position = position;
        let window = self.window();
        let mut report = FrameReport {
            wanted: position,
            ..FrameReport::default()
        };
        for (index, why) in std::mem::take(&mut self.unreported) {
            if let Some(position) = self.position(index) {
                report.failures.push((position, why));
            }
        }
        self.admit(&window, &mut report);
        let resident_or_failed = |e: &Engine, p: usize| {
            e.bake_index(p)
                .is_none_or(|i| e.pool.contains(i) || e.failed.contains_key(&i))
        };
        if !self.last_window.contains(&position) && !resident_or_failed(self, position) {
            self.urgent = Some(position);
        }
        if self.urgent != Some(position) || resident_or_failed(self, position) {
            self.urgent = None;
        }
        match self.urgent.and_then(|p| self.bake_index(p)) {
            Some(index) => {
                self.prefetch.request_urgent(&[index]);
            }
            None => self.request(&window),
        }
        self.last_window = window;
        let wanted_index = self.bake_index(position);
        let shown_index = match wanted_index {
            Some(i) if self.pool.contains(i) => Some(i),
            Some(_) => self.pool.nearest_by(|i| {
                self.position(i)
                    .map_or(usize::MAX, |p| p.abs_diff(position))
            }),
            None => None,
        };
        let Some(shown_index) = shown_index else {
            return Ok(report);
        };
        report.shown = self.position(shown_index);
        report.stand_in = Some(shown_index) != wanted_index;
        self.shown = Some(shown_index);
        self.ensure_field(shown_index)?;
        let (width, height) = (request.camera.width.max(1), request.camera.height.max(1));
        if self.targets.as_ref().map(FrameTargets::size) != Some((width, height)) {
            self.targets = Some(self.tracer.targets(&self.gpu, width, height)?);
            self.refinement.invalidate();
        }
        let key = ViewKey::new(
            report.shown.unwrap_or(position),
            request.camera,
            &request.params,
            self.field.clone(),
            self.revision,
        );
        // A stand-in is a still view of its own step: it refines like any other, and the
        // step asked for starts over at one iteration when it arrives (another key).
        let moving = request.camera_moving || time_moved || scrubbed || self.timeline.is_playing();
        let target = request.params.iterations.max(1);
        match request.frame_budget_ms {
            Some(ms) if self.frame_budget.as_ref().map(FrameBudget::budget_ms) != Some(ms) => {
                self.frame_budget = Some(FrameBudget::new(ms));
            }
            Some(_) => {}
            None => self.frame_budget = None,
        }
        // The interval since the last frame, against the GPU time that frame measured: what
        // the rest of a frame costs.
        if let (Some(budget), Some(gpu_ms)) = (&mut self.frame_budget, self.last_gpu_ms.take()) {
            budget.record_frame(request.seconds * 1e3, gpu_ms);
        }
        let preview_scale = self
            .frame_budget
            .as_mut()
            .map_or(1.0, |b| b.preview_scale(width, height));
        let pacing = self.frame_budget.as_ref().map(|budget| Pacing {
            budget,
            preview: preview_scale < 1.0,
        });
        let step = self.pool.get(shown_index).ok_or_else(|| Error::Series {
            path: self.series.dir().to_path_buf(),
            problem: "the shown step left the pool".into(),
        })?;
        // Under a budget, the neighbour masks a refined frame needs are derived first, a
        // part per frame, instead of all at once inside it.
        if let Some(p) = pacing {
            let mut probe = self.refinement.clone();
            let refines = probe
                .next(key.clone(), moving, target, pacing)
                .is_some_and(|d| d.iterations() > 1);
            if refines && !self.tracer.mask_progress(step).finished() {
                let clusters = p.budget.mask_clusters();
                let progress = self
                    .tracer
                    .derive_masks(&self.gpu, step, clusters, encoder)?;
                self.unmeasured = Some((Recorded::Masks { clusters }, std::time::Instant::now()));
                report.masks = Some(progress);
                report.progress = Some(self.refinement.progress(target));
                report.quality = self.quality;
                return Ok(report);
            }
        }
        let draw = self.refinement.next(key, moving, target, pacing);
        report.drawn = draw.as_ref().map(Draw::iterations);
        report.progress = Some(self.refinement.progress(target));
        if let Some(draw) = &draw {
            let params = TraceParams {
                iterations: draw.iterations(),
                ..request.params
            };
            let missing = || Error::Series {
                path: self.series.dir().to_path_buf(),
                problem: "no frame targets".into(),
            };
            match draw {
                Draw::Preview => {
                    let size = (
                        ((width as f32 * preview_scale).round() as u32).max(1),
                        ((height as f32 * preview_scale).round() as u32).max(1),
                    );
                    if self.preview_targets.as_ref().map(FrameTargets::size) != Some(size) {
                        self.preview_targets =
                            Some(self.tracer.targets(&self.gpu, size.0, size.1)?);
                    }
                    let targets = self.preview_targets.as_ref().ok_or_else(missing)?;
                    self.tracer.record(
                        &self.gpu,
                        step,
                        targets,
                        &request.camera,
                        &params,
                        encoder,
                    )?;
                    let recorded = Recorded::Trace {
                        iterations: 1,
                        pixels: u64::from(size.0) * u64::from(size.1),
                        preview: true,
                    };
                    self.unmeasured = Some((recorded, std::time::Instant::now()));
                    self.frames_recorded += 1;
                    self.showing_preview = true;
                    self.quality = Some(Quality {
                        scale: preview_scale,
                        iterations: 1,
                    });
                }
                Draw::Whole { iterations } | Draw::Rows { iterations, .. } => {
                    let rows = match draw {
                        Draw::Rows { rows, .. } => *rows,
                        _ => RowSet::WHOLE,
                    };
                    let completes = draw.completes_frame();
                    let targets = self.targets.as_ref().ok_or_else(missing)?;
                    self.tracer.record_rows(
                        &self.gpu,
                        step,
                        targets,
                        &request.camera,
                        &params,
                        rows,
                        completes,
                        encoder,
                    )?;
                    let pixels = u64::from(width) * u64::from(rows.count(height));
                    let recorded = Recorded::Trace {
                        iterations: *iterations,
                        pixels,
                        preview: false,
                    };
                    self.unmeasured = Some((recorded, std::time::Instant::now()));
                    self.frames_recorded += 1;
                    if completes {
                        self.showing_preview = false;
                        self.quality = Some(Quality {
                            scale: 1.0,
                            iterations: *iterations,
                        });
                    }
                }
            }
        }
        report.draw = draw;
        report.quality = self.quality;
        Ok(report)
    }

    /// Switches the shown step to the engine's field where it holds another one.
    fn ensure_field(&mut self, index: usize) -> Result<()> {
        if self.step_fields.get(&index) == Some(&self.field) {
            return Ok(());
        }
        let field = match &self.field {
            Some(name) => {
                let path = self.source.path(index).ok_or_else(|| Error::Series {
                    path: self.series.dir().to_path_buf(),
                    problem: format!("step {index} is not in the series"),
                })?;
                let file = slosh_cache::CacheFile::open(&path)?;
                Some(HostField::read(&file, name)?)
            }
            None => None,
        };
        if let Some(step) = self.pool.get_mut(index) {
            step.set_field(&self.gpu, field.as_ref())?;
        }
        self.pool.refresh_bytes(index);
        self.step_fields.insert(index, self.field.clone());
        Ok(())
    }
}
