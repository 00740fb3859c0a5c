//! What the picture on screen shows at a pixel: the hit read back from the GPU, the step's
//! surface probed there on the host (world position, nearest particle, field value), and
//! that particle's index in the EnSight case the step was baked from. What a step's probes
//! need (its surface decoded, its case's particles read: a second or more for a large ASCII
//! case) is prepared on a thread of its own, and the pixel is read back without waiting for
//! the GPU, so that the UI thread never waits for either.

use slosh_cache::{CacheFile, NearestPoints, ProbeReading, Source, SurfaceProbe};
use slosh_ensight::{Case, PointSource, StepRequest};
use slosh_render::{GpuHit, GpuStep, HostField, PendingHit, status};

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
    /// The step's particles as its EnSight case holds them, searchable for the nearest.
    input: std::result::Result<(Vec<[f32; 3]>, NearestPoints), String>,
    source: Source,
    /// How far a stored point may lie from its input particle: f32 round trips.
    tolerance: f64,
}

/// A step's [`HeldProbe`] being prepared: for the resident step and field revision it was
/// asked for.
#[derive(Debug)]
pub(super) struct PreparingProbe {
    step_id: u64,
    revision: u64,
    thread: std::thread::JoinHandle<Result<HeldProbe>>,
}

impl PreparingProbe {
    pub(super) fn is_finished(&self) -> bool {
        self.thread.is_finished()
    }
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
    /// What probing the step file `path` needs (field `field` read), for the resident step
    /// `step_id` at field revision `revision`.
    fn prepare(
        path: &std::path::Path,
        field: Option<&str>,
        step_id: u64,
        revision: u64,
    ) -> Result<HeldProbe> {
        let file = CacheFile::open(path)?;
        let field = match field {
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
        Ok(HeldProbe {
            step_id,
            revision,
            surface: SurfaceProbe::open(&file)?,
            field,
            input: input_particles(&header.source).map(|p| {
                let nearest = NearestPoints::new(&p);
                (p, nearest)
            }),
            source: header.source.clone(),
            // Positions go through f32 local coordinates and back.
            tolerance: 1e-5 * header.transform.scale.max(f64::MIN_POSITIVE)
                + 1e-6
                    * header
                        .transform
                        .origin
                        .iter()
                        .fold(0.0f64, |m, o| m.max(o.abs())),
        })
    }

    /// The input particle at the stored point `world`: its index and position.
    fn input_at(&self, world: [f64; 3]) -> std::result::Result<(usize, [f64; 3]), String> {
        let source = &self.source;
        let (particles, nearest) = self.input.as_ref().map_err(Clone::clone)?;
        let index = nearest
            .nearest(world.map(|c| c as f32))
            .ok_or_else(|| format!("{} holds no particles at step {}", source.path, source.step))?;
        let d2: f64 = (0..3)
            .map(|a| (f64::from(particles[index][a]) - world[a]).powi(2))
            .sum();
        if d2.sqrt() > self.tolerance {
            return Err(format!(
                "{} holds no particle where the stored one is (changed since the bake?)",
                source.path
            ));
        }
        Ok((index, particles[index].map(f64::from)))
    }
}

/// A pixel asked for: where, of which step and frame size, and in which recorded frame.
#[derive(Debug, Clone, Copy, PartialEq)]
struct HitKey {
    x: u32,
    y: u32,
    step_id: u64,
    size: (u32, u32),
    frame: u64,
}

impl HitKey {
    /// The same pixel of the same step's picture, perhaps of a frame recorded since: a hit
    /// read from a frame a few passes older is still a point of that step's surface.
    fn same_pixel(&self, other: &HitKey) -> bool {
        HitKey {
            frame: other.frame,
            ..*self
        } == *other
    }
}

/// The hit a probe asked for, read back without waiting for the GPU (which on a software
/// adapter runs the copy behind the window's paint and present), and the last one read.
#[derive(Debug, Default)]
pub(super) struct HitReadback {
    pending: Option<(HitKey, PendingHit)>,
    read: Option<(HitKey, Option<GpuHit>)>,
}

impl Engine {
    /// Whether what a probe asked for is still being prepared or read back (probe again
    /// once not).
    pub fn probe_preparing(&self) -> bool {
        self.probing.as_ref().is_some_and(|p| !p.is_finished()) || self.hit.pending.is_some()
    }

