//! `slosh bench accuracy`: the CPU MLS tracer against analytic scenes. Writes a markdown
//! report (error against cost, per setting) and a PNG plot.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use slosh_mls::{Camera, NormalsMode, Params, Real, Surface, SurfaceParams, TraceHit};
use slosh_scenes::{DVec3, Scene, SceneKind, SceneSpec, TrueRay, Truth};

use crate::stats::percentile;

mod report;

pub use report::{Accuracy, AccuracyReport, MetricRow, ReversedRow, SingleRow, SphReport};

/// What `slosh bench accuracy` measures and where it writes.
#[derive(Debug, Clone)]
pub struct Settings {
    /// Markdown report to write.
    pub out: PathBuf,
    /// PNG plot of error against cost.
    pub plot: PathBuf,
    /// Image side in pixels of each rendered scene.
    pub size: u32,
    /// Small images and fewer settings (seconds instead of minutes).
    pub quick: bool,
    /// Directory of SPH cases compared with splashsurf (`scripts/sph_reference.py`).
    pub sph: Option<PathBuf>,
    /// Only the SPH section.
    pub sph_only: bool,
    /// The SPH results as JSON too.
    pub json: Option<PathBuf>,
    /// Write the small SPH fixture the tests keep (each case's reference depths) here.
    pub sph_fixture: Option<PathBuf>,
}

