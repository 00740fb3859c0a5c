//! The raw-EnSight row of `slosh bench scrub`: a case of the moving sphere played by the
//! engine with no bake first (`Engine::open_baking`), every step baked by the loader that
//! first needs it into an emptied cache directory. Sequential playback, random jumps to
//! steps not baked yet, and one step's read and bake alone on the same machine.

use slosh_fileio::say;
use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{Context, Result};
use rand::{Rng, SeedableRng};
use slosh_bake::{EnsightSource, OnDemand, StepOutcome, StepSource};
use slosh_play::{Engine, EngineOptions, FrameRequest, Pace};
use slosh_render::{Gpu, TraceParams};
use slosh_scenes::{Scene, SceneKind, SceneSpec};

use super::{Settings, series_params};
use crate::stats::{Spread, median, spread};

/// What a raw case measured.
#[derive(Debug, Clone)]
pub struct RawCaseReport {
    /// Where the steps' neighbours were found.
    pub bake_device: String,
    pub points: usize,
    pub steps: usize,
    /// EnSight bytes of one step (geometry and normals).
    pub case_step_bytes: u64,
    /// The engine's loaders, each baking a step at once.
    pub loaders: usize,
    /// One step alone on all cores: reading it from the case, and reading and baking it
    /// into its file (medians of 3).
    pub read_ms: f64,
    pub bake_ms: f64,
    pub sequential_steps_per_s: f64,
    pub sequential: Spread,
    /// Jumps to steps not baked yet, from a series baked nowhere but around the start.
    pub jumps: Spread,
}

/// `steps` steps of the moving sphere of `points` surface points with their normals, as an
/// EnSight 6 binary case in `dir` (written again unless it holds that case); the case file.
fn ensure_case(dir: &Path, points: usize, steps: usize) -> Result<std::path::PathBuf> {
    let case = dir.join("sphere.case");
    if slosh_ensight::Case::open(&case).is_ok_and(|c| c.step_count() == steps)
        && std::fs::read_to_string(dir.join("points")).ok() == Some(points.to_string())
    {
        say!("  reusing the case {}", case.display());
        return Ok(case);
    }
    let _ = std::fs::remove_dir_all(dir);
    let scene = Scene::new(SceneSpec::new(SceneKind::Sphere, points, 1))?;
    slosh_testkit::write_surface_case(dir, "sphere", &scene, steps)?;
    std::fs::write(dir.join("points"), points.to_string())
        .with_context(|| format!("writing {}", dir.display()))?;
    Ok(case)
}

/// The case of `points` points a step, to be baked into `cache` (emptied first) as the
/// engine asks, its stages run by `stages`, `loaders` steps at once (default: as
/// `slosh play CASE.case` bakes, [`slosh_bake::viewer_jobs`]).
fn on_demand(
    case: &Path,
    cache: &Path,
    points: usize,
    stages: &slosh_bake::Stages,
    loaders: Option<usize>,
) -> Result<OnDemand> {
    let _ = std::fs::remove_dir_all(cache);
    let cores = slosh_bake::cores();
    let jobs = loaders.unwrap_or_else(|| {
        let batch = slosh_bake::default_jobs(
            cores,
            slosh_bake::available_memory(),
            Some(points),
            stages.device_memory,
        );
        slosh_bake::viewer_jobs(batch.0, cores)
    });
    Ok(OnDemand::of_case(
        slosh_ensight::Case::open(case)?,
        case,
        cache.to_path_buf(),
        series_params(),
        (cores, jobs),
        stages.clone(),
    )?)
}

