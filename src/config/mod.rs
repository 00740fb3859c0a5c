//! Validated settings built from parsed flags: every check on user input happens here, once.

pub mod bench;
pub mod demo;
pub mod inspect;
pub mod on_demand;
pub mod play;
pub mod render;

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use slosh_ensight::{ByteOrder, Placement, WriteFormat};
use slosh_scenes::{HardCases, SceneKind, SceneSpec};

use crate::cli::{ByteOrderArg, FormatArg, GenArgs};

impl From<ByteOrderArg> for ByteOrder {
    fn from(b: ByteOrderArg) -> Self {
        match b {
            ByteOrderArg::Little => ByteOrder::Little,
            ByteOrderArg::Big => ByteOrder::Big,
        }
    }
}

impl From<FormatArg> for WriteFormat {
    fn from(f: FormatArg) -> Self {
        match f {
            FormatArg::E6Ascii => WriteFormat::E6Ascii,
            FormatArg::E6Binary => WriteFormat::E6Binary,
            FormatArg::GoldAscii => WriteFormat::GoldAscii,
            FormatArg::GoldBinary => WriteFormat::GoldBinary,
        }
    }
}

/// What `slosh gen` writes.
#[derive(Debug)]
pub enum GenSource {
    Scene { spec: SceneSpec, steps: usize },
    File(PathBuf),
}

#[derive(Debug)]
pub struct GenConfig {
    pub source: GenSource,
    pub out: PathBuf,
    pub format: WriteFormat,
    pub byte_order: ByteOrder,
    pub placement: Placement,
}

impl GenConfig {
    pub fn from_args(a: &GenArgs) -> Result<GenConfig> {
        let source = if a.scene == "from-file" {
            let input = a
                .input
                .clone()
                .context("`slosh gen from-file` needs the PLY or OBJ file to convert")?;
            GenSource::File(input)
        } else {
            if a.input.is_some() {
                bail!("a file argument only goes with `from-file`");
            }
            let kind: SceneKind = a.scene.parse().map_err(anyhow::Error::msg)?;
            if a.steps == 0 {
                bail!("--steps must be at least 1");
            }
            let mut spec = SceneSpec::new(kind, a.points, a.seed);
            spec.dt = a.dt;
            if let Some(d) = a.droplets {
                if !matches!(
                    kind,
                    SceneKind::Tank | SceneKind::Droplets | SceneKind::Wave
                ) {
                    bail!("--droplets applies to the tank, droplets and wave scenes");
                }
                spec.droplets = d;
            }
            spec.hard = HardCases {
                noise: a.noise,
                flip_normals: a.flip_normals,
                offset: a.offset,
                duplicates: a.duplicates,
                bad_normals: a.bad_normals,
                collinear: a.collinear,
                coplanar: a.coplanar,
                density_jump: a.density_jump,
                isolated: a.isolated,
            };
            GenSource::Scene {
                spec,
                steps: a.steps,
            }
        };
        Ok(GenConfig {
            source,
            out: a.out.clone(),
            format: a.format.into(),
            byte_order: a.byte_order.into(),
            placement: if a.measured {
                Placement::Measured
            } else {
                Placement::PointPart
            },
        })
    }
}

/// What `slosh bake` reads.
#[derive(Debug)]
pub enum BakeInput {
    Case(slosh_ensight::Case),
    PointCloud(slosh_bake::PointCloud),
}

/// Validated `slosh bake` settings: every "auto" resolved against the input.
#[derive(Debug)]
pub struct BakeConfig {
    pub input: BakeInput,
    pub input_path: PathBuf,
    pub options: slosh_bake::BatchOptions,
    pub quiet: bool,
    /// Why `--jobs` took its value, when it was not given.
    pub jobs_chosen: Option<String>,
}

