//! `slosh play` flags turned into the player's validated options.

use anyhow::{Result, bail};
use slosh_play::EngineOptions;
use slosh_play::app::PlayOptions;

use crate::cli::PlayArgs;

fn up_axis(s: &str) -> Result<[f64; 3]> {
    Ok(match s {
        "x" | "X" => [1.0, 0.0, 0.0],
        "y" | "Y" => [0.0, 1.0, 0.0],
        "z" | "Z" => [0.0, 0.0, 1.0],
        other => bail!("--up {other}: expected x, y or z"),
    })
}

fn window(s: &str) -> Result<(f32, f32)> {
    let (w, h) = super::render::parse_size("window", s)?;
    Ok((w as f32, h as f32))
}

/// The player's options from `slosh play`'s flags, every value checked.
pub fn play_options(args: &PlayArgs) -> Result<PlayOptions> {
    let (dir, bake) = if args.input.is_dir() {
        if args.cache.is_some() {
            bail!(
                "--cache: {} is a cache directory already (--cache is where a .case file's steps are baked)",
                args.input.display()
            );
        }
        (args.input.clone(), None)
    } else if args.input.is_file() {
        let bake = super::on_demand::open(
            &args.input,
            args.cache.as_deref(),
            &args.bake,
            args.field.as_deref(),
            // Each loader bakes a step: as many steps at once as loaders.
            (
                args.adapter.as_deref(),
                args.loaders
                    .map(|n| n.clamp(1, super::most_jobs(slosh_bake::cores()))),
            ),
        )?;
        (bake.dir().to_path_buf(), Some(std::sync::Arc::new(bake)))
    } else {
        bail!(
            "{}: no such cache directory or .case file (give the --out directory of `slosh bake`, or the case)",
            args.input.display()
        );
    };
    let budget = match args.budget {
        Some(g) if g.is_finite() && g > 0.0 => Some((g * f64::from(1u32 << 30)) as u64),
        Some(g) => bail!("--budget {g}: expected a positive number of GiB"),
        None => None,
    };
    if !(0.25..=2.0).contains(&args.render_scale) {
        bail!("--render-scale {}: expected 0.25 to 2", args.render_scale);
    }
    let frame_budget_ms = match args.frame_budget_ms {
        0.0 => None,
        ms if ms.is_finite() && ms > 0.0 => Some(ms),
        ms => bail!(
            "--frame-budget-ms {ms}: expected a positive number of milliseconds, or 0 for none"
        ),
    };
    let mut engine = EngineOptions {
        budget,
        field: args.field.clone(),
        load_delay: args.load_delay_ms.map(std::time::Duration::from_millis),
        ..EngineOptions::default()
    };
    if let Some(n) = args.loaders {
        engine.loaders = n.clamp(1, 64);
    }
    // A raw case's loaders each bake a step: as many as its bake takes at once (`--loaders`,
    // else `slosh_bake::viewer_jobs`: what `slosh bake` would take, at most half the cores).
    if let Some(bake) = &bake {
        engine.loaders = bake.jobs();
    }
    Ok(PlayOptions {
        dir,
        bake,
        adapter: args.adapter.clone(),
        engine,
        render_scale: args.render_scale,
        up: args.up.as_deref().map(up_axis).transpose()?,
        iterations: args.iterations.clamp(1, 8),
        mode: args.mode.into(),
        frame_budget_ms,
        window: window(&args.window)?,
        output: args.output.clone(),
        log_frames: args.log_frames,
        range_mode: slosh_play::RangeMode::parse(&args.field_range)
            .map_err(|why| anyhow::anyhow!("--field-range {why}"))?,
        colormap: args.colormap.into(),
    })
}
