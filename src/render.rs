//! `slosh render`: frames (PNG) and hit buffers (.npy) from a cache, one step or a range of
//! steps. The GPU path uploads each step into wgpu buffers and runs the WGSL trace and shade
//! passes; `--cpu` runs the CPU reference tracer on the mapped cache through its baked BVH.

use slosh_fileio::say;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use slosh_cache::{CacheFile, LoadedStep, step_file_name};
use slosh_mls::{Camera, NormalsMode, Params};
use slosh_render::{TraceParams, Tracer, cpu_shade};

use crate::cli::{ModeArg, RenderArgs};

fn parse_vec3(flag: &str, s: &str) -> Result<[f64; 3]> {
    let parts: Vec<&str> = s.split(',').collect();
    let bad = || anyhow::anyhow!("--{flag} {s}: expected X,Y,Z");
    if parts.len() != 3 {
        return Err(bad());
    }
    let mut v = [0.0f64; 3];
    for (o, p) in v.iter_mut().zip(&parts) {
        *o = p.trim().parse().map_err(|_| bad())?;
        if !o.is_finite() {
            return Err(bad());
        }
    }
    Ok(v)
}

pub fn parse_size(s: &str) -> Result<(u32, u32)> {
    let bad = || anyhow::anyhow!("--size {s}: expected WxH, e.g. 1280x800");
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(bad)?;
    let (w, h): (u32, u32) = (w.parse().map_err(|_| bad())?, h.parse().map_err(|_| bad())?);
    if w == 0 || h == 0 || u64::from(w) * u64::from(h) > 1 << 28 {
        return Err(bad());
    }
    Ok((w, h))
}

fn step_path(path: &Path, step: usize) -> PathBuf {
    if path.is_dir() {
        path.join(step_file_name(step))
    } else {
        path.to_path_buf()
    }
}

fn write_png(path: &Path, width: u32, height: u32, rgb: &[u8]) -> Result<()> {
    Ok(slosh_render::write_rgb_png(path, width, height, rgb)?)
}

/// A GPU frame's RGBA pixels as an RGB PNG.
pub fn write_frame_png(path: &Path, frame: &slosh_render::Frame) -> Result<()> {
    Ok(slosh_render::write_frame_png(path, frame)?)
}

fn write_npy(path: &Path, height: u32, width: u32, channels: usize, data: &[f32]) -> Result<()> {
    Ok(slosh_render::write_npy(
        path, height, width, channels, data,
    )?)
}

/// `{}` or `{:0N}` in `pattern` replaced by `step` (zero-padded to N digits).
fn expand_pattern(pattern: &Path, step: usize) -> PathBuf {
    let text = pattern.to_string_lossy();
    let Some(open) = text.find('{') else {
        return pattern.to_path_buf();
    };
    let Some(close) = text[open..].find('}').map(|c| open + c) else {
        return pattern.to_path_buf();
    };
    let width: usize = text[open + 1..close]
        .trim_start_matches(':')
        .parse()
        .unwrap_or(0);
    PathBuf::from(format!(
        "{}{step:0width$}{}",
        &text[..open],
        &text[close + 1..]
    ))
}

/// "A..B" (B excluded) or "A..=B".
fn parse_steps(s: &str) -> Result<Vec<usize>> {
    let (first, last) = crate::config::parse_step_range(s)?;
    Ok((first..=last).collect())
}

/// A step rendered from a cache directory must belong to its series (`manifest`, read once
/// per run where the directory has one).
fn check_belongs(
    manifest: Option<&slosh_cache::Manifest>,
    dir: &Path,
    step: usize,
    path: &Path,
    file: &CacheFile,
) -> Result<()> {
    if let Some(manifest) = manifest {
        let problems = manifest.step_problems(step, file);
        if !problems.is_empty() {
            bail!(
                "{}: not step {step} of the series in {}: {}",
                path.display(),
                dir.display(),
                problems.join("; ")
            );
        }
    }
    Ok(())
}

/// Memory a rendered frame takes per pixel: hits and pixels on the device, their readback
/// and the hit buffer written out.
const BYTES_PER_PIXEL: u64 = 120;

/// The validated settings of one `slosh render` run.
struct RenderConfig {
    steps: Vec<usize>,
    sequence: bool,
    width: u32,
    height: u32,
}