/// Points of step `index` of the input, where it can be read now (a step that cannot is
/// reported by the bake itself).
fn first_step_points(input: &BakeInput, index: usize) -> Option<usize> {
    match input {
        BakeInput::PointCloud(cloud) => Some(cloud.positions.len()),
        BakeInput::Case(case) => {
            let request = slosh_ensight::StepRequest {
                fields: vec![],
                ..Default::default()
            };
            case.read_step(index.min(case.step_count().saturating_sub(1)), &request)
                .ok()
                .map(|s| s.positions.len())
        }
    }
}

/// Parses `A..B` (inclusive) or a single step `A`.
/// The one `--steps` grammar of every subcommand, Rust's: `A..B` (B excluded), `A..=B` (B
/// included), or `N` (that step alone). Returns the first and last step, both included; an
/// empty range is an error saying so.
pub fn parse_step_range(s: &str) -> Result<(usize, usize)> {
    let parse = |v: &str| -> Result<usize> {
        v.trim().parse().with_context(|| {
            format!("--steps {s}: '{v}' is not a step index (expected A..B, A..=B or N)")
        })
    };
    let (a, last) = if let Some((a, b)) = s.split_once("..=") {
        (parse(a)?, parse(b)?)
    } else if let Some((a, b)) = s.split_once("..") {
        let (a, b) = (parse(a)?, parse(b)?);
        if b <= a {
            bail!(
                "--steps {s}: the range is empty (A..B excludes B: {a}..{} or {a}..={b} includes step {b})",
                a + 1
            );
        }
        (a, b - 1)
    } else {
        let n = parse(s)?;
        (n, n)
    };
    if a > last {
        bail!("--steps {s}: the range is empty (A..=B needs A ≤ B)");
    }
    Ok((a, last))
}

/// `--shard slurm`: this task's place in a SLURM job array, from the variables SLURM sets
/// (`SLURM_ARRAY_TASK_ID` − `SLURM_ARRAY_TASK_MIN` of `SLURM_ARRAY_TASK_COUNT`). The array's
/// ids must be consecutive (`--array=0-15`, not `0-15:4`).
fn slurm_shard(var: impl Fn(&str) -> Option<String>) -> Result<slosh_bake::Shard> {
    let get = |name: &str| -> Result<usize> {
        let v = var(name).with_context(|| {
            format!("--shard slurm: ${name} is not set (run inside a SLURM job array: sbatch --array=0-N)")
        })?;
        v.trim()
            .parse()
            .with_context(|| format!("--shard slurm: ${name} is '{v}', expected a number"))
    };
    let (id, count) = (get("SLURM_ARRAY_TASK_ID")?, get("SLURM_ARRAY_TASK_COUNT")?);
    let min = if var("SLURM_ARRAY_TASK_MIN").is_some() {
        get("SLURM_ARRAY_TASK_MIN")?
    } else {
        0
    };
    let index = id.checked_sub(min).filter(|i| *i < count).with_context(|| {
        format!(
            "--shard slurm: task {id} of an array from {min} with {count} tasks; the array's ids \
             must be consecutive (--array=A-B, no step)"
        )
    })?;
    Ok(slosh_bake::Shard { index, count })
}

fn parse_shard(s: &str) -> Result<slosh_bake::Shard> {
    if s == "slurm" {
        return slurm_shard(|name| std::env::var(name).ok());
    }
    let bad = || anyhow::anyhow!("--shard {s}: expected I/N with 0 ≤ I < N, e.g. 0/3, or slurm");
    let (i, n) = s.split_once('/').ok_or_else(bad)?;
    let (index, count): (usize, usize) = (
        i.trim().parse().map_err(|_| bad())?,
        n.trim().parse().map_err(|_| bad())?,
    );
    if count == 0 || index >= count {
        return Err(bad());
    }
    Ok(slosh_bake::Shard { index, count })
}

