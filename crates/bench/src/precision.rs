//! `slosh bench precision`: what the compact layout of a step (octahedral normals, half-float
//! coefficients, radii and reaches, BVH boxes on a grid, lists recovered from the stored
//! normals) costs. Each analytic
//! scene is baked once; its cache, read back, and the same step stored exactly (the bake's
//! own values in f32, `slosh_testkit::bake_exact_and_stored`) are traced by the CPU tracer
//! (the GPU's reference): error against the exact surface, hits against each other, and
//! bytes per point.

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
}
use slosh_fileio::say;

/// The step as stored and as computed, and the cache's bytes per point.
struct Baked {
    stored: LoadedStep,
    exact: LoadedStep,
    bytes_per_point: f64,
}

fn bake(case: &Scenario) -> Result<Baked> {
    let input = StepInput {
        source: case.name.clone(),
        positions: case.positions.clone(),
        normals: Some(case.normals.clone()),
        ..StepInput::default()
    };
    let params = BakeParams::new(SurfaceSelect::All, NormalSource::Variable("normal".into()));
    let (exact, file) =
        slosh_testkit::bake_exact_and_stored(&input, &params, Path::new("precision.slc"))?;
    let bytes_per_point = file.bytes().len() as f64 / case.positions.len() as f64;
    file.verify()?;
    Ok(Baked {
        stored: LoadedStep::load(&file)?,
        exact,
        bytes_per_point,
    })
}

fn trace(case: &Scenario, step: &LoadedStep, iterations: u32) -> Render {
    Render::from_hits(step.render(
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
    /// The whole step file's bytes per point.
    pub bytes_per_point: f64,
    /// Error of the hits against the exact surface, in spacings (silhouettes excluded):
    /// stored exactly, then as stored.
    pub exact_rms: f64,
    pub exact_p99: f64,
    pub rms: f64,
    pub p99: f64,
    pub angle_mean: f64,
    /// |Δt| against the step stored exactly, in spacings, over pixels both hit.
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
        let baked = bake(&case)?;
        for iterations in [1, 3] {
            let exact = trace(&case, &baked.exact, iterations);
            let stored = trace(&case, &baked.stored, iterations);
            let m = metrics(&case, &stored, &exact);
            let exact_m = metrics(&case, &exact, &exact);
            let mut moved = Vec::new();
            let mut differ = 0usize;
            for (a, b) in stored.hits.iter().zip(&exact.hits) {
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
                bytes_per_point: baked.bytes_per_point,
                exact_rms: exact_m.rms,
                exact_p99: exact_m.p99,
                rms: m.rms,
                p99: m.p99,
                angle_mean: m.angle_mean,
                moved_p99: percentile(moved, 0.99),
                moved_max,
                differ,
                pixels: stored.hits.len(),
            });
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
                "| {} | {} | {} | {:.1} | {:.2e} / {:.2e} | {:.2e} / {:.2e} | {:.3} | {:.2e} | {:.2e} | {} of {} |",
                r.scene,
                r.noise,
                r.iterations,
                r.bytes_per_point,
                r.exact_rms,
                r.rms,
                r.exact_p99,
                r.p99,
                r.angle_mean,
                r.moved_p99,
                r.moved_max,
                r.differ,
                r.pixels,
            );
        }
        format!(
            "# Stored precision: the compact layout against the step stored exactly\n\n\
             Written by `slosh bench precision --points {} --size {}`. Each scene ({} \
             particles, time step 3, normals from the scene) is baked once; its cache (format \
             {}: octahedral support and data normals, coefficients, radii and reaches as half \
             floats, BVH boxes on a 16-bit grid, neighbour lists recovered from the stored \
             normals) is read back, and the same step is also kept \
             exactly (the bake's own normals, coefficients and lists in f32). Both are traced \
             by the CPU tracer, the GPU's reference, at {}×{} pixels, with 1 and 3 iterations. \
             Distances are in particle spacings: the error of each hit against the exact \
             surface (RMS and p99, silhouette pixels excluded; exact / stored), and |Δt| of \
             each hit of the stored step against the exact one (every pixel both hit). The \
             tracer in f32 is held to 1e-3 spacing against the f64 oracle \
             (`crates/bake/tests/bake.rs`). Bytes per point are the whole step file at the \
             default zstd level (−1).\n\n\
             | scene | noise | iterations | B/pt | RMS to surface (exact / stored) | p99 to surface (exact / stored) | normal ° | \
             \\|Δt\\| p99 vs exact | \\|Δt\\| max vs exact | hit/miss differ |\n\
             |---|---|---|---|---|---|---|---|---|---|\n{table}",
            args.points,
            args.size,
            args.points,
            slosh_cache::MAJOR,
            args.size,
            args.size,
        )
    }
}
