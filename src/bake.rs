//! `slosh bake`: the batch driver with a progress bar and a summary.

use std::time::Duration;

use slosh_fileio::say;

use anyhow::{Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use slosh_bake::{EnsightSource, Event, StepInput, StepOutcome, StepSource, run_batch};
use slosh_cache::Manifest;
use slosh_ensight::PointSource;

use crate::config::{BakeConfig, BakeInput};
use slosh_bake::PointCloud;

/// A PLY/OBJ point cloud as a one-step series.
struct CloudSource<'a> {
    cloud: &'a PointCloud,
    label: String,
}

impl StepSource for CloudSource<'_> {
    fn source_path(&self) -> String {
        self.label.clone()
    }

    fn steps(&self) -> Vec<(usize, f64)> {
        vec![(0, 0.0)]
    }

    fn read(&self, index: usize) -> Result<StepInput, String> {
        Ok(StepInput {
            index,
            time: 0.0,
            source: self.label.clone(),
            positions: self.cloud.positions.clone(),
            normals: self.cloud.normals.clone(),
            surface_flags: None,
            fields: Vec::new(),
            identity: None,
        })
    }

    /// The point-cloud file itself.
    fn identity(&self, _index: usize) -> Option<String> {
        slosh_bake::files_identity([std::path::Path::new(&self.label)])
    }
}

pub fn manifest_only(dir: &std::path::Path) -> Result<()> {
    let (manifest, problems) = Manifest::refresh(dir)?;
    say!(
        "wrote {} ({})",
        dir.join(slosh_cache::MANIFEST_NAME).display(),
        steps(manifest.steps.len())
    );
    for (path, e) in &problems {
        eprintln!("left out {}: {e}", path.display());
    }
    let missing = manifest.missing();
    if let Some(gaps) = manifest.key().describe_missing(&missing) {
        eprintln!("{gaps}");
    }
    match (problems.len(), missing.len()) {
        (0, 0) => Ok(()),
        (0, m) => bail!("the series is incomplete: {m} steps are missing"),
        (p, 0) => bail!("{p} step files failed their checks"),
        (p, m) => bail!("{p} step files failed their checks and {m} steps are missing"),
    }
}

