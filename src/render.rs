//! `slosh render`: frames (PNG, or an MP4 movie of a range) and hit buffers (.npy) from a
//! cache, one step or a range of steps. The GPU path uploads each step into wgpu buffers and runs the WGSL trace and shade
//! passes; `--cpu` runs the CPU reference tracer on the mapped cache through its baked BVH.

use slosh_fileio::say;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use slosh_cache::{CacheFile, LoadedStep, step_file_name};
use slosh_mls::{Camera, HitStatus, NormalsMode, Params};
use slosh_play::RangeMode;
use slosh_play::export::{check_belongs, step_pattern};
use slosh_play::overlay::{Legend, Overlay};
use slosh_render::{TraceParams, Tracer, cpu_shade};

use crate::config::render::RenderConfig;

/// Bakes the `steps` of the case `args.path` that its cache does not hold yet (`slosh bake`'s
/// single-step bake, with the default fit and `args.bake`'s selection), going on past a step
/// that fails: the cache directory, and the steps that did not bake (each said on stderr),
/// which the render leaves out and reports. An error where none baked.
pub fn bake_case(args: &crate::cli::RenderArgs, steps: &[usize]) -> Result<(PathBuf, Vec<usize>)> {
    let settings = crate::cli::BakeSettings {
        fit: crate::cli::FitSettings::default(),
        select: args.bake.clone(),
    };
    let bake = crate::config::on_demand::open(
        &args.path,
        args.cache.as_deref(),
        &settings,
        args.field.as_deref(),
        // One step at a time, on every core.
        (args.adapter.as_deref(), None),
    )?;
    let mut failed = Vec::new();
    for &step in steps {
        match bake.bake(step) {
            slosh_bake::StepOutcome::Baked {
                seconds,
                points,
                stats,
                ..
            } => {
                let dropped = dropped_particles(&stats);
                say!("baked step {step} ({points} points, {seconds:.2} s{dropped})");
            }
            slosh_bake::StepOutcome::Kept => {}
            slosh_bake::StepOutcome::Failed(why) => {
                eprintln!("step {step} did not bake: {why}");
                failed.push(step);
            }
        }
    }
    if failed.len() == steps.len() {
        anyhow::bail!(
            "{} of {} steps did not bake (steps {failed:?}); nothing was rendered",
            failed.len(),
            steps.len()
        );
    }
    Ok((bake.dir().to_path_buf(), failed))
}

/// The particles a step's bake dropped as damaged input, said after its line ("" for none), as
/// the bake's summary says them.
fn dropped_particles(stats: &slosh_cache::StepStats) -> String {
    slosh_bake::dropped_input(stats.dropped_non_finite, stats.dropped_far)
        .map_or(String::new(), |dropped| format!("; dropped {dropped}"))
}

/// A case render's outcome: the render's, with the `unbaked` of the `asked` steps named too
/// (a render that also failed to draw some of the others says both).
pub fn with_unbaked(rendered: Result<()>, unbaked: &[usize], asked: usize) -> Result<()> {
    if unbaked.is_empty() {
        return rendered;
    }
    let did_not_bake = format!(
        "{} of {asked} steps did not bake (steps {unbaked:?})",
        unbaked.len()
    );
    match rendered {
        Ok(()) => bail!("{did_not_bake}; the others were rendered"),
        Err(e) => Err(e.context(did_not_bake)),
    }
}

/// The widest range of `field`'s finite values over the steps `config` draws, so that a
/// colour means one value through a sequence: each step's header's (format 9.1), else its
/// values' (decoded); a step that cannot be read, or has no such field or no finite value of
/// it, adds nothing (the frame loop reports the first two).
fn series_field_range(config: &RenderConfig, field: &str) -> Option<(f32, f32)> {
    let ranges: Vec<(f32, f32)> = config
        .steps
        .iter()
        .filter_map(|&step| {
            let file = CacheFile::open(&step_path(&config.path, step)).ok()?;
            let header = file.header();
            if !header.field_ranges.is_empty() {
                let [lo, hi] = *header.field_ranges.get(field)?;
                return Some((lo, hi));
            }
            slosh_render::HostField::read(&file, field).ok()?.range()
        })
        .collect();
    let range = ranges
        .into_iter()
        .reduce(|(a, b), (lo, hi)| (a.min(lo), b.max(hi)));
    if let Some((lo, hi)) = range {
        say!(
            "colours of '{field}' span {lo:e} to {hi:e}, its range over the {} steps",
            config.steps.len()
        );
    }
    range
}

