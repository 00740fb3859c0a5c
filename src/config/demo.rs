//! `slosh demo` flags turned into one validated [`DemoConfig`].

use std::path::PathBuf;

use anyhow::{Context, Result, bail};

use crate::cli::DemoArgs;

/// Where the demo lives, how large it is, and whether it may open a window.
#[derive(Debug, Clone)]
pub struct DemoConfig {
    /// The demo's folder: `case/`, `cache/` and `frames/` go here.
    pub root: PathBuf,
    pub steps: usize,
    pub points: usize,
    /// Frames rendered where there is no window, at most the steps.
    pub frames: usize,
    pub headless: bool,
}

/// `$XDG_CACHE_HOME/slosh/demo`, else `~/.cache/slosh/demo`.
fn demo_dir() -> Result<PathBuf> {
    let base = std::env::var_os("XDG_CACHE_HOME")
        .map(PathBuf::from)
        .filter(|p| p.is_absolute())
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))
        .context("neither XDG_CACHE_HOME nor HOME is set: give --dir")?;
    Ok(base.join("slosh").join("demo"))
}

impl DemoConfig {
    pub fn from_args(args: &DemoArgs) -> Result<DemoConfig> {
        if args.steps < 2 || args.points < 100 {
            bail!("--steps must be at least 2 and --points at least 100");
        }
        Ok(DemoConfig {
            root: match &args.dir {
                Some(d) => d.clone(),
                None => demo_dir()?,
            },
            steps: args.steps,
            points: args.points,
            frames: args.frames.clamp(1, args.steps),
            headless: args.headless,
        })
    }
}
