//! `slosh bench gpu`: frame times of the trace and shade passes by GPU timestamp queries
//! (warm-up, then the median of N frames), in the setups of the thesis's tables 4.1, 4.5 and
//! 4.6 plus 1M points and 1920×1080, each row beside its error against the analytic surface
//! (or, for the bunny, against the 5-iteration solution), and upload times per step.

use slosh_fileio::say;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use slosh_bake::{BakeParams, NormalSource, StepInput, SurfaceSelect};
use slosh_cache::{CacheFile, Compression};
use slosh_mls::Camera;
use slosh_render::{Gpu, GpuStep, ShadeMode, TraceParams, Tracer, status};
use slosh_scenes::{Scene, SceneKind, SceneSpec, Truth};

use slosh_render::write_frame_png;

use crate::report::Report;
use crate::stats::{median, spread};

/// A table of `slosh bench gpu`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Table {
    /// Table 4.1: the bunny, iterations 1–5, quadratic and cubic.
    Bunny,
    /// Table 4.5: the tank at four image sizes.
    Tank,
    /// Figure 4.9: the water shader on the tank.
    Water,
    /// Table 4.6: point counts at 1280×800 (and 1920×1080 from 100k points).
    Points,
}

/// What `slosh bench gpu` measures and where it writes.
#[derive(Debug, Clone)]
pub struct Settings {
    /// Markdown report to write.
    pub out: PathBuf,
    /// Timed frames per row (after warm-up).
    pub frames: usize,
    /// Most iterations measured.
    pub max_iterations: u32,
    /// Small sizes only.
    pub quick: bool,
    /// The bunny's points, read by the caller (table 4.1 is skipped without them).
    pub bunny: Option<StepInput>,
    /// Folder for the tables' pictures.
    pub images: PathBuf,
    /// GPU adapter whose name contains this.
    pub adapter: Option<String>,
    /// Tables measured (empty: all).
    pub tables: Vec<Table>,
    /// Point counts of table 4.6 (empty: the defaults).
    pub points: Vec<usize>,
}

/// A baked step in memory, its analytic truth if it has one, and its world spacing.
struct Bench {
    label: String,
    file: CacheFile,
    truth: Option<Truth>,
    points: usize,
}

fn bake(label: &str, input: &StepInput, degree: u8, truth: Option<Truth>) -> Result<Bench> {
    let mut params = BakeParams::new(SurfaceSelect::All, NormalSource::Variable("normal".into()));
    params.mls.degree = degree;
    params.compression = Compression::Level(3);
    let file = slosh_testkit::bake_in_memory(input, &params, Path::new(label))?;
    Ok(Bench {
        label: label.to_string(),
        points: input.positions.len(),
        file,
        truth,
    })
}

fn scene(kind: SceneKind, points: usize, degree: u8) -> Result<Bench> {
    let scene = Scene::new(SceneSpec::new(kind, points, 1))?;
    let input = slosh_testkit::scene_step(&scene, 0, &format!("{} {points}", kind.name()));
    let label = format!("{} ({} surface points)", kind.name(), input.positions.len());
    bake(&label, &input, degree, Some(scene.truth(scene.time(0))))
}

/// Median and 99th percentile of |distance to the truth| / spacing over the hit pixels.
fn error(
    bench: &Bench,
    step: &GpuStep,
    hits: &[slosh_render::GpuHit],
    reference: Option<&[slosh_render::GpuHit]>,
) -> Option<(f64, f64)> {
    let mut d: Vec<f64> = Vec::new();
    for (i, h) in hits.iter().enumerate() {
        if h.status == status::MISS || h.status == status::DROPLET {
            continue;
        }
        let p = step.info.transform.to_world(h.position.map(f64::from));
        if let Some(truth) = &bench.truth {
            d.push(truth.signed_distance(p.into()).abs() / step.info.spacing);
        } else if let Some(r) = reference.and_then(|r| r.get(i)).filter(|r| r.status != 0) {
            d.push(f64::from((r.t - h.t).abs()) * step.info.transform.scale / step.info.spacing);
        }
    }
    if d.is_empty() {
        return None;
    }
    let spread = spread(d);
    Some((spread.p50, spread.p99))
}

/// One measured frame setup: GPU times of the passes, the error, the thesis's figure.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    /// The thesis table it extends: "4.1", "4.5", "4.6" or "water".
    pub table: &'static str,
    pub scene: String,
    pub size: (u32, u32),
    pub degree: u8,
    pub iterations: u32,
    /// Medians over the timed frames.
    pub trace_ms: f64,
    pub shade_ms: f64,
    /// Median and p99 distance to the truth (or the reference) in spacings.
    pub error: Option<(f64, f64)>,
    pub thesis_fps: Option<f64>,
}