impl RenderConfig {
    fn from_args(args: &RenderArgs) -> Result<RenderConfig> {
        if args.out.is_none() && args.aov.is_none() {
            bail!("nothing to write: give --out frame.png and/or --aov hits.npy");
        }
        if args.iterations == 0 {
            bail!("--iterations must be at least 1");
        }
        if args.h_scale.is_some_and(|h| !(h.is_finite() && h > 0.0)) {
            bail!("--h-scale must be a positive number");
        }
        if args.cpu && args.field.is_some() {
            bail!("--field colours on the GPU path only; drop --cpu");
        }
        if args.cpu && matches!(args.mode, ModeArg::Water) {
            bail!("--mode water traces secondary rays on the GPU only; drop --cpu");
        }
        if !(args.fov.is_finite() && args.fov > 0.0 && args.fov < 180.0) {
            bail!(
                "--fov {}: expected a vertical field of view between 0 and 180 degrees, exclusive",
                args.fov
            );
        }
        if let (Some(out), Some(aov)) = (&args.out, &args.aov)
            && out == aov
        {
            bail!(
                "--out and --aov are both {}: the hit buffer would replace the picture",
                out.display()
            );
        }
        // Writing into the cache directory could replace the input itself.
        let cache_dir = if args.path.is_dir() {
            Some(args.path.as_path())
        } else {
            args.path.parent()
        };
        for (flag, path) in [("--out", &args.out), ("--aov", &args.aov)] {
            if let (Some(p), Some(dir)) = (path, cache_dir)
                && let Some(name) = p.file_name().and_then(|n| n.to_str())
                && (name.ends_with(".slc") || name == slosh_cache::MANIFEST_NAME)
                && p.parent().and_then(|d| d.canonicalize().ok()) == dir.canonicalize().ok()
            {
                bail!(
                    "{flag} {}: that is a file of the cache being rendered; write the frame elsewhere",
                    p.display()
                );
            }
        }
        let (width, height) = parse_size(&args.size)?;
        // A frame holds its hits and pixels on the device and again in memory when read back
        // (about 120 bytes a pixel): refuse what the machine cannot hold instead of aborting.
        let needed = u64::from(width) * u64::from(height) * BYTES_PER_PIXEL;
        if let Some(available) = slosh_bake::available_memory()
            && needed > available
        {
            bail!(
                "--size {}: a {width}×{height} frame needs about {:.1} GB for its buffers; this machine has {:.1} GB available",
                args.size,
                needed as f64 / 1e9,
                available as f64 / 1e9
            );
        }
        let (steps, sequence) = match &args.steps {
            Some(range) => (parse_steps(range)?, true),
            None => (vec![args.step], false),
        };
        if sequence {
            for (flag, path) in [("--out", &args.out), ("--aov", &args.aov)] {
                if let Some(p) = path
                    && !p.to_string_lossy().contains('{')
                {
                    bail!(
                        "{flag} {}: a sequence needs a pattern with {{}} or {{:05}} for the step number",
                        p.display()
                    );
                }
            }
        }
        Ok(RenderConfig {
            steps,
            sequence,
            width,
            height,
        })
    }
}

/// The framing camera of the step, up from `--up`, else from the data (the header's `up`),
/// else z; `--eye` and `--target` replace the framing's.
fn camera_for(
    args: &RenderArgs,
    header: &slosh_cache::Header,
    width: u32,
    height: u32,
) -> Result<Camera> {
    let up = match &args.up {
        Some(u) => parse_vec3("up", u)?,
        None => header.up.unwrap_or([0.0, 0.0, 1.0]),
    };
    let mut camera = Camera::framing(&header.bounds, args.fov, width, height, up);
    // An explicit up is taken as given (the framing snapped it to an axis).
    camera.up = up;
    if let Some(e) = &args.eye {
        camera.eye = parse_vec3("eye", e)?;
    }
    if let Some(t) = &args.target {
        camera.target = parse_vec3("target", t)?;
    }
    // A camera with no view direction, or an up along it, has no image plane.
    let view: [f64; 3] = std::array::from_fn(|a| camera.target[a] - camera.eye[a]);
    let length = (view[0] * view[0] + view[1] * view[1] + view[2] * view[2]).sqrt();
    if length.is_nan() || length == 0.0 {
        bail!("--eye and --target are the same point: the camera looks nowhere");
    }
    let up_length = (camera.up.iter().map(|u| u * u).sum::<f64>()).sqrt();
    let along = (view[0] * camera.up[0] + view[1] * camera.up[1] + view[2] * camera.up[2]).abs();
    if up_length.is_nan() || up_length == 0.0 || along > 0.9999 * length * up_length {
        bail!(
            "--up {:?} is parallel to the view direction (or zero): give an up that is not along --target minus --eye",
            camera.up
        );
    }
    Ok(camera)
}

fn h_factor(args: &RenderArgs, baked: f64) -> f64 {
    args.h_scale.map_or(1.0, |h| h / baked)
}