/// One scene at one time, rendered once by the exact truth.
pub(crate) struct Scenario {
    pub(crate) name: String,
    noise: f64,
    pub(crate) spacing: f64,
    truth: Truth,
    pub(crate) camera: Camera,
    pub(crate) positions: Vec<[f64; 3]>,
    pub(crate) normals: Vec<[f64; 3]>,
    /// Exact hit (t, outward normal) per pixel.
    exact: Vec<Option<(f64, DVec3)>>,
    /// Pixels whose 3 × 3 neighbourhood has both truth hits and misses.
    silhouette: Vec<bool>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Config {
    degree: u8,
    iterations: u32,
    normals: NormalsMode,
    h_scale: f64,
    single: bool,
}

impl Config {
    fn base() -> Config {
        Config {
            degree: 2,
            iterations: 3,
            normals: NormalsMode::Mean,
            h_scale: 1.5,
            single: false,
        }
    }
}

pub(crate) struct Render {
    pub(crate) hits: Vec<Option<TraceHit>>,
    us_per_ray: f64,
    /// Droplet spheres of the surface, and the normals its build reversed.
    spheres: usize,
    orientation: slosh_mls::OrientationRepair,
}

/// A render against the truth and the converged solution, in spacings.
#[derive(Debug, Default, Clone, Copy, PartialEq)]
pub struct Metrics {
    pub rms: f64,
    pub p99: f64,
    pub max: f64,
    pub angle_mean: f64,
    pub solver_rms: f64,
    pub solver_p99: f64,
    pub disagree_pct: f64,
    pub us_per_ray: f64,
}

pub(crate) fn scenario(
    kind: SceneKind,
    points: usize,
    step: usize,
    noise: f64,
    size: u32,
) -> Result<Scenario> {
    scenario_reversed(kind, points, step, noise, 0.0, size)
}

/// [`case`] with a fraction `reversed` of the normals reversed.
fn scenario_reversed(
    kind: SceneKind,
    points: usize,
    step: usize,
    noise: f64,
    reversed: f64,
    size: u32,
) -> Result<Scenario> {
    let mut spec = SceneSpec::new(kind, points, 7);
    spec.hard.noise = noise;
    spec.hard.flip_normals = reversed;
    let scene = Scene::new(spec)?;
    let t = scene.time(step);
    let p = scene.particles(step);
    let (positions, normals) = p.surface_arrays();
    let camera = slosh_testkit::analytic_camera(&positions, kind == SceneKind::Tank, size);
    let truth = scene.truth(t);
    let exact: Vec<Option<(f64, DVec3)>> = (0..size * size)
        .map(|i| {
            let (o, d) = camera.ray(i % size, i / size);
            truth
                .intersect(
                    &TrueRay::new(DVec3::from(o), DVec3::from(d)),
                    0.0,
                    f64::INFINITY,
                )
                .map(|h| (h.t, h.normal))
        })
        .collect();
    let depth: Vec<Option<f64>> = exact.iter().map(|e| e.map(|(t, _)| t)).collect();
    let silhouette = slosh_testkit::silhouette_mask(&depth, size as usize, None);
    let name = match kind {
        SceneKind::Tank => format!("tank t={t:.2}"),
        _ => kind.name().to_string(),
    };
    Ok(Scenario {
        name,
        noise,
        spacing: scene.spacing(),
        truth,
        camera,
        positions,
        normals,
        exact,
        silhouette,
    })
}

impl Render {
    /// Hits traced elsewhere (a cache), with no cost or surface figures.
    pub(crate) fn from_hits(hits: Vec<Option<TraceHit>>) -> Render {
        Render {
            hits,
            us_per_ray: 0.0,
            spheres: 0,
            orientation: slosh_mls::OrientationRepair::default(),
        }
    }
}

fn render_as<T: Real>(
    case: &Scenario,
    cfg: &Config,
    iterations: u32,
    epsilon: f64,
) -> Result<Render> {
    let sp = SurfaceParams {
        degree: cfg.degree,
        normals: cfg.normals,
        h_scale: cfg.h_scale,
        ..SurfaceParams::default()
    };
    let normals = (cfg.normals == NormalsMode::Mean).then_some(case.normals.as_slice());
    let surface = Surface::<T>::build(&case.positions, normals, &sp)?;
    let params = Params {
        degree: cfg.degree,
        iterations,
        epsilon: T::c(epsilon),
        normals: cfg.normals,
        h_factor: T::one(),
    };
    // One thread: a cost per ray that does not depend on what else the machine runs in parallel.
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    let start = Instant::now();
    let hits = pool.install(|| surface.render(&case.camera, &params));
    let us_per_ray = start.elapsed().as_secs_f64() * 1e6 / hits.len() as f64;
    Ok(Render {
        hits,
        us_per_ray,
        spheres: surface.spheres.len(),
        orientation: surface.orientation,
    })
}

fn render(case: &Scenario, cfg: &Config) -> Result<Render> {
    if cfg.single {
        render_as::<f32>(case, cfg, cfg.iterations, 1e-4)
    } else {
        render_as::<f64>(case, cfg, cfg.iterations, 1e-4)
    }
}

/// The converged f64 MLS surface at the same settings: the solver's target.
fn reference(case: &Scenario, cfg: &Config) -> Result<Render> {
    render_as::<f64>(case, cfg, 40, 1e-10)
}

pub(crate) fn metrics(case: &Scenario, r: &Render, reference: &Render) -> Metrics {
    let (mut dist, mut angles, mut solver) = (Vec::new(), Vec::new(), Vec::new());
    let (mut compared, mut disagree) = (0usize, 0usize);
    for (i, h) in r.hits.iter().enumerate() {
        if case.silhouette[i] {
            continue;
        }
        compared += 1;
        if h.is_some() != case.exact[i].is_some() {
            disagree += 1;
        }
        let Some(h) = h else { continue };
        let p = DVec3::from(h.position);
        dist.push(case.truth.signed_distance(p).abs() / case.spacing);
        let n = case.truth.normal_at(p);
        angles.push(
            n.dot(DVec3::from(h.normal))
                .clamp(-1.0, 1.0)
                .acos()
                .to_degrees(),
        );
        if let Some(rh) = reference.hits[i] {
            solver.push((h.t - rh.t).abs() / case.spacing);
        }
    }
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt();
    Metrics {
        rms: rms(&dist),
        p99: percentile(dist.clone(), 0.99),
        max: dist.iter().copied().fold(0.0, f64::max),
        angle_mean: angles.iter().sum::<f64>() / angles.len().max(1) as f64,
        solver_rms: rms(&solver),
        solver_p99: percentile(solver, 0.99),
        disagree_pct: 100.0 * disagree as f64 / compared.max(1) as f64,
        us_per_ray: r.us_per_ray,
    }
}

/// Each SPH case under `root` compared with splashsurf, its side-by-side image written beside
/// `plot`.
fn sph_results(root: &Path, plot: &Path) -> Result<Vec<crate::sph::SphResult>> {
    let mut results = Vec::new();
    for dir in crate::sph::cases(root)? {
        let name = dir
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let image = plot.with_file_name(format!("sph-{name}.png"));
        results.push(crate::sph::compare_case(&dir, Some(&image))?);
    }
    Ok(results)
}

pub fn run(args: &Settings) -> Result<Accuracy> {
    if let (Some(root), Some(fixture)) = (&args.sph, &args.sph_fixture) {
        for dir in crate::sph::cases(root)? {
            let name = dir
                .file_name()
                .map(|n| n.to_os_string())
                .unwrap_or_default();
            let target = fixture.join(name);
            std::fs::create_dir_all(&target)
                .with_context(|| format!("creating {}", target.display()))?;
            for file in ["particles.ply", "meta.json"] {
                std::fs::copy(dir.join(file), target.join(file)).with_context(|| {
                    format!(
                        "copying {} to {}",
                        dir.join(file).display(),
                        target.display()
                    )
                })?;
            }
            crate::sph::write_reference_depth(&dir, &target.join("reference-depth.npy"))?;
        }
        return Ok(Accuracy::Fixture(fixture.clone()));
    }
    if args.sph_only {
        let root = args.sph.as_deref().context("--sph-only needs --sph")?;
        return Ok(Accuracy::SphOnly(SphReport {
            results: sph_results(root, &args.plot)?,
        }));
    }
    let size = if args.quick {
        args.size.min(32)
    } else {
        args.size
    };
    let mut cases = Vec::new();
    let noises: &[f64] = if args.quick { &[0.0] } else { &[0.0, 0.1] };
    for &noise in noises {
        cases.push(scenario(SceneKind::Sphere, 5000, 0, noise, size)?);
        if !args.quick {
            cases.push(scenario(SceneKind::Torus, 8000, 0, noise, size)?);
            for step in [0, 7, 14] {
                cases.push(scenario(SceneKind::Tank, 40_000, step, noise, size)?);
            }
        }
    }
    let max_iter = if args.quick { 3 } else { 5 };
    let metric_row = |c: &Scenario, setting: String, metrics: Metrics| MetricRow {
        scene: c.name.clone(),
        noise: c.noise,
        setting,
        metrics,
    };
    let mut plot: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    let (mut worst_converged, mut worst_one) = (0.0f64, 0.0f64);
    let mut iteration_rows = Vec::new();
    for c in &cases {
        for degree in [2u8, 3] {
            let base = Config {
                degree,
                ..Config::base()
            };
            let reference = reference(c, &base)?;
            let mut series = Vec::new();
            for iterations in 1..=max_iter {
                let cfg = Config { iterations, ..base };
                let m = metrics(c, &render(c, &cfg)?, &reference);
                iteration_rows.push(metric_row(
                    c,
                    format!("degree {degree}, {iterations} it."),
                    m,
                ));
                series.push((m.us_per_ray, m.rms));
                if c.noise == 0.0 {
                    if iterations == 1 {
                        worst_one = worst_one.max(m.rms);
                    }
                    if iterations == max_iter {
                        worst_converged = worst_converged.max(m.rms);
                    }
                }
            }
            if c.noise == 0.0 {
                plot.push((format!("{} deg {degree}", c.name), series));
            }
        }
    }
    let mut support = Vec::new();
    for c in cases.iter().filter(|c| c.noise == 0.0) {
        for (mode, label) in [
            (NormalsMode::Mean, "(a) mean normals"),
            (NormalsMode::Covariance, "(b) covariance, no normals"),
        ] {
            let cfg = Config {
                normals: mode,
                ..Config::base()
            };
            let m = metrics(c, &render(c, &cfg)?, &reference(c, &cfg)?);
            support.push(metric_row(c, label.to_string(), m));
        }
    }
    let mut smoothing = Vec::new();
    for c in cases.iter().filter(|c| c.noise == 0.0) {
        for h_scale in [1.0, 1.5, 2.5] {
            let cfg = Config {
                h_scale,
                ..Config::base()
            };
            let m = metrics(c, &render(c, &cfg)?, &reference(c, &cfg)?);
            smoothing.push(metric_row(c, format!("h scale {h_scale}"), m));
        }
    }
    let mut single = Vec::new();
    for c in &cases {
        for degree in [2u8, 3] {
            let cfg = Config {
                degree,
                ..Config::base()
            };
            let r64 = render(c, &cfg)?;
            let r32 = render(
                c,
                &Config {
                    single: true,
                    ..cfg
                },
            )?;
            let (mut shared, mut within, mut worst, mut differ) = (0usize, 0usize, 0.0f64, 0usize);
            for (a, b) in r64.hits.iter().zip(&r32.hits) {
                match (a, b) {
                    (Some(a), Some(b)) => {
                        let d = (a.t - b.t).abs() / c.spacing;
                        shared += 1;
                        within += usize::from(d <= 1e-3);
                        worst = worst.max(d);
                    }
                    (None, None) => {}
                    _ => differ += 1,
                }
            }
            single.push(SingleRow {
                scene: c.name.clone(),
                noise: c.noise,
                degree,
                shared,
                within,
                worst,
                differ,
                f32_us_per_ray: r32.us_per_ray,
                f64_us_per_ray: r64.us_per_ray,
            });
        }
    }
    let reversed_size = if args.quick { size } else { size.max(256) };
    let mut worst_ratio = 0.0f64;
    let flip_scenes: &[(SceneKind, usize)] = if args.quick {
        &[(SceneKind::Sphere, 5000)]
    } else {
        &[
            (SceneKind::Sphere, 20_000),
            (SceneKind::Torus, 20_000),
            (SceneKind::Tank, 40_000),
        ]
    };
    let mut reversed_rows = Vec::new();
    for &(kind, points) in flip_scenes {
        let cfg = Config {
            iterations: 5,
            ..Config::base()
        };
        let mut clean_rms = 0.0;
        for reversed in [0.0, 0.1, 0.3] {
            let c = scenario_reversed(kind, points, 0, 0.0, reversed, reversed_size)?;
            let r = render(&c, &cfg)?;
            let m = metrics(&c, &r, &r);
            if reversed == 0.0 {
                clean_rms = m.rms;
            } else {
                worst_ratio = worst_ratio.max(m.rms / clean_rms.max(f64::MIN_POSITIVE));
            }
            reversed_rows.push(ReversedRow {
                scene: c.name.clone(),
                points,
                reversed,
                metrics: m,
                spheres: r.spheres,
                flipped_points: r.orientation.flipped_points,
                patch_points: r.orientation.patch_points,
                clean_rms,
            });
        }
    }
    let sph = args
        .sph
        .as_deref()
        .map(|root| sph_results(root, &args.plot))
        .transpose()?;
    Ok(Accuracy::Full(AccuracyReport {
        quick: args.quick,
        size,
        reversed_size,
        max_iterations: max_iter,
        iterations: iteration_rows,
        support,
        smoothing,
        single,
        reversed: reversed_rows,
        worst_converged,
        worst_one,
        worst_ratio,
        sph,
        plot,
    }))
}