/// One step's upload, timed.
#[derive(Debug, Clone, PartialEq)]
pub struct Upload {
    pub label: String,
    pub points: usize,
    pub stats: slosh_render::UploadStats,
}

/// What `slosh bench gpu` measured.
#[derive(Debug, Clone)]
pub struct GpuReport {
    /// The adapter, as `Gpu::describe` gives it.
    pub adapter: String,
    /// Timed frames per row.
    pub frames: usize,
    /// Whether the frames went to docs/img, which the report then links.
    pub link_images: bool,
    pub rows: Vec<Row>,
    pub uploads: Vec<Upload>,
}

struct Runner<'a> {
    gpu: &'a Gpu,
    tracer: Tracer,
    frames: usize,
}

impl Runner<'_> {
    /// The framing camera, up from the data (the bunny is y-up).
    fn camera(bench: &Bench, w: u32, h: u32) -> Camera {
        let header = bench.file.header();
        Camera::framing(
            &header.bounds,
            40.0,
            w,
            h,
            header.up.unwrap_or([0.0, 0.0, 1.0]),
        )
    }

    /// Times `iterations` on `bench` at w × h; also returns the frame for errors and images.
    fn time(
        &self,
        bench: &Bench,
        step: &GpuStep,
        (w, h): (u32, u32),
        degree: u8,
        iterations: u32,
        mode: ShadeMode,
    ) -> Result<(f64, f64, slosh_render::Frame)> {
        let camera = Self::camera(bench, w, h);
        let mut params = TraceParams::for_step(step, iterations);
        params.degree = degree;
        params.mode = mode;
        let targets = self.tracer.targets(self.gpu, w, h)?;
        let mut trace = Vec::new();
        let mut shade = Vec::new();
        // Warm-up: 10 frames and at least half a second, so that the GPU's clocks have risen
        // after the host-side work before this row (a bake, an upload).
        let warm_up = Instant::now();
        let mut warm = 0;
        while warm < 10 || warm_up.elapsed().as_secs_f64() < 0.5 {
            self.tracer
                .run(self.gpu, step, &targets, &camera, &params)?
                .context("this adapter has no timestamp queries")?;
            warm += 1;
        }
        for _ in 0..self.frames {
            let times = self
                .tracer
                .run(self.gpu, step, &targets, &camera, &params)?
                .context("this adapter has no timestamp queries")?;
            trace.push(times.trace_ms);
            shade.push(times.shade_ms);
        }
        let frame = self.tracer.render(self.gpu, step, &camera, &params)?;
        Ok((median(trace), median(shade), frame))
    }
}

/// Thesis table 4.1 (35k-point bunny, 800×800, OptiX): fps at iterations 1–5, quadratic LU
/// and cubic bisection LU.
const THESIS_BUNNY_FPS: [[f64; 5]; 2] = [
    [39.81, 1.67, 0.85, 0.58, 0.43],
    [38.72, 1.04, 0.52, 0.35, 0.26],
];
/// Thesis table 4.5 (tank, ~10k points): fps by image size at iterations 1–3.
const THESIS_TANK_FPS: [((u32, u32), [f64; 3]); 4] = [
    ((200, 100), [212.57, 19.16, 10.19]),
    ((400, 200), [145.27, 7.98, 4.14]),
    ((800, 400), [83.40, 3.11, 1.60]),
    ((1600, 800), [36.24, 1.17, 0.55]),
];
/// Thesis table 4.6 (1280×800): fps by point count at iterations 1–3.
const THESIS_POINTS_FPS: [(usize, [f64; 3]); 3] = [
    (2_500, [73.05, 4.18, 2.17]),
    (10_000, [65.35, 2.81, 1.44]),
    (100_000, [28.43, 1.47, 0.75]),
];

