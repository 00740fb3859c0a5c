//! `slosh bench scrub`: the player's engine driven headless through a series of cache files
//! from the page cache: sequential playback (steps per second, request-to-frame latency),
//! random jumps to steps in the GPU pool and to steps only in the page cache, the cost of a
//! step (bytes on the GPU, host ms, GPU upload and passes ms), and, in the same run, the
//! floors: `std::fs::read` of the same files and a raw `Queue::write_buffer` of as many bytes.

use slosh_fileio::say;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use rand::{Rng, SeedableRng};
use slosh_bake::{BakeParams, NormalSource, SurfaceSelect, bake_step};
use slosh_cache::{Compression, Manifest, step_file_name, write_step};
use slosh_play::{Engine, EngineOptions, FrameReport, FrameRequest, Pace};
use slosh_render::{Gpu, GpuStep, HostStep, TraceParams};
use slosh_scenes::{Scene, SceneKind, SceneSpec};

use crate::stats::{median, spread};

mod raw_case;
mod report;

pub use raw_case::RawCaseReport;
pub use report::{CodecRow, Cold, JumpBreakdown, ScrubReport, SeriesReport};

/// What `slosh bench scrub` measures and where it writes.
#[derive(Debug, Clone)]
pub struct Settings {
    /// Markdown report to write.
    pub out: PathBuf,
    /// Points per step of each series measured (empty: 100000 and 1000000; quick: 2000).
    pub points: Vec<usize>,
    /// Steps per series.
    pub steps: usize,
    /// Distinct baked shapes per series (default: every step up to 200k points, 8 above).
    pub distinct: Option<usize>,
    /// Frame size, width and height.
    pub size: (u32, u32),
    /// Random jumps measured, in the pool and from the page cache each.
    pub jumps: usize,
    /// Seed of the jumps' steps.
    pub seed: u64,
    /// Loader threads (default: the player's).
    pub loaders: Option<usize>,
    /// Steps the GPU pool holds while streaming.
    pub pool_steps: u64,
    /// Where the series live (default: a temporary directory).
    pub dir: Option<PathBuf>,
    /// Small series and frames.
    pub quick: bool,
    /// GPU adapter whose name contains this.
    pub adapter: Option<String>,
    /// Also jumps read from storage: the page cache dropped before each (needs root).
    pub cold: bool,
    /// Steps stored without compression (`--compress none`), so a load is a copy.
    pub raw: bool,
    /// Also each size as a raw EnSight case, baked as the engine plays it.
    pub raw_case: bool,
    /// The raw case's steps baked with the GPU's neighbour search, on the engine's device.
    pub raw_case_gpu: bool,
    /// The raw cases alone: no baked series is made or measured.
    pub raw_case_only: bool,
}

/// Percentiles of a sample, in the sample's unit.
/// How the series are baked: the sphere's own normals, the bake's defaults.
fn series_params() -> BakeParams {
    BakeParams::new(SurfaceSelect::All, NormalSource::Variable("normal".into()))
}