/// What a camera frames: a box, and the data's up where a step recorded one.
struct Framing {
    bounds: [[f64; 3]; 2],
    up: Option<[f64; 3]>,
}

/// The framing of the steps `config` draws: the union of the bounds of those that open and
/// hold particles (a dam break spreads far beyond its first step's column; a Lagrangian
/// run's first steps may hold none, and an empty step has no extent), with the data's up
/// (the first such step's); `None` where there is no such step.
fn sequence_framing(config: &RenderConfig) -> Option<Framing> {
    config
        .steps
        .iter()
        .filter_map(|&s| CacheFile::open(&step_path(&config.path, s)).ok())
        .filter(|f| f.header().points > 0)
        .map(|f| Framing {
            bounds: f.header().bounds,
            up: f.header().up,
        })
        .reduce(|union, next| {
            let (a, b) = (union.bounds, next.bounds);
            Framing {
                bounds: [
                    std::array::from_fn(|k| a[0][k].min(b[0][k])),
                    std::array::from_fn(|k| a[1][k].max(b[1][k])),
                ],
                up: union.up,
            }
        })
}

fn step_path(path: &Path, step: usize) -> PathBuf {
    if path.is_dir() {
        path.join(step_file_name(step))
    } else {
        path.to_path_buf()
    }
}

