//! A point set prepared for tracing: recentred coordinates, radii of trust, neighbour lists
//! (CSR), initial support normals and polynomials, and a uniform grid over the balls.
//! This is the CPU reference of what the bake will store in caches.

use std::num::NonZero;

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;

use crate::fit::FitStatus;
use crate::grid::Grid;
use crate::intersect::{Ball, Params, initial_fit};
use crate::poly::Poly;
use crate::real::{Real, V3};
use crate::support::NormalsMode;

#[derive(Debug, Clone, PartialEq)]
pub struct SurfaceParams {
    /// Radius of trust ρ_i = distance to the k-th nearest neighbour.
    pub k: usize,
    /// h = h_scale × mean ρ (thesis §4.1.2: 1.5).
    pub h_scale: f64,
    /// Neighbour lists reach ρ_i + support × h, where the weight has died out (θ(3h) ≈ 1e-4).
    pub support: f64,
    /// At most this many neighbours per point (the nearest).
    pub neighbour_cap: usize,
    pub degree: u8,
    pub normals: NormalsMode,
    /// h_i = h_scale × ρ_i per ball instead of one global h (for uneven sampling).
    pub per_point_h: bool,
}

impl Default for SurfaceParams {
    fn default() -> Self {
        SurfaceParams {
            k: 6,
            h_scale: 1.5,
            support: 3.0,
            neighbour_cap: 128,
            degree: 2,
            normals: NormalsMode::Mean,
            per_point_h: false,
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum SurfaceError {
    #[error("point {index} has a non-finite coordinate {value:?}")]
    NonFinite { index: usize, value: [f64; 3] },
    #[error("a surface needs at least 2 points, got {0}")]
    TooFew(usize),
    #[error("k must be at least 1")]
    BadK,
    #[error("spatial index: {0}")]
    Index(String),
}

/// Per-ball state of the initial fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BallFit {
    Fitted(FitStatus),
    /// No support plane or fit at the centre: the ball is never a candidate.
    None,
}

#[derive(Debug, Clone)]
pub struct Surface<T> {
    /// Subtracted from every input coordinate (in f64) before conversion to `T`, so f32 keeps
    /// its precision at any offset.
    pub origin: [f64; 3],
    pub points: Vec<V3<T>>,
    pub normals: Option<Vec<V3<T>>>,
    pub radii: Vec<T>,
    /// The global smoothing length h_scale × mean ρ (each ball carries the h it uses).
    pub h: T,
    /// CSR neighbour lists: the neighbours of point i are `neighbours[start[i]..start[i + 1]]`.
    pub neighbour_start: Vec<u32>,
    pub neighbours: Vec<u32>,
    /// Points whose neighbour list was cut at the cap.
    pub capped: usize,
    pub balls: Vec<Ball<T>>,
    pub ball_fits: Vec<BallFit>,
    pub params: SurfaceParams,
    pub(crate) grid: Grid,
}

impl<T: Real> Surface<T> {
    pub fn build(
        points: &[[f64; 3]],
        normals: Option<&[[f64; 3]]>,
        params: &SurfaceParams,
    ) -> Result<Surface<T>, SurfaceError> {
        if points.len() < 2 {
            return Err(SurfaceError::TooFew(points.len()));
        }
        if params.k == 0 {
            return Err(SurfaceError::BadK);
        }
        if let Some(index) = points.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
            return Err(SurfaceError::NonFinite {
                index,
                value: points[index],
            });
        }
        let n = points.len();
        let (lo, hi) = bounds(points);
        let origin = [
            0.5 * (lo[0] + hi[0]),
            0.5 * (lo[1] + hi[1]),
            0.5 * (lo[2] + hi[2]),
        ];
        let rel: Vec<[f64; 3]> = points
            .iter()
            .map(|p| [p[0] - origin[0], p[1] - origin[1], p[2] - origin[2]])
            .collect();
        let unit_normals: Option<Vec<Option<[f64; 3]>>> =
            normals.map(|ns| ns.iter().map(|n| unit(*n)).collect());

        let tree: ImmutableKdTree<f64, 3> = ImmutableKdTree::new_from_slice(&rel)
            .map_err(|e| SurfaceError::Index(format!("{e:?}")))?;
        let k = params.k.min(n - 1);
        let k_query = NonZero::new(k + 1).ok_or(SurfaceError::BadK)?;
        let mut radii: Vec<f64> = rel
            .par_iter()
            .map(|p| {
                let nn = tree
                    .query(p)
                    .nearest_n::<SquaredEuclidean<f64>>(k_query)
                    .execute();
                nn.last().map_or(0.0, |r| r.distance.sqrt())
            })
            .collect();
        let mean = radii.iter().sum::<f64>() / n as f64;
        // Coincident points give ρ = 0: keep every ball a tenth of the mean radius at least.
        let floor = 0.1 * mean;
        for r in &mut radii {
            *r = r.max(floor);
        }
        let mean = radii.iter().sum::<f64>() / n as f64;
        let h = params.h_scale * mean;
        let ball_h = |i: usize| {
            if params.per_point_h {
                params.h_scale * radii[i]
            } else {
                h
            }
        };
        let cap = NonZero::new(params.neighbour_cap.max(1)).ok_or(SurfaceError::BadK)?;

        let lists: Vec<(Vec<u32>, bool)> = (0..n)
            .into_par_iter()
            .map(|i| {
                let reach = radii[i] + params.support * ball_h(i);
                let found = tree
                    .query(&rel[i])
                    .nearest_n::<SquaredEuclidean<f64>>(cap)
                    .within(reach * reach)
                    .execute();
                let capped = found.len() == cap.get();
                let own = unit_normals.as_ref().and_then(|ns| ns[i]);
                let list = found
                    .iter()
                    .map(|r| r.item)
                    .filter(|&j| {
                        // Thin sheets: a neighbour whose normal opposes the centre's is the other side.
                        match (own, unit_normals.as_ref().and_then(|ns| ns[j as usize])) {
                            (Some(a), Some(b)) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2] >= 0.0,
                            _ => true,
                        }
                    })
                    .collect();
                (list, capped)
            })
            .collect();
        let mut neighbour_start = Vec::with_capacity(n + 1);
        let mut neighbours = Vec::new();
        let mut capped = 0;
        neighbour_start.push(0u32);
        for (list, c) in &lists {
            neighbours.extend_from_slice(list);
            neighbour_start.push(neighbours.len() as u32);
            capped += usize::from(*c);
        }

        let to_t = |p: [f64; 3]| V3::<T>::from_f64(p);
        let pts: Vec<V3<T>> = rel.iter().map(|p| to_t(*p)).collect();
        // Unusable normals (NaN, zero) become zero vectors, which every consumer ignores.
        let nrm: Option<Vec<V3<T>>> = unit_normals
            .as_ref()
            .map(|ns| ns.iter().map(|n| n.map_or(V3::zero(), to_t)).collect());
        let h_t = T::c(h);
        let fit_params = Params {
            degree: params.degree,
            iterations: 1,
            epsilon: T::c(1e-4),
            normals: params.normals,
        };
        let fits: Vec<(Ball<T>, BallFit)> = (0..n)
            .into_par_iter()
            .map_init(
                || (Vec::new(), Vec::new()),
                |(np, nn), i| {
                    gather(
                        &pts,
                        nrm.as_deref(),
                        &neighbours[neighbour_start[i] as usize..neighbour_start[i + 1] as usize],
                        np,
                        nn,
                    );
                    let centre = pts[i];
                    // Without data normals the plane faces away from the set's centre.
                    let toward = centre * T::c(2.0);
                    let hi = T::c(ball_h(i));
                    let ball = |normal, poly| Ball {
                        centre,
                        radius: T::c(radii[i]),
                        h: hi,
                        normal,
                        poly,
                    };
                    match initial_fit(
                        centre,
                        np,
                        nrm.as_ref().map(|_| nn.as_slice()),
                        hi,
                        &fit_params,
                        toward,
                    ) {
                        Some((normal, f)) => (ball(normal, f.poly), BallFit::Fitted(f.status)),
                        None => (
                            ball(V3::new(T::zero(), T::zero(), T::one()), Poly::zero(0)),
                            BallFit::None,
                        ),
                    }
                },
            )
            .collect();
        let (balls, ball_fits): (Vec<_>, Vec<_>) = fits.into_iter().unzip();
        let grid = Grid::build(&rel, &radii, mean);
        Ok(Surface {
            origin,
            points: pts,
            normals: nrm,
            radii: radii.iter().map(|&r| T::c(r)).collect(),
            h: h_t,
            neighbour_start,
            neighbours,
            capped,
            balls,
            ball_fits,
            params: params.clone(),
            grid,
        })
    }

    pub fn len(&self) -> usize {
        self.points.len()
    }

    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    pub fn neighbours_of(&self, i: usize) -> &[u32] {
        &self.neighbours[self.neighbour_start[i] as usize..self.neighbour_start[i + 1] as usize]
    }
}

/// Copies the positions (and normals) of `ids` into the scratch vectors.
pub(crate) fn gather<T: Real>(
    points: &[V3<T>],
    normals: Option<&[V3<T>]>,
    ids: &[u32],
    out_p: &mut Vec<V3<T>>,
    out_n: &mut Vec<V3<T>>,
) {
    out_p.clear();
    out_n.clear();
    out_p.extend(ids.iter().map(|&j| points[j as usize]));
    if let Some(ns) = normals {
        out_n.extend(ids.iter().map(|&j| ns[j as usize]));
    }
}

fn unit(n: [f64; 3]) -> Option<[f64; 3]> {
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    (len.is_finite() && len > 1e-12).then(|| [n[0] / len, n[1] / len, n[2] / len])
}

pub(crate) fn bounds(points: &[[f64; 3]]) -> ([f64; 3], [f64; 3]) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in points {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    (lo, hi)
}