pub fn measure(
    gpu: &Arc<Gpu>,
    root: &Path,
    points: usize,
    size: (u32, u32),
    args: &Settings,
) -> Result<RawCaseReport> {
    let steps = args.steps;
    // The engine's own device bakes too, where the GPU's stages are asked for.
    let stages = if args.raw_case_gpu {
        Arc::new(slosh_gpubake::GpuStages::new(gpu.clone())?).stages()
    } else {
        slosh_bake::Stages::cpu()
    };
    let dir = root.join(format!("case-{points}-{steps}"));
    let case = ensure_case(&dir.join("case"), points, steps)?;
    let cache = dir.join("cache");
    let case_step_bytes = ["sphere.geo00000", "sphere.normal00000"]
        .iter()
        .filter_map(|f| std::fs::metadata(dir.join("case").join(f)).ok())
        .map(|m| m.len())
        .sum();
    // One step alone: read, then read and bake (into a directory of its own each time).
    let (mut read_ms, mut bake_ms) = (Vec::new(), Vec::new());
    for _ in 0..3 {
        let bake = on_demand(&case, &cache, points, &stages, args.loaders)?;
        let source = EnsightSource::new(
            slosh_ensight::Case::open(&case)?,
            &case,
            slosh_ensight::PointSource::Auto,
            &series_params(),
        );
        let t = Instant::now();
        source.read(1).map_err(anyhow::Error::msg)?;
        read_ms.push(t.elapsed().as_secs_f64() * 1e3);
        let t = Instant::now();
        if let StepOutcome::Failed(why) = bake.bake(1) {
            anyhow::bail!("{}: step 1 did not bake: {why}", case.display());
        }
        bake_ms.push(t.elapsed().as_secs_f64() * 1e3);
    }
    let bounds = slosh_cache::CacheFile::open(&cache.join(slosh_cache::step_file_name(1)))?
        .header()
        .bounds;
    let mut request = FrameRequest {
        seconds: 0.0,
        camera: slosh_mls::Camera::framing(&bounds, 40.0, size.0, size.1, [0.0, 0.0, 1.0]),
        params: TraceParams::default(),
        camera_moving: false,
        frame_budget_ms: None,
    };
    // As many loaders as steps the bake takes at once, as `slosh play CASE.case` has.
    let options = |bake: &OnDemand| EngineOptions {
        loaders: bake.jobs(),
        ..EngineOptions::default()
    };
    let pace = Pace {
        real_time: true,
        pause: std::time::Duration::ZERO,
        timeout: std::time::Duration::from_secs(600),
    };
    let show = |engine: &mut Engine, request: &mut FrameRequest, position: usize| {
        let t = Instant::now();
        engine
            .show_and_wait(request, position, pace, |_, _| {})
            .map(|_| t.elapsed().as_secs_f64() * 1e3)
    };
    // Sequential playback from an empty cache.
    let bake = Arc::new(on_demand(&case, &cache, points, &stages, args.loaders)?);
    let loaders = bake.jobs();
    let mut engine = Engine::open_baking(gpu.clone(), bake.clone(), options(&bake))?;
    show(&mut engine, &mut request, 0)?;
    let mut sequential = Vec::new();
    let start = Instant::now();
    for position in 1..steps {
        sequential.push(show(&mut engine, &mut request, position)?);
    }
    let sequential_steps_per_s = (steps - 1) as f64 / start.elapsed().as_secs_f64();
    drop(engine);
    // Jumps to steps not baked yet, from an empty cache again.
    let bake = Arc::new(on_demand(&case, &cache, points, &stages, args.loaders)?);
    let mut engine = Engine::open_baking(gpu.clone(), bake.clone(), options(&bake))?;
    show(&mut engine, &mut request, 0)?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(args.seed);
    let mut jumps = Vec::new();
    let mut tries = 0;
    while jumps.len() < args.jumps && tries < 100 * args.jumps {
        tries += 1;
        let target = rng.random_range(0..steps);
        if cache.join(slosh_cache::step_file_name(target)).exists()
            || engine.prefetching().contains(&target)
        {
            continue;
        }
        jumps.push(show(&mut engine, &mut request, target)?);
    }
    Ok(RawCaseReport {
        bake_device: stages.describe(),
        points,
        steps,
        case_step_bytes,
        loaders,
        read_ms: median(read_ms),
        bake_ms: median(bake_ms),
        sequential_steps_per_s,
        sequential: spread(sequential),
        jumps: spread(jumps),
    })
}