/// The camera framing `bounds`, up from `--up`, else from the data (`data_up`, a header's),
/// else z; `--eye` and `--target` replace the framing's.
fn camera_for(
    cfg: &RenderConfig,
    bounds: &[[f64; 3]; 2],
    data_up: Option<[f64; 3]>,
) -> Result<Camera> {
    let up = cfg.view.up.or(data_up).unwrap_or([0.0, 0.0, 1.0]);
    let mut camera = Camera::framing(bounds, cfg.view.fov, cfg.width, cfg.height, up);
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
    // Framed by the first step that opens (a sequence goes on past one that does not).
    let first = match config
        .steps
        .iter()
        .find_map(|&s| CacheFile::open(&step_path(&config.path, s)).ok())
    {
        Some(file) => file,
        None => CacheFile::open(&step_path(&config.path, config.steps[0]))
            .with_context(|| format!("opening step {}", config.steps[0]))?,
    };
    let framing = sequence_framing(config).unwrap_or(Framing {
        bounds: first.header().bounds,
        up: first.header().up,
    });
    let camera = camera_for(config, &framing.bounds, framing.up)?;
    drop(first);
    let manifest = if config.path.is_dir() {
        slosh_cache::Manifest::read(&config.path).ok()
    } else {
        None
    };
    // Output folders (e.g. frames/ of a sequence) are created as needed.
    for pattern in [&config.out, &config.aov].into_iter().flatten() {
        if let Some(dir) = step_pattern(pattern, 0).parent()
            && !dir.as_os_str().is_empty()
        {
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        }
    }
    let mut movie = match (config.movie, &config.out) {
        (Some(timing), Some(out)) => {
            let files: Vec<PathBuf> = config
                .steps
                .iter()
                .map(|&s| step_path(&config.path, s))
                .collect();
            let size = (config.width, config.height);
            Some(
                slosh_play::export::open_movie(out, timing, &files, size)
                    .map_err(anyhow::Error::msg)?,
            )
        }
        _ => None,
    };
    let targets = |step: usize| {
        (
            config
                .out
                .as_ref()
                .filter(|_| config.movie.is_none())
                .map(|p| step_pattern(p, step)),
            config.aov.as_ref().map(|p| step_pattern(p, step)),
        )
    };
    let field_range = match (config.field.as_deref(), config.field_range) {
        (_, RangeMode::Fixed(lo, hi)) => Some((lo, hi)),
        (Some(field), RangeMode::Series) if config.steps.len() > 1 => {
            series_field_range(config, field)
        }
        _ => None,
    };
    // Steps that could not be drawn, each said when it failed; a sequence goes on past them.
    let mut failed = Vec::new();
    if config.cpu {
        for (i, &step) in config.steps.iter().enumerate() {
            let (out, aov) = targets(step);
            let making_movie = movie.is_some();
            let frame = movie.as_mut().map(|(m, seconds)| (m, seconds[i]));
            let drawn = render_cpu(
                config,
                manifest.as_ref(),
                (&camera, field_range),
                step,
                (out.as_deref(), frame),
                aov.as_deref(),
            );
            go_on(drawn, step, making_movie, &mut failed)?;
        }
        finish_movie(movie)?;
        return all_drawn(&failed, config.steps.len());
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
        let making_movie = movie.is_some();
        let mut draw = || -> Result<()> {
            let path = step_path(&config.path, step);
            let file = CacheFile::open(&path).with_context(|| format!("opening step {step}"))?;
            check_belongs(manifest.as_ref(), &config.path, step, &path, &file)
                .map_err(anyhow::Error::msg)?;
            let h = file.header();
            let params = TraceParams {
                iterations: config.iterations,
                degree: config.degree.unwrap_or(h.mls.degree),
                h_factor: h_factor(config, h.mls.h_scale) as f32,
                covariance: config.covariance || h.mls.normals == "covariance",
                epsilon: 1e-4,
                mode: config.mode,
                field_range,
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
            let overlay = config
                .labels
                .then(|| Overlay::for_step(h.source.time, step, &gpu_step, &params));
            let rgb = slosh_play::overlay::frame_rgb(&frame, overlay.as_ref());
            if let Some(out) = &out {
                slosh_render::write_rgb_png(out, frame.width, frame.height, &rgb)?;
            }
            if let Some((movie, seconds)) = movie.as_mut() {
                movie.push_rgb(&rgb, seconds[i])?;
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
            if let Some((name, _, _)) = gpu_step
                .field
                .as_ref()
                .filter(|_| gpu_step.field_missing > 0)
            {
                say!(
                    "step {step}: {} of {} points have no finite value of '{name}'; a hit that finds none (a one-iteration frame reads its ball's own) is drawn magenta",
                    gpu_step.field_missing,
                    h.points
                );
            }
            Ok(())
        };
        go_on(draw(), step, making_movie, &mut failed)?;
    }
    finish_movie(movie)?;
    all_drawn(&failed, config.steps.len())
}

/// A step that was not drawn: said, and counted in `failed`, so that a sequence goes on past
/// it; a movie stops there (one with a frame missing would pass for whole).
fn go_on(drawn: Result<()>, step: usize, movie: bool, failed: &mut Vec<usize>) -> Result<()> {
    match drawn {
        Ok(()) => Ok(()),
        Err(e) if movie => Err(e.context(format!("step {step}; the movie was not made"))),
        Err(e) => {
            eprintln!("step {step}: {}", crate::message(&e));
            failed.push(step);
            Ok(())
        }
    }
}

/// An error naming the steps that were not drawn, if any.
fn all_drawn(failed: &[usize], steps: usize) -> Result<()> {
    if failed.is_empty() {
        return Ok(());
    }
    anyhow::bail!(
        "{} of {steps} steps were not drawn (steps {failed:?}); the others were",
        failed.len()
    )
}

fn finish_movie(movie: Option<(slosh_movie::MovieWriter, Vec<f64>)>) -> Result<()> {
    if let Some((movie, _)) = movie {
        say!(
            "{}",
            slosh_play::export::finish_movie(movie).map_err(anyhow::Error::msg)?
        );
    }
    Ok(())
}

/// Each hit's colour of field `name` before lighting, as the shade pass colours it: in a
/// refined frame the MLS-weighted mean over the hit ball's neighbours (`SurfaceProbe`,
/// missing values left out), in a one-iteration frame the ball's own value; placed on the
/// colour map over `range` (the step's own where `None`);
/// magenta where no value is found; a droplet keeps the surface's colour (`None`); and the
/// range the colours span (`None` where the step has no value to span).
fn field_colours(
    file: &CacheFile,
    name: &str,
    hits: &[Option<slosh_mls::TraceHit>],
    range: Option<(f32, f32)>,
    (colormap, h_factor, iterations): (slosh_render::Colormap, f32, u32),
) -> Result<FieldColours> {
    let field = slosh_render::HostField::read(file, name)?;
    let values: Vec<f32> = field
        .bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    let range = range.or(field.range());
    let (lo, hi) = range.unwrap_or((0.0, 0.0));
    let map = slosh_render::FieldMap::new(lo, hi);
    // Only a refined frame weighs neighbours, and the probe builds a tree of the points.
    let probe = (iterations > 1)
        .then(|| slosh_cache::SurfaceProbe::open(file))
        .transpose()?;
    let transform = file.header().transform;
    let colours = hits
        .iter()
        .map(|hit| {
            let hit = hit.as_ref().filter(|h| h.status != HitStatus::Droplet)?;
            let ball = hit.ball as usize;
            let value = match &probe {
                Some(probe) => {
                    let local = transform.to_local(hit.position).map(|c| c as f32);
                    let reading = probe.read(local, Some(ball), h_factor, Some(&values));
                    reading.and_then(|r| r.field)
                }
                None => values
                    .get(ball)
                    .copied()
                    .filter(|&v| !slosh_cache::field_missing(v)),
            };
            let colour = match value {
                Some(v) => colormap.at(map.t(v)),
                None => slosh_render::MISSING_FIELD_COLOUR,
            };
            Some(colour.map(f64::from))
        })
        .collect();
    Ok(FieldColours { colours, range })
}

/// The colours of a field at a frame's hits ([`field_colours`]), and the range they span.
struct FieldColours {
    colours: Vec<Option<[f64; 3]>>,
    range: Option<(f32, f32)>,
}

fn render_cpu(
    config: &RenderConfig,
    manifest: Option<&slosh_cache::Manifest>,
    (camera, field_range): (&Camera, Option<(f32, f32)>),
    step_index: usize,
    (out, movie): (Option<&Path>, Option<(&mut slosh_movie::MovieWriter, f64)>),
    aov: Option<&Path>,
) -> Result<()> {
    let (width, height) = (camera.width, camera.height);
    let path = step_path(&config.path, step_index);
    let file = CacheFile::open(&path).with_context(|| format!("opening step {step_index}"))?;
    check_belongs(manifest, &config.path, step_index, &path, &file).map_err(anyhow::Error::msg)?;
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
        let coloured = match config.field.as_deref() {
            Some(name) => {
                let how = (config.colormap, params.h_factor, params.iterations);
                Some((name, field_colours(&file, name, &hits, field_range, how)?))
            }
            None => None,
        };
        let base = |i: usize| coloured.as_ref().and_then(|(_, c)| c.colours[i]);
        let mut rgb = cpu_shade::cpu_frame_rgb_coloured(&hits, camera, config.mode, base);
        if config.labels {
            let time = Some((h.source.time, step_index));
            let legend = coloured.as_ref().map(|(name, c)| Legend {
                field: name.to_string(),
                range: c.range,
                colormap: config.colormap,
            });
            let overlay = Overlay { time, legend };
            slosh_play::overlay::draw(&mut rgb, width, height, &overlay);
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Steps that did not bake are named whether or not the render drew all the others.
    #[test]
    fn a_case_render_names_unbaked_and_undrawn_steps_alike() {
        let said = |r: Result<()>| r.map_err(|e| crate::message(&e)).unwrap_err();
        assert_eq!(
            said(with_unbaked(Ok(()), &[2], 3)),
            "1 of 3 steps did not bake (steps [2]); the others were rendered"
        );
        assert_eq!(
            said(with_unbaked(all_drawn(&[0], 2), &[2], 3)),
            "1 of 3 steps did not bake (steps [2]): 1 of 2 steps were not drawn (steps [0]); \
             the others were"
        );
        assert!(with_unbaked(Ok(()), &[], 3).is_ok());
        assert_eq!(
            said(with_unbaked(all_drawn(&[1], 3), &[], 3)),
            "1 of 3 steps were not drawn (steps [1]); the others were"
        );
    }
}
