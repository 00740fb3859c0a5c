//! What the picture on screen shows at a pixel: the hit read back from the GPU, and the
//! step's surface probed there on the host (world position, nearest particle, field value).

use slosh_cache::{CacheFile, ProbeReading, SurfaceProbe};
use slosh_render::{HostField, status};

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
}

/// The shown step's surface, held for probing, with the field it was read with.
#[derive(Debug)]
pub(super) struct HeldProbe {
    index: usize,
    revision: u64,
    surface: SurfaceProbe,
    field: Option<Vec<f32>>,
}

impl Engine {
    /// What the picture on screen shows at pixel (`x`, `y`) of [`Engine::targets`]: `None`
    /// for a miss, before any frame, or while the shown step is a preview's (its pixels are
    /// another size). The step's surface is decoded on the first probe of each step.
    pub fn probe(&mut self, x: u32, y: u32, h_factor: f32) -> Result<Option<Probe>> {
        let (Some(index), Some(targets)) = (self.shown, self.targets()) else {
            return Ok(None);
        };
        let Some(hit) = self.tracer.read_hit(&self.gpu, targets, x, y)? else {
            return Ok(None);
        };
        let stale = self
            .probed
            .as_ref()
            .is_none_or(|p| p.index != index || p.revision != self.revision);
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
            self.probed = Some(HeldProbe {
                index,
                revision: self.revision,
                surface: SurfaceProbe::open(&file)?,
                field,
            });
        }
        let Some(held) = &self.probed else {
            return Ok(None);
        };
        let ball = (hit.status != status::DROPLET).then_some(hit.item as usize);
        Ok(held
            .surface
            .read(hit.position, ball, h_factor, held.field.as_deref())
            .map(|reading| Probe {
                step: index,
                status: hit.status,
                field: self.field.clone(),
                reading,
            }))
    }
}
