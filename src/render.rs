//! `slosh render`: frames (PNG, or an MP4 movie of a range) and hit buffers (.npy) from a
//! cache, one step or a range of steps. The GPU path uploads each step into wgpu buffers and runs the WGSL trace and shade
//! passes; `--cpu` runs the CPU reference tracer on the mapped cache through its baked BVH.

use slosh_fileio::say;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use slosh_cache::{CacheFile, LoadedStep, step_file_name};
use slosh_mls::{Camera, NormalsMode, Params};
use slosh_render::{TraceParams, Tracer, cpu_shade};

use crate::config::render::RenderConfig;

fn step_path(path: &Path, step: usize) -> PathBuf {
    if path.is_dir() {
        path.join(step_file_name(step))
    } else {
        path.to_path_buf()
    }
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

/// The framing camera of the step, up from `--up`, else from the data (the header's `up`),
/// else z; `--eye` and `--target` replace the framing's.
fn camera_for(cfg: &RenderConfig, header: &slosh_cache::Header) -> Result<Camera> {
    let up = cfg.view.up.or(header.up).unwrap_or([0.0, 0.0, 1.0]);
    let mut camera = Camera::framing(&header.bounds, cfg.view.fov, cfg.width, cfg.height, up);
    // An explicit up is taken as given (the framing snapped it to an axis).
    camera.up = up;
    if let Some(eye) = cfg.view.eye {
        camera.eye = eye;
    }
    if let Some(target) = cfg.view.target {
        camera.target = target;
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

fn h_factor(cfg: &RenderConfig, baked: f64) -> f64 {
    cfg.h_scale.map_or(1.0, |h| h / baked)
}

pub fn run(config: &RenderConfig) -> Result<()> {
    let first = CacheFile::open(&step_path(&config.path, config.steps[0]))
        .with_context(|| format!("opening step {}", config.steps[0]))?;
    // The first step of the range with particles frames it (a Lagrangian run's first steps
    // may hold none, and an empty step has no extent).
    let framing = match first.header().points {
        0 => config
            .steps
            .iter()
            .skip(1)
            .filter_map(|&s| CacheFile::open(&step_path(&config.path, s)).ok())
            .find(|f| f.header().points > 0)
            .unwrap_or(first),
        _ => first,
    };
    let camera = camera_for(config, framing.header())?;
    drop(framing);
    let manifest = if config.path.is_dir() {
        slosh_cache::Manifest::read(&config.path).ok()
    } else {
        None
    };
    // Output folders (e.g. frames/ of a sequence) are created as needed.
    for pattern in [&config.out, &config.aov].into_iter().flatten() {
        if let Some(dir) = expand_pattern(pattern, 0).parent()
            && !dir.as_os_str().is_empty()
        {
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        }
    }
    let mut movie = match (config.movie, &config.out) {
        (Some(timing), Some(out)) => Some(start_movie(config, timing, out)?),
        _ => None,
    };
    let targets = |step: usize| {
        (
            config
                .out
                .as_ref()
                .filter(|_| config.movie.is_none())
                .map(|p| expand_pattern(p, step)),
            config.aov.as_ref().map(|p| expand_pattern(p, step)),
        )
    };
    if config.cpu {
        for (i, &step) in config.steps.iter().enumerate() {
            let (out, aov) = targets(step);
            let movie = movie.as_mut().map(|(m, seconds)| (m, seconds[i]));
            render_cpu(
                config,
                manifest.as_ref(),
                &camera,
                step,
                (out.as_deref(), movie),
                aov.as_deref(),
            )?;
        }
        return finish_movie(movie);
    }
    let gpu = slosh_render::Gpu::new(config.adapter.as_deref())?;
    let tracer = Tracer::new(&gpu)?;
    if config.sequence {
        say!(
            "rendering {} steps on {}",
            config.steps.len(),
            gpu.describe()
        );
    }
    for (i, &step) in config.steps.iter().enumerate() {
        let path = step_path(&config.path, step);
        let file = CacheFile::open(&path).with_context(|| format!("opening step {step}"))?;
        check_belongs(manifest.as_ref(), &config.path, step, &path, &file)?;
        let h = file.header();
        let params = TraceParams {
            iterations: config.iterations,
            degree: config.degree.unwrap_or(h.mls.degree),
            h_factor: h_factor(config, h.mls.h_scale) as f32,
            covariance: config.covariance || h.mls.normals == "covariance",
            epsilon: 1e-4,
            mode: config.mode,
            field_range: None,
            colormap: config.colormap,
            key_light: slosh_render::DEFAULT_KEY_LIGHT,
        };
        let start = std::time::Instant::now();
        let (gpu_step, frame) = slosh_play::export::trace_file(
            &gpu,
            &tracer,
            &file,
            config.field.as_deref(),
            &camera,
            &params,
        )?;
        // The frame's time, the upload's (timed on its own) left out.
        let seconds = start.elapsed().as_secs_f64() - gpu_step.upload.total_seconds;
        let (out, aov) = targets(step);
        if let Some(out) = &out {
            slosh_render::write_frame_png(out, &frame)?;
        }
        if let Some((movie, seconds)) = movie.as_mut() {
            let rgba: Vec<u8> = frame.rgba.iter().flat_map(|p| p.to_le_bytes()).collect();
            movie.push_rgba(&rgba, seconds[i])?;
        }
        if let Some(aov) = &aov {
            slosh_render::write_npy(
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
    finish_movie(movie)
}

/// The movie `--out` names, with each step's frame duration (from `--fps`, or the steps'
/// times read from their headers).
fn start_movie(
    config: &RenderConfig,
    timing: slosh_movie::Timing,
    out: &Path,
) -> Result<(slosh_movie::MovieWriter, Vec<f64>)> {
    let mut times = Vec::with_capacity(config.steps.len());
    if matches!(timing, slosh_movie::Timing::SeriesTimes { .. }) {
        for &step in &config.steps {
            let file = CacheFile::open(&step_path(&config.path, step))
                .with_context(|| format!("opening step {step}"))?;
            times.push(file.header().source.time);
        }
    } else {
        times.resize(config.steps.len(), 0.0);
    }
    let seconds = slosh_movie::frame_seconds(timing, &times)
        .map_err(|e| anyhow::anyhow!("{}: {e}", out.display()))?;
    let fps = seconds.len() as f64 / seconds.iter().sum::<f64>();
    let writer = slosh_movie::MovieWriter::new(out, config.width, config.height, fps)?;
    Ok((writer, seconds))
}

fn finish_movie(movie: Option<(slosh_movie::MovieWriter, Vec<f64>)>) -> Result<()> {
    if let Some((movie, _)) = movie {
        let path = movie.path().to_path_buf();
        let s = movie.finish()?;
        say!(
            "wrote {}: {} frames, {}x{}, {:.3} s, {:.1} MB (H.264 in MP4)",
            path.display(),
            s.frames,
            s.width,
            s.height,
            s.seconds,
            s.bytes as f64 / 1e6
        );
    }
    Ok(())
}

fn render_cpu(
    config: &RenderConfig,
    manifest: Option<&slosh_cache::Manifest>,
    camera: &Camera,
    step_index: usize,
    (out, movie): (Option<&Path>, Option<(&mut slosh_movie::MovieWriter, f64)>),
    aov: Option<&Path>,
) -> Result<()> {
    let (width, height) = (camera.width, camera.height);
    let path = step_path(&config.path, step_index);
    let file = CacheFile::open(&path).with_context(|| format!("opening step {step_index}"))?;
    check_belongs(manifest, &config.path, step_index, &path, &file)?;
    let step = LoadedStep::load(&file)?;
    let h = file.header();
    let params = Params {
        degree: config.degree.unwrap_or(h.mls.degree),
        iterations: config.iterations,
        epsilon: 1e-4,
        normals: if config.covariance || h.mls.normals == "covariance" {
            NormalsMode::Covariance
        } else {
            NormalsMode::Mean
        },
        h_factor: h_factor(config, h.mls.h_scale) as f32,
    };
    let start = std::time::Instant::now();
    let hits = step.render(camera, &params);
    let seconds = start.elapsed().as_secs_f64();
    let hit_count = hits.iter().filter(|h| h.is_some()).count();
    if out.is_some() || movie.is_some() {
        let mut rgb = Vec::with_capacity(hits.len() * 3);
        for (i, hit) in hits.iter().enumerate() {
            let (x, y) = (i as u32 % width, i as u32 / width);
            let colour = match hit {
                Some(hit) => cpu_shade::shade(hit, camera.ray(x, y).1, config.mode),
                None => cpu_shade::background(y, height),
            };
            rgb.extend(colour.map(cpu_shade::srgb));
        }
        if let Some(out) = out {
            slosh_render::write_rgb_png(out, width, height, &rgb)?;
        }
        if let Some((movie, seconds)) = movie {
            movie.push_rgb(&rgb, seconds)?;
        }
    }
    if let Some(aov) = aov {
        slosh_render::write_npy(aov, height, width, 8, &cpu_shade::cpu_hit_buffer(&hits))?;
    }
    say!(
        "step {} ({} points): {width}x{height}, {} iterations, {hit_count} hit pixels, traced in {seconds:.2} s on the CPU",
        h.source.step,
        h.points,
        config.iterations
    );
    Ok(())
}
