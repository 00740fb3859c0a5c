//! `slosh gen`: synthetic scenes (with truth.json) and PLY/OBJ conversion to EnSight.

use std::path::Path;

use anyhow::{Context, Result};
use serde::Serialize;
use slosh_ensight::{CaseWriter, VarData, VarType, atomic_write};
use slosh_scenes::{Droplet, Extra, Scene, SceneSpec, Truth};

use crate::config::{GenConfig, GenSource};
use slosh_bake::read_point_cloud;

/// `truth.json`: everything needed to compute exact errors against the analytic surface.
/// Schema documented in docs/truth-json.md.
#[derive(Debug, Serialize)]
struct TruthFile<'a> {
    format_version: u32,
    case: String,
    spec: &'a SceneSpec,
    /// Mean spacing of the main body's surface particles.
    spacing: f64,
    /// Gap between the two faces of the `sheet` scene.
    sheet_gap: Option<f64>,
    extras: Vec<Extra>,
    droplets: &'a [Droplet],
    steps: Vec<TruthStep>,
}

#[derive(Debug, Serialize)]
struct TruthStep {
    step: usize,
    time: f64,
    points: usize,
    surface_points: usize,
    surface: Truth,
}

const VARIABLES: [(&str, VarType); 3] = [
    ("normal", VarType::Vector),
    ("pressure", VarType::Scalar),
    ("surface", VarType::Scalar),
];

pub fn run(cfg: &GenConfig) -> Result<()> {
    match &cfg.source {
        GenSource::Scene { spec, steps } => gen_scene(cfg, spec, *steps),
        GenSource::File(path) => gen_from_file(cfg, path),
    }
}

fn to_f32(v: &[slosh_scenes::DVec3]) -> Vec<[f32; 3]> {
    v.iter()
        .map(|p| [p.x as f32, p.y as f32, p.z as f32])
        .collect()
}

fn gen_scene(cfg: &GenConfig, spec: &SceneSpec, steps: usize) -> Result<()> {
    let scene = Scene::new(spec.clone())?;
    let name = spec.kind.name();
    let mut writer = CaseWriter::create(&cfg.out, name, cfg.format, cfg.placement, &VARIABLES)?
        .with_byte_order(cfg.byte_order);
    let mut truth_steps = Vec::with_capacity(steps);
    let mut total = 0usize;
    for step in 0..steps {
        let t = scene.time(step);
        let p = scene.particles(step);
        let positions = to_f32(&p.positions);
        let normals = to_f32(&p.normals);
        let pressure: Vec<f32> = p.pressure.iter().map(|&v| v as f32).collect();
        let surface: Vec<f32> = p
            .surface
            .iter()
            .map(|&s| if s { 1.0 } else { 0.0 })
            .collect();
        writer
            .write_step(
                t,
                &positions,
                &[
                    VarData::Vector("normal", &normals),
                    VarData::Scalar("pressure", &pressure),
                    VarData::Scalar("surface", &surface),
                ],
            )
            .with_context(|| format!("writing step {step}"))?;
        total += p.len();
        truth_steps.push(TruthStep {
            step,
            time: t,
            points: p.len(),
            surface_points: p.surface.iter().filter(|s| **s).count(),
            surface: scene.truth(t),
        });
    }
    let truth = TruthFile {
        format_version: 1,
        case: format!("{name}.case"),
        spec,
        spacing: scene.spacing(),
        sheet_gap: (spec.kind == slosh_scenes::SceneKind::Sheet).then(|| scene.sheet_gap()),
        extras: scene.extras(),
        droplets: scene.droplets(),
        steps: truth_steps,
    };
    let json = serde_json::to_vec_pretty(&truth)?;
    atomic_write(&cfg.out.join("truth.json"), &json)?;
    slosh_fileio::stdout::print(&format!(
        "wrote {} ({} steps, {:.0} points per step on average, mean spacing {:.4e}) and {}\n",
        writer.case_path().display(),
        steps,
        total as f64 / steps as f64,
        scene.spacing(),
        cfg.out.join("truth.json").display()
    ))?;
    Ok(())
}

fn gen_from_file(cfg: &GenConfig, path: &Path) -> Result<()> {
    let cloud = read_point_cloud(path)?;
    let name = path
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("points")
        .replace(|c: char| c.is_whitespace() || c == '*', "_");
    let vars: &[(&str, VarType)] = if cloud.normals.is_some() {
        &[("normal", VarType::Vector)]
    } else {
        &[]
    };
    let mut writer = CaseWriter::create(&cfg.out, &name, cfg.format, cfg.placement, vars)?
        .with_byte_order(cfg.byte_order);
    let positions: Vec<[f32; 3]> = cloud
        .positions
        .iter()
        .map(|p| p.map(|c| c as f32))
        .collect();
    let normals: Option<Vec<[f32; 3]>> = cloud
        .normals
        .as_ref()
        .map(|n| n.iter().map(|p| p.map(|c| c as f32)).collect());
    let data: Vec<VarData<'_>> = normals
        .as_deref()
        .map(|n| VarData::Vector("normal", n))
        .into_iter()
        .collect();
    writer.write_step(0.0, &positions, &data)?;
    slosh_fileio::stdout::print(&format!(
        "wrote {} ({} points, {})\n",
        writer.case_path().display(),
        positions.len(),
        if normals.is_some() {
            "normals normalised to unit length"
        } else {
            "no normals in the file"
        }
    ))?;
    Ok(())
}
