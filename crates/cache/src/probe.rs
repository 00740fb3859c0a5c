//! Reading the surface back where a ray hit it: the world position, the stored particle
//! nearest to it and a field's value there, weighted as the shade pass weights it. What a
//! click on the player's picture asks.

use slosh_mls::{MIN_WEIGHT, V3, expand_one, weight};

use crate::error::{Error, Result};
use crate::format::Transform;
use crate::layout::field_missing;
use crate::names;
use crate::nearest_point::NearestPoints;
use crate::reader::CacheFile;

/// One step's points, neighbour lists and input indices, held for probing.
#[derive(Debug)]
pub struct SurfaceProbe {
    transform: Transform,
    positions: Vec<V3<f32>>,
    normals: Option<Vec<V3<f32>>>,
    reach: Vec<f32>,
    /// Each ball's smoothing length.
    h: Vec<f32>,
    cluster_size: usize,
    cluster_start: Vec<u32>,
    candidates: Vec<u32>,
    /// The stored points, searchable for the nearest.
    nearest: NearestPoints,
}

/// What the surface holds at a probed point.
#[derive(Debug, Clone, PartialEq)]
pub struct ProbeReading {
    /// The point in world coordinates.
    pub world: [f64; 3],
    /// The stored particle nearest to it (in the cache's order), where it is in world
    /// coordinates, and how far.
    pub nearest: usize,
    pub nearest_world: [f64; 3],
    pub nearest_distance: f64,
    /// The field's value there: the weighted mean over the hit ball's neighbours (`θ` with
    /// the ball's `h`), as the shade pass colours it; the ball's own value where no weight
    /// reaches, the nearest particle's where the hit is a droplet. Missing values
    /// ([`crate::field_missing`]) are left out; `None` where there is none but those.
    pub field: Option<f32>,
}

impl SurfaceProbe {
    /// Decodes what probing `file` needs.
    pub fn open(file: &CacheFile) -> Result<SurfaceProbe> {
        let geometry = file.geometry()?;
        let balls = file.balls()?;
        let cluster_start: Vec<u32> = file.decode(names::CLUSTER_START)?;
        let candidates = file.cluster_candidates(&cluster_start)?;
        let n = geometry.positions.len();
        if balls.len() != n {
            return Err(Error::Invalid {
                path: file.path().to_path_buf(),
                problem: format!("{n} points, {} balls", balls.len()),
            });
        }
        let nearest = NearestPoints::new(
            &geometry
                .positions
                .iter()
                .map(|p| [p.x, p.y, p.z])
                .collect::<Vec<_>>(),
        );
        Ok(SurfaceProbe {
            nearest,
            transform: file.header().transform,
            positions: geometry.positions,
            normals: geometry.normals,
            reach: geometry.reach,
            h: balls.iter().map(|b| b.h).collect(),
            cluster_size: file.header().neighbour_cluster.max(1) as usize,
            cluster_start,
            candidates,
        })
    }

    pub fn point_count(&self) -> usize {
        self.positions.len()
    }

    /// The world coordinates of a point in the cache's local ones.
    pub fn to_world(&self, local: [f32; 3]) -> [f64; 3] {
        self.transform.to_world(local.map(f64::from))
    }

    /// Reads the surface at `local` (the cache's local coordinates, as the hit buffer holds
    /// them), hit on ball `ball` (`None` for a droplet), with the smoothing lengths scaled by
    /// `h_factor`, and `field` one value per stored point where a field is shown. `None`
    /// for a step without points.
    pub fn read(
        &self,
        local: [f32; 3],
        ball: Option<usize>,
        h_factor: f32,
        field: Option<&[f32]>,
    ) -> Option<ProbeReading> {
        let x = V3::new(local[0], local[1], local[2]);
        let nearest = self.nearest.nearest(local)?;
        let d2 = (self.positions[nearest] - x).length_squared();
        let own = |i: usize, f: &[f32]| Some(f[i]).filter(|&v| !field_missing(v));
        let field = field
            .filter(|f| f.len() == self.positions.len())
            .and_then(|f| match ball.filter(|&i| i < self.positions.len()) {
                Some(i) => self.weighted_mean(i, x, h_factor, f).or_else(|| own(i, f)),
                None => own(nearest, f),
            });
        Some(ProbeReading {
            world: self.to_world(local),
            nearest,
            nearest_world: {
                let p = self.positions[nearest];
                self.to_world([p.x, p.y, p.z])
            },
            nearest_distance: f64::from(d2).sqrt() * self.transform.scale,
            field,
        })
    }

    /// The θ-weighted mean of `field` at `x` over ball `i`'s neighbours (its list recovered
    /// from its cluster's candidates, as the tracer's masks select them).
    fn weighted_mean(&self, i: usize, x: V3<f32>, h_factor: f32, field: &[f32]) -> Option<f32> {
        let cluster = i / self.cluster_size;
        let range = self.cluster_start.get(cluster).copied()? as usize
            ..self.cluster_start.get(cluster + 1).copied()? as usize;
        let mut list = Vec::new();
        expand_one(
            i,
            &self.positions,
            self.normals.as_deref(),
            &self.reach,
            self.candidates.get(range)?,
            &mut list,
        );
        let h = self.h[i] * h_factor;
        let h2 = h * h;
        // The sums in f64: f32 overflows where values lie near its limits (the mean of finite
        // f32s is one); the weights' also in f32, as the shade pass tests them.
        let (mut sum, mut wsum, mut wsum32) = (0.0f64, 0.0f64, 0.0f32);
        for &j in &list {
            let v = field[j as usize];
            if field_missing(v) {
                continue;
            }
            let w = weight((self.positions[j as usize] - x).length_squared(), h2);
            sum += f64::from(w) * f64::from(v);
            wsum += f64::from(w);
            wsum32 += w;
        }
        // Below the fits' least summed weight the shade pass takes the ball's own value.
        (wsum32 > MIN_WEIGHT as f32).then(|| (sum / wsum) as f32)
    }
}