pub fn run(args: &Settings) -> Result<GpuReport> {
    if args.frames == 0 {
        bail!("--frames must be at least 1");
    }
    let gpu = Gpu::new(args.adapter.as_deref())?;
    if !gpu.timestamps {
        bail!(
            "{} has no timestamp queries: GPU frame times cannot be measured",
            gpu.describe()
        );
    }
    let runner = Runner {
        gpu: &gpu,
        tracer: Tracer::new(&gpu)?,
        frames: args.frames,
    };
    say!("GPU benchmark on {}", gpu.describe());
    let mut rows: Vec<Row> = Vec::new();
    let mut uploads: Vec<Upload> = Vec::new();
    std::fs::create_dir_all(&args.images).ok();
    let wanted = |table| args.tables.is_empty() || args.tables.contains(&table);

    // Table 4.1: the bunny.
    if let Some(input) = args.bunny.as_ref().filter(|_| wanted(Table::Bunny)) {
        let size = if args.quick { (200, 200) } else { (800, 800) };
        for degree in [2u8, 3] {
            let bench = bake(
                &format!("bunny.obj ({} points)", input.positions.len()),
                input,
                degree,
                None,
            )?;
            let step = GpuStep::upload(&gpu, &bench.file, None)?;
            let (_, _, reference) = runner.time(
                &bench,
                &step,
                size,
                degree,
                args.max_iterations.min(5) + 3,
                ShadeMode::Shade,
            )?;
            for iterations in 1..=args.max_iterations.min(5) {
                let (trace_ms, shade_ms, frame) =
                    runner.time(&bench, &step, size, degree, iterations, ShadeMode::Shade)?;
                if degree == 3 && iterations == args.max_iterations.min(5) {
                    write_frame_png(&args.images.join("bunny.png"), &frame)?;
                }
                rows.push(Row {
                    table: "4.1",
                    scene: bench.label.clone(),
                    size,
                    degree,
                    iterations,
                    trace_ms,
                    shade_ms,
                    error: error(&bench, &step, &frame.hits, Some(&reference.hits)),
                    thesis_fps: Some(
                        THESIS_BUNNY_FPS[usize::from(degree == 3)][iterations as usize - 1],
                    ),
                });
                say!(
                    "  bunny degree {degree} {iterations} it: {:.3} ms",
                    trace_ms + shade_ms
                );
            }
        }
    } else if wanted(Table::Bunny) {
        say!("  (no bunny.obj: give --bunny or set SLOSH_DATA; table 4.1 skipped)");
    }

    // Table 4.5: the tank, ~10k surface points, image sizes.
    if wanted(Table::Tank) || wanted(Table::Water) {
        tank_rows(
            args,
            &runner,
            &mut rows,
            wanted(Table::Tank),
            wanted(Table::Water),
        )?;
    }
    if wanted(Table::Points) {
        points_rows(args, &runner, &mut rows, &mut uploads)?;
    }
    Ok(GpuReport {
        adapter: gpu.describe(),
        frames: args.frames,
        link_images: args.images == Path::new("docs/img"),
        rows,
        uploads,
    })
}

/// Table 4.5 (the tank at four image sizes) and the water row.
fn tank_rows(
    args: &Settings,
    runner: &Runner,
    rows: &mut Vec<Row>,
    sizes_table: bool,
    water: bool,
) -> Result<()> {
    let gpu = runner.gpu;
    let tank = scene(
        SceneKind::Tank,
        if args.quick { 60_000 } else { 250_000 },
        2,
    )?;
    let tank_step = GpuStep::upload(gpu, &tank.file, None)?;
    let sizes: &[(u32, u32)] = if !sizes_table {
        &[]
    } else if args.quick {
        &[(200, 100), (400, 200)]
    } else {
        &[(200, 100), (400, 200), (800, 400), (1600, 800)]
    };
    for &size in sizes {
        for iterations in 1..=args.max_iterations.min(3) {
            let (trace_ms, shade_ms, frame) =
                runner.time(&tank, &tank_step, size, 2, iterations, ShadeMode::Shade)?;
            if size == *sizes.last().unwrap_or(&size) && iterations == args.max_iterations.min(3) {
                write_frame_png(&args.images.join("tank.png"), &frame)?;
            }
            rows.push(Row {
                table: "4.5",
                scene: tank.label.clone(),
                size,
                degree: 2,
                iterations,
                trace_ms,
                shade_ms,
                error: error(&tank, &tank_step, &frame.hits, None),
                thesis_fps: THESIS_TANK_FPS
                    .iter()
                    .find(|(s, _)| *s == size)
                    .map(|(_, f)| f[iterations as usize - 1]),
            });
        }
    }
    if !water {
        return Ok(());
    }
    // The thesis's water shader (fig. 4.9): the tank at 1270×610, 2 iterations, reflection and
    // refraction; 4.59 s per frame there.
    let (trace_ms, shade_ms, frame) =
        runner.time(&tank, &tank_step, (1270, 610), 2, 2, ShadeMode::Water)?;
    write_frame_png(&args.images.join("tank-water.png"), &frame)?;
    rows.push(Row {
        table: "water",
        scene: tank.label.clone(),
        size: (1270, 610),
        degree: 2,
        iterations: 2,
        trace_ms,
        shade_ms,
        error: error(&tank, &tank_step, &frame.hits, None),
        thesis_fps: Some(1.0 / 4.59),
    });
    say!("  tank done");
    Ok(())
}