/// The bake's stages where `--device` asks for them, the GPU's fits for `degree` compiled.
/// `auto` takes the GPU's where `adapter` is named, or where an adapter that is a GPU opens
/// and `k` is within its search; else the CPU's (the bake's `stages:` line says which).
fn bake_stages(
    device: crate::cli::BakeDevice,
    adapter: Option<&str>,
    degree: u8,
    k: usize,
) -> Result<slosh_bake::Stages> {
    let gpu_stages = || -> Result<slosh_bake::Stages> {
        let gpu = slosh_render::Gpu::new(adapter).context("--device gpu")?;
        gpu_stages_on(gpu, degree)
    };
    Ok(match device {
        crate::cli::BakeDevice::Cpu => slosh_bake::Stages::cpu(),
        // An adapter named is a GPU asked for: a name no adapter has is an error, not a
        // silent bake on the CPU.
        crate::cli::BakeDevice::Gpu => gpu_stages()?,
        crate::cli::BakeDevice::Auto if adapter.is_some() => gpu_stages()?,
        crate::cli::BakeDevice::Auto => {
            // Adapters are listed before one is opened (once: the one opened comes from
            // the same list): most machines without a GPU have none, or only a software one.
            let is_gpu = |info: &wgpu::AdapterInfo| {
                matches!(
                    info.device_type,
                    wgpu::DeviceType::DiscreteGpu | wgpu::DeviceType::IntegratedGpu
                )
            };
            let listed = (k < slosh_gpubake::NEAREST_MAX)
                .then(slosh_render::Adapters::list)
                .filter(|listed| listed.infos().iter().any(is_gpu));
            match listed.map(|listed| slosh_render::Gpu::from_adapters(listed, adapter)) {
                Some(Ok(gpu)) if is_gpu(&gpu.info) => {
                    let name = gpu.describe();
                    // A GPU whose passes will not build is said, not passed over in silence:
                    // the bake goes on, on the CPU.
                    gpu_stages_on(gpu, degree).unwrap_or_else(|e| {
                        eprintln!(
                            "--device auto: {name} was found, but the bake's passes did not \
                             build on it ({e:#}); baking on the CPU (--device gpu makes this \
                             an error)"
                        );
                        slosh_bake::Stages::cpu()
                    })
                }
                _ => slosh_bake::Stages::cpu(),
            }
        }
    })
}

/// The GPU's stages on `gpu`, its fits for `degree` compiled.
fn gpu_stages_on(gpu: slosh_render::Gpu, degree: u8) -> Result<slosh_bake::Stages> {
    let stages = slosh_gpubake::GpuStages::new(std::sync::Arc::new(gpu))
        .context("--device gpu: the bake's passes")?;
    stages
        .compile_fits(degree)
        .context("--device gpu: the initial fits")?;
    Ok(std::sync::Arc::new(stages).stages())
}

