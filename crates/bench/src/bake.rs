//! `slosh bench bake`: the bake's stage breakdown beside the thesis's load-time tables, bytes
//! per point per section, the measured trade-off of each section encoding, and load times.
//! Writes a Markdown report (docs/results-bake.md).

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

use crate::report::Report;
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

/// One size's bake by stage, beside the bare core and the thesis (seconds).
#[derive(Debug, Clone, PartialEq)]
pub struct StageRow {
    pub points: usize,
    /// kNN + radii, neighbour lists, initial fits, droplets, BVH, order + sections, encode.
    pub stages: [f64; 7],
    pub total: f64,
    pub bare: f64,
    /// The thesis's kNN, MLS and total seconds for this size, where it has them.
    pub thesis: Option<(f64, f64, f64)>,
}

/// One size beside splashsurf: slosh's seconds, and the peer's seconds and triangles where
/// it ran.
#[derive(Debug, Clone, PartialEq)]
pub struct PeerRow {
    pub points: usize,
    pub total: f64,
    pub peer: Option<(f64, u64)>,
}

/// One size's stored bytes: the file, and each section's stored and raw bytes.
#[derive(Debug, Clone, PartialEq)]
pub struct SizeRow {
    pub points: usize,
    pub file_bytes: u64,
    pub sections: Vec<(String, u64, u64)>,
}

/// One size's load times from the page cache (seconds).
#[derive(Debug, Clone, PartialEq)]
pub struct LoadRow {
    pub points: usize,
    pub open: f64,
    pub load: f64,
    /// Raw bytes of every section.
    pub raw_bytes: u64,
    pub load_uncompressed: f64,
    pub verify: f64,
    pub cpu_ready: f64,
}

/// One section under one encoding: sizes and single-thread seconds.
#[derive(Debug, Clone, PartialEq)]
pub struct EncodingRow {
    pub section: String,
    pub raw_bytes: usize,
    pub encoding: String,
    pub chosen: bool,
    pub stored_bytes: usize,
    pub compress: f64,
    pub decompress: f64,
}

/// One size on one thread count: each `STAGE_COLUMNS` stage and the total (seconds), and
/// the total on the fewest threads.
#[derive(Debug, Clone, PartialEq)]
pub struct ScalingRow {
    pub points: usize,
    pub threads: usize,
    pub stages: Vec<f64>,
    pub total: f64,
    pub fewest_threads_total: f64,
}

/// One size's series through the batch driver, beside one step alone (seconds).
#[derive(Debug, Clone, PartialEq)]
pub struct SeriesRow {
    pub points: usize,
    pub jobs: usize,
    pub wall: f64,
    pub per_step: f64,
    pub one_step: f64,
}

/// What `slosh bench bake` measured.
#[derive(Debug, Clone)]
pub struct BakeReport {
    pub settings: Settings,
    /// rayon's threads, and the machine's cores.
    pub threads: usize,
    pub cores: usize,
    pub stages: Vec<StageRow>,
    pub peers: Vec<PeerRow>,
    pub sizes: Vec<SizeRow>,
    pub loads: Vec<LoadRow>,
    /// The size whose sections the encodings table measures.
    pub encodings_points: usize,
    pub encodings: Vec<EncodingRow>,
    pub scaling: Vec<ScalingRow>,
    pub series: Vec<SeriesRow>,
}

