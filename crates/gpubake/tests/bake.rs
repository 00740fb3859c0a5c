#![allow(clippy::unwrap_used)]
//! A step baked with the GPU's neighbours against the same step baked on the CPU: the same
//! spray components and orientation flips, and the same picture (hit/miss on ≥ 99.9 % of
//! pixels, |Δt| p99 ≤ 1e-3 spacings at 3 iterations, by the CPU tracer), on every generated
//! scene, the hard cases, and pysplishsplash dam breaks at two resolutions.

use std::path::Path;
use std::sync::Arc;

use slosh_bake::{
    BakeParams, NormalSource, Stages, StepInput, SurfaceSelect, bake_step_parts,
    bake_step_parts_with, read_point_cloud,
};
use slosh_cache::{CacheFile, LoadedStep, encode_step};
use slosh_fileio::FileBytes;
use slosh_gpubake::{GpuStages, KeptBuffers};
use slosh_mls::Params;
use slosh_render::Gpu;
use slosh_scenes::{HardCases, Scene, SceneKind, SceneSpec};
use slosh_testkit::{adapter, framing_camera, gpu_or_skip, scene_step};

/// The bounds: pixels that hit in one picture and miss in the other, and the p99 of
/// |Δt| over pixels both hit, in particle spacings.
const MOST_SWITCHED: f64 = 1e-3;
const MOST_MOVED_P99: f64 = 1e-3;
const SIZE: u32 = 160;

fn bake(
    input: &StepInput,
    params: &BakeParams,
    stages: Option<&Stages>,
    name: &str,
) -> (slosh_mls::SurfaceParts<f64>, LoadedStep) {
    let (baked, parts) = match stages {
        Some(stages) => bake_step_parts_with(input, params, stages),
        None => bake_step_parts(input, params),
    }
    .unwrap_or_else(|e| panic!("{name}: {e}"));
    // The bake orders its points as the GPU's search does, which then casts the orientation
    // check's first votes itself.
    let cast_by_the_search = baked
        .header
        .stats
        .stage_seconds
        .iter()
        .any(|(part, _)| part == slosh_mls::ORIENTATION_VOTES_CAST_BY_THE_SEARCH);
    assert_eq!(
        cast_by_the_search,
        stages.is_some() && parts.normals.is_some(),
        "{name}: the orientation votes were cast by the GPU's search"
    );
    let bytes = encode_step(baked.header, &baked.sections, params.compression).unwrap();
    let file = CacheFile::from_bytes(FileBytes::from_vec(Path::new(name), bytes)).unwrap();
    file.verify()
        .unwrap_or_else(|e| panic!("{name}: the verifier rejects it: {e}"));
    (parts, LoadedStep::load(&file).unwrap())
}

