//! `slosh bench precision`: what storing the fits and normals with fewer mantissa bits
//! (`--mantissa-bits`) costs. Each analytic scene is baked at each precision and the cache,
//! read back, is traced by the CPU tracer (the GPU's reference): error against the exact
//! surface, hits against the cache stored exactly (23 bits), and bytes per point.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::Result;
use slosh_bake::{BakeParams, NormalSource, StepInput, SurfaceSelect};
use slosh_cache::LoadedStep;
use slosh_mls::{NormalsMode, Params};
use slosh_scenes::SceneKind;

use crate::accuracy::{Render, Scenario, metrics, scenario};
use crate::report::Report;
use crate::stats::percentile;

/// What `slosh bench precision` measures and where it writes.
#[derive(Debug, Clone)]
pub struct Settings {
    /// Markdown report to write.
    pub out: PathBuf,
    /// Points per scene.
    pub points: usize,
    /// Image side in pixels.
    pub size: u32,
    /// Mantissa bits compared (23 is exact f32).
    pub bits: Vec<u32>,
}
use slosh_fileio::say;

/// One scene baked at one precision and read back: the step and its file's size.
struct Baked {
    step: LoadedStep,
    bytes_per_point: f64,
}

fn bake(case: &Scenario, bits: u32) -> Result<Baked> {
    let input = StepInput {
        source: case.name.clone(),
        positions: case.positions.clone(),
        normals: Some(case.normals.clone()),
        ..StepInput::default()
    };
    let mut params = BakeParams::new(SurfaceSelect::All, NormalSource::Variable("normal".into()));
    params.mantissa_bits = bits;
    let file = slosh_testkit::bake_in_memory(&input, &params, Path::new("precision.slc"))?;
    let bytes_per_point = file.bytes().len() as f64 / case.positions.len() as f64;
    file.verify()?;
    Ok(Baked {
        step: LoadedStep::load(&file)?,
        bytes_per_point,
    })
}

fn trace(case: &Scenario, baked: &Baked, iterations: u32) -> Render {
    Render::from_hits(baked.step.render(
        &case.camera,
        &Params::<f32> {
            degree: 2,
            iterations,
            epsilon: 1e-4,
            normals: NormalsMode::Mean,
            h_factor: 1.0,
        },
    ))
}

/// One row of the table: a scene at one noise, iteration count and precision.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    pub scene: String,
    pub noise: f64,
    pub iterations: u32,
    pub bits: u32,
    /// The whole step file's bytes per point.
    pub bytes_per_point: f64,
    /// Error of the hits against the exact surface, in spacings (silhouettes excluded).
    pub rms: f64,
    pub p99: f64,
    pub angle_mean: f64,
    /// |Δt| against the bake stored exactly, in spacings, over pixels both hit.
    pub moved_p99: f64,
    pub moved_max: f64,
    /// Pixels hit in one and missed in the other.
    pub differ: usize,
    pub pixels: usize,
}

/// What `slosh bench precision` measured.
#[derive(Debug, Clone)]
pub struct PrecisionReport {
    pub settings: Settings,
    pub rows: Vec<Row>,
}

pub fn run(args: &Settings) -> Result<PrecisionReport> {
    let scenes = [
        (SceneKind::Sphere, 0.0),
        (SceneKind::Sphere, 0.1),
        (SceneKind::Torus, 0.0),
        (SceneKind::Tank, 0.0),
    ];
    let mut rows = Vec::new();
    for (kind, noise) in scenes {
        let case = scenario(kind, args.points, 3, noise, args.size)?;
        // Each precision baked once, traced at every iteration count.
        let exact = bake(&case, slosh_cache::F32_MANTISSA_BITS)?;
        let rounded: Vec<(u32, Option<Baked>)> = args
            .bits
            .iter()
            .map(|&bits| {
                let baked = (bits != slosh_cache::F32_MANTISSA_BITS)
                    .then(|| bake(&case, bits))
                    .transpose()?;
                Ok((bits, baked))
            })
            .collect::<Result<_>>()?;
        for iterations in [1, 3] {
            let exact_render = trace(&case, &exact, iterations);
            for (bits, baked) in &rounded {
                let own;
                let (traced, bytes_per_point) = match baked {
                    Some(b) => {
                        own = trace(&case, b, iterations);
                        (&own, b.bytes_per_point)
                    }
                    None => (&exact_render, exact.bytes_per_point),
                };
                let m = metrics(&case, traced, &exact_render);
                // Against the exact cache, pixel by pixel (silhouettes included).
                let mut moved = Vec::new();
                let mut differ = 0usize;
                for (a, b) in traced.hits.iter().zip(&exact_render.hits) {
                    match (a, b) {
                        (Some(a), Some(b)) => moved.push((a.t - b.t).abs() / case.spacing),
                        (None, None) => {}
                        _ => differ += 1,
                    }
                }
                let moved_max = moved.iter().copied().fold(0.0, f64::max);
                rows.push(Row {
                    scene: case.name.clone(),
                    noise,
                    iterations,
                    bits: *bits,
                    bytes_per_point,
                    rms: m.rms,
                    p99: m.p99,
                    angle_mean: m.angle_mean,
                    moved_p99: percentile(moved, 0.99),
                    moved_max,
                    differ,
                    pixels: traced.hits.len(),
                });
            }
            say!("{} noise {noise}, {iterations} iterations: done", case.name);
        }
    }
    Ok(PrecisionReport {
        settings: args.clone(),
        rows,
    })
}

impl Report for PrecisionReport {
    fn markdown(&self) -> String {
        let args = &self.settings;
        let mut table = String::new();
        for r in &self.rows {
            let _ = writeln!(
                table,
                "| {} | {} | {} | {} | {:.1} | {:.2e} | {:.2e} | {:.3} | {:.2e} | {:.2e} | {} of {} |",
                r.scene,
                r.noise,
                r.iterations,
                r.bits,
                r.bytes_per_point,
                r.rms,
                r.p99,
                r.angle_mean,
                r.moved_p99,
                r.moved_max,
                r.differ,
                r.pixels,
            );
        }
        let bits: Vec<String> = args.bits.iter().map(u32::to_string).collect();
        format!(
            "# Stored precision: mantissa bits against accuracy and bytes\n\n\
             Written by `slosh bench precision --points {} --size {} --bits {}`. Each scene \
             ({} particles, time step 3, normals from the scene) is baked with `--mantissa-bits` \
             at each value (the initial fits' normals and coefficients and the data normals \
             rounded to that many mantissa bits; positions, radii and reach stay exact), then read \
             back and traced by the CPU tracer, the GPU's reference, at {}×{} pixels, with 1 and \
             3 iterations. Distances are in particle spacings: the error of each hit against the \
             exact surface (RMS and p99, silhouette pixels excluded), and |Δt| of each hit \
             against the same bake stored exactly (23 bits, every pixel both hit). The tracer in \
             f32 is held to 1e-3 spacing against the f64 oracle (`crates/bake/tests/bake.rs`). \
             Bytes per point are the whole step file at the default zstd level (−1).\n\n\
             | scene | noise | iterations | bits | B/pt | RMS to surface | p99 to surface | normal ° | \
             \\|Δt\\| p99 vs 23 bits | \\|Δt\\| max vs 23 bits | hit/miss differ vs 23 bits |\n\
             |---|---|---|---|---|---|---|---|---|---|---|\n{table}",
            args.points,
            args.size,
            bits.join(","),
            args.points,
            args.size,
            args.size,
        )
    }
}