pub fn run(args: &Settings) -> Result<BakeReport> {
    let sizes: Vec<usize> = if !args.points.is_empty() {
        args.points.clone()
    } else if args.quick {
        vec![2_500, 10_000]
    } else {
        vec![2_500, 10_000, 100_000, 1_000_000]
    };
    let params = BakeParams::new(SurfaceSelect::All, NormalSource::Variable("normal".into()));
    // The largest size up to 100k, or the smallest where every size is larger.
    let encodings_size = sizes
        .iter()
        .copied()
        .filter(|&s| s <= 100_000)
        .max()
        .or_else(|| sizes.iter().copied().min())
        .unwrap_or(10_000);
    let mut encodings_step = None;
    let (mut stage_rows, mut peer_rows, mut size_rows, mut load_rows) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
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
        peer_rows.push(PeerRow {
            points: n,
            total,
            peer,
        });
        stage_rows.push(StageRow {
            points: n,
            stages: [
                stage("kd-tree and radii (kNN)"),
                stage("neighbour lists"),
                stage("initial fits"),
                stage("droplets"),
                stage("bvh"),
                stage("select") + stage("recentre") + stage("morton order") + stage("sections"),
                stage("encode"),
            ],
            total,
            bare,
            thesis: THESIS.iter().find(|t| t.0 == n).map(|t| (t.1, t.2, t.3)),
        });

        // Bytes per point per section.
        let file =
            CacheFile::from_bytes(FileBytes::from_vec(Path::new("bench.slc"), encoded.clone()))?;
        size_rows.push(SizeRow {
            points: n,
            file_bytes: encoded.len() as u64,
            sections: file
                .header()
                .sections
                .iter()
                .map(|s| (s.name.clone(), s.stored, s.raw))
                .collect(),
        });

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
        load_rows.push(LoadRow {
            points: n,
            open: open_only,
            load,
            raw_bytes: file.header().sections.iter().map(|s| s.raw).sum(),
            load_uncompressed: load_raw,
            verify,
            cpu_ready,
        });
        eprintln!(
            "{n} points: total {total:.3} s, bare {bare:.3} s, load {:.2} ms",
            load * 1e3
        );
        if n == encodings_size {
            encodings_step = Some(baked);
        }
    }
    let (scaling, series) = scaling_and_series(args, &sizes, &params, &one_step)?;

    // Encodings measured on the 100k (or largest) step's sections.
    let Some(baked) = encodings_step else {
        unreachable!("the encodings size is one of the sizes baked")
    };
    let mut encodings = Vec::new();
    for s in &baked.sections {
        if s.bytes.is_empty() {
            continue;
        }
        let by_element = Encoding::shuffled_elements(s.element.size());
        let mut candidates = vec![
            Encoding::Zstd,
            Encoding::Shuffle4Zstd,
            Encoding::Delta4Shuffle4Zstd,
        ];
        if !candidates.contains(&by_element) {
            candidates.push(by_element);
        }
        for enc in candidates {
            let mut packed = Vec::new();
            let c = time(5, || {
                packed = encode_bytes(&s.bytes, enc, 1).unwrap_or_default();
            });
            let mut out = vec![0u8; s.bytes.len()];
            let mut scratch = Vec::new();
            let d = time(5, || {
                slosh_cache::decode_bytes(&packed, enc, &mut out, &mut scratch)
            });
            encodings.push(EncodingRow {
                section: s.name.clone(),
                raw_bytes: s.bytes.len(),
                encoding: enc.name().to_string(),
                chosen: enc == s.encoding,
                stored_bytes: packed.len(),
                compress: c,
                decompress: d,
            });
        }
    }
    Ok(BakeReport {
        settings: args.clone(),
        threads: rayon::current_num_threads(),
        cores: slosh_bake::cores(),
        stages: stage_rows,
        peers: peer_rows,
        sizes: size_rows,
        loads: load_rows,
        encodings_points: encodings_size,
        encodings,
        scaling,
        series,
    })
}