pub fn run(args: &RenderArgs) -> Result<()> {
    let config = RenderConfig::from_args(args)?;
    let first = CacheFile::open(&step_path(&args.path, config.steps[0]))
        .with_context(|| format!("opening step {}", config.steps[0]))?;
    // The first step of the range with particles frames it (a Lagrangian run's first steps
    // may hold none, and an empty step has no extent).
    let framing = match first.header().points {
        0 => config
            .steps
            .iter()
            .skip(1)
            .filter_map(|&s| CacheFile::open(&step_path(&args.path, s)).ok())
            .find(|f| f.header().points > 0)
            .unwrap_or(first),
        _ => first,
    };
    let camera = camera_for(args, framing.header(), config.width, config.height)?;
    drop(framing);
    let manifest = if args.path.is_dir() {
        slosh_cache::Manifest::read(&args.path).ok()
    } else {
        None
    };
    // Output folders (e.g. frames/ of a sequence) are created as needed.
    for pattern in [&args.out, &args.aov].into_iter().flatten() {
        if let Some(dir) = expand_pattern(pattern, 0).parent()
            && !dir.as_os_str().is_empty()
        {
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        }
    }
    let targets = |step: usize| {
        (
            args.out.as_ref().map(|p| expand_pattern(p, step)),
            args.aov.as_ref().map(|p| expand_pattern(p, step)),
        )
    };
    if args.cpu {
        for &step in &config.steps {
            let (out, aov) = targets(step);
            render_cpu(
                args,
                manifest.as_ref(),
                &camera,
                step,
                out.as_deref(),
                aov.as_deref(),
            )?;
        }
        return Ok(());
    }
    let gpu = slosh_render::Gpu::new(args.adapter.as_deref())?;
    let (tracer, passes) = (Tracer::new(&gpu)?, slosh_render::StepPasses::new(&gpu));
    if config.sequence {
        say!(
            "rendering {} steps on {}",
            config.steps.len(),
            gpu.describe()
        );
    }
    for &step in &config.steps {
        let path = step_path(&args.path, step);
        let file = CacheFile::open(&path).with_context(|| format!("opening step {step}"))?;
        check_belongs(manifest.as_ref(), &args.path, step, &path, &file)?;
        let h = file.header();
        let params = TraceParams {
            iterations: args.iterations,
            degree: args.degree.unwrap_or(h.mls.degree),
            h_factor: h_factor(args, h.mls.h_scale) as f32,
            covariance: args.covariance || h.mls.normals == "covariance",
            epsilon: 1e-4,
            mode: args.mode.into(),
            field_range: None,
            key_light: slosh_render::DEFAULT_KEY_LIGHT,
        };
        let start = std::time::Instant::now();
        let (gpu_step, frame) = slosh_play::export::trace_file(
            &gpu,
            &tracer,
            &passes,
            &file,
            args.field.as_deref(),
            &camera,
            &params,
        )?;
        // The frame's time, the upload's (timed on its own) left out.
        let seconds = start.elapsed().as_secs_f64() - gpu_step.upload.total_seconds;
        let (out, aov) = targets(step);
        if let Some(out) = &out {
            write_frame_png(out, &frame)?;
        }
        if let Some(aov) = &aov {
            write_npy(
                aov,
                frame.height,
                frame.width,
                8,
                &cpu_shade::gpu_hit_buffer(&gpu_step, &frame.hits),
            )?;
        }
        let hits = frame.hits.iter().filter(|h| h.status != 0).count();
        let up = gpu_step.upload;
        say!(
            "step {step} ({} points): {}x{}, {} iterations, {hits} hit pixels; upload {:.1} ms ({:.2} GB/s), frame {:.1} ms with readback, on {}",
            h.points,
            frame.width,
            frame.height,
            params.iterations,
            up.total_seconds * 1e3,
            up.gigabytes_per_second(),
            seconds * 1e3,
            gpu.info.name
        );
    }
    Ok(())
}

fn render_cpu(
    args: &RenderArgs,
    manifest: Option<&slosh_cache::Manifest>,
    camera: &Camera,
    step_index: usize,
    out: Option<&Path>,
    aov: Option<&Path>,
) -> Result<()> {
    let (width, height) = (camera.width, camera.height);
    let path = step_path(&args.path, step_index);
    let file = CacheFile::open(&path).with_context(|| format!("opening step {step_index}"))?;
    check_belongs(manifest, &args.path, step_index, &path, &file)?;
    let step = LoadedStep::load(&file)?;
    let h = file.header();
    let params = Params {
        degree: args.degree.unwrap_or(h.mls.degree),
        iterations: args.iterations,
        epsilon: 1e-4,
        normals: if args.covariance || h.mls.normals == "covariance" {
            NormalsMode::Covariance
        } else {
            NormalsMode::Mean
        },
        h_factor: h_factor(args, h.mls.h_scale) as f32,
    };
    let start = std::time::Instant::now();
    let hits = step.render(camera, &params);
    let seconds = start.elapsed().as_secs_f64();
    let hit_count = hits.iter().filter(|h| h.is_some()).count();
    if let Some(out) = out {
        let mut rgb = Vec::with_capacity(hits.len() * 3);
        for (i, hit) in hits.iter().enumerate() {
            let (x, y) = (i as u32 % width, i as u32 / width);
            let colour = match hit {
                Some(hit) => cpu_shade::shade(hit, camera.ray(x, y).1, args.mode.into()),
                None => cpu_shade::background(y, height),
            };
            rgb.extend(colour.map(cpu_shade::srgb));
        }
        write_png(out, width, height, &rgb)?;
    }
    if let Some(aov) = aov {
        write_npy(aov, height, width, 8, &cpu_shade::cpu_hit_buffer(&hits))?;
    }
    say!(
        "step {} ({} points): {width}x{height}, {} iterations, {hit_count} hit pixels, traced in {seconds:.2} s on the CPU",
        h.source.step,
        h.points,
        args.iterations
    );
    Ok(())
}