/// A series of `steps` cache files of a moving sphere of `points` surface points: `distinct`
/// instants baked, cycled over the steps (each step its own file, time values increasing).
/// Reused when `dir` already holds that series.
fn ensure_series(
    dir: &Path,
    points: usize,
    steps: usize,
    distinct: usize,
    compression: Compression,
) -> Result<()> {
    let params = BakeParams {
        compression,
        ..series_params()
    };
    let record = params.record();
    // Reused only when baked by this bake into this cache format: a series left by an older
    // slosh is baked again, not refused step by step.
    if let Ok(m) = Manifest::read(dir)
        && m.steps.len() == steps
        && m.steps.iter().all(|s| s.points == points as u64)
        && m.bake.get("scrub_distinct").and_then(|v| v.as_u64()) == Some(distinct as u64)
        && ["compression", "revision", "cache_major"]
            .iter()
            .all(|&k| m.bake.get(k) == record.get(k))
    {
        say!("  reusing the series in {}", dir.display());
        return Ok(());
    }
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let scene = Scene::new(SceneSpec::new(SceneKind::Sphere, points, 1))?;
    let start = Instant::now();
    let mut baked = Vec::with_capacity(distinct);
    for d in 0..distinct {
        // The instants spread over the scene's motion.
        let instant = d * 4;
        let mut input = slosh_testkit::scene_step(&scene, instant, &format!("sphere {points}"));
        input.index = d;
        baked.push(bake_step(&input, &params)?);
    }
    say!(
        "  baked {distinct} distinct steps of {points} points in {:.1} s",
        start.elapsed().as_secs_f64()
    );
    for step in 0..steps {
        let source = &baked[step % distinct];
        let mut header = source.header.clone();
        header.source.step = step;
        header.source.time = step as f64 * 0.01;
        if let Some(bake) = header.bake.as_object_mut() {
            bake.insert("scrub_distinct".into(), distinct.into());
        }
        write_step(
            &dir.join(step_file_name(step)),
            header,
            &source.sections,
            params.compression,
        )?;
    }
    let (manifest, failed) = Manifest::rebuild(dir)?;
    if let Some((path, e)) = failed.first() {
        bail!("{}: {e}", path.display());
    }
    manifest.write(dir)?;
    say!(
        "  wrote {steps} step files to {} in {:.1} s",
        dir.display(),
        start.elapsed().as_secs_f64()
    );
    Ok(())
}

/// The host and record ms of every step the engine's loaders prepared, as they reported
/// them: under the load of streaming, beside the same halves timed alone.
#[derive(Default)]
struct LoadTimes {
    host_ms: Vec<f64>,
    record_ms: Vec<f64>,
}

impl LoadTimes {
    fn add(&mut self, report: &FrameReport) {
        for u in &report.uploaded {
            self.host_ms.push(u.host_ms);
            self.record_ms.push(u.record_ms);
        }
    }
}

/// Where one jump's time went: the host and record halves of the step asked for, and the rest.
struct JumpParts {
    total: f64,
    host: f64,
    record: f64,
}

impl JumpBreakdown {
    /// Medians over all jumps, and means over the slowest tenth.
    fn of(parts: &[JumpParts], fresh: slosh_play::FreshBuffers) -> JumpBreakdown {
        let rest = |p: &JumpParts| p.total - p.host - p.record;
        let column = |f: &dyn Fn(&JumpParts) -> f64| median(parts.iter().map(f).collect());
        let mut slowest: Vec<&JumpParts> = parts.iter().collect();
        slowest.sort_by(|a, b| b.total.total_cmp(&a.total));
        slowest.truncate(parts.len().div_ceil(10));
        let mean = |f: &dyn Fn(&JumpParts) -> f64| {
            slowest.iter().map(|p| f(p)).sum::<f64>() / slowest.len().max(1) as f64
        };
        JumpBreakdown {
            median: [column(&|p| p.host), column(&|p| p.record), column(&rest)],
            slowest_tenth: [
                mean(&|p| p.total),
                mean(&|p| p.host),
                mean(&|p| p.record),
                mean(&rest),
            ],
            fresh,
        }
    }
}

/// Frames until `position` is drawn (not a stand-in); the seconds from the request.
fn show(engine: &mut Engine, request: &mut FrameRequest, position: usize) -> Result<f64> {
    show_with(engine, request, position, |_| {})
}

/// [`show`], adding the loads that arrived to `loads`.
fn show_timed(
    engine: &mut Engine,
    request: &mut FrameRequest,
    position: usize,
    loads: &mut LoadTimes,
) -> Result<f64> {
    show_with(engine, request, position, |report| loads.add(report))
}

/// [`show`], handing `each` every frame's report.
fn show_with(
    engine: &mut Engine,
    request: &mut FrameRequest,
    position: usize,
    mut each: impl FnMut(&FrameReport),
) -> Result<f64> {
    let start = Instant::now();
    let pace = Pace {
        real_time: true,
        pause: Duration::ZERO,
        timeout: Duration::from_secs(60),
    };
    engine.show_and_wait(request, position, pace, |_, report| each(report))?;
    Ok(start.elapsed().as_secs_f64())
}