/// Table 4.6: point counts at 1280×800, plus 1M points and 1920×1080, with upload times.
fn points_rows(
    args: &Settings,
    runner: &Runner,
    rows: &mut Vec<Row>,
    uploads: &mut Vec<Upload>,
) -> Result<()> {
    let counts: &[usize] = if !args.points.is_empty() {
        &args.points
    } else if args.quick {
        &[2_500, 10_000]
    } else {
        &[2_500, 10_000, 100_000, 1_000_000]
    };
    for &points in counts {
        let start = Instant::now();
        let bench = scene(SceneKind::Sphere, points, 2)?;
        say!(
            "  sphere {points}: baked in {:.1} s",
            start.elapsed().as_secs_f64()
        );
        let step = GpuStep::upload(runner.gpu, &bench.file, None)?;
        // Upload: the median of 5 uploads of the same in-memory step.
        let mut best = Vec::new();
        for _ in 0..5 {
            best.push(GpuStep::upload(runner.gpu, &bench.file, None)?.upload);
        }
        best.sort_by(|a, b| a.total_seconds.total_cmp(&b.total_seconds));
        uploads.push(Upload {
            label: bench.label.clone(),
            points: bench.points,
            stats: best[2],
        });
        let mut sizes = vec![(1280, 800)];
        if points >= 100_000 && !args.quick {
            sizes.push((1920, 1080));
        }
        for size in sizes {
            for iterations in 1..=args.max_iterations.min(3) {
                let (trace_ms, shade_ms, frame) =
                    runner.time(&bench, &step, size, 2, iterations, ShadeMode::Shade)?;
                rows.push(Row {
                    table: "4.6",
                    scene: bench.label.clone(),
                    size,
                    degree: 2,
                    iterations,
                    trace_ms,
                    shade_ms,
                    error: error(&bench, &step, &frame.hits, None),
                    thesis_fps: THESIS_POINTS_FPS
                        .iter()
                        .find(|(n, _)| *n == points && size == (1280, 800))
                        .map(|(_, f)| f[iterations as usize - 1]),
                });
            }
        }
    }
    Ok(())
}

/// A speed goal: the row that measures it (table, image, degree, iterations) and its fps.
struct Goal {
    name: &'static str,
    table: &'static str,
    size: (u32, u32),
    degree: u8,
    iterations: u32,
    fps: f64,
}

const GOALS: [Goal; 3] = [
    Goal {
        name: "100k points, 1280×800, 1 iteration",
        table: "4.6",
        size: (1280, 800),
        degree: 2,
        iterations: 1,
        fps: 2000.0,
    },
    Goal {
        name: "100k points, 1280×800, 2 iterations",
        table: "4.6",
        size: (1280, 800),
        degree: 2,
        iterations: 2,
        fps: 300.0,
    },
    Goal {
        name: "bunny, 800×800, cubic, 5 iterations",
        table: "4.1",
        size: (800, 800),
        degree: 3,
        iterations: 5,
        fps: 200.0,
    },
];

/// The speed goals against the rows that measure them.
fn write_goals(md: &mut String, rows: &[Row]) {
    let _ = writeln!(md, "## Goals\n");
    let _ = writeln!(md, "| goal | fps wanted | fps measured | met |");
    let _ = writeln!(md, "|---|---|---|---|");
    for goal in &GOALS {
        let row = rows.iter().find(|r| {
            r.table == goal.table
                && r.size == goal.size
                && r.degree == goal.degree
                && r.iterations == goal.iterations
                && (goal.table != "4.6" || r.scene.contains("(100000 surface"))
        });
        let (measured, met) = row.map_or(("not run".to_string(), "—"), |r| {
            let fps = 1000.0 / (r.trace_ms + r.shade_ms);
            (
                format!("{fps:.0}"),
                if fps >= goal.fps { "yes" } else { "no" },
            )
        });
        let _ = writeln!(
            md,
            "| {} | ≥ {:.0} | {measured} | {met} |",
            goal.name, goal.fps
        );
    }
    md.push('\n');
}

