//! A raw EnSight case for `slosh play`: `slosh bake`'s settings, validated the same way, over
//! a cache directory its steps are baked into as they are needed.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use slosh_bake::{EnsightSource, OnDemand};
use slosh_ensight::PointSource;

use super::{BakeConfig, BakeInput};
use crate::cli::{BakeArgs, BakeSettings};

/// Where a case's steps are baked by default: NAME.slosh beside NAME.case.
pub fn default_cache(case: &Path) -> PathBuf {
    let stem = case
        .file_stem()
        .map_or_else(|| "case".into(), |s| s.to_string_lossy().into_owned());
    case.with_file_name(format!("{stem}.slosh"))
}

/// The variable of the case at `case` that field view `view` reads, which the bake must store:
/// `view` where the case has a variable so named, else the vector of a component view
/// (`velocity.x`: `velocity`); `view` where it names neither (the bake then says so).
fn variable_of_view(case: &Path, view: &str) -> String {
    let Ok(opened) = slosh_ensight::Case::open(case) else {
        return view.to_string();
    };
    let named = |name: &str| opened.variables().iter().any(|v| v.name == name);
    match slosh_cache::component_view(view) {
        Some((vector, _)) if !named(view) && named(vector) => vector.to_string(),
        _ => view.to_string(),
    }
}

/// The case at `case`, held for baking into `cache` (default [`default_cache`]) with
/// `settings` and the `shown` field (the one frames are coloured by is baked with them), on
/// the adapter named `adapter` where the settings bake on the GPU, `jobs` steps at once
/// (default: [`slosh_bake::viewer_jobs`] of what `slosh bake` would take); refused where the
/// directory holds another series or another bake holds it.
pub fn open(
    case: &Path,
    cache: Option<&Path>,
    settings: &BakeSettings,
    shown: Option<&str>,
    (adapter, jobs): (Option<&str>, Option<usize>),
) -> Result<OnDemand> {
    let out = cache.map_or_else(|| default_cache(case), Path::to_path_buf);
    let mut settings = settings.clone();
    if let Some(field) = shown.map(|view| variable_of_view(case, view))
        && !settings.select.fields.contains(&field)
    {
        settings.select.fields.push(field);
    }
    let args = BakeArgs {
        input: case.to_path_buf(),
        out: Some(out.clone()),
        steps: None,
        jobs,
        shard: None,
        settings,
        adapter: adapter.map(str::to_string),
        manifest_only: false,
        quiet: true,
    };
    let mut cfg = BakeConfig::from_args(&args)?;
    if jobs.is_none() {
        cfg.options.jobs = slosh_bake::viewer_jobs(cfg.options.jobs, cfg.options.threads);
    }
    crate::machine::keep_freed_pages_on_a_device(&cfg.options.stages);
    let BakeInput::Case(case_data) = cfg.input else {
        bail!(
            "{}: a point cloud is one step: bake it with `slosh bake {} --out DIR` and play DIR",
            case.display(),
            case.display()
        );
    };
    let source = EnsightSource::new(
        case_data,
        &cfg.input_path,
        PointSource::Auto,
        &cfg.options.params,
    );
    OnDemand::open(Box::new(source), cfg.options)
        .with_context(|| format!("baking {} into {}", case.display(), out.display()))
}