/// Hit/miss switches and the p99 of |Δt| in spacings.
fn compare(name: &str, input: &StepInput, params: &BakeParams, stages: &Stages) {
    let (cpu_parts, cpu) = bake(input, params, None, name);
    let (gpu_parts, gpu) = bake(input, params, Some(stages), name);
    assert_eq!(
        cpu_parts.spheres.len(),
        gpu_parts.spheres.len(),
        "{name}: droplet count"
    );
    for (a, b) in cpu_parts.spheres.iter().zip(&gpu_parts.spheres) {
        assert_eq!(a.centre, b.centre, "{name}: a droplet moved");
        assert_eq!(a.radius, b.radius, "{name}: a droplet's radius");
    }
    assert_eq!(
        cpu_parts.orientation, gpu_parts.orientation,
        "{name}: orientation flips"
    );
    assert_eq!(cpu_parts.h, gpu_parts.h, "{name}: h");
    // The fits in f32 against the CPU's in f64: the same outcome (fitted, degraded, none) and
    // support normals within 1e-4 rad but at a few ill-conditioned balls.
    let mut status_differs = 0;
    let mut angles: Vec<f64> = Vec::new();
    for (i, (a, b)) in cpu_parts.balls.iter().zip(&gpu_parts.balls).enumerate() {
        if cpu_parts.ball_fits[i] != gpu_parts.ball_fits[i] {
            status_differs += 1;
        } else if matches!(cpu_parts.ball_fits[i], slosh_mls::BallFit::Fitted(_)) {
            // atan2(|a × b|, a · b): exact near 0, where acos of a dot product is not.
            let (u, v) = (a.normal, b.normal);
            let cross = [
                u.y * v.z - u.z * v.y,
                u.z * v.x - u.x * v.z,
                u.x * v.y - u.y * v.x,
            ];
            let sin = cross.iter().map(|c| c * c).sum::<f64>().sqrt();
            angles.push(sin.atan2(u.x * v.x + u.y * v.y + u.z * v.z));
        }
    }
    angles.sort_by(f64::total_cmp);
    let angle_p99 = angles.get(angles.len() * 99 / 100).copied().unwrap_or(0.0);
    eprintln!(
        "{name}: {status_differs} fit outcomes differ, support normal angle p99 {angle_p99:.2e} \
         max {:.2e} rad",
        angles.last().copied().unwrap_or(0.0)
    );
    assert!(
        status_differs * 1000 <= cpu_parts.len(),
        "{name}: {status_differs} of {} fit outcomes differ",
        cpu_parts.len()
    );
    assert!(
        angle_p99 < 1e-4,
        "{name}: support normals p99 {angle_p99} rad apart"
    );
    let camera = framing_camera(&input.positions, SIZE);
    let params = Params::<f32> {
        degree: params.mls.degree,
        iterations: 3,
        epsilon: 1e-4,
        normals: params.mls.normals,
        h_factor: 1.0,
    };
    let (a, b) = (cpu.render(&camera, &params), gpu.render(&camera, &params));
    let spacing = cpu_parts.spacing * cpu.transform.scale;
    let mut moved: Vec<f64> = Vec::new();
    let mut switched = 0usize;
    for (a, b) in a.iter().zip(&b) {
        match (a, b) {
            (Some(a), Some(b)) => moved.push((a.t - b.t).abs() / spacing),
            (None, None) => {}
            _ => switched += 1,
        }
    }
    assert!(
        moved.len() > a.len() / 20,
        "{name}: too few hits to compare"
    );
    moved.sort_by(f64::total_cmp);
    let p99 = moved[(moved.len() - 1) * 99 / 100];
    let switched_share = switched as f64 / a.len() as f64;
    eprintln!(
        "{name}: {} points, {} droplets, {} flipped; {switched} of {} pixels switch, |Δt| p99 \
         {p99:.2e} max {:.2e} spacings",
        gpu_parts.len(),
        gpu_parts.spheres.len(),
        gpu_parts.orientation.flipped_points,
        a.len(),
        moved[moved.len() - 1]
    );
    assert!(
        switched_share <= MOST_SWITCHED,
        "{name}: {switched} of {} pixels switch between hit and miss",
        a.len()
    );
    assert!(p99 <= MOST_MOVED_P99, "{name}: |Δt| p99 {p99} spacings");
}