impl Report for GpuReport {
    fn markdown(&self) -> String {
        let rows = &self.rows;
        let mut md = String::new();
        let _ = writeln!(md, "# GPU results (`slosh bench gpu`)\n");
        let _ = writeln!(
            md,
            "Measured on **{}**, with GPU timestamp queries around the trace and the shade pass: at least 10 warm-up frames and 0.5 s, then the median of {} frames. fps = 1000 / (trace + shade). Error: median and 99th percentile over hit pixels of the distance to the analytic surface in mean spacings (the bunny has no analytic surface: its error is |Δt| against 8 iterations of the same fit, in spacings).\n",
            self.adapter, self.frames
        );
        write_goals(&mut md, rows);
        for (table, title) in [
            (
                "4.1",
                "Thesis table 4.1: the bunny at 800×800 (thesis: OptiX, 35k-point bunny; here the 28k-vertex bunny.obj of the pymeshlab wheel)",
            ),
            ("4.5", "Thesis table 4.5: tank, image sizes"),
            (
                "water",
                "Thesis figure 4.9: the water shader (reflection, refraction, shadows over a checkerboard; shade ms is the water pass with its secondary rays, which take each candidate's initial hit; thesis: 2 recursions, 4.59 s per frame)",
            ),
            (
                "4.6",
                "Thesis table 4.6: point counts at 1280×800 (sphere), extended to 1M points and 1920×1080",
            ),
        ] {
            let rows: Vec<&Row> = rows.iter().filter(|r| r.table == table).collect();
            if rows.is_empty() {
                continue;
            }
            let _ = writeln!(md, "## {title}\n");
            let _ = writeln!(
                md,
                "| scene | image | degree | iterations | trace ms | shade ms | fps | thesis fps | speed-up | error median | error p99 |"
            );
            let _ = writeln!(md, "|---|---|---|---|---|---|---|---|---|---|---|");
            for r in rows {
                let fps = 1000.0 / (r.trace_ms + r.shade_ms);
                let (thesis, speedup) = match r.thesis_fps {
                    Some(t) => (format!("{t:.2}"), format!("{:.0}×", fps / t)),
                    None => ("—".into(), "—".into()),
                };
                let (e50, e99) = r.error.map_or(("—".into(), "—".into()), |(a, b)| {
                    (format!("{a:.2e}"), format!("{b:.2e}"))
                });
                let _ = writeln!(
                    md,
                    "| {} | {}×{} | {} | {} | {:.3} | {:.3} | {:.0} | {thesis} | {speedup} | {e50} | {e99} |",
                    r.scene,
                    r.size.0,
                    r.size.1,
                    r.degree,
                    r.iterations,
                    r.trace_ms,
                    r.shade_ms,
                    fps
                );
            }
            md.push('\n');
        }
        // The frames, linked relative to docs/ when they were written to the default docs/img.
        if self.link_images {
            let _ = writeln!(
                md,
                "## Frames\n\nThe bunny at 5 cubic iterations (800×800), the tank at 3 iterations (1600×800), and the tank in the water shader (1270×610):\n\n![bunny](img/bunny.png)\n\n![tank](img/tank.png)\n\n![tank, water shader](img/tank-water.png)\n"
            );
        }
        let _ = writeln!(
            md,
            "## Upload per step\n\nFrom a step in memory (as from the page cache): the host half (checksums, the sections it reads decoded, the tree checked), the recording (buffers created, a `mapped_at_creation` staging buffer filled, compressed sections decoded straight into it), `copy_buffer_to_buffer` into device-local storage, waited for (no pass runs per upload: the tracer widens the BVH2 of the step it draws into the 4-wide tree, and derives the neighbour masks of the step it refines, before their first frames). Median of 5. Bytes on the GPU count the sections.\n"
        );
        let _ = writeln!(
            md,
            "| step | bytes on the GPU | bytes stored | host ms | record ms | GPU copy ms | total ms | GB/s |"
        );
        let _ = writeln!(md, "|---|---|---|---|---|---|---|---|");
        for Upload {
            label, stats: u, ..
        } in &self.uploads
        {
            let _ = writeln!(
                md,
                "| {label} | {} | {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} |",
                u.bytes,
                u.stored_bytes,
                u.host_seconds * 1e3,
                u.record_seconds * 1e3,
                u.gpu_seconds * 1e3,
                u.total_seconds * 1e3,
                u.gigabytes_per_second()
            );
        }
        md
    }
}
