//! Bake parameters, resolved (no "auto" left), and the hash that tells a resumed bake whether
//! an existing step file was made with the same settings.

use serde::Serialize;
use slosh_cache::{Compression, MlsSettings};
use slosh_mls::{NormalsMode, SurfaceParams};
use xxhash_rust::xxh3::xxh3_64;

/// Which particles make up the surface.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub enum SurfaceSelect {
    /// Every particle.
    All,
    /// Particles whose value of this scalar variable is nonzero.
    Variable(String),
    /// Particles estimated to lie on the free surface (see `select::estimate_surface`).
    Estimate,
}

/// Where particle normals come from.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub enum NormalSource {
    /// This vector variable (support planes from the weighted mean normal).
    Variable(String),
    /// None: support planes from the weighted covariance (PCA).
    Pca,
    /// Estimated from the particles (SPH output has none): outward, away from the centroid
    /// of each particle's neighbours among all particles of the step
    /// (`select::estimate_surface_normals`); support planes from the weighted mean normal.
    Estimate,
}

#[derive(Debug, Clone, PartialEq)]
pub struct BakeParams {
    pub mls: SurfaceParams,
    pub surface: SurfaceSelect,
    pub normals: NormalSource,
    /// Variables stored per point, in this order.
    pub fields: Vec<String>,
    pub compression: Compression,
}

/// Bumped whenever the bake's output for the same input and parameters changes.
pub const BAKE_REVISION: u32 = 23;

/// The surface's default offset, in particle radii, where the surface is estimated from
/// particles that fill the fluid's volume (SPH): ¾ of a radius outside the outer centres,
/// the offset nearest splashsurf's iso-surface on SPlisHSPlasH dam breaks (`docs/results-sph.md`).
pub const VOLUME_PARTICLE_OFFSET: f64 = 0.75;

impl BakeParams {
    /// Parameters with the MLS defaults and the normals mode matching `normals`.
    pub fn new(surface: SurfaceSelect, normals: NormalSource) -> BakeParams {
        let mls = SurfaceParams {
            normals: match normals {
                NormalSource::Variable(_) | NormalSource::Estimate => NormalsMode::Mean,
                NormalSource::Pca => NormalsMode::Covariance,
            },
            // Particles that fill the volume stand for fluid out to about their radius.
            offset: match surface {
                SurfaceSelect::Estimate => VOLUME_PARTICLE_OFFSET,
                SurfaceSelect::All | SurfaceSelect::Variable(_) => 0.0,
            },
            ..SurfaceParams::default()
        };
        BakeParams {
            mls,
            surface,
            normals,
            fields: Vec::new(),
            compression: Compression::Level(-1),
        }
    }

    /// Everything that shapes the output, as recorded in each step header and the manifest.
    pub fn record(&self) -> serde_json::Value {
        serde_json::json!({
            "revision": BAKE_REVISION,
            "cache_major": slosh_cache::MAJOR,
            "mls": MlsSettings::from_params(&self.mls),
            "surface": self.surface,
            "normals": self.normals,
            "fields": self.fields,
            "compression": match self.compression {
                Compression::None => "none".to_string(),
                Compression::Level(l) => format!("zstd level {l}"),
            },
        })
    }

    /// xxh3-64 of the canonical record, in hex.
    pub fn hash(&self) -> String {
        slosh_cache::hex64(xxh3_64(self.record().to_string().as_bytes()))
    }
}
