//! `slosh bench bake`: the bake's stage breakdown beside the thesis's load-time tables, bytes
//! per point per section, the measured trade-off of each section encoding, and load times.
//! Writes a Markdown report (docs/results-bake.md).

use slosh_fileio::say;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use slosh_bake::{
    BakeParams, BakedStep, BatchOptions, NormalSource, Shard, StepInput, StepSource, SurfaceSelect,
    bake_step, run_batch,
};
use slosh_cache::{CacheFile, Compression, Encoding, LoadedStep, encode_bytes, encode_step};
use slosh_fileio::FileBytes;
use slosh_mls::{Surface, SurfaceParams};
use slosh_scenes::{Scene, SceneKind, SceneSpec};

use crate::stats::median;

/// What `slosh bench bake` measures and where it writes.
#[derive(Debug, Clone)]
pub struct Settings {
    /// Markdown report to write.
    pub out: PathBuf,
    /// Timed runs per measurement (the median is reported).
    pub runs: usize,
    /// Small sizes only.
    pub quick: bool,
    /// Point counts measured (empty: the defaults).
    pub points: Vec<usize>,
    /// Thread counts measured (empty: 1, 2, 4 … up to the cores).
    pub threads: Vec<usize>,
    /// Steps per series in the end-to-end rows.
    pub series: usize,
}

/// The thesis's table 4.7 (sloshing tank, 50 neighbours, quadratic): nearest neighbours,
/// initial MLS and total seconds per step, by point count.
const THESIS: [(usize, f64, f64, f64); 3] = [
    (2_500, 0.071, 0.080, 1.008),
    (10_000, 0.397, 0.315, 2.093),
    (100_000, 2.730, 3.341, 14.176),
];

/// The sphere step of `points` points, and its mean particle spacing.
fn input(points: usize) -> (StepInput, f64) {
    let scene = Scene::new(SceneSpec::new(SceneKind::Sphere, points, 1))
        .unwrap_or_else(|_| unreachable!("sphere scenes of a positive size always build"));
    let input = slosh_testkit::scene_step(&scene, 0, &format!("sphere {points}"));
    (input, scene.spacing())
}