/// Every compressed section of `path` re-encoded in its encoding's chunks at each level (each
/// keeps its filter: shuffle, delta), then decoded on one core.
fn codec_table(path: &Path) -> Result<Vec<CodecRow>> {
    let file = slosh_cache::CacheFile::open(path)?;
    let mut sections = Vec::new();
    for entry in &file.header().sections {
        if entry.encoding != slosh_cache::Encoding::Raw {
            let mut raw = vec![0u8; entry.raw as usize];
            file.decode_into(entry, &mut raw, &mut Vec::new())?;
            sections.push((entry.encoding, entry.chunk_raw, raw));
        }
    }
    let mut rows = Vec::new();
    for level in [-5, -1, 1, 3, 9] {
        let (mut stored, mut raw_bytes) = (0u64, 0u64);
        let mut packed = Vec::new();
        let t = Instant::now();
        // In the file's own chunks.
        for (encoding, chunk_raw, raw) in &sections {
            for chunk in raw.chunks(*chunk_raw as usize) {
                let bytes = slosh_cache::encode_bytes(chunk, *encoding, level)?;
                stored += bytes.len() as u64;
                raw_bytes += chunk.len() as u64;
                packed.push((*encoding, bytes, chunk.len()));
            }
        }
        let encode = t.elapsed().as_secs_f64();
        let mut out = vec![0u8; slosh_cache::CHUNK_RAW as usize];
        let mut scratch = Vec::new();
        let t = Instant::now();
        for (encoding, bytes, len) in &packed {
            slosh_cache::decode_bytes(bytes, *encoding, &mut out[..*len], &mut scratch)?;
        }
        let decode = t.elapsed().as_secs_f64();
        rows.push(CodecRow {
            level,
            raw: raw_bytes,
            stored,
            encode_mb_s: raw_bytes as f64 / encode / 1e6,
            decode_gb_s: raw_bytes as f64 / decode / 1e9,
        });
    }
    Ok(rows)
}

