//! What the picture on screen shows at a pixel: the hit read back from the GPU, the step's
//! surface probed there on the host (world position, nearest particle, field value), and
//! that particle's index in the EnSight case the step was baked from.

use slosh_cache::{CacheFile, ProbeReading, Source, SurfaceProbe};
use slosh_ensight::{Case, PointSource, StepRequest};
use slosh_render::{GpuStep, HostField, status};

use super::Engine;
use crate::error::{Error, Result};

/// A pixel of the picture read back.
#[derive(Debug, Clone, PartialEq)]
pub struct Probe {
    /// The bake index of the step shown.
    pub step: usize,
    /// The hit's status (`slosh_render::status`).
    pub status: u32,
    /// The field shown, if any, and its value there.
    pub field: Option<String>,
    pub reading: ProbeReading,
    /// The nearest particle's index among the step's particles in its EnSight case (counted
    /// from 0 in the file's order) and its position there; why not where the case cannot be
    /// read or no longer holds that particle.
    pub input: std::result::Result<(usize, [f64; 3]), String>,
}

/// The shown step's surface, held for probing, with the field it was read with.
#[derive(Debug)]
pub(super) struct HeldProbe {
    /// The resident step it was read for (`GpuStep::id`: a step file that changed and was
    /// loaded again is another) and the field revision.
    step_id: u64,
    revision: u64,
    surface: SurfaceProbe,
    field: Option<Vec<f32>>,
    /// The step's particles as its EnSight case holds them, once read.
    input: Option<std::result::Result<Vec<[f32; 3]>, String>>,
    source: Source,
    /// How far a stored point may lie from its input particle: f32 round trips.
    tolerance: f64,
}

/// The particles of step `source.step` of the case `source.path`, as the bake read them.
fn input_particles(source: &Source) -> std::result::Result<Vec<[f32; 3]>, String> {
    let case = Case::open(&source.path)
        .map_err(|e| format!("the case the step was baked from cannot be read: {e}"))?;
    let request = StepRequest {
        points: PointSource::Auto,
        allow_non_finite: true,
        ..StepRequest::default()
    };
    case.read_step(source.step, &request)
        .map(|step| step.positions)
        .map_err(|e| format!("step {} of {}: {e}", source.step, source.path))
}

impl HeldProbe {
    /// The input particle at the stored point `world`: its index and position.
    fn input_at(&mut self, world: [f64; 3]) -> std::result::Result<(usize, [f64; 3]), String> {
        let source = &self.source;
        let particles = self
            .input
            .get_or_insert_with(|| input_particles(source))
            .as_ref()
            .map_err(Clone::clone)?;
        let distance2 =
            |p: &[f32; 3]| -> f64 { (0..3).map(|a| (f64::from(p[a]) - world[a]).powi(2)).sum() };
        let (index, d2) = particles
            .iter()
            .enumerate()
            .map(|(i, p)| (i, distance2(p)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .ok_or_else(|| format!("{} holds no particles at step {}", source.path, source.step))?;
        if d2.sqrt() > self.tolerance {
            return Err(format!(
                "{} holds no particle where the stored one is (changed since the bake?)",
                source.path
            ));
        }
        Ok((index, particles[index].map(f64::from)))
    }
}

impl Engine {
    /// What the picture on screen shows at pixel (`x`, `y`) of [`Engine::targets`] (a
    /// preview's pixels while one is shown): `None` for a miss or before any frame. The
    /// step's surface is decoded on the first probe of each step loaded.
    pub fn probe(&mut self, x: u32, y: u32, h_factor: f32) -> Result<Option<Probe>> {
        let (Some(index), Some(targets)) = (self.shown, self.targets()) else {
            return Ok(None);
        };
        let Some(step_id) = self.pool.peek(index).map(GpuStep::id) else {
            return Ok(None);
        };
        let Some(hit) = self.tracer.read_hit(&self.gpu, targets, x, y)? else {
            return Ok(None);
        };
        let stale = self
            .probed
            .as_ref()
            .is_none_or(|p| p.step_id != step_id || p.revision != self.revision);
        if stale {
            let path = self.source.path(index).ok_or_else(|| Error::Series {
                path: self.series.dir().to_path_buf(),
                problem: format!("step {index} is not in the series"),
            })?;
            let file = CacheFile::open(&path)?;
            let field = match &self.field {
                Some(name) => Some(
                    HostField::read(&file, name)?
                        .bytes
                        .chunks_exact(4)
                        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                        .collect(),
                ),
                None => None,
            };
            let header = file.header();
            self.probed = Some(HeldProbe {
                step_id,
                revision: self.revision,
                surface: SurfaceProbe::open(&file)?,
                field,
                input: None,
                source: header.source.clone(),
                // Positions go through f32 local coordinates and back.
                tolerance: 1e-5 * header.transform.scale.max(f64::MIN_POSITIVE)
                    + 1e-6
                        * header
                            .transform
                            .origin
                            .iter()
                            .fold(0.0f64, |m, o| m.max(o.abs())),
            });
        }
        let Some(held) = &mut self.probed else {
            return Ok(None);
        };
        let ball = (hit.status != status::DROPLET).then_some(hit.item as usize);
        let Some(reading) = held
            .surface
            .read(hit.position, ball, h_factor, held.field.as_deref())
        else {
            return Ok(None);
        };
        let input = held.input_at(reading.nearest_world);
        Ok(Some(Probe {
            step: index,
            status: hit.status,
            field: self.field.clone(),
            reading,
            input,
        }))
    }
}