impl BakeConfig {
    pub fn from_args(a: &crate::cli::BakeArgs) -> Result<BakeConfig> {
        use slosh_bake::{BakeParams, NormalSource, SurfaceSelect};
        use slosh_ensight::VarType;
        let out = a
            .out
            .clone()
            .context("--out DIR is required (where the .slc files go)")?;
        if !(1..=3).contains(&a.settings.fit.degree) {
            bail!("--degree {}: expected 1, 2 or 3", a.settings.fit.degree);
        }
        if a.settings.select.device == crate::cli::BakeDevice::Gpu
            && a.settings.fit.k >= slosh_gpubake::NEAREST_MAX
        {
            bail!(
                "--k {}: the GPU's nearest-point search finds at most {} neighbours a point; \
                 use --device cpu for a larger k",
                a.settings.fit.k,
                slosh_gpubake::NEAREST_MAX - 1
            );
        }
        if a.settings.fit.k == 0 {
            bail!("--k must be at least 1");
        }
        if !(a.settings.fit.h_scale.is_finite() && a.settings.fit.h_scale > 0.0) {
            bail!(
                "--h-scale {}: expected a positive number",
                a.settings.fit.h_scale
            );
        }
        if a.settings.fit.neighbour_cap < 3 {
            bail!(
                "--neighbour-cap {}: at least 3 neighbours are needed for a plane",
                a.settings.fit.neighbour_cap
            );
        }
        let compression = match a.settings.select.compress.as_str() {
            "none" => slosh_cache::Compression::None,
            l => {
                let level: i32 = l
                    .parse()
                    .ok()
                    .filter(|v| (-7..=22).contains(v) && *v != 0)
                    .with_context(|| {
                        format!(
                            "--compress {l}: expected a zstd level from -7 (fastest) to 22, not 0, or 'none'"
                        )
                    })?;
                slosh_cache::Compression::Level(level)
            }
        };
        let ext = a
            .input
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        let point_cloud = matches!(ext.as_deref(), Some("ply" | "obj"));
        let (input, surface, normals) = if point_cloud {
            let surface = match a.settings.select.surface.as_deref() {
                None | Some("all") => SurfaceSelect::All,
                Some("estimate") => SurfaceSelect::Estimate,
                Some(v) => {
                    bail!("--surface {v}: a point cloud has no variables (use all or estimate)")
                }
            };
            let cloud = slosh_bake::read_point_cloud(&a.input)?;
            let normals = match a.settings.select.normals.as_deref() {
                Some("pca") => NormalSource::Pca,
                Some("estimate") => NormalSource::Estimate,
                None if cloud.normals.is_some() => NormalSource::Variable("normals".into()),
                None if surface == SurfaceSelect::Estimate => NormalSource::Estimate,
                None => NormalSource::Pca,
                Some(v) => bail!(
                    "--normals {v}: a point cloud has only its own normals (or pca, or estimate)"
                ),
            };
            (BakeInput::PointCloud(cloud), surface, normals)
        } else {
            let mut case = slosh_ensight::Case::open(&a.input)?;
            case.set_byte_order(a.settings.select.byte_order.map(Into::into));
            let has = |name: &str, ty: VarType| {
                case.variables()
                    .iter()
                    .any(|v| v.name == name && v.var_type == ty)
            };
            let scalar = |name: &str| -> Result<()> {
                if !has(name, VarType::Scalar) {
                    bail!(
                        "{}: no scalar variable '{name}' (variables: {})",
                        a.input.display(),
                        case.variables()
                            .iter()
                            .map(|v| v.name.as_str())
                            .collect::<Vec<_>>()
                            .join(", ")
                    );
                }
                Ok(())
            };
            let surface = match a.settings.select.surface.as_deref() {
                None if has("surface", VarType::Scalar) => {
                    SurfaceSelect::Variable("surface".into())
                }
                None | Some("all") => SurfaceSelect::All,
                Some("estimate") => SurfaceSelect::Estimate,
                Some(v) => {
                    scalar(v)?;
                    SurfaceSelect::Variable(v.into())
                }
            };
            let normals = match a.settings.select.normals.as_deref() {
                None => ["normal", "normals"]
                    .into_iter()
                    .find(|n| has(n, VarType::Vector))
                    .map_or(
                        if surface == SurfaceSelect::Estimate {
                            NormalSource::Estimate
                        } else {
                            NormalSource::Pca
                        },
                        |n| NormalSource::Variable(n.into()),
                    ),
                Some("pca") => NormalSource::Pca,
                Some("estimate") => NormalSource::Estimate,
                Some(v) => {
                    if !has(v, VarType::Vector) {
                        bail!(
                            "{}: no vector variable '{v}' for --normals",
                            a.input.display()
                        );
                    }
                    NormalSource::Variable(v.into())
                }
            };
            for f in &a.settings.select.fields {
                if !case.variables().iter().any(|v| &v.name == f) {
                    bail!("{}: no variable '{f}' for --fields", a.input.display());
                }
            }
            (BakeInput::Case(case), surface, normals)
        };
        if point_cloud && !a.settings.select.fields.is_empty() {
            bail!("--fields: a point cloud has no variables");
        }
        let mut params = BakeParams::new(surface, normals);
        params.mls.degree = a.settings.fit.degree;
        params.mls.k = a.settings.fit.k;
        params.mls.h_scale = a.settings.fit.h_scale;
        params.mls.neighbour_cap = a.settings.fit.neighbour_cap;
        params.mls.per_point_h = a.settings.fit.per_point_h;
        if let Some(offset) = a.settings.fit.surface_offset {
            if !(offset.is_finite() && (0.0..=2.0).contains(&offset)) {
                bail!(
                    "--surface-offset {offset}: expected 0 to 2 particle radii (a ball reaches at most 4)"
                );
            }
            params.mls.offset = offset;
        }
        params.mls.droplet_below = a
            .settings
            .fit
            .droplet_below
            .unwrap_or(slosh_mls::coefficient_count(a.settings.fit.degree));
        params.fields = a.settings.select.fields.clone();
        params.compression = compression;
        let cores = slosh_bake::cores();
        let most_jobs = most_jobs(cores);
        if let Some(jobs) = a.jobs
            && (jobs == 0 || jobs > most_jobs)
        {
            bail!(
                "--jobs {jobs}: expected 1 to {most_jobs} (steps baked at once, each parallel inside; this machine has {cores} cores)"
            );
        }
        let steps = a.steps.as_deref().map(parse_step_range).transpose()?;
        let stages = bake_stages(
            a.settings.select.device,
            a.adapter.as_deref(),
            a.settings.fit.degree,
            a.settings.fit.k,
        )?;
        let (jobs, jobs_chosen) = match a.jobs {
            Some(jobs) => (jobs, None),
            None => {
                let points = first_step_points(&input, steps.map_or(0, |(f, _)| f));
                let (jobs, why) = slosh_bake::default_jobs(
                    cores,
                    slosh_bake::available_memory(),
                    points,
                    stages.device_memory,
                );
                (jobs, Some(why))
            }
        };
        Ok(BakeConfig {
            input,
            input_path: a.input.clone(),
            options: slosh_bake::BatchOptions {
                out,
                steps,
                jobs,
                threads: cores,
                shard: a
                    .shard
                    .as_deref()
                    .map(parse_shard)
                    .transpose()?
                    .unwrap_or(slosh_bake::Shard::WHOLE),
                params,
                stages,
            },
            quiet: a.quiet,
            jobs_chosen,
        })
    }
}

