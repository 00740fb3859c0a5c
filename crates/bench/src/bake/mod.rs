//! `slosh bench bake`: the bake's stage breakdown beside the thesis's load-time tables, bytes
//! per point per section, the measured trade-off of each section encoding, and load times.
//! Writes a Markdown report (docs/results-bake.md).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use slosh_bake::{
    BakeParams, BakedStep, BatchOptions, NormalSource, Shard, StepInput, StepSource, SurfaceSelect,
    bake_step_with, run_batch,
};
use slosh_cache::{CacheFile, Compression, Encoding, LoadedStep, encode_bytes, encode_step};
use slosh_fileio::FileBytes;
use slosh_mls::{Surface, SurfaceParams};
use slosh_scenes::{Scene, SceneKind, SceneSpec};

use crate::stats::median;

mod report;
mod volume;

pub use report::{
    BakeReport, EncodingRow, GpuBakeRow, LoadRow, PeerRow, ScalingRow, SeriesRow, SizeRow, StageRow,
};

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
    /// The GPU's stages each size is also baked with (alternating with the CPU's), or why
    /// there are none.
    pub gpu: Result<std::sync::Arc<slosh_gpubake::GpuStages>, String>,
}

/// The thesis's table 4.7 (sloshing tank, 50 neighbours, quadratic): nearest neighbours,
/// initial MLS and total seconds per step, by point count.
const THESIS: [(usize, f64, f64, f64); 3] = [
    (2_500, 0.071, 0.080, 1.008),
    (10_000, 0.397, 0.315, 2.093),
    (100_000, 2.730, 3.341, 14.176),
];

/// The stages `--device gpu` runs on the GPU, as the bake's clock names them.
const GPU_STAGES: [&str; 4] = [
    "kd-tree and radii (kNN)",
    "neighbour lists",
    "initial fits",
    "bvh",
];

/// The part of `stage` a stage lap is, if it is one ([`slosh_mls::stage_part`]): the GPU
/// search's neighbour lists, or the sections.
fn part_of<'a>(name: &'a str, stage: &str) -> Option<&'a str> {
    slosh_mls::stage_part(name)
        .filter(|(of, _)| *of == stage)
        .map(|(_, part)| part)
}

/// The parts of `stage` among `stages` (in their order), each timed by `time` (its name,
/// its seconds in `stages`).
fn parts_in(
    stages: &[(String, f64)],
    stage: &str,
    time: impl Fn(&str, f64) -> f64,
) -> Vec<(String, f64)> {
    stages
        .iter()
        .filter_map(|(name, s)| Some((part_of(name, stage)?.to_string(), time(name, *s))))
        .collect()
}