fn measure(
    gpu: &Arc<Gpu>,
    dir: &Path,
    points: usize,
    label: String,
    size: (u32, u32),
    args: &Settings,
) -> Result<SeriesReport> {
    let manifest = Manifest::read(dir)?;
    let paths: Vec<PathBuf> = manifest.steps.iter().map(|s| dir.join(&s.file)).collect();
    let steps = paths.len();
    if steps < 2 {
        bail!(
            "{}: a series of {steps} steps cannot be scrubbed",
            dir.display()
        );
    }
    // Warm-up: a GPU that was idle runs its first seconds of work at low clocks (the first
    // series of a cold run traced its frames 3 times slower), so frames run for a while
    // before anything is measured, as in `bench gpu`.
    {
        let camera =
            slosh_mls::Camera::framing(&manifest.bounds, 40.0, size.0, size.1, [0.0, 0.0, 1.0]);
        let mut request = FrameRequest {
            seconds: 0.0,
            camera,
            params: TraceParams::default(),
            camera_moving: true,
            frame_budget_ms: None,
        };
        let options = EngineOptions {
            loaders: args.loaders.unwrap_or_else(slosh_play::default_loaders),
            ..EngineOptions::default()
        };
        let mut engine = Engine::open(gpu.clone(), dir, options)?;
        show(&mut engine, &mut request, 0)?;
        warm_up(&mut engine, &request, args)?;
    }
    // Floors. First a read of every file, so that all come from the page cache.
    for p in &paths {
        std::fs::read(p).with_context(|| format!("reading {}", p.display()))?;
    }
    let mut read_ms = Vec::new();
    let mut read_bytes = 0u64;
    let read_start = Instant::now();
    for p in &paths {
        let t = Instant::now();
        read_bytes += std::fs::read(p)?.len() as u64;
        read_ms.push(t.elapsed().as_secs_f64() * 1e3);
    }
    let read_gbps = read_bytes as f64 / read_start.elapsed().as_secs_f64() / 1e9;
    // The cost of a step, both halves, on a few steps (median).
    let sample: Vec<&PathBuf> = paths.iter().take(8).collect();
    // Staging memory reused as the engine reuses it (the first sample allocates it).
    let staging = slosh_render::StagingPool::new(2);
    let (mut host_ms, mut record_ms) = (Vec::new(), Vec::new());
    let (mut copy_ms, mut pass_ms) = (Vec::new(), Vec::new());
    // GPU timestamps of the mask pass, where the adapter has them.
    let (mut mask_pass_ms, mut mask_bytes) = (Vec::new(), 0);
    let stamps = gpu.timestamps.then(|| {
        let buffer = |usage| {
            gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("pass stamps"),
                size: 16,
                usage,
                mapped_at_creation: false,
            })
        };
        (
            gpu.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("mask pass"),
                ty: wgpu::QueryType::Timestamp,
                count: 2,
            }),
            buffer(wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC),
            buffer(wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST),
        )
    });
    let (mut step_gpu_bytes, mut section_bytes, mut stored_bytes) = (0, 0, 0);
    // The mask pass a step's first refined frame records, timed alone.
    let tracer = slosh_render::Tracer::new(gpu)?;
    for p in &sample {
        let host = HostStep::open(p, None)?;
        let encoder = || {
            gpu.device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None })
        };
        let (mut copies, mut passes) = (encoder(), encoder());
        let mut step = GpuStep::create_in(
            gpu,
            &host,
            &mut copies,
            slosh_render::UploadOptions {
                staging: Some(&staging),
                ..slosh_render::UploadOptions::default()
            },
        )?;
        let t = Instant::now();
        gpu.queue.submit([copies.finish()]);
        gpu.wait()?;
        copy_ms.push(t.elapsed().as_secs_f64() * 1e3);
        if let Some(buffer) = step.take_staging() {
            staging.recycle(buffer);
        }
        let (masks, candidates) = tracer.neighbour_masks(
            gpu,
            &step,
            &mut passes,
            stamps.as_ref().map(|(set, _, _)| set),
        )?;
        if let Some((set, resolve, readback)) = &stamps {
            passes.resolve_query_set(set, 0..2, resolve, 0);
            passes.copy_buffer_to_buffer(resolve, 0, readback, 0, 16);
        }
        let t = Instant::now();
        gpu.queue.submit([passes.finish()]);
        gpu.wait()?;
        pass_ms.push(t.elapsed().as_secs_f64() * 1e3);
        mask_bytes = masks.size() + candidates.size();
        if let Some((_, _, readback)) = &stamps {
            let ticks: Vec<u64> = slosh_render::read_buffer(gpu, readback)?;
            let period = f64::from(gpu.queue.get_timestamp_period()) * 1e-6;
            mask_pass_ms.push(ticks[1].saturating_sub(ticks[0]) as f64 * period);
        }
        host_ms.push(step.upload.host_seconds * 1e3);
        record_ms.push(step.upload.record_seconds * 1e3);
        step_gpu_bytes = step.gpu_bytes();
        section_bytes = step.upload.bytes;
        stored_bytes = step.upload.stored_bytes;
    }
    // A raw write_buffer of as many bytes as a step holds on the GPU.
    let raw = vec![0x5au8; step_gpu_bytes as usize];
    let target = gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("raw write floor"),
        size: step_gpu_bytes.next_multiple_of(4),
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut write_ms = Vec::new();
    for _ in 0..8 {
        let t = Instant::now();
        gpu.queue.write_buffer(&target, 0, &raw[..raw.len() & !3]);
        gpu.queue.submit([]);
        gpu.wait()?;
        write_ms.push(t.elapsed().as_secs_f64() * 1e3);
    }
    drop((raw, target));

    let bounds = manifest.bounds;
    let camera = slosh_mls::Camera::framing(&bounds, 40.0, size.0, size.1, [0.0, 0.0, 1.0]);
    let params = TraceParams {
        iterations: 1,
        ..TraceParams::default()
    };
    let mut request = FrameRequest {
        seconds: 0.0,
        camera,
        params,
        camera_moving: false,
        frame_budget_ms: None,
    };
    let streaming_budget = step_gpu_bytes * args.pool_steps.max(3);
    let options = |budget| EngineOptions {
        budget: Some(budget),
        loaders: args.loaders.unwrap_or_else(slosh_play::default_loaders),
        ..EngineOptions::default()
    };
    // Sequential playback, streaming through a pool smaller than the series.
    let mut engine = Engine::open(gpu.clone(), dir, options(streaming_budget))?;
    show(&mut engine, &mut request, 0)?;
    let mut sequential = Vec::new();
    let mut loads = LoadTimes::default();
    let start = Instant::now();
    for position in 1..steps {
        sequential.push(show_timed(&mut engine, &mut request, position, &mut loads)? * 1e3);
    }
    let sequential_steps_per_s = (steps - 1) as f64 / start.elapsed().as_secs_f64();
    // Trace time alone: the same view drawn again (camera marked moving, so it is redrawn).
    let mut trace = Vec::new();
    request.camera_moving = true;
    for _ in 0..20 {
        let t = Instant::now();
        engine.frame_and_wait(&request)?;
        trace.push(t.elapsed().as_secs_f64() * 1e3);
    }
    request.camera_moving = false;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(args.seed);
    // Jumps to steps only in the page cache: a pool of a few steps.
    drop(engine);
    let mut engine = Engine::open(gpu.clone(), dir, options(step_gpu_bytes * 3))?;
    show(&mut engine, &mut request, 0)?;
    let fresh_before = engine.fresh_buffers();
    let mut page_cache = Vec::new();
    let mut jump_parts = Vec::new();
    while page_cache.len() < args.jumps {
        let target = rng.random_range(0..steps);
        if engine.resident().contains(&target) || engine.prefetching().contains(&target) {
            continue;
        }
        let (mut host, mut record) = (0.0, 0.0);
        let total = show_with(&mut engine, &mut request, target, |report| {
            if let Some(u) = report.uploaded.iter().find(|u| u.position == target) {
                (host, record) = (u.host_ms, u.record_ms);
            }
        })? * 1e3;
        page_cache.push(total);
        jump_parts.push(JumpParts {
            total,
            host,
            record,
        });
    }
    let fresh_after = engine.fresh_buffers();
    let fresh = slosh_play::FreshBuffers {
        staging: fresh_after.staging - fresh_before.staging,
        sections: fresh_after.sections - fresh_before.sections,
    };
    // Jumps from storage: the page cache dropped before each one (root only).
    let cold = if args.cold {
        Some(cold_jumps(
            &mut engine,
            &mut request,
            &mut rng,
            &paths,
            args.jumps,
        )?)
    } else {
        None
    };
    // Jumps to resident steps: a pool that holds the series, filled first, where the device
    // can hold it.
    drop(engine);
    let series_bytes = step_gpu_bytes * steps as u64;
    let room = gpu.device_memory().map(|m| m / 10 * 9);
    let jumps_pool = match room {
        Some(room) if series_bytes > room => Err(format!(
            "the series holds {:.1} GB on the GPU, over 90 % of its {:.1} GB",
            series_bytes as f64 / 1e9,
            room as f64 / 0.9 / 1e9
        )),
        _ => Ok(resident_jumps(
            gpu,
            dir,
            &options,
            &mut request,
            &mut rng,
            steps,
            step_gpu_bytes,
            args,
        )?),
    };
    Ok(SeriesReport {
        label,
        points,
        steps,
        step_gpu_bytes,
        section_bytes,
        stored_bytes,
        host_ms: median(host_ms),
        record_ms: median(record_ms),
        copy_ms: median(copy_ms),
        pass_ms: median(pass_ms),
        mask_pass_ms: median(mask_pass_ms),
        mask_bytes,
        read_ms: median(read_ms),
        read_gbps,
        write_buffer_ms: median(write_ms),
        trace_ms: median(trace),
        sequential_steps_per_s,
        sequential: spread(sequential),
        streaming_host_ms: median(loads.host_ms),
        streaming_record_ms: median(loads.record_ms),
        jumps_pool: jumps_pool.map(spread),
        jumps_page_cache: spread(page_cache),
        jump_parts: JumpBreakdown::of(&jump_parts, fresh),
        cold,
        codecs: codec_table(&paths[0])?,
    })
}

