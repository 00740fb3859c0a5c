//! `slosh play` (one call into the player) and `slosh demo` (generate, bake, then play, or
//! render frames where there is no display).

use slosh_fileio::say;
use std::path::Path;

use anyhow::{Context, Result};
use clap::Parser;
use slosh_play::app::run as run_player;

use crate::cli::{Cli, PlayArgs};
use crate::config::demo::DemoConfig;
use crate::config::play::play_options;
use crate::config::render::{RenderConfig, ViewFlags};

pub fn play(args: &PlayArgs) -> Result<()> {
    Ok(run_player(play_options(args)?)?)
}

/// Runs a `slosh` command line in this process.
fn slosh(args: &[&str]) -> Result<()> {
    let cli = Cli::try_parse_from(std::iter::once("slosh").chain(args.iter().copied()))
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    crate::run(cli)
}

fn path(p: &Path) -> Result<&str> {
    p.to_str()
        .with_context(|| format!("{}: the demo needs a UTF-8 path", p.display()))
}

/// Whether `cache` holds a complete demo of `steps` steps, baked by this version from the
/// wave scene (an earlier demo's series is made again).
fn demo_ready(cache: &Path, steps: usize) -> bool {
    slosh_cache::Manifest::read(cache).is_ok_and(|m| {
        m.steps.len() == steps
            && m.missing().is_empty()
            && m.source.ends_with("wave.case")
            && m.bake.get("revision").and_then(|r| r.as_u64())
                == Some(u64::from(slosh_bake::BAKE_REVISION))
    })
}

pub fn demo(args: &DemoConfig) -> Result<()> {
    let root = args.root.clone();
    let case_dir = root.join("case");
    let cache = root.join("cache");
    // One demo prepares the directory at a time: another waits, then finds it ready (two
    // writing one case at once would bake a mixture of both). Released before playing.
    std::fs::create_dir_all(&root).with_context(|| format!("creating {}", root.display()))?;
    let lock_path = root.join(".demo.lock");
    let lock = std::fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(&lock_path)
        .with_context(|| format!("opening {}", lock_path.display()))?;
    match lock.try_lock() {
        Ok(()) => {}
        Err(std::fs::TryLockError::WouldBlock) => {
            say!(
                "another slosh demo is preparing {}; waiting for it to finish",
                root.display()
            );
            lock.lock()
                .with_context(|| format!("locking {}", lock_path.display()))?;
        }
        Err(std::fs::TryLockError::Error(e)) => {
            return Err(e).with_context(|| format!("locking {}", lock_path.display()));
        }
    }
    if demo_ready(&cache, args.steps) {
        say!("demo series: {} (already baked)", cache.display());
    } else {
        say!(
            "generating the demo series: a tank sloshing hard, its crests throwing droplets, {} steps of {} particles, in {}",
            args.steps,
            args.points,
            root.display()
        );
        let (steps, points) = (args.steps.to_string(), args.points.to_string());
        slosh(&[
            "gen",
            "wave",
            "--points",
            &points,
            "--steps",
            &steps,
            "--dt",
            "0.02",
            "--out",
            path(&case_dir)?,
        ])?;
        say!("baking it (resumes if interrupted)");
        // The whole body of water, as a solver's particles make it: its surface found from
        // all of them (free surface, walls and floor), so it shows as a closed volume.
        slosh(&[
            "bake",
            path(&case_dir.join("wave.case"))?,
            "--out",
            path(&cache)?,
            "--fields",
            "pressure",
            "--surface",
            "estimate",
        ])?;
    }
    drop(lock);
    let display = std::env::var_os("DISPLAY").is_some_and(|d| !d.is_empty())
        || std::env::var_os("WAYLAND_DISPLAY").is_some_and(|d| !d.is_empty());
    if display && !args.headless {
        let play_args = PlayArgs {
            input: cache.clone(),
            cache: None,
            bake: crate::cli::BakeSettings::default(),
            adapter: None,
            budget: None,
            field: Some("pressure".into()),
            field_range: "series".into(),
            colormap: crate::cli::ColormapArg::Viridis,
            render_scale: 1.0,
            up: None,
            iterations: 3,
            mode: crate::cli::ModeArg::Water,
            frame_budget_ms: 33.0,
            window: "1280x800".into(),
            output: root.clone(),
            loaders: None,
            load_delay_ms: None,
            log_frames: false,
        };
        match run_player(play_options(&play_args)?) {
            Ok(()) => return Ok(()),
            Err(slosh_play::app::AppError::NoGpu(e)) => {
                eprintln!("no Vulkan adapter ({e}); rendering frames with the CPU tracer instead")
            }
            Err(e) => return Err(e.into()),
        }
    } else if !args.headless {
        say!("no display (neither DISPLAY nor WAYLAND_DISPLAY is set): rendering frames instead");
    }
    headless(&cache, &root.join("frames"), args.frames)
}

/// A short sequence of frames, on the GPU where there is one, else the CPU tracer.
fn headless(cache: &Path, frames: &Path, count: usize) -> Result<()> {
    std::fs::create_dir_all(frames).with_context(|| format!("creating {}", frames.display()))?;
    let gpu = slosh_render::Gpu::new(None);
    let cpu = match &gpu {
        Ok(g) => {
            say!("rendering {count} frames on {}", g.describe());
            false
        }
        Err(e) => {
            say!("rendering {count} frames with the CPU tracer (no GPU: {e})");
            true
        }
    };
    drop(gpu);
    crate::render::run(&RenderConfig {
        path: cache.to_path_buf(),
        steps: (0..count).collect(),
        sequence: true,
        width: 640,
        height: 400,
        view: ViewFlags {
            eye: None,
            target: None,
            up: None,
            fov: crate::cli::DEFAULT_FOV,
        },
        iterations: 3,
        // Water where secondary rays can run; the CPU tracer shades.
        mode: if cpu {
            slosh_render::ShadeMode::Shade
        } else {
            slosh_render::ShadeMode::Water
        },
        out: Some(frames.join("{:05}.png")),
        movie: None,
        aov: None,
        cpu,
        degree: None,
        h_scale: None,
        covariance: false,
        field: Some("pressure".to_string()),
        field_range: slosh_play::RangeMode::Series,
        colormap: slosh_render::Colormap::Viridis,
        labels: false,
        adapter: None,
    })?;
    say!(
        "frames: {} ({count} PNG files, 00000.png to {:05}.png)",
        frames.display(),
        count - 1
    );
    Ok(())
}
