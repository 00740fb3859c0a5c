//! `slosh render` flags turned into one validated [`RenderConfig`], and the size and vector
//! grammars that other subcommands share.

use std::path::PathBuf;

use anyhow::{Result, anyhow, bail};
use slosh_render::ShadeMode;

use crate::cli::{ModeArg, RenderArgs};

/// `X,Y,Z` of finite numbers, for `--flag`.
pub fn parse_vec3(flag: &str, s: &str) -> Result<[f64; 3]> {
    let parts: Vec<&str> = s.split(',').collect();
    let bad = || anyhow!("--{flag} {s}: expected X,Y,Z");
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

/// The most pixels a `WxH` flag may ask for.
const MAX_PIXELS: u64 = 1 << 28;

/// `WxH` of positive sides, at most [`MAX_PIXELS`] pixels, for `--flag`.
pub fn parse_size(flag: &str, s: &str) -> Result<(u32, u32)> {
    let bad = || anyhow!("--{flag} {s}: expected WxH, e.g. 1280x800");
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(bad)?;
    let (w, h): (u32, u32) = (w.parse().map_err(|_| bad())?, h.parse().map_err(|_| bad())?);
    if w == 0 || h == 0 {
        bail!("--{flag} {s}: expected both sides of at least one pixel");
    }
    let pixels = u64::from(w) * u64::from(h);
    if pixels > MAX_PIXELS {
        bail!("--{flag} {s}: {pixels} pixels, expected at most {MAX_PIXELS} (16384x16384)");
    }
    Ok((w, h))
}

/// Memory a rendered frame takes per pixel: hits and pixels on the device, their readback
/// and the hit buffer written out.
const BYTES_PER_PIXEL: u64 = 120;

/// Where the camera looks from, as given; what is not given comes from the step's framing.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewFlags {
    pub eye: Option<[f64; 3]>,
    pub target: Option<[f64; 3]>,
    pub up: Option<[f64; 3]>,
    /// Vertical field of view in degrees, in (0, 180).
    pub fov: f64,
}

/// The validated settings of one `slosh render` run.
#[derive(Debug, Clone)]
pub struct RenderConfig {
    /// A cache directory or one step file.
    pub path: PathBuf,
    pub steps: Vec<usize>,
    /// A range of steps (`--steps`): the outputs are patterns.
    pub sequence: bool,
    pub width: u32,
    pub height: u32,
    pub view: ViewFlags,
    pub iterations: u32,
    pub mode: ShadeMode,
    pub out: Option<PathBuf>,
    /// `--out` is an MP4, timed so.
    pub movie: Option<slosh_movie::Timing>,
    pub aov: Option<PathBuf>,
    pub cpu: bool,
    pub degree: Option<u8>,
    pub h_scale: Option<f64>,
    pub covariance: bool,
    pub field: Option<String>,
    /// How the field's values span the colour map (`--field-range`).
    pub field_range: slosh_play::RangeMode,
    pub colormap: slosh_render::Colormap,
    /// The time label and legend drawn into each frame.
    pub labels: bool,
    pub adapter: Option<String>,
}

impl RenderConfig {
    pub fn from_args(args: &RenderArgs) -> Result<RenderConfig> {
        if args.out.is_none() && args.aov.is_none() {
            bail!("nothing to write: give --out frame.png and/or --aov hits.npy");
        }
        if args.iterations == 0 {
            bail!("--iterations must be at least 1");
        }
        if args.h_scale.is_some_and(|h| !(h.is_finite() && h > 0.0)) {
            bail!("--h-scale must be a positive number");
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
        let (width, height) = parse_size("size", &args.size)?;
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
            Some(range) => {
                let (first, last) = super::parse_step_range(range)?;
                ((first..=last).collect(), true)
            }
            None => (vec![args.step], false),
        };
        let movie = args
            .out
            .as_ref()
            .filter(|p| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("mp4")))
            .map(|_| match args.fps {
                Some(fps) => slosh_movie::Timing::Fps(fps),
                None => slosh_movie::Timing::SeriesTimes {
                    slowdown: args.slowdown.unwrap_or(1.0),
                },
            });
        if movie.is_none() && (args.fps.is_some() || args.slowdown.is_some()) {
            bail!("--fps and --slowdown time a movie: give --out NAME.mp4");
        }
        if let Some(timing) = movie {
            slosh_movie::frame_seconds(timing, &[0.0, 1.0]).map_err(|e| anyhow!("{e}"))?;
        }
        if sequence {
            let patterned = [("--out", &args.out), ("--aov", &args.aov)];
            for (flag, path) in patterned.into_iter().skip(usize::from(movie.is_some())) {
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
        let vec3 = |flag: &str, value: &Option<String>| {
            value.as_deref().map(|v| parse_vec3(flag, v)).transpose()
        };
        Ok(RenderConfig {
            path: args.path.clone(),
            steps,
            sequence,
            width,
            height,
            view: ViewFlags {
                eye: vec3("eye", &args.eye)?,
                target: vec3("target", &args.target)?,
                up: vec3("up", &args.up)?,
                fov: args.fov,
            },
            iterations: args.iterations,
            mode: args.mode.into(),
            out: args.out.clone(),
            movie,
            aov: args.aov.clone(),
            cpu: args.cpu,
            degree: args.degree,
            h_scale: args.h_scale,
            covariance: args.covariance,
            field: args.field.clone(),
            field_range: slosh_play::RangeMode::parse(&args.field_range)
                .map_err(|why| anyhow::anyhow!("--field-range {why}"))?,
            colormap: args.colormap.into(),
            labels: args.labels,
            adapter: args.adapter.clone(),
        })
    }
}