/// Jumps to random steps with the page cache dropped before each, and the disk's own floor:
/// a step file read cold.
fn cold_jumps(
    engine: &mut Engine,
    request: &mut FrameRequest,
    rng: &mut rand_chacha::ChaCha8Rng,
    paths: &[PathBuf],
    jumps: usize,
) -> Result<Cold> {
    let steps = paths.len();
    let (mut jump_ms, mut read_ms, mut read_bytes) = (Vec::new(), Vec::new(), 0u64);
    let mut at = engine.timeline().current();
    while jump_ms.len() < jumps {
        let target = rng.random_range(0..steps);
        if target == at
            || engine.resident().contains(&target)
            || engine.prefetching().contains(&target)
        {
            continue;
        }
        drop_page_cache()?;
        jump_ms.push(show(engine, request, target)? * 1e3);
        at = target;
        drop_page_cache()?;
        let t = Instant::now();
        read_bytes += std::fs::read(&paths[target])?.len() as u64;
        read_ms.push(t.elapsed().as_secs_f64() * 1e3);
    }
    let read_seconds: f64 = read_ms.iter().sum::<f64>() / 1e3;
    Ok(Cold {
        jumps: spread(jump_ms),
        read_ms: median(read_ms),
        read_gbps: read_bytes as f64 / read_seconds.max(1e-12) / 1e9,
    })
}

