//! Step 1 of the bake: which particles to keep. Finite positions only; the surface by flag,
//! by estimate, or all.

use std::num::NonZero;

use rayon::prelude::*;
use slosh_ensight::FieldValues;
use slosh_mls::{KdSearch, NeighbourSearch, SurfaceError, distance2};

/// One step's particles as read, before selection.
#[derive(Debug, Clone, Default)]
pub struct StepInput {
    pub index: usize,
    pub time: f64,
    /// Where the step came from (recorded in the header).
    pub source: String,
    pub positions: Vec<[f64; 3]>,
    pub normals: Option<Vec<[f64; 3]>>,
    /// Surface flags from a variable (`SurfaceSelect::Variable`).
    pub surface_flags: Option<Vec<bool>>,
    pub fields: Vec<(String, FieldValues)>,
    /// The input files' identity ([`crate::StepSource::identity`]), recorded in the cache.
    pub identity: Option<String>,
}

/// Neighbours looked at per particle by the surface estimate.
pub const ESTIMATE_NEIGHBOURS: usize = 24;
/// A particle is on the surface when the centroid of its neighbours is offset from it by more
/// than this fraction of their mean distance.
pub const ESTIMATE_THRESHOLD: f64 = 0.25;

/// A neighbourhood is flat, a sheet one particle thick, when the spread across it (the
/// smallest eigenvalue of its covariance) is below this fraction of the next.
pub const ESTIMATE_FLAT: f64 = 0.05;

/// Free-surface estimate for solvers that flag nothing (SPH): inside the fluid a particle's
/// nearest neighbours surround it and their centroid is close to it; at the surface they all
/// lie on one side, pulling the centroid inward by a sizeable fraction of their distance. The
/// same idea as the SPH free-surface detectors based on the kernel-gradient sum; this form
/// needs no kernel. It flags every boundary of the fluid body, walls included.
pub fn estimate_surface(points: &[[f64; 3]]) -> Vec<bool> {
    estimate_surface_normals(points)
        .into_iter()
        .map(|(surface, _)| surface)
        .collect()
}

/// [`estimate_surface`], with each particle's outward normal: away from the centroid of its
/// neighbours, the direction in which the particle indicator (the colour field) falls, as its
/// negated gradient does. A zero vector where the neighbours surround the particle evenly.
pub fn estimate_surface_normals(points: &[[f64; 3]]) -> Vec<(bool, [f64; 3])> {
    estimate_surface_normals_with(points, &KdSearch)
        .unwrap_or_else(|_| vec![(true, [0.0; 3]); points.len()])
}

/// [`estimate_surface_normals`], the neighbours found by `search` (the GPU's, say): the same
/// flags and normals wherever no two distances tie at the last neighbour.
pub fn estimate_surface_normals_with(
    points: &[[f64; 3]],
    search: &dyn NeighbourSearch,
) -> Result<Vec<(bool, [f64; 3])>, SurfaceError> {
    if points.len() <= ESTIMATE_NEIGHBOURS {
        return Ok(vec![(true, [0.0; 3]); points.len()]);
    }
    let k = NonZero::new(ESTIMATE_NEIGHBOURS + 1).ok_or(SurfaceError::BadK)?;
    let nearest = search.index(points)?.nearest(k)?;
    Ok(nearest
        .par_chunks(k.get())
        .zip(points)
        .map(|(nn, p)| {
            // The nearest is the particle itself (or a particle where it is).
            let others = &nn[1..];
            let m = others.len() as f64;
            let mut c = [0.0; 3];
            let mut mean_dist = 0.0;
            for &j in others {
                let q = points[j as usize];
                for a in 0..3 {
                    c[a] += (q[a] - p[a]) / m;
                }
                mean_dist += distance2(*p, q).sqrt() / m;
            }
            let offset = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
            let one_sided = offset > ESTIMATE_THRESHOLD * mean_dist;
            if one_sided {
                return (true, c.map(|v| -v / offset));
            }
            // A sheet one particle thick surrounds its particles within its plane, so the
            // centroid test misses it; its neighbourhood is flat. Both faces are surface and
            // neither is outward: no normal (the support plane then comes from the
            // covariance).
            let mut cov = [[0.0f64; 3]; 3];
            for &j in others {
                let q = points[j as usize];
                let d: [f64; 3] = std::array::from_fn(|a| q[a] - p[a] - c[a]);
                for i in 0..3 {
                    for j in 0..3 {
                        cov[i][j] += d[i] * d[j] / m;
                    }
                }
            }
            let (mut values, _) = slosh_mls::jacobi_eigen(cov);
            values.sort_by(f64::total_cmp);
            (values[0] <= ESTIMATE_FLAT * values[1], [0.0; 3])
        })
        .collect())
}