impl Report for BakeReport {
    fn markdown(&self) -> String {
        let args = &self.settings;
        let mut md = String::new();
        let threads = self.threads;
        let _ = writeln!(
            md,
            "# Bake speed, size and load time\n\nWritten by `slosh bench bake{}` on this machine ({threads} threads). \
             Point sets are sphere surfaces with normals from `crates/scenes` (every particle a surface particle); \
             default parameters (k 6, h-scale 1.5, neighbour cap 128, quadratic, zstd level 1). Times are medians of \
             {} runs (1 at 1M points), wall clock; the bare baseline and the bake alternate run by run so that \
             their ratio compares like with like on this shared machine.\n",
            if args.quick { " --quick" } else { "" },
            args.runs
        );
        let _ = writeln!(md, "## Stages per step\n");
        let _ = writeln!(
            md,
            "| points | read | kNN + radii | neighbour lists | initial fits | droplets | BVH | order + sections | compress + encode | **total** | bare kNN + lists + fits | total / bare | thesis kNN | thesis MLS | thesis total | speed-up |"
        );
        let _ = writeln!(
            md,
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
        );
        let ms = |s: f64| format!("{:.1} ms", s * 1e3);
        for r in &self.stages {
            let [knn, lists, fits, droplets, bvh, sections, encode] = r.stages;
            let _ = writeln!(
                md,
                "| {} | (in memory) | {} | {} | {} | {} | {} | {} | {} | **{}** | {} | {:.2} | {} | {} | {} | {} |",
                r.points,
                ms(knn),
                ms(lists),
                ms(fits),
                ms(droplets),
                ms(bvh),
                ms(sections),
                ms(encode),
                ms(r.total),
                ms(r.bare),
                r.total / r.bare,
                r.thesis.map_or("".into(), |t| format!("{:.3} s", t.0)),
                r.thesis.map_or("".into(), |t| format!("{:.3} s", t.1)),
                r.thesis.map_or("".into(), |t| format!("{:.3} s", t.2)),
                r.thesis
                    .map_or("".into(), |t| format!("{:.0}×", t.2 / r.total)),
            );
        }
        let mut peer_rows = String::new();
        for r in &self.peers {
            let n = r.points;
            let rate = |s: f64| format!("{:.0}k", n as f64 / s / 1e3);
            let _ = match r.peer {
                Some((seconds, triangles)) => writeln!(
                    peer_rows,
                    "| {n} | {:.3} s | {} | {seconds:.3} s ({triangles} triangles) | {} | {:.2}× |",
                    r.total,
                    rate(r.total),
                    rate(seconds),
                    seconds / r.total
                ),
                None => writeln!(
                    peer_rows,
                    "| {n} | {:.3} s | {} | not run: python3 cannot import pysplashsurf (pip install pysplashsurf==0.14.1) | — | — |",
                    r.total,
                    rate(r.total)
                ),
            };
        }
        let _ = writeln!(
            md,
            "\n*bare* is `Surface::build` alone (kiddo kNN and radii, neighbour lists, initial fits) in the same run; \
             *total* adds selection, recentring, Morton order, droplets, BVH and section encoding (compression included). \
             The thesis's rows are its table 4.7 (sloshing tank, 50 nearest neighbours, quadratic; 2012 CPU), \
             its *total* including its OptiX scene graph and context compilation, which slosh does not need: \
             a slosh step is ready when its sections are decoded (next table).\n"
        );
        let _ = writeln!(
            md,
            "## Beside the peer: splashsurf on the same particles and cores\n\n\
             splashsurf (pysplashsurf 0.14.1, the field's standard SPH surface reconstruction) turns the same sphere particles \
             into a triangle mesh on the same machine and threads: particle radius half the mean spacing, smoothing length 2r, \
             marching-cubes cells 0.5r, iso 0.6 (given in particle radii, which pysplashsurf takes despite its docstring). The \
             jobs differ (a memory-mappable cache of MLS balls and a BVH against a mesh), but each is the step that turns a \
             step's particles into a viewable surface. Medians as above; the peer runs in its own process after slosh.\n\n\
             | points | slosh bake | slosh points/s | splashsurf | splashsurf points/s | slosh faster by |\n|---|---|---|---|---|---|\n{peer_rows}"
        );
        md += &self.scaling_markdown();
        md += &self.series_markdown();
        let mut size_rows = String::new();
        for r in &self.sizes {
            let per = |b: u64| b as f64 / r.points as f64;
            let mut cells = String::new();
            for (name, stored, raw) in &r.sections {
                let _ = write!(
                    cells,
                    "{name}: {:.1} ({:.1} raw); ",
                    per(*stored),
                    per(*raw)
                );
            }
            let _ = writeln!(
                size_rows,
                "| {} | {:.1} | {cells} |",
                r.points,
                per(r.file_bytes)
            );
        }
        let _ = writeln!(
            md,
            "## Stored bytes per point\n\n| points | total B/pt | per section: stored (raw) B/pt |\n|---|---|---|\n{size_rows}"
        );
        let mut load_rows = String::new();
        for r in &self.loads {
            let _ = writeln!(
                load_rows,
                "| {} | {:.2} ms | {:.2} ms | {:.2} GB/s | {:.2} ms | {:.1} ms | {:.1} ms |",
                r.points,
                r.open * 1e3,
                r.load * 1e3,
                r.raw_bytes as f64 / r.load / 1e9,
                r.load_uncompressed * 1e3,
                r.verify * 1e3,
                r.cpu_ready * 1e3
            );
        }
        let _ = writeln!(
            md,
            "## Load time (file in the page cache)\n\n| points | open (map + checks) | open + decode every section into ready buffers | effective rate (raw bytes) | same, written with `--compress none` | open + full verify | open + CPU tracer structures |\n|---|---|---|---|---|---|---|\n{load_rows}"
        );
        let n = self.encodings_points;
        let _ = writeln!(
            md,
            "## Section encodings ({n} points, zstd level 1)\n\nRatio = raw / stored; speeds are raw bytes per second, single thread, median of 5.\n\n| section | raw B/pt | encoding | ratio | compress GB/s | decompress GB/s |\n|---|---|---|---|---|---|"
        );
        for e in &self.encodings {
            let mark = if e.chosen { " (chosen)" } else { "" };
            let _ = writeln!(
                md,
                "| {} | {:.1} | {}{mark} | {:.2} | {:.2} | {:.2} |",
                e.section,
                e.raw_bytes as f64 / n as f64,
                e.encoding,
                e.raw_bytes as f64 / e.stored_bytes.max(1) as f64,
                e.raw_bytes as f64 / e.compress / 1e9,
                e.raw_bytes as f64 / e.decompress / 1e9
            );
        }
        md
    }
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

/// The scaling rows (each size on pools of each thread count, stage by stage) and the
/// series rows (the batch driver with its default `--jobs` against one step alone).
fn scaling_and_series(
    args: &Settings,
    sizes: &[usize],
    params: &BakeParams,
    one_step: &[(usize, f64)],
) -> Result<(Vec<ScalingRow>, Vec<SeriesRow>)> {
    let cores = slosh_bake::cores();
    let mut scaling = Vec::new();
    for &n in sizes {
        let (inp, _) = input(n);
        let runs = if n >= 1_000_000 { 1 } else { args.runs.max(1) };
        let mut first_total = None;
        for t in thread_counts(args, cores) {
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
            let stages: Vec<f64> = STAGE_COLUMNS
                .iter()
                .map(|(_, names)| {
                    median(
                        stage_runs
                            .iter()
                            .map(|laps: &Vec<(String, f64)>| {
                                laps.iter()
                                    .filter(|(l, _)| names.contains(&l.as_str()))
                                    .map(|(_, v)| v)
                                    .sum()
                            })
                            .collect(),
                    )
                })
                .collect();
            scaling.push(ScalingRow {
                points: n,
                threads: t,
                stages,
                total,
                fewest_threads_total: base,
            });
            eprintln!("{n} points on {t} threads: {total:.3} s");
        }
    }
    let mut series = Vec::new();
    if args.series == 0 {
        return Ok((scaling, series));
    }
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
        series.push(SeriesRow {
            points: n,
            jobs,
            wall,
            per_step: per,
            one_step: alone,
        });
        eprintln!("{n} points, series of {}: {per:.3} s per step", args.series);
    }
    Ok((scaling, series))
}