/// Where Linux takes the order to drop its page cache.
const DROP_CACHES: &str = "/proc/sys/vm/drop_caches";

/// Writes back dirty pages and drops the page cache, so that the next read comes from
/// storage.
fn drop_page_cache() -> Result<()> {
    let synced = std::process::Command::new("sync").status();
    if !synced.is_ok_and(|s| s.success()) {
        bail!("--cold: `sync` failed before dropping the page cache");
    }
    std::fs::write(DROP_CACHES, "3").with_context(|| {
        format!(
            "--cold drops the page cache before each jump, which needs root (writing {DROP_CACHES})"
        )
    })
}

/// Frames back to back for a while (`--quick`: briefly): a GPU that was idle, at the start
/// or while the page cache was dropped and read again (`--cold`), runs its first work at low
/// clocks.
fn warm_up(engine: &mut Engine, request: &FrameRequest, args: &Settings) -> Result<()> {
    let start = Instant::now();
    let seconds = if args.quick { 0.2 } else { 2.0 };
    let mut request = request.clone();
    request.camera_moving = true;
    while start.elapsed().as_secs_f64() < seconds {
        engine.frame_and_wait(&request)?;
    }
    Ok(())
}

/// Jumps to random resident steps in a pool that holds the whole series, filled first.
#[allow(clippy::too_many_arguments)]
fn resident_jumps(
    gpu: &Arc<Gpu>,
    dir: &Path,
    options: &dyn Fn(u64) -> EngineOptions,
    request: &mut FrameRequest,
    rng: &mut rand_chacha::ChaCha8Rng,
    steps: usize,
    step_gpu_bytes: u64,
    args: &Settings,
) -> Result<Vec<f64>> {
    let jumps = args.jumps;
    let mut engine = Engine::open(
        gpu.clone(),
        dir,
        options(step_gpu_bytes * (steps as u64 + 2)),
    )?;
    for position in 0..steps {
        show(&mut engine, request, position)?;
    }
    if engine.resident().len() != steps {
        bail!(
            "the pool holds {} of {steps} steps after a pass",
            engine.resident().len()
        );
    }
    warm_up(&mut engine, request, args)?;
    let mut pool = Vec::new();
    let mut at = engine.timeline().current();
    while pool.len() < jumps {
        let target = rng.random_range(0..steps);
        if target == at {
            continue;
        }
        pool.push(show(&mut engine, request, target)? * 1e3);
        at = target;
    }
    Ok(pool)
}

/// The fewest steps a series needs: page-cache and storage jumps pick steps neither resident
/// (a pool of 3 steps) nor being loaded (the window around the current step), and a shorter
/// series would leave none to pick.
const MIN_STEPS: usize = 8;

/// The lock file a run holds in its folder.
const SCRUB_LOCK: &str = ".scrub.lock";