/// The sphere step of `points` points, and its mean particle spacing.
fn input(points: usize) -> Result<(StepInput, f64)> {
    let scene = Scene::new(SceneSpec::new(SceneKind::Sphere, points, 1))?;
    let input = slosh_testkit::scene_step(&scene, 0, &format!("sphere {points}"));
    Ok((input, scene.spacing()))
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
    // The same with the GPU's stages, where they ran.
    let mut gpu_one_step: Vec<(usize, f64)> = Vec::new();
    for &n in &sizes {
        let (inp, spacing) = input(n)?;
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
        let mut gpu_runs: Vec<TimedStep> = Vec::new();
        let mut gpu_times: Vec<f64> = Vec::new();
        // Each run's GPU time by pass.
        let mut gpu_pass_runs: Vec<Vec<(String, f64)>> = Vec::new();
        // The size's first GPU step, apart from the runs: it makes the pools' buffers for a
        // step of this size (device memory, host memory the read backs map), which a
        // series' later steps find made.
        let gpu_first = match &args.gpu {
            Ok(gpu) => Some(bake_and_encode(&inp, &params, &gpu.clone().stages())?),
            Err(_) => None,
        };
        // Baseline and bake (and the bake with the GPU's neighbours) alternate, so that all
        // see the same machine load.
        for _ in 0..runs {
            bares.push(time(1, || {
                Surface::<f64>::build(&inp.positions, inp.normals.as_deref(), &bare_params)
            }));
            let step = bake_and_encode(&inp, &params, &slosh_bake::Stages::cpu())?;
            totals.push(step.seconds);
            stage_runs.push(step.stages);
            encoded = step.encoded;
            last_baked = Some(step.baked);
            if let Ok(gpu) = &args.gpu {
                let (before, passes_before) = (gpu.gpu_seconds(), gpu.gpu_seconds_by_pass());
                gpu_runs.push(bake_and_encode(&inp, &params, &gpu.clone().stages())?);
                if let (Some(a), Some(b)) = (before, gpu.gpu_seconds()) {
                    gpu_times.push(b - a);
                }
                gpu_pass_runs.push(
                    gpu.gpu_seconds_by_pass()
                        .into_iter()
                        .map(|(pass, after)| {
                            let was = passes_before
                                .iter()
                                .find(|p| p.0 == pass)
                                .map_or(0.0, |p| p.1);
                            (pass.to_string(), after - was)
                        })
                        .collect(),
                );
            }
        }
        let Some(baked) = last_baked else {
            anyhow::bail!("no run baked {n} points: at least one run per size is needed");
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
        let gpu_stage = |name: &str| {
            median(
                gpu_runs
                    .iter()
                    .map(|r| {
                        r.stages
                            .iter()
                            .filter(|(n, _)| n == name)
                            .map(|(_, v)| v)
                            .sum()
                    })
                    .collect(),
            )
        };
        // A stage's parts, in the order the first GPU run timed them, medians of the runs.
        let parts = |of: &str| {
            gpu_runs.first().map_or(Vec::new(), |run| {
                parts_in(&run.stages, of, |name, _| gpu_stage(name))
            })
        };
        let gpu = (!gpu_runs.is_empty()).then(|| GpuBakeRow {
            total: median(gpu_runs.iter().map(|r| r.seconds).collect()),
            gpu_time: (!gpu_times.is_empty()).then(|| median(gpu_times.clone())),
            nearest: gpu_stage(GPU_STAGES[0]),
            lists: gpu_stage(GPU_STAGES[1]),
            fits: gpu_stage(GPU_STAGES[2]),
            bvh: gpu_stage(GPU_STAGES[3]),
            cpu_nearest: stage(GPU_STAGES[0]),
            cpu_lists: stage(GPU_STAGES[1]),
            cpu_fits: stage(GPU_STAGES[2]),
            cpu_bvh: stage(GPU_STAGES[3]),
            on_cpu: gpu_runs[0]
                .stages
                .iter()
                .filter(|(name, _)| {
                    !GPU_STAGES.contains(&name.as_str()) && slosh_mls::stage_part(name).is_none()
                })
                .map(|(name, _)| (name.clone(), gpu_stage(name)))
                .collect(),
            first: gpu_first.as_ref().map_or(0.0, |f| f.seconds),
            first_list_parts: gpu_first.as_ref().map_or(Vec::new(), |f| {
                parts_in(&f.stages, GPU_STAGES[1], |_, seconds| seconds)
            }),
            knn_parts: parts(GPU_STAGES[0]),
            list_parts: parts(GPU_STAGES[1]),
            fit_parts: parts(GPU_STAGES[2]),
            section_parts: parts("sections"),
            gpu_passes: gpu_pass_runs.last().map_or(Vec::new(), |last| {
                last.iter()
                    .map(|(pass, _)| {
                        let of_pass = |run: &Vec<(String, f64)>| {
                            run.iter().find(|p| &p.0 == pass).map_or(0.0, |p| p.1)
                        };
                        (
                            pass.clone(),
                            median(gpu_pass_runs.iter().map(of_pass).collect()),
                        )
                    })
                    .collect()
            }),
        });
        if let Some(g) = &gpu {
            gpu_one_step.push((n, g.total));
        }
        peer_rows.push(PeerRow {
            points: n,
            total,
            peer,
            gpu,
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
    let (scaling, series) = scaling_and_series(args, &sizes, &params, [&one_step, &gpu_one_step])?;

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
    let volume = volume::volume_rows(args, &sizes)?;
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
        volume,
    })
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

fn bake_and_encode(
    input: &StepInput,
    params: &BakeParams,
    stages: &slosh_bake::Stages,
) -> Result<TimedStep> {
    let t = Instant::now();
    let baked = bake_step_with(input, params, stages)?;
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
    [cpu_one_step, gpu_one_step]: [&[(usize, f64)]; 2],
) -> Result<(Vec<ScalingRow>, Vec<SeriesRow>)> {
    let cores = slosh_bake::cores();
    let mut scaling = Vec::new();
    for &n in sizes {
        let (inp, _) = input(n)?;
        let runs = if n >= 1_000_000 { 1 } else { args.runs.max(1) };
        let mut first_total = None;
        for t in thread_counts(args, cores) {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(t).build()?;
            let mut totals = Vec::new();
            let mut stage_runs = Vec::new();
            for _ in 0..runs {
                let step =
                    pool.install(|| bake_and_encode(&inp, params, &slosh_bake::Stages::cpu()))?;
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
    // The CPU bake, then (where an adapter opened) the bake with the GPU's stages.
    let mut devices: Vec<(&'static str, slosh_bake::Stages, _)> =
        vec![("cpu", slosh_bake::Stages::cpu(), cpu_one_step)];
    if let Ok(gpu) = &args.gpu {
        devices.push(("gpu", gpu.clone().stages(), gpu_one_step));
    }
    for &n in sizes {
        for (device, stages, one_step) in &devices {
            let Some(&(_, alone)) = one_step.iter().find(|(m, _)| *m == n) else {
                continue;
            };
            let scene = Scene::new(SceneSpec::new(SceneKind::Sphere, n, 1))?;
            let source = SceneSteps {
                scene,
                steps: args.series,
            };
            let (jobs, _) = slosh_bake::default_jobs(
                cores,
                slosh_bake::available_memory(),
                Some(n),
                stages.device_memory,
            );
            let dir = tempfile::tempdir()?;
            let opts = BatchOptions {
                out: dir.path().to_path_buf(),
                steps: None,
                jobs,
                threads: cores,
                shard: Shard::WHOLE,
                params: params.clone(),
                stages: stages.clone(),
            };
            let t = Instant::now();
            let report = run_batch(&source, &opts, &|_| {})?;
            let wall = t.elapsed().as_secs_f64();
            if !report.failed.is_empty() {
                anyhow::bail!("the {device} series bake failed: {:?}", report.failed);
            }
            let per = wall / args.series as f64;
            series.push(SeriesRow {
                device,
                points: n,
                jobs,
                wall,
                per_step: per,
                one_step: alone,
            });
            eprintln!(
                "{n} points, series of {} ({device}): {per:.3} s per step",
                args.series
            );
        }
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