    /// The hit at pixel (`x`, `y`) of the step `step_id`'s picture on screen, once read
    /// back: asked for at the first call, taken at a later one (`Ok(None)` until then, and
    /// for a miss).
    fn hit_at(&mut self, step_id: u64, x: u32, y: u32) -> Result<Option<GpuHit>> {
        let Some(size) = self.targets().map(|t| t.size()) else {
            return Ok(None);
        };
        let key = HitKey {
            x,
            y,
            step_id,
            size,
            frame: self.frames_recorded,
        };
        if let Some((at, hit)) = &self.hit.read
            && *at == key
        {
            return Ok(*hit);
        }
        match self.hit.pending.take() {
            Some((at, pending)) if at.same_pixel(&key) => match pending.poll(&self.gpu)? {
                Some(hit) => {
                    self.hit.read = Some((at, hit));
                    Ok(hit)
                }
                None => {
                    self.hit.pending = Some((at, pending));
                    Ok(None)
                }
            },
            // None asked for yet, or for another pixel or step: that one is let go.
            _ => {
                let pending = self
                    .targets()
                    .and_then(|t| self.tracer.request_hit(&self.gpu, t, x, y));
                self.hit.pending = pending.map(|p| (key, p));
                Ok(None)
            }
        }
    }

    /// What the picture on screen shows at pixel (`x`, `y`) of [`Engine::targets`] (a
    /// preview's pixels while one is shown): `None` for a miss, before any frame, or while
    /// the pixel is read back or what the shown step's probes need is prepared
    /// ([`Engine::probe_preparing`]: the pixel asked for by a probe of another pixel or step,
    /// the rest by the first probe of each step loaded).
    pub fn probe(&mut self, x: u32, y: u32, h_factor: f32) -> Result<Option<Probe>> {
        let Some(index) = self.shown else {
            return Ok(None);
        };
        let Some(step_id) = self.pool.peek(index).map(GpuStep::id) else {
            return Ok(None);
        };
        let Some(hit) = self.hit_at(step_id, x, y)? else {
            return Ok(None);
        };
        let revision = self.revision;
        let stale = self
            .probed
            .as_ref()
            .is_none_or(|p| p.step_id != step_id || p.revision != revision);
        if stale {
            match self.probing.take() {
                Some(p) if p.step_id == step_id && p.revision == revision => {
                    if !p.is_finished() {
                        self.probing = Some(p);
                        return Ok(None);
                    }
                    let held = p.thread.join().map_err(|_| Error::Series {
                        path: self.series.dir().to_path_buf(),
                        problem: format!("reading step {index} for probing failed"),
                    })??;
                    self.probed = Some(held);
                }
                // One for another step (the shown one changed meanwhile) is let finish first:
                // one preparation at a time, however fast steps are flipped.
                Some(p) if !p.is_finished() => {
                    self.probing = Some(p);
                    return Ok(None);
                }
                // None yet, or another step's, finished and no longer wanted.
                _ => {
                    let path = self.source.path(index).ok_or_else(|| Error::Series {
                        path: self.series.dir().to_path_buf(),
                        problem: format!("step {index} is not in the series"),
                    })?;
                    let field = self.field.clone();
                    let thread = std::thread::Builder::new()
                        .name("probe".into())
                        .spawn(move || {
                            HeldProbe::prepare(&path, field.as_deref(), step_id, revision)
                        })
                        .map_err(|e| Error::Series {
                            path: self.series.dir().to_path_buf(),
                            problem: format!("no thread to read step {index} for probing: {e}"),
                        })?;
                    self.probing = Some(PreparingProbe {
                        step_id,
                        revision,
                        thread,
                    });
                    return Ok(None);
                }
            }
        }
        let Some(held) = &self.probed else {
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