pub fn run(args: &Settings) -> Result<ScrubReport> {
    let size = if args.quick { (160, 100) } else { args.size };
    let counts: Vec<usize> = match (&args.points[..], args.quick) {
        ([], true) => vec![2_000],
        ([], false) => vec![100_000, 1_000_000],
        (given, _) => given.to_vec(),
    };
    let steps = if args.quick {
        args.steps.min(12)
    } else {
        args.steps
    };
    if steps < MIN_STEPS {
        bail!(
            "--steps {steps}: jumps need steps outside the page-cache pool (3 steps) and the loaders' window: give at least {MIN_STEPS}"
        );
    }
    if args.jumps == 0 {
        bail!("--jumps must be at least 1");
    }
    // Refused before any series is baked, not after.
    if args.cold {
        std::fs::OpenOptions::new()
            .write(true)
            .open(DROP_CACHES)
            .with_context(|| format!("--cold drops the page cache before each jump, which needs root (writing {DROP_CACHES})"))?;
    }
    let jumps_args = Settings {
        jumps: if args.quick {
            args.jumps.min(10)
        } else {
            args.jumps
        },
        points: Vec::new(),
        steps,
        ..args.clone()
    };
    let root = args
        .dir
        .clone()
        .unwrap_or_else(|| std::env::temp_dir().join("slosh-scrub"));
    // Held to the end: a second run on the same folder would empty the raw case's cache, and
    // rewrite the series, under this one. Taken before the device is, so that a refusal costs
    // nothing.
    std::fs::create_dir_all(&root).with_context(|| format!("{}", root.display()))?;
    let lock_path = root.join(SCRUB_LOCK);
    let locks = slosh_fileio::RangeLocks::open(&lock_path)
        .with_context(|| format!("{}", lock_path.display()))?;
    let Some(_held) = locks
        .try_lock(0)
        .with_context(|| format!("{}", lock_path.display()))?
    else {
        bail!(
            "{}: another `slosh bench scrub` is running there now; give this one a folder of \
             its own with --dir",
            root.display()
        );
    };
    let gpu = Arc::new(Gpu::new(args.adapter.as_deref())?);
    let cores = slosh_bake::cores();
    say!("scrub benchmark on {} ({cores} cores)", gpu.describe());
    let mut reports = Vec::new();
    let mut raw_cases = Vec::new();
    for points in counts {
        if args.raw_case {
            say!("raw EnSight case: {points} points, {steps} steps, baked as played");
            let r = raw_case::measure(&gpu, &root, points, size, &jumps_args)?;
            say!(
                "  sequential {:.2} steps/s; jumps to unbaked steps p50 {:.0} / p99 {:.0} ms; one step: read {:.0} ms, read and bake {:.0} ms",
                r.sequential_steps_per_s,
                r.jumps.p50,
                r.jumps.p99,
                r.read_ms,
                r.bake_ms
            );
            raw_cases.push(r);
        }
        if args.raw_case_only {
            continue;
        }
        let distinct = args
            .distinct
            .unwrap_or(if points <= 200_000 { steps } else { 8 })
            .clamp(1, steps);
        let (compression, stored) = if args.raw {
            (Compression::None, ", stored raw")
        } else {
            (series_params().compression, "")
        };
        let dir = root.join(format!(
            "sphere-{points}-{steps}{}",
            if args.raw { "-raw" } else { "" }
        ));
        say!("series: {points} points, {steps} steps ({distinct} distinct{stored})");
        ensure_series(&dir, points, steps, distinct, compression)?;
        let label = format!("{points} points, {steps} steps ({distinct} distinct shapes{stored})");
        let report = measure(&gpu, &dir, points, label, size, &jumps_args)?;
        let pool = report
            .jumps_pool
            .as_ref()
            .map_or("not possible".into(), |j| format!("{:.2} ms", j.p99));
        say!(
            "  sequential {:.1} steps/s; jumps p99: pool {pool}, page cache {:.2} ms",
            report.sequential_steps_per_s,
            report.jumps_page_cache.p99
        );
        reports.push(report);
    }
    Ok(ScrubReport {
        adapter: gpu.describe(),
        cores,
        size,
        settings: args.clone(),
        series: reports,
        raw_cases,
    })
}