pub fn run(cfg: &BakeConfig) -> Result<()> {
    let opts = &cfg.options;
    let label = cfg.input_path.display().to_string();
    let ensight;
    let cloud;
    let source: &dyn StepSource = match &cfg.input {
        BakeInput::Case(case) => {
            ensight = EnsightSource::new(
                case.clone(),
                &cfg.input_path,
                PointSource::Auto,
                &opts.params,
            );
            &ensight
        }
        BakeInput::PointCloud(c) => {
            cloud = CloudSource {
                cloud: c,
                label: slosh_bake::canonical_label(&cfg.input_path),
            };
            &cloud
        }
    };
    // A range that selects none of the series' steps is a mistake, not a bake of nothing.
    if let Some((a, b)) = opts.steps {
        let all = source.steps();
        if !all.iter().any(|(i, _)| (a..=b).contains(i)) {
            let span = match (all.first(), all.last()) {
                (Some((f, _)), Some((l, _))) => format!("steps {f}..={l}"),
                _ => "no steps".into(),
            };
            bail!("--steps selects steps {a}..={b}, none of which {label} has (it has {span})");
        }
    }
    if let Some(why) = &cfg.jobs_chosen
        && !cfg.quiet
    {
        say!("{why}");
    }
    if !cfg.quiet {
        say!("stages: {}", cfg.options.stages.describe());
    }
    crate::machine::keep_freed_pages_on_a_device(&opts.stages);
    let bar = if cfg.quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(0)
    };
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {bar:30} {pos}/{len} steps, ETA {eta}, {msg}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.enable_steady_tick(Duration::from_millis(250));
    // Throughput for the bar: points baked so far over the time since the bake started.
    let baked_points = std::sync::atomic::AtomicU64::new(0);
    let started = std::time::Instant::now();
    let report = run_batch(source, opts, &|event| match event {
        Event::Planned { steps } => bar.set_length(steps as u64),
        Event::Done { index, outcome } => {
            match outcome {
                StepOutcome::Baked {
                    points, seconds, ..
                } => {
                    let total = baked_points
                        .fetch_add(points, std::sync::atomic::Ordering::Relaxed)
                        + points;
                    let rate = total as f64 / started.elapsed().as_secs_f64().max(1e-9);
                    bar.set_message(format!(
                        "{:.0}k points/s; step {index}: {points} points, {seconds:.1} s",
                        rate / 1e3
                    ));
                }
                StepOutcome::Kept => bar.set_message(format!("step {index}: kept")),
                StepOutcome::Failed(e) => bar.println(format!("step {index} failed: {e}")),
            }
            bar.inc(1);
        }
    })?;
    bar.finish_and_clear();

    // A stage's parts ("stage: part") lie within its own lap.
    let stage_total: f64 = report
        .stages
        .iter()
        .filter(|(name, _)| slosh_mls::stage_part(name).is_none())
        .map(|(_, s)| s)
        .sum();
    say!(
        "baked {}, kept {} already current, {} failed, into {} in {:.2} s",
        steps(report.baked),
        report.kept,
        report.failed.len(),
        opts.out.display(),
        report.wall_seconds
    );
    if report.baked > 0 {
        // Empty steps hold headers and no points: no bytes per point to say.
        let per_point = match report.points {
            0 => String::new(),
            n => format!(" ({:.1} bytes per point)", report.bytes as f64 / n as f64),
        };
        say!(
            "{} points, {:.1} MB written{per_point}; each stage's wall seconds summed over steps:",
            report.points,
            report.bytes as f64 / 1e6,
        );
        for (name, s) in &report.stages {
            let shown = match slosh_mls::stage_part(name) {
                Some((_, part)) => format!("  of which {part}"),
                None => name.clone(),
            };
            say!(
                "  {shown:<26} {s:>9.3} s  {:>5.1} %",
                100.0 * s / stage_total.max(f64::MIN_POSITIVE)
            );
        }
    }
    // What the steps do, said of one and of several.
    for (listed, what) in [
        (
            &report.empty,
            ["holds", "hold"].map(|v| format!("{v} no particles")),
        ),
        (
            &report.too_few,
            ["keeps", "keep"].map(|v| {
                format!("{v} fewer than two particles after selection (too few to size a surface)")
            }),
        ),
    ] {
        if listed.is_empty() {
            continue;
        }
        let (what, baked) = if listed.len() == 1 {
            (&what[0], "was baked as an empty step")
        } else {
            (&what[1], "were baked as empty steps")
        };
        say!(
            "{} {what} and {baked}: {}",
            steps(listed.len()),
            first_of(listed.iter().map(|i| i.to_string()))
        );
    }
    // Dropped particles are recorded in each step's statistics (`slosh inspect`); said here
    // too, so that a run's input damage is not found only by opening its steps.
    for (listed, what) in [
        (&report.non_finite, slosh_bake::NON_FINITE_PARTICLES),
        (&report.far, slosh_bake::FAR_PARTICLES),
    ] {
        if listed.is_empty() {
            continue;
        }
        say!(
            "particles {what} were dropped in {}: {}",
            steps(listed.len()),
            first_of(
                listed
                    .iter()
                    .map(|s| format!("{} ({} of {})", s.step, s.dropped, s.read))
            )
        );
    }
    for (path, e) in &report.manifest_problems {
        eprintln!("manifest: left out {}: {e}", path.display());
    }
    // Every failure is said, but a long run of them is summarised (a case that promises a
    // million steps over three files must not print a million lines).
    for (i, e) in report.failed.iter().take(SHOWN) {
        eprintln!("step {i}: {e}");
    }
    if report.failed.len() > SHOWN {
        eprintln!("… and {} more failed steps", report.failed.len() - SHOWN);
    }
    for &i in report.gone.iter().take(SHOWN) {
        eprintln!(
            "step {i}: {} was gone or damaged when the manifest was rebuilt (deleted, moved or \
             changed while the bake ran), so the manifest leaves it out",
            opts.out.join(slosh_cache::step_file_name(i)).display()
        );
    }
    if report.gone.len() > SHOWN {
        eprintln!("… and {} more steps gone", report.gone.len() - SHOWN);
    }
    if let Some(e) = &report.manifest_error {
        eprintln!("manifest: {e}");
    }
    // Each way the run fell short, in one line; none is hidden behind another.
    let mut short = Vec::new();
    if !report.failed.is_empty() {
        short.push(format!(
            "{} of {} failed: {}",
            report.failed.len(),
            steps(report.baked + report.kept + report.failed.len()),
            first_of(report.failed.iter().map(|(i, _)| i.to_string()))
        ));
    }
    if !report.gone.is_empty() {
        short.push(format!(
            "{} this run baked or kept {} gone from {} when the manifest was rebuilt: {}; bake \
             again to restore {}",
            steps(report.gone.len()),
            if report.gone.len() == 1 {
                "was"
            } else {
                "were"
            },
            opts.out.display(),
            first_of(report.gone.iter().map(|i| i.to_string())),
            if report.gone.len() == 1 { "it" } else { "them" }
        ));
    }
    if report.manifest_error.is_some() {
        short.push("the manifest was not written".into());
    }
    if !short.is_empty() {
        bail!("{}", short.join("; and "));
    }
    Ok(())
}

/// Steps said one by one before a run's summary says the rest.
const SHOWN: usize = 20;

/// The first [`SHOWN`] of `items`, comma-separated, then how many there are in all where
/// there are more.
fn first_of(items: impl ExactSizeIterator<Item = String>) -> String {
    let count = items.len();
    let mut list: Vec<String> = items.take(SHOWN).collect();
    if count > SHOWN {
        list.push(format!("… ({count} in all)"));
    }
    list.join(", ")
}

/// "1 step", "N steps".
fn steps(n: usize) -> String {
    if n == 1 {
        "1 step".into()
    } else {
        format!("{n} steps")
    }
}