/// The peer on the same particles and cores: splashsurf (pysplashsurf 0.14.1) reconstructing
/// a mesh with particle radius half the spacing, smoothing length 2r, cubes 0.5r and iso 0.6
/// (given in particle radii, as pysplashsurf takes them). Median seconds of `runs`, with the
/// mesh's triangle count; `Ok(None)` where python3 cannot import pysplashsurf.
fn splashsurf_seconds(
    positions: &[[f64; 3]],
    radius: f64,
    runs: usize,
) -> Result<Option<(f64, u64)>> {
    const SCRIPT: &str = "import sys, time, numpy as np, pysplashsurf
p = np.fromfile(sys.argv[1], dtype='<f4').reshape(-1, 3)
r, runs = float(sys.argv[2]), int(sys.argv[3])
times = []
for _ in range(runs):
    t = time.perf_counter()
    m = pysplashsurf.reconstruct_surface(p, particle_radius=r, smoothing_length=2.0,
                                         cube_size=0.5, iso_surface_threshold=0.6)
    times.append(time.perf_counter() - t)
times.sort()
print(times[len(times) // 2], len(m.mesh.triangles))
";
    let available = std::process::Command::new("python3")
        .args(["-c", "import pysplashsurf"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !available {
        return Ok(None);
    }
    let file = tempfile::NamedTempFile::new()?;
    let bytes: Vec<u8> = positions
        .iter()
        .flat_map(|p| p.iter().flat_map(|&c| (c as f32).to_le_bytes()))
        .collect();
    std::fs::write(file.path(), bytes)?;
    let out = std::process::Command::new("python3")
        .args(["-c", SCRIPT])
        .arg(file.path())
        .arg(radius.to_string())
        .arg(runs.max(1).to_string())
        .output()?;
    if !out.status.success() {
        anyhow::bail!(
            "pysplashsurf failed: {}",
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    let text = String::from_utf8_lossy(&out.stdout);
    let mut words = text.split_whitespace();
    let seconds: f64 = words
        .next()
        .and_then(|w| w.parse().ok())
        .with_context(|| format!("pysplashsurf printed '{}'", text.trim()))?;
    let triangles: u64 = words.next().and_then(|w| w.parse().ok()).unwrap_or(0);
    Ok(Some((seconds, triangles)))
}

fn time<T>(runs: usize, mut f: impl FnMut() -> T) -> f64 {
    median(
        (0..runs.max(1))
            .map(|_| {
                let t = Instant::now();
                std::hint::black_box(f());
                t.elapsed().as_secs_f64()
            })
            .collect(),
    )
}

pub fn run(args: &Settings) -> Result<()> {
    let sizes: Vec<usize> = if !args.points.is_empty() {
        args.points.clone()
    } else if args.quick {
        vec![2_500, 10_000]
    } else {
        vec![2_500, 10_000, 100_000, 1_000_000]
    };
    let params = BakeParams::new(SurfaceSelect::All, NormalSource::Variable("normal".into()));
    let mut md = String::new();
    let threads = rayon::current_num_threads();
    writeln!(
        md,
        "# Bake speed, size and load time\n\nWritten by `slosh bench bake{}` on this machine ({threads} threads). \
         Point sets are sphere surfaces with normals from `crates/scenes` (every particle a surface particle); \
         default parameters (k 6, h-scale 1.5, neighbour cap 128, quadratic, zstd level 1). Times are medians of \
         {} runs (1 at 1M points), wall clock; the bare baseline and the bake alternate run by run so that \
         their ratio compares like with like on this shared machine.\n",
        if args.quick { " --quick" } else { "" },
        args.runs
    )?;
    writeln!(md, "## Stages per step\n")?;
    writeln!(
        md,
        "| points | read | kNN + radii | neighbour lists | initial fits | droplets | BVH | order + sections | compress + encode | **total** | bare kNN + lists + fits | total / bare | thesis kNN | thesis MLS | thesis total | speed-up |"
    )?;
    writeln!(
        md,
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    )?;
    // The largest size up to 100k, or the smallest where every size is larger.
    let encodings_size = sizes
        .iter()
        .copied()
        .filter(|&s| s <= 100_000)
        .max()
        .or_else(|| sizes.iter().copied().min())
        .unwrap_or(10_000);
    let mut encodings_step = None;
    let mut size_rows = String::new();
    let mut peer_rows = String::new();
    let mut load_rows = String::new();
    // Each size's step alone on every core, for the series table.
    let mut one_step: Vec<(usize, f64)> = Vec::new();
    for &n in &sizes {
        let (inp, spacing) = input(n);
        let runs = if n >= 1_000_000 { 1 } else { args.runs };
        // The bare baseline: kiddo kNN, neighbour lists and fits, nothing else.
        let bare_params = SurfaceParams {
            droplet_below: 0,
            ..params.mls.clone()
        };
        let mut stage_runs: Vec<Vec<(String, f64)>> = Vec::new();
        let mut totals = Vec::new();
        let mut bares = Vec::new();
        let mut encoded = Vec::new();
        let mut last_baked = None;
        // Baseline and bake alternate, so that both see the same machine load.
        for _ in 0..runs {
            bares.push(time(1, || {
                Surface::<f64>::build(&inp.positions, inp.normals.as_deref(), &bare_params)
            }));
            let step = bake_and_encode(&inp, &params)?;
            totals.push(step.seconds);
            stage_runs.push(step.stages);
            encoded = step.encoded;
            last_baked = Some(step.baked);
        }
        let Some(baked) = last_baked else {
            unreachable!("at least one run per size")
        };
        let stage = |name: &str| {
            median(
                stage_runs
                    .iter()
                    .map(|s| s.iter().filter(|(n, _)| n == name).map(|(_, v)| v).sum())
                    .collect(),
            )
        };
        let total = median(totals);
        one_step.push((n, total));
        let bare = median(bares);
        let peer = splashsurf_seconds(&inp.positions, 0.5 * spacing, runs)?;
        let rate = |s: f64| format!("{:.0}k", n as f64 / s / 1e3);
        match peer {
            Some((seconds, triangles)) => writeln!(
                peer_rows,
                "| {n} | {:.3} s | {} | {seconds:.3} s ({triangles} triangles) | {} | {:.2}× |",
                total,
                rate(total),
                rate(seconds),
                seconds / total
            )?,
            None => writeln!(
                peer_rows,
                "| {n} | {:.3} s | {} | not run: python3 cannot import pysplashsurf (pip install pysplashsurf==0.14.1) | — | — |",
                total,
                rate(total)
            )?,
        }
        let ms = |s: f64| format!("{:.1} ms", s * 1e3);
        let thesis = THESIS.iter().find(|t| t.0 == n);
        writeln!(
            md,
            "| {n} | (in memory) | {} | {} | {} | {} | {} | {} | {} | **{}** | {} | {:.2} | {} | {} | {} | {} |",
            ms(stage("kd-tree and radii (kNN)")),
            ms(stage("neighbour lists")),
            ms(stage("initial fits")),
            ms(stage("droplets")),
            ms(stage("bvh")),
            ms(stage("select") + stage("recentre") + stage("morton order") + stage("sections")),
            ms(stage("encode")),
            ms(total),
            ms(bare),
            total / bare,
            thesis.map_or("".into(), |t| format!("{:.3} s", t.1)),
            thesis.map_or("".into(), |t| format!("{:.3} s", t.2)),
            thesis.map_or("".into(), |t| format!("{:.3} s", t.3)),
            thesis.map_or("".into(), |t| format!("{:.0}×", t.3 / total)),
        )?;

        // Bytes per point per section.
        let file =
            CacheFile::from_bytes(FileBytes::from_vec(Path::new("bench.slc"), encoded.clone()))?;
        let per = |b: u64| b as f64 / n as f64;
        let mut cells = String::new();
        for s in &file.header().sections {
            write!(
                cells,
                "{}: {:.1} ({:.1} raw); ",
                s.name,
                per(s.stored),
                per(s.raw)
            )?;
        }
        writeln!(
            size_rows,
            "| {n} | {:.1} | {cells} |",
            per(encoded.len() as u64)
        )?;

        // Load: from a file in the page cache, open (map + structural checks), then decode
        // every section into ready buffers; and the same with full verification.
        let dir = tempfile::tempdir()?;
        let path = dir.path().join("step.slc");
        slosh_fileio::atomic_write(&path, &encoded)?;
        let mut buffers = file.section_buffers();
        let load_runs = if n >= 1_000_000 { 5 } else { 20 };
        let load = time(load_runs, || {
            CacheFile::open(&path).and_then(|f| f.decode_all_into(&mut buffers))
        });
        let open_only = time(load_runs, || CacheFile::open(&path).map(|_| ()));
        // The same step written uncompressed (`--compress none`): loading is copying.
        let raw_path = dir.path().join("raw.slc");
        slosh_fileio::atomic_write(
            &raw_path,
            &encode_step(baked.header.clone(), &baked.sections, Compression::None)?,
        )?;
        let load_raw = time(load_runs, || {
            CacheFile::open(&raw_path).and_then(|f| f.decode_all_into(&mut buffers))
        });
        let verify = time(load_runs.min(5), || {
            CacheFile::open(&path).and_then(|f| f.verify())
        });
        let cpu_ready = time(load_runs.min(5), || -> Result<()> {
            let f = CacheFile::open(&path)?;
            LoadedStep::load(&f)?;
            Ok(())
        });
        let raw_total: u64 = file.header().sections.iter().map(|s| s.raw).sum();
        writeln!(
            load_rows,
            "| {n} | {:.2} ms | {:.2} ms | {:.2} GB/s | {:.2} ms | {:.1} ms | {:.1} ms |",
            open_only * 1e3,
            load * 1e3,
            raw_total as f64 / load / 1e9,
            load_raw * 1e3,
            verify * 1e3,
            cpu_ready * 1e3
        )?;
        eprintln!(
            "{n} points: total {total:.3} s, bare {bare:.3} s, load {:.2} ms",
            load * 1e3
        );
        if n == encodings_size {
            encodings_step = Some(baked);
        }
    }
    let (scaling, series) = scaling_and_series(args, &sizes, &params, &one_step)?;
    writeln!(
        md,
        "\n*bare* is `Surface::build` alone (kiddo kNN and radii, neighbour lists, initial fits) in the same run; \
         *total* adds selection, recentring, Morton order, droplets, BVH and section encoding (compression included). \
         The thesis's rows are its table 4.7 (sloshing tank, 50 nearest neighbours, quadratic; 2012 CPU), \
         its *total* including its OptiX scene graph and context compilation, which slosh does not need: \
         a slosh step is ready when its sections are decoded (next table).\n"
    )?;
    writeln!(
        md,
        "## Beside the peer: splashsurf on the same particles and cores\n\n\
         splashsurf (pysplashsurf 0.14.1, the field's standard SPH surface reconstruction) turns the same sphere particles \
         into a triangle mesh on the same machine and threads: particle radius half the mean spacing, smoothing length 2r, \
         marching-cubes cells 0.5r, iso 0.6 (given in particle radii, which pysplashsurf takes despite its docstring). The \
         jobs differ (a memory-mappable cache of MLS balls and a BVH against a mesh), but each is the step that turns a \
         step's particles into a viewable surface. Medians as above; the peer runs in its own process after slosh.\n\n\
         | points | slosh bake | slosh points/s | splashsurf | splashsurf points/s | slosh faster by |\n|---|---|---|---|---|---|\n{peer_rows}"
    )?;
    md += &scaling;
    md += &series;
    writeln!(
        md,
        "## Stored bytes per point\n\n| points | total B/pt | per section: stored (raw) B/pt |\n|---|---|---|\n{size_rows}"
    )?;
    writeln!(
        md,
        "## Load time (file in the page cache)\n\n| points | open (map + checks) | open + decode every section into ready buffers | effective rate (raw bytes) | same, written with `--compress none` | open + full verify | open + CPU tracer structures |\n|---|---|---|---|---|---|---|\n{load_rows}"
    )?;

    // Encodings measured on the 100k (or largest) step's sections.
    let n = encodings_size;
    let Some(baked) = encodings_step else {
        unreachable!("the encodings size is one of the sizes baked")
    };
    writeln!(
        md,
        "## Section encodings ({n} points, zstd level 1)\n\nRatio = raw / stored; speeds are raw bytes per second, single thread, median of 5.\n\n| section | raw B/pt | encoding | ratio | compress GB/s | decompress GB/s |\n|---|---|---|---|---|---|"
    )?;
    for s in &baked.sections {
        if s.bytes.is_empty() {
            continue;
        }
        let by_element = Encoding::shuffled_elements(s.element.size());
        let mut encodings = vec![
            Encoding::Zstd,
            Encoding::Shuffle4Zstd,
            Encoding::Delta4Shuffle4Zstd,
        ];
        if !encodings.contains(&by_element) {
            encodings.push(by_element);
        }
        for enc in encodings {
            let mut packed = Vec::new();
            let c = time(5, || {
                packed = encode_bytes(&s.bytes, enc, 1).unwrap_or_default();
            });
            let mut out = vec![0u8; s.bytes.len()];
            let mut scratch = Vec::new();
            let d = time(5, || {
                slosh_cache::decode_bytes(&packed, enc, &mut out, &mut scratch)
            });
            let mark = if enc == s.encoding { " (chosen)" } else { "" };
            writeln!(
                md,
                "| {} | {:.1} | {}{mark} | {:.2} | {:.2} | {:.2} |",
                s.name,
                s.bytes.len() as f64 / n as f64,
                enc.name(),
                s.bytes.len() as f64 / packed.len().max(1) as f64,
                s.bytes.len() as f64 / c / 1e9,
                s.bytes.len() as f64 / d / 1e9
            )?;
        }
    }
    slosh_fileio::atomic_write(&args.out, md.as_bytes())?;
    say!("wrote {}", args.out.display());
    Ok(())
}

/// The stages a row of the scaling table shows, in pipeline order: (heading, stage laps
/// summed into it).
const STAGE_COLUMNS: [(&str, &[&str]); 9] = [
    ("select + order", &["select", "recentre", "morton order"]),
    ("kNN + radii", &["kd-tree and radii (kNN)"]),
    ("orientation", &["orientation"]),
    ("neighbour lists", &["neighbour lists"]),
    ("initial fits", &["initial fits"]),
    ("droplets", &["droplets"]),
    ("BVH", &["bvh"]),
    ("sections", &["sections"]),
    ("encode", &["encode"]),
];

/// One step baked and encoded.
struct TimedStep {
    baked: BakedStep,
    encoded: Vec<u8>,
    /// Wall seconds, bake and encoding.
    seconds: f64,
    /// Seconds of each stage, "encode" last.
    stages: Vec<(String, f64)>,
}

fn bake_and_encode(input: &StepInput, params: &BakeParams) -> Result<TimedStep> {
    let t = Instant::now();
    let baked = bake_step(input, params)?;
    let t_enc = Instant::now();
    let encoded = encode_step(baked.header.clone(), &baked.sections, params.compression)?;
    let mut stages = baked.header.stats.stage_seconds.clone();
    stages.push(("encode".into(), t_enc.elapsed().as_secs_f64()));
    Ok(TimedStep {
        baked,
        encoded,
        seconds: t.elapsed().as_secs_f64(),
        stages,
    })
}

/// A moving sphere series generated in memory: the batch driver's input without files.
struct SceneSteps {
    scene: Scene,
    steps: usize,
}

impl StepSource for SceneSteps {
    fn source_path(&self) -> String {
        "bench series".into()
    }

    fn steps(&self) -> Vec<(usize, f64)> {
        (0..self.steps).map(|i| (i, i as f64)).collect()
    }

    fn read(&self, index: usize) -> std::result::Result<StepInput, String> {
        let (positions, normals) = self.scene.particles(index).surface_arrays();
        Ok(StepInput {
            index,
            time: index as f64,
            source: "bench series".into(),
            positions,
            normals: Some(normals),
            ..StepInput::default()
        })
    }
}

/// The scaling table (each size on pools of each thread count, stage by stage) and the series
/// table (the batch driver with its default `--jobs` against one step alone), as Markdown.
fn scaling_and_series(
    args: &Settings,
    sizes: &[usize],
    params: &BakeParams,
    one_step: &[(usize, f64)],
) -> Result<(String, String)> {
    let cores = slosh_bake::cores();
    let mut threads: Vec<usize> = if args.threads.is_empty() {
        vec![1, 2, cores]
    } else {
        args.threads.clone()
    };
    threads.retain(|&t| t >= 1);
    threads.sort_unstable();
    threads.dedup();
    let mut scaling = String::new();
    writeln!(
        scaling,
        "## Scaling with threads\n\nEach step baked and encoded on a rayon pool of that many threads \
         ({cores} cores here); medians of {} runs (1 at 1M points and above). Speed-up is against \
         the fewest threads of the same size.\n",
        args.runs
    )?;
    let heads: Vec<&str> = STAGE_COLUMNS.iter().map(|c| c.0).collect();
    writeln!(
        scaling,
        "| points | threads | {} | **total** | points/s | speed-up |\n|{}",
        heads.join(" | "),
        "---|".repeat(heads.len() + 5)
    )?;
    for &n in sizes {
        let (inp, _) = input(n);
        let runs = if n >= 1_000_000 { 1 } else { args.runs.max(1) };
        let mut first_total = None;
        for &t in &threads {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(t).build()?;
            let mut totals = Vec::new();
            let mut stage_runs = Vec::new();
            for _ in 0..runs {
                let step = pool.install(|| bake_and_encode(&inp, params))?;
                totals.push(step.seconds);
                stage_runs.push(step.stages);
            }
            let total = median(totals);
            let base = *first_total.get_or_insert(total);
            let cells: Vec<String> = STAGE_COLUMNS
                .iter()
                .map(|(_, names)| {
                    let s = median(
                        stage_runs
                            .iter()
                            .map(|laps: &Vec<(String, f64)>| {
                                laps.iter()
                                    .filter(|(l, _)| names.contains(&l.as_str()))
                                    .map(|(_, v)| v)
                                    .sum()
                            })
                            .collect(),
                    );
                    format!("{:.1} ms", s * 1e3)
                })
                .collect();
            writeln!(
                scaling,
                "| {n} | {t} | {} | **{:.1} ms** | {:.0}k | {:.2}× |",
                cells.join(" | "),
                total * 1e3,
                n as f64 / total / 1e3,
                base / total
            )?;
            eprintln!("{n} points on {t} threads: {total:.3} s");
        }
    }
    let mut series = String::new();
    if args.series == 0 {
        return Ok((scaling, series));
    }
    writeln!(
        series,
        "\n## A series against one step alone\n\n{} steps of the moving sphere baked by the batch driver \
         as `slosh bake` runs it (generated in memory instead of read; compressed, verified and written \
         to a temporary directory), with the `--jobs` it would choose here, on all {cores} cores. \
         *One step* is the same size's step alone on all cores, from the first table (baked and encoded, \
         not verified or written).\n\n| points | jobs | wall | per step | points/s | one step | per step / one step |\n|---|---|---|---|---|---|---|",
        args.series
    )?;
    for &n in sizes {
        let Some(&(_, alone)) = one_step.iter().find(|(m, _)| *m == n) else {
            continue;
        };
        let scene = Scene::new(SceneSpec::new(SceneKind::Sphere, n, 1))?;
        let source = SceneSteps {
            scene,
            steps: args.series,
        };
        let (jobs, _) = slosh_bake::default_jobs(cores, slosh_bake::available_memory(), Some(n));
        let dir = tempfile::tempdir()?;
        let opts = BatchOptions {
            out: dir.path().to_path_buf(),
            steps: None,
            jobs,
            threads: cores,
            shard: Shard::WHOLE,
            params: params.clone(),
        };
        let t = Instant::now();
        let report = run_batch(&source, &opts, &|_| {})?;
        let wall = t.elapsed().as_secs_f64();
        if !report.failed.is_empty() {
            anyhow::bail!("the series bake failed: {:?}", report.failed);
        }
        let per = wall / args.series as f64;
        writeln!(
            series,
            "| {n} | {jobs} | {wall:.2} s | {:.1} ms | {:.0}k | {:.1} ms | {:.2}× |",
            per * 1e3,
            n as f64 / per / 1e3,
            alone * 1e3,
            per / alone
        )?;
        eprintln!("{n} points, series of {}: {per:.3} s per step", args.series);
    }
    Ok((scaling, series))
}