/// The thread counts of the scaling table: the settings', else 1, 2 and every core.
fn thread_counts(args: &Settings, cores: usize) -> Vec<usize> {
    let mut threads: Vec<usize> = if args.threads.is_empty() {
        vec![1, 2, cores]
    } else {
        args.threads.clone()
    };
    threads.retain(|&t| t >= 1);
    threads.sort_unstable();
    threads.dedup();
    threads
}

impl BakeReport {
    fn scaling_markdown(&self) -> String {
        let cores = self.cores;
        let mut scaling = String::new();
        let _ = writeln!(
            scaling,
            "## Scaling with threads\n\nEach step baked and encoded on a rayon pool of that many threads \
             ({cores} cores here); medians of {} runs (1 at 1M points and above). Speed-up is against \
             the fewest threads of the same size.\n",
            self.settings.runs
        );
        let heads: Vec<&str> = STAGE_COLUMNS.iter().map(|c| c.0).collect();
        let _ = writeln!(
            scaling,
            "| points | threads | {} | **total** | points/s | speed-up |\n|{}",
            heads.join(" | "),
            "---|".repeat(heads.len() + 5)
        );
        for r in &self.scaling {
            let cells: Vec<String> = r
                .stages
                .iter()
                .map(|s| format!("{:.1} ms", s * 1e3))
                .collect();
            let _ = writeln!(
                scaling,
                "| {} | {} | {} | **{:.1} ms** | {:.0}k | {:.2}× |",
                r.points,
                r.threads,
                cells.join(" | "),
                r.total * 1e3,
                r.points as f64 / r.total / 1e3,
                r.fewest_threads_total / r.total
            );
        }
        scaling
    }

    fn series_markdown(&self) -> String {
        let mut series = String::new();
        if self.settings.series == 0 {
            return series;
        }
        let _ = writeln!(
            series,
            "\n## A series against one step alone\n\n{} steps of the moving sphere baked by the batch driver \
             as `slosh bake` runs it (generated in memory instead of read; compressed, verified and written \
             to a temporary directory), with the `--jobs` it would choose here, on all {} cores. \
             *One step* is the same size's step alone on all cores, from the first table (baked and encoded, \
             not verified or written).\n\n| points | jobs | wall | per step | points/s | one step | per step / one step |\n|---|---|---|---|---|---|---|",
            self.settings.series, self.cores
        );
        for r in &self.series {
            let _ = writeln!(
                series,
                "| {} | {} | {:.2} s | {:.1} ms | {:.0}k | {:.1} ms | {:.2}× |",
                r.points,
                r.jobs,
                r.wall,
                r.per_step * 1e3,
                r.points as f64 / r.per_step / 1e3,
                r.one_step * 1e3,
                r.per_step / r.one_step
            );
        }
        series
    }
}
