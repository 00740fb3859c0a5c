//! The volume rows of `slosh bench bake`: particles filling a block of fluid, as SPH and FPM
//! solvers write them, baked as such output is (`--surface estimate`, normals estimated), on
//! the CPU and with the GPU's stages. The surface estimate looks at every particle, not only
//! the surface's, so its neighbour search is the largest stage of such a bake.

use anyhow::Result;
use slosh_bake::{BakeParams, NormalSource, StepInput, SurfaceSelect};

use super::report::VolumeRow;
use super::{Settings, bake_and_encode};
use crate::stats::median;

/// A block of about `particles` particles, a unit spacing apart, jittered.
fn block(particles: usize) -> StepInput {
    let side = (particles as f64).cbrt().round().max(2.0) as usize;
    let positions = slosh_scenes::jittered_block(side, 1.0, [0.0; 3]);
    StepInput {
        source: format!("block of {} particles", positions.len()),
        positions,
        ..StepInput::default()
    }
}

/// Each size's block baked on the CPU and, where an adapter opened, with the GPU's stages,
/// alternating run by run.
pub(super) fn volume_rows(args: &Settings, sizes: &[usize]) -> Result<Vec<VolumeRow>> {
    let params = BakeParams::new(SurfaceSelect::Estimate, NormalSource::Estimate);
    let cpu = slosh_bake::Stages::cpu();
    let gpu = args.gpu.as_ref().ok().map(|g| g.clone().stages());
    let mut rows = Vec::new();
    for &n in sizes {
        let input = block(n);
        let runs = if n >= 1_000_000 { 1 } else { args.runs.max(1) };
        let (mut on_cpu, mut on_gpu) = (Vec::new(), Vec::new());
        let mut surface = 0;
        for _ in 0..runs {
            let step = bake_and_encode(&input, &params, &cpu)?;
            surface = step.baked.header.points as usize;
            on_cpu.push(step);
            if let Some(stages) = &gpu {
                on_gpu.push(bake_and_encode(&input, &params, stages)?);
            }
        }
        let total = |steps: &[super::TimedStep]| median(steps.iter().map(|s| s.seconds).collect());
        let select = |steps: &[super::TimedStep]| {
            median(
                steps
                    .iter()
                    .map(|s| {
                        s.stages
                            .iter()
                            .filter(|(n, _)| n == "select")
                            .map(|(_, v)| v)
                            .sum()
                    })
                    .collect(),
            )
        };
        eprintln!(
            "volume of {} particles: {:.3} s",
            input.positions.len(),
            total(&on_cpu)
        );
        rows.push(VolumeRow {
            particles: input.positions.len(),
            surface,
            cpu: (total(&on_cpu), select(&on_cpu)),
            gpu: (!on_gpu.is_empty()).then(|| (total(&on_gpu), select(&on_gpu))),
        });
    }
    Ok(rows)
}