#[test]
fn a_bake_with_gpu_neighbours_draws_the_cpu_bakes_picture() {
    let Some(gpu) = gpu_or_skip(Gpu::new(adapter().as_deref())) else {
        return;
    };
    let stages = Arc::new(GpuStages::new(Arc::new(gpu)).unwrap()).stages();
    let with_normals = BakeParams::new(SurfaceSelect::All, NormalSource::Variable("normal".into()));
    let hard = HardCases {
        noise: 0.1,
        duplicates: 0.02,
        flip_normals: 0.05,
        bad_normals: 0.02,
        isolated: true,
        ..HardCases::default()
    };
    let mut scenes: Vec<(String, SceneSpec)> = SceneKind::ALL
        .iter()
        .map(|&kind| (kind.name().to_string(), SceneSpec::new(kind, 6000, 3)))
        .collect();
    for kind in [SceneKind::Sphere, SceneKind::Droplets] {
        let mut spec = SceneSpec::new(kind, 6000, 5);
        spec.hard = hard.clone();
        scenes.push((format!("{}, hard", kind.name()), spec));
    }
    // A sheet written twice over in part, a fifth of its normals reversed: the nearest
    // points tie at every duplicate, and the flips must fall alike.
    let mut twice = SceneSpec::new(SceneKind::Sheet, 20_000, 5);
    twice.hard = HardCases {
        duplicates: 0.1,
        flip_normals: 0.2,
        ..HardCases::default()
    };
    scenes.push(("sheet, duplicated and reversed".into(), twice));
    for (name, spec) in scenes {
        let scene = Scene::new(spec).unwrap();
        let input = scene_step(&scene, 1, &name);
        compare(&name, &input, &with_normals, &stages);
    }
    // The SPH fixtures: volume particles, surface and normals estimated; SPlisHSPlasH's dam
    // break at two particle radii (0.025 at three times, 0.0175 at 0.4 s:
    // `scripts/sph_reference.py`).
    let sph = BakeParams::new(SurfaceSelect::Estimate, NormalSource::Estimate);
    for (resolution, time) in [
        ("sph/coarse-t", "0.4"),
        ("sph/coarse-t", "0.6"),
        ("sph/coarse-t", "1"),
        ("sph-fine/t", "0.4"),
    ] {
        let path = format!(
            "{}/../../tests/data/{resolution}{time}/particles.ply",
            env!("CARGO_MANIFEST_DIR")
        );
        let cloud = read_point_cloud(Path::new(&path)).unwrap();
        let input = StepInput {
            source: path.clone(),
            positions: cloud.positions,
            ..StepInput::default()
        };
        let name = format!("dam break {resolution}{time}");
        compare(&name, &input, &sph, &stages);
    }
}

/// The buffers a device's stages keep between steps (pass buffers, staging and read-back
/// buffers) shrink to the share of the steps still in flight as a batch's jobs find no step
/// left (which still holds a small step's pass buffers whole), to none after the last; a
/// batch after it keeps them again.
#[test]
fn kept_buffers_go_as_the_steps_left_end() {
    use slosh_bake::StepsInFlight;
    let Some(gpu) = gpu_or_skip(Gpu::new(adapter().as_deref())) else {
        return;
    };
    let gpu_stages = Arc::new(GpuStages::new(Arc::new(gpu)).unwrap());
    let stages = gpu_stages.clone().stages();
    let params = BakeParams::new(SurfaceSelect::All, NormalSource::Variable("normal".into()));
    let scene = Scene::new(SceneSpec::new(SceneKind::Sphere, 4000, 3)).unwrap();
    let input = scene_step(&scene, 1, "sphere");
    let bake_one = || {
        bake_step_parts_with(&input, &params, &stages).unwrap();
    };
    gpu_stages.steps_at_once(2);
    bake_one();
    let kept = gpu_stages.kept();
    assert!(
        kept.pass_bytes > 0,
        "a baked step leaves its pass buffers kept"
    );
    assert!(
        kept.readback > 0,
        "a baked step leaves its read-back buffers kept"
    );
    gpu_stages.steps_left(1);
    assert_eq!(gpu_stages.kept().pass_bytes, kept.pass_bytes);
    gpu_stages.steps_left(0);
    assert_eq!(
        gpu_stages.kept(),
        KeptBuffers {
            pass_bytes: 0,
            staging: 0,
            readback: 0
        }
    );
    gpu_stages.steps_at_once(2);
    bake_one();
    let again = gpu_stages.kept();
    assert_eq!(again.pass_bytes, kept.pass_bytes);
    assert!(again.readback > 0);
}