/// The most steps a bake takes at once on `cores` cores: each job holds a whole step in
/// memory and is parallel inside, so more than a few per core only cost memory and threads.
pub fn most_jobs(cores: usize) -> usize {
    (4 * cores).max(8)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env(pairs: &'static [(&'static str, &'static str)]) -> impl Fn(&str) -> Option<String> {
        move |name: &str| {
            pairs
                .iter()
                .find(|(k, _)| *k == name)
                .map(|(_, v)| v.to_string())
        }
    }

    #[test]
    fn shards_come_from_a_slurm_array() {
        let s = slurm_shard(env(&[
            ("SLURM_ARRAY_TASK_ID", "6"),
            ("SLURM_ARRAY_TASK_COUNT", "4"),
            ("SLURM_ARRAY_TASK_MIN", "4"),
        ]))
        .unwrap();
        assert_eq!((s.index, s.count), (2, 4));
        let e = slurm_shard(env(&[("SLURM_ARRAY_TASK_COUNT", "4")])).unwrap_err();
        assert!(
            format!("{e:#}").contains("SLURM_ARRAY_TASK_ID is not set"),
            "{e:#}"
        );
        let e = slurm_shard(env(&[
            ("SLURM_ARRAY_TASK_ID", "12"),
            ("SLURM_ARRAY_TASK_COUNT", "4"),
        ]))
        .unwrap_err();
        assert!(format!("{e:#}").contains("consecutive"), "{e:#}");
    }
}
