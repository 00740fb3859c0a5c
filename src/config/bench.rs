//! `slosh bench …` flags turned into each benchmark's settings.

use std::path::PathBuf;

use anyhow::Result;
use slosh_bake::StepInput;
use slosh_bench::{accuracy, bake, gpu, precision, scrub};

use crate::cli::{
    AccuracyArgs, BakeBenchArgs, BenchTable, GpuBenchArgs, PrecisionBenchArgs, ScrubBenchArgs,
};
use slosh_bake::read_point_cloud;

pub fn accuracy(a: &AccuracyArgs) -> accuracy::Settings {
    accuracy::Settings {
        out: a.out.clone(),
        plot: a.plot.clone(),
        size: a.size,
        quick: a.quick,
        sph: a.sph.clone(),
        sph_only: a.sph_only,
        json: a.json.clone(),
        sph_fixture: a.sph_fixture.clone(),
    }
}

pub fn bake(a: &BakeBenchArgs) -> bake::Settings {
    bake::Settings {
        out: a.out.clone(),
        runs: a.runs,
        quick: a.quick,
        points: a.points.clone(),
        threads: a.threads.clone(),
        series: a.series,
        gpu: if a.no_gpu {
            Err("--no-gpu".into())
        } else {
            slosh_render::Gpu::new(a.adapter.as_deref())
                .map_err(|e| e.to_string())
                .and_then(|gpu| {
                    let search = slosh_gpubake::GpuStages::new(std::sync::Arc::new(gpu))
                        .map_err(|e| e.to_string())?;
                    // The bench bakes quadratic fits; compiled before anything is timed.
                    search.compile_fits(2).map_err(|e| e.to_string())?;
                    Ok(search)
                })
                .map(std::sync::Arc::new)
        },
    }
}

pub fn precision(a: &PrecisionBenchArgs) -> precision::Settings {
    precision::Settings {
        out: a.out.clone(),
        points: a.points,
        size: a.size,
    }
}

/// The bunny comes from `--bunny`, else `$SLOSH_DATA/bunny.obj`, where that file exists and
/// table 4.1 is wanted.
pub fn gpu(a: &GpuBenchArgs) -> Result<gpu::Settings> {
    let tables: Vec<gpu::Table> = a
        .tables
        .iter()
        .map(|t| match t {
            BenchTable::Bunny => gpu::Table::Bunny,
            BenchTable::Tank => gpu::Table::Tank,
            BenchTable::Water => gpu::Table::Water,
            BenchTable::Points => gpu::Table::Points,
        })
        .collect();
    let bunny_wanted = tables.is_empty() || tables.contains(&gpu::Table::Bunny);
    let bunny_path = a
        .bunny
        .clone()
        .or_else(|| std::env::var_os("SLOSH_DATA").map(|d| PathBuf::from(d).join("bunny.obj")))
        .filter(|p| bunny_wanted && p.exists());
    let bunny = match bunny_path {
        Some(path) => {
            let cloud = read_point_cloud(&path)?;
            Some(StepInput {
                source: path.display().to_string(),
                positions: cloud.positions,
                normals: cloud.normals,
                ..StepInput::default()
            })
        }
        None => None,
    };
    Ok(gpu::Settings {
        out: a.out.clone(),
        frames: a.frames,
        max_iterations: a.max_iterations,
        quick: a.quick,
        bunny,
        images: a.images.clone(),
        adapter: a.adapter.clone(),
        tables,
        points: a.points.clone(),
    })
}

pub fn scrub(a: &ScrubBenchArgs) -> Result<scrub::Settings> {
    if a.raw_case_only && (a.cold || a.raw) {
        anyhow::bail!(
            "--raw-case-only leaves out the baked series, which --cold and --raw are about"
        );
    }
    Ok(scrub::Settings {
        out: a.out.clone(),
        points: a.points.clone(),
        steps: a.steps,
        distinct: a.distinct,
        size: super::render::parse_size("size", &a.size)?,
        jumps: a.jumps,
        seed: a.seed,
        loaders: a.loaders,
        pool_steps: a.pool_steps,
        dir: a.dir.clone(),
        quick: a.quick,
        adapter: a.adapter.clone(),
        cold: a.cold,
        raw: a.raw,
        raw_case: a.raw_case || a.raw_case_only,
        raw_case_gpu: a.raw_case_gpu,
        raw_case_only: a.raw_case_only,
    })
}
