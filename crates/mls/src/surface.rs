//! A point set prepared for tracing: recentred coordinates, radii of trust, neighbour lists
//! (CSR, sorted by index), initial support normals and polynomials, droplets too small for a
//! fit as spheres, and a uniform grid over the balls. This is the CPU reference of what the
//! bake stores in caches.

use std::borrow::Cow;
use std::num::NonZero;

use rayon::prelude::*;

pub use crate::error::SurfaceError;
use crate::fit::FitStatus;
use crate::found::{KeptLists, NeighbourLists};
use crate::geometry::recentred;
use crate::grid::Grid;
use crate::intersect::{Ball, Params, initial_fit_with};
use crate::lists::distance2;
use crate::neighbours::Neighbours;
use crate::orient::{NearestIds, ORIENT_NEIGHBOURS, OrientationRepair, repair_orientation};
use crate::poly::Poly;
use crate::real::{Real, V3};
use crate::runs::RunUnions;
use crate::search::{FitRequest, KdSearch, ListRequest, NeighbourSearch};
use crate::spray::{Sphere, droplets};
use crate::support::{DataNormals, NormalsMode};
use crate::timing::{StageClock, stage_part};

#[derive(Debug, Clone, PartialEq)]
pub struct SurfaceParams {
    /// Radius of trust ρ_i = distance to the k-th nearest neighbour.
    pub k: usize,
    /// h = h_scale × ρ of the dense fluid, the median of ρ (thesis §4.1.2: 1.5 ×
    /// mean ρ, which spray inflates).
    pub h_scale: f64,
    /// Neighbour lists reach ρ_i + support × h, where the weight has died out (θ(3h) ≈ 1e-4).
    pub support: f64,
    /// At most this many neighbours per point (the nearest).
    pub neighbour_cap: usize,
    pub degree: u8,
    pub normals: NormalsMode,
    /// h_i = h_scale × ρ_i per ball instead of one global h (for uneven sampling).
    pub per_point_h: bool,
    /// Connected components (points linked within h) with fewer points than this, or no
    /// wider than h, are spray, drawn as spheres instead of MLS patches; 0 turns spray
    /// detection off.
    pub droplet_below: usize,
    /// The surface drawn this far outside the MLS surface along its normal, in particle
    /// radii (half the dense spacing s₅₀): where particles fill the fluid's volume (SPH),
    /// its free surface lies outside the outer particles' centres; 0 where the particles lie
    /// on it (FPM's free-surface particles).
    pub offset: f64,
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
            droplet_below: 6,
            offset: 0.0,
        }
    }
}

/// Per-ball state of the initial fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BallFit {
    Fitted(FitStatus),
    /// No support plane or fit at the centre: the ball is never a candidate.
    None,
    /// Part of a component too small for a fit: drawn as `spheres[index]` instead.
    Droplet(u32),
}

/// What [`SurfaceParts::build_with`] hands to the work it runs beside the initial fits.
#[derive(Debug, Clone, Copy)]
pub struct BesideFits<'a, T> {
    /// The points as the parts hold them (recentred), in f64.
    pub points: &'a [[f64; 3]],
    /// The balls' radii, in f64.
    pub radii: &'a [f64],
    /// (point, sphere) for every point drawn as spray.
    pub droplet_of: &'a [(u32, u32)],
    pub spheres: &'a [Sphere<T>],
}

/// Everything a [`Surface`] holds except its search grid: what a cache stores.
#[derive(Debug, Clone)]
pub struct SurfaceParts<T> {
    /// Subtracted from every input coordinate (in f64) before conversion to `T`, so f32 keeps
    /// its precision at any offset.
    pub origin: [f64; 3],
    pub points: Vec<V3<T>>,
    pub normals: Option<Vec<V3<T>>>,
    pub radii: Vec<T>,
    /// The global smoothing length h_scale × the median of ρ (each ball carries the h
    /// it uses).
    pub h: T,
    /// Mean distance to the nearest other point.
    pub spacing: T,
    /// How far outside the MLS surface the drawn surface lies, along its normal
    /// (`SurfaceParams::offset` particle radii).
    pub offset: T,
    /// Every point's neighbour list (point i's is `neighbours_of(i)`), or where a bake's search
    /// kept only the cluster unions (`run_unions`), each list's members near its reach.
    pub neighbours: KeptLists,
    /// How far each point's neighbour list reaches: ρ_i + support·h_i, or the distance of the
    /// farthest neighbour kept where the cap cut the list.
    pub reach: Vec<T>,
    /// Points whose neighbour list was cut at the cap.
    pub capped: usize,
    /// The union of the lists of each run of consecutive points of the lists stage, where the
    /// build's points came in spatial order (none for parts read back from a cache).
    pub run_unions: Option<RunUnions>,
    pub balls: Vec<Ball<T>>,
    pub ball_fits: Vec<BallFit>,
    /// Droplets; in candidate lists sphere d is item `len() + d`.
    pub spheres: Vec<Sphere<T>>,
    /// Normals the build reversed before using them (`crate::orient`); zero for parts read
    /// back from a cache.
    pub orientation: OrientationRepair,
    pub params: SurfaceParams,
}

/// A point set ready for tracing: its parts (read through `Deref`, since a surface is its
/// parts plus an index over them) and a uniform grid over the balls.
#[derive(Debug, Clone)]
pub struct Surface<T> {
    parts: SurfaceParts<T>,
    /// Seconds spent per stage of [`Surface::build`] (empty for surfaces from parts).
    pub build_seconds: Vec<(&'static str, f64)>,
    pub(crate) grid: Grid,
}

impl<T> std::ops::Deref for Surface<T> {
    type Target = SurfaceParts<T>;
    fn deref(&self) -> &SurfaceParts<T> {
        &self.parts
    }
}

impl<T: Real> Surface<T> {
    /// The parts ([`SurfaceParts::build`]) and the grid over them; "grid" is the last lap.
    pub fn build(
        points: &[[f64; 3]],
        normals: Option<&[[f64; 3]]>,
        params: &SurfaceParams,
    ) -> Result<Surface<T>, SurfaceError> {
        let (parts, mut laps) = SurfaceParts::build(points, normals, params)?;
        let start = std::time::Instant::now();
        let mut surface = Surface::from_parts(parts)?;
        laps.push(("grid", start.elapsed().as_secs_f64()));
        surface.build_seconds = laps;
        Ok(surface)
    }
}

impl<T: Real> SurfaceParts<T> {
    /// Everything a cache stores, from particles: kNN and radii, orientation, neighbour
    /// lists, initial fits and droplets, with the seconds each stage took.
    #[allow(clippy::type_complexity)]
    pub fn build(
        points: &[[f64; 3]],
        normals: Option<&[[f64; 3]]>,
        params: &SurfaceParams,
    ) -> Result<(SurfaceParts<T>, Vec<(&'static str, f64)>), SurfaceError> {
        Self::build_with(points, normals, params, &KdSearch, None, |_| {})
    }

    /// [`SurfaceParts::build`], running `beside` on the points, radii and spray as soon as
    /// the droplets are found, at the same time as the initial fits: work that needs those but
    /// not the fits (a bake's BVH) takes the cores the fits leave idle instead of waiting for
    /// them. The neighbours are found by `search`; with `near_reach_band`, it may keep only
    /// the cluster unions and each list's members within that of its reach
    /// (`ListRequest::near_reach_band`): parts for a cache, not for tracing.
    #[allow(clippy::type_complexity)]
    pub fn build_with(
        points: &[[f64; 3]],
        normals: Option<&[[f64; 3]]>,
        params: &SurfaceParams,
        search: &dyn NeighbourSearch,
        near_reach_band: Option<f64>,
        beside: impl FnOnce(BesideFits<'_, T>) + Send,
    ) -> Result<(SurfaceParts<T>, Vec<(&'static str, f64)>), SurfaceError> {
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
        let mut clock = StageClock::start();
        // The kNN stage by part, after it.
        let mut knn_parts = StageClock::start();
        // Per-point maps run in parallel throughout: at 1M points a serial one is milliseconds
        // that every other thread waits for.
        let (rel, origin) = recentred(points);
        let mut unit_normals: Option<Vec<Option<[f64; 3]>>> =
            normals.map(|ns| ns.par_iter().map(|n| unit(*n)).collect());

        knn_parts.lap("kd-tree and radii (kNN): points");
        let index = search.index(&rel)?;
        knn_parts.lap("kd-tree and radii (kNN): index");
        let k = params.k.min(n - 1);
        // One query serves the radii (the k-th) and, with normals, the orientation check.
        let orient_with = if unit_normals.is_some() {
            ORIENT_NEIGHBOURS.min(n - 1)
        } else {
            0
        };
        let k_query = NonZero::new(k.max(orient_with) + 1).ok_or(SurfaceError::BadK)?;
        let nearest_ids = index.nearest(k_query)?;
        knn_parts.lap("kd-tree and radii (kNN): nearest");
        // Distances in f64 whichever search found the points; each array made by its own pass
        // over the ids, where one array of every point's (radius, nearest, around, second)
        // made fresh memory that at 4M points cost more than the passes.
        let neighbours_of = |i: usize| &nearest_ids[i * k_query.get()..][..k_query.get()];
        let dist =
            |i: usize, slot: usize| distance2(rel[i], rel[neighbours_of(i)[slot] as usize]).sqrt();
        let (mut radii, nearest): (Vec<f64>, Vec<f64>) = (0..n)
            .into_par_iter()
            .map(|i| (dist(i, k), dist(i, 1)))
            .unzip();
        // h is sized by the median radius: where that is 0, more than half the points have
        // their k nearest at their own position (piles deeper than k: a particle written
        // eight times), and h and every ball would be the floor of a half float, the whole
        // step spray. Refused, as piles alone are, rather than baked so.
        // (A count: the median is 0 where more radii than its rank are, none being below.)
        let piled = radii.par_iter().filter(|&&r| r == 0.0).count();
        if piled > quantile_rank(n, H_QUANTILE) {
            return Err(SurfaceError::Piles {
                piled,
                points: n,
                positions: distinct_positions(&rel),
                nearest: k,
            });
        }
        let spacing = nearest.iter().sum::<f64>() / n as f64;
        knn_parts.lap("kd-tree and radii (kNN): radii");
        clock.lap("kd-tree and radii (kNN)");
        clock.extend(&knn_parts.laps);
        let mut orientation_parts = StageClock::start();
        let orientation = match unit_normals.as_mut() {
            Some(ns) => {
                let nearest = NearestIds::new(&nearest_ids, k_query.get(), orient_with);
                let votes = index.orientation_votes(nearest, ns)?;
                if votes.is_some() {
                    orientation_parts.lap(ORIENTATION_VOTES_CAST_BY_THE_SEARCH);
                }
                repair_orientation(&rel, ns, nearest, votes.as_deref())
            }
            None => OrientationRepair::default(),
        };
        clock.lap("orientation");
        clock.extend(&orientation_parts.laps);
        let reaches_start = std::time::Instant::now();
        let mean = radii.iter().sum::<f64>() / n as f64;
        // Coincident points give ρ = 0: keep every ball a tenth of the mean radius at least.
        let floor = 0.1 * mean;
        for r in &mut radii {
            *r = r.max(floor);
        }
        // h from the dense fluid, not the spray: the median radius, which sparse points
        // (large radii) cannot inflate while they are fewer than half.
        let median_radius = quantile(&radii, H_QUANTILE);
        let h = half_precision(params.h_scale * median_radius);
        // Where most particles have a twin at their place (a pile, or particles written
        // twice), the median nearest distance is 0, and every ball and spray sphere sized by
        // it would be too: the spacing is then the median of each point's distance to its
        // nearest at another place (of the distances that are not 0 alone, a step whose every
        // particle was written twice had none, and was refused as piles). More than half
        // the points have one (their k-th nearest, whose median is not 0, is apart).
        // Where most have a twin a little apart (written twice, then moved by noise), that
        // median is a fraction of the spacing, while the second nearest distance is not:
        // below half the median second nearest distance, the spacing is that. Each point's
        // second nearest lies within its radius (the k-th, k ≥ 2), so where the median
        // nearest reaches half the median radius (almost every step) that median is not
        // computed.
        let dense_spacing = match quantile(&nearest, H_QUANTILE) {
            s if s > 0.0 && (k < 2 || s < 0.5 * median_radius) => {
                let second: Vec<f64> = (0..n)
                    .into_par_iter()
                    .map(|i| {
                        if k_query.get() > 2 {
                            dist(i, 2)
                        } else {
                            f64::NAN
                        }
                    })
                    .collect();
                match quantile(&second, H_QUANTILE) {
                    s2 if s < 0.5 * s2 => s2,
                    _ => s,
                }
            }
            s if s > 0.0 => s,
            _ => {
                // Each point's nearest at another place: the first of its nearest not at its
                // own (a twin's distance is 0, its neighbours' are not).
                let apart: Vec<f64> = (0..n)
                    .into_par_iter()
                    .filter_map(|i| (1..k_query.get()).map(|s| dist(i, s)).find(|&d| d > 0.0))
                    .collect();
                quantile(&apart, H_QUANTILE)
            }
        };
        // A ball is trusted no farther than its data reach: beyond 2h a fit has no weight;
        // and no farther than two dense spacings, since every hit lies in its ball: a sparse
        // point's fit would otherwise stretch a fin out to 2h (3 spacings) from any particle.
        if !params.per_point_h {
            let trust = (2.0 * h).min(MAX_BALL_SPACINGS * dense_spacing);
            for r in &mut radii {
                *r = r.min(trust);
            }
        }
        let ball_h = |i: usize| {
            if params.per_point_h {
                half_precision(params.h_scale * radii[i])
            } else {
                h
            }
        };
        let cap = NonZero::new(params.neighbour_cap.max(1)).ok_or(SurfaceError::BadK)?;

        let reach_wanted: Vec<f64> = (0..n)
            .into_par_iter()
            .map(|i| radii[i] + params.support * ball_h(i))
            .collect();
        // h and each list's reach, from the radii.
        let reaches_seconds = reaches_start.elapsed().as_secs_f64();
        let NeighbourLists {
            lists: neighbours,
            reach,
            capped,
            run_unions,
            links,
            components,
            fits: searched_fits,
            fit_seconds: searched_fit_seconds,
            parts: list_parts,
        } = index.lists(ListRequest {
            reach: &reach_wanted,
            cap: cap.get(),
            normals: unit_normals.as_deref(),
            // The links that join spray into components, found with the lists.
            link_distance2: (params.droplet_below > 1).then_some(&|i: usize| ball_h(i).powi(2)),
            // Fitted beside the lists where the search can (the GPU's), else below.
            fits: Some(FitRequest {
                h: &ball_h,
                degree: params.degree,
                normals: params.normals,
            }),
            near_reach_band,
        })?;
        drop(index);
        // The fits from every list, where the search made none.
        let lists_to_fit = match (&searched_fits, neighbours.whole()) {
            (Some(_), _) => None,
            (None, Some(lists)) => Some(lists),
            (None, None) => {
                return Err(SurfaceError::Index(
                    "the search kept neither every neighbour list nor the initial fits".into(),
                ));
            }
        };
        clock.lap("neighbour lists");
        // Fits made beside the lists count as fits.
        if let Some(lap) = clock.laps.last_mut() {
            lap.1 = (lap.1 - searched_fit_seconds).max(0.0);
        }
        // The search's parts of it, after it (their sum is within the lap and the fits).
        clock.extend(&[("neighbour lists: reaches", reaches_seconds)]);
        // The fits' parts go after the fits' own lap.
        let (fit_parts, list_parts): (Vec<_>, Vec<_>) = list_parts
            .into_iter()
            .partition(|(name, _)| stage_part(name).is_some_and(|(s, _)| s == "initial fits"));
        clock.extend(&list_parts);

        // Spray first, from the lists alone and on every core: the fits do not need it, but the
        // work beside them does, and beside the fits it would get too few cores to keep up.
        let droplets_start = std::time::Instant::now();
        let (spheres, droplet_of) = droplets::<T>(
            &rel,
            &links,
            components,
            &ball_h,
            &nearest,
            dense_spacing,
            params.droplet_below,
        );
        let droplets_seconds = droplets_start.elapsed().as_secs_f64();
        let to_t = |p: [f64; 3]| V3::<T>::from_f64(p);
        let fits_start = std::time::Instant::now();
        let pts: Vec<V3<T>> = rel.par_iter().map(|p| to_t(*p)).collect();
        // Unusable normals (NaN, zero) become zero vectors, which every consumer ignores.
        let nrm: Option<Vec<V3<T>>> = unit_normals
            .as_ref()
            .map(|ns| ns.par_iter().map(|n| n.map_or(V3::zero(), to_t)).collect());
        let h_t = T::c(h);
        let fit_params = Params {
            degree: params.degree,
            iterations: 1,
            epsilon: T::c(1e-4),
            normals: params.normals,
            h_factor: T::one(),
        };
        // The balls and their fits, and where the search fitted, the seconds its fits took
        // to become balls (a part of the fits' lap).
        let initial_fits = || -> (Vec<Ball<T>>, Vec<BallFit>, Option<f64>) {
            let ball = |i: usize, normal, poly| Ball {
                centre: pts[i],
                radius: T::c(radii[i]),
                h: T::c(ball_h(i)),
                normal,
                poly,
            };
            let unfitted = |i: usize| {
                (
                    ball(i, V3::new(T::zero(), T::zero(), T::one()), Poly::zero(0)),
                    BallFit::None,
                )
            };
            if let Some(fits) = &searched_fits {
                // The search's fits (in f32), as the balls hold them.
                let converting = std::time::Instant::now();
                let (balls, fits): (Vec<Ball<T>>, Vec<BallFit>) = (0..n)
                    .into_par_iter()
                    .map(|i| match fits[i] {
                        Some(f) => {
                            let [x, y, z] = f.normal.map(|c| T::c(f64::from(c)));
                            let poly = Poly {
                                degree: f.poly.degree,
                                c: f.poly.c.map(|c| T::c(f64::from(c))),
                            };
                            let status = if f.degraded {
                                FitStatus::Degraded {
                                    requested: params.degree,
                                    used: f.poly.degree,
                                }
                            } else {
                                FitStatus::Full
                            };
                            (ball(i, V3::new(x, y, z), poly), BallFit::Fitted(status))
                        }
                        None => unfitted(i),
                    })
                    .unzip();
                return (balls, fits, Some(converting.elapsed().as_secs_f64()));
            }
            // Each normal normalised once here, not once for every list it is in.
            let unit_nrm: Option<Vec<V3<T>>> = nrm.as_ref().map(|ns| {
                ns.par_iter()
                    .map(|n| n.normalized().unwrap_or(V3::zero()))
                    .collect()
            });
            let (balls, fits): (Vec<Ball<T>>, Vec<BallFit>) = (0..n)
                .into_par_iter()
                .map_init(
                    || (Vec::new(), Vec::new(), Vec::new()),
                    |(np, nn, weights), i| {
                        let list = lists_to_fit.map_or(&[][..], |lists| lists.of(i));
                        gather(&pts, unit_nrm.as_deref(), list, np, nn);
                        let centre = pts[i];
                        // Without data normals the plane faces away from the set's centre.
                        let toward = centre * T::c(2.0);
                        let hi = T::c(ball_h(i));
                        match initial_fit_with(
                            centre,
                            np,
                            unit_nrm.as_ref().map(|_| DataNormals::Unit(nn.as_slice())),
                            hi,
                            &fit_params,
                            toward,
                            weights,
                        ) {
                            Some((normal, f)) => {
                                (ball(i, normal, f.poly), BallFit::Fitted(f.status))
                            }
                            None => unfitted(i),
                        }
                    },
                )
                .unzip();
            (balls, fits, None)
        };
        // The fits, and beside them the caller's work on the spray (a bake's BVH): obvhs leaves
        // cores idle that the fits take.
        let ((balls, mut ball_fits, balls_seconds, fits_seconds), ()) = rayon::join(
            || {
                // From before the conversions above, which only the fits wait for.
                let (balls, fits, balls_seconds) = initial_fits();
                (
                    balls,
                    fits,
                    balls_seconds,
                    fits_start.elapsed().as_secs_f64() + searched_fit_seconds,
                )
            },
            || {
                beside(BesideFits {
                    points: &rel,
                    radii: &radii,
                    droplet_of: &droplet_of,
                    spheres: &spheres,
                })
            },
        );
        for &(i, d) in &droplet_of {
            ball_fits[i as usize] = BallFit::Droplet(d);
        }
        clock.extend(&[("initial fits", fits_seconds)]);
        clock.extend(&fit_parts);
        if let Some(seconds) = balls_seconds {
            clock.extend(&[("initial fits: balls", seconds)]);
        }
        clock.extend(&[("droplets", droplets_seconds)]);
        let parts = SurfaceParts {
            origin,
            points: pts,
            normals: nrm,
            radii: radii.par_iter().map(|&r| T::c(r)).collect(),
            h: h_t,
            spacing: T::c(spacing),
            offset: T::c(params.offset * 0.5 * dense_spacing),
            neighbours,
            reach: reach.par_iter().map(|&r| T::c(r)).collect(),
            capped,
            run_unions,
            balls,
            ball_fits,
            spheres,
            orientation,
            params: params.clone(),
        };
        Ok((parts, clock.laps))
    }

    pub fn len(&self) -> usize {
        self.points.len()
    }

    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// The parts of a step without particles (a Lagrangian run before its first injection):
    /// nothing to fit, nothing to hit.
    pub fn empty(params: &SurfaceParams) -> SurfaceParts<T> {
        SurfaceParts {
            origin: [0.0; 3],
            points: Vec::new(),
            normals: None,
            radii: Vec::new(),
            h: T::c(0.0),
            spacing: T::c(0.0),
            offset: T::c(0.0),
            neighbours: KeptLists::Whole(
                Neighbours::from_csr(vec![0], Vec::new())
                    .unwrap_or_else(|| unreachable!("one offset of 0 over no ids is a CSR index")),
            ),
            reach: Vec::new(),
            capped: 0,
            run_unions: None,
            balls: Vec::new(),
            ball_fits: Vec::new(),
            spheres: Vec::new(),
            orientation: OrientationRepair::default(),
            params: params.clone(),
        }
    }

    /// Point i's neighbour list; empty where the build kept only the members near each
    /// list's reach (a bake's parts, which no [`Surface`] is made from: `from_parts` refuses
    /// them).
    pub fn neighbours_of(&self, i: usize) -> &[u32] {
        self.neighbours.whole().map_or(&[], |lists| lists.of(i))
    }

    /// The union of the lists of each cluster of `size` consecutive points (CSR): the runs'
    /// unions themselves where the build kept them for runs of `size` (the GPU's, for the
    /// bake's clusters), merged from them where `size` is a multiple of their run, else from
    /// every point's list; an error where there are neither (parts that kept only the members
    /// near each list's reach, but unions of other runs).
    #[allow(clippy::type_complexity)]
    pub fn cluster_lists(
        &self,
        size: usize,
    ) -> Result<(Cow<'_, [u32]>, Cow<'_, [u32]>), SurfaceError> {
        let whole = self.run_unions.as_ref().filter(|u| u.run() == size);
        if let Some((start, ids)) = whole.and_then(RunUnions::as_one) {
            return Ok((Cow::Borrowed(start), Cow::Borrowed(ids)));
        }
        let (start, ids) = match (&self.run_unions, self.neighbours.whole()) {
            (Some(unions), _) if size > 0 && size.is_multiple_of(unions.run()) => {
                crate::clusters::cluster_lists_from_runs(unions, size)
            }
            (_, Some(lists)) => crate::clusters::cluster_lists(lists, size),
            (_, None) => {
                return Err(SurfaceError::Parts(format!(
                    "clusters of {size} asked of parts with neither their lists nor unions \
                     of runs that divide {size}"
                )));
            }
        };
        Ok((Cow::Owned(start), Cow::Owned(ids)))
    }
}

impl<T: Real> Surface<T> {
    /// A surface from stored parts (a cache); checks that they fit together and builds the grid.
    pub fn from_parts(parts: SurfaceParts<T>) -> Result<Surface<T>, SurfaceError> {
        let n = parts.points.len();
        let bad = |what: String| Err(SurfaceError::Parts(what));
        if parts.radii.len() != n || parts.balls.len() != n || parts.ball_fits.len() != n {
            return bad(format!(
                "{n} points but {} radii, {} balls, {} fit states",
                parts.radii.len(),
                parts.balls.len(),
                parts.ball_fits.len()
            ));
        }
        if parts.normals.as_ref().is_some_and(|v| v.len() != n) {
            return bad("normals and points differ in count".into());
        }
        if parts.reach.len() != n {
            return bad(format!("{n} points but {} reaches", parts.reach.len()));
        }
        let Some(lists) = parts.neighbours.whole() else {
            return bad("the parts kept only each list's members near its reach".into());
        };
        if lists.len() != n {
            return bad(format!("{n} points but {} neighbour lists", lists.len()));
        }
        if lists.ids().any(|j| j as usize >= n) {
            return bad("a neighbour index is out of range".into());
        }
        if parts
            .ball_fits
            .iter()
            .any(|f| matches!(f, BallFit::Droplet(d) if *d as usize >= parts.spheres.len()))
        {
            return bad("a droplet index is out of range".into());
        }
        let centres: Vec<[f64; 3]> = parts
            .points
            .iter()
            .map(|p| p.to_f64())
            .chain(parts.spheres.iter().map(|s| s.centre.to_f64()))
            .collect();
        let radii: Vec<f64> = parts
            .radii
            .iter()
            .chain(parts.spheres.iter().map(|s| &s.radius))
            .map(|&r| Real::to_f64(r))
            .collect();
        let mean = parts.radii.iter().map(|&r| Real::to_f64(r)).sum::<f64>() / n.max(1) as f64;
        let grid = Grid::build(&centres, &radii, mean);
        Ok(Surface {
            parts,
            build_seconds: Vec::new(),
            grid,
        })
    }

    /// The stored parts, without the grid.
    pub fn into_parts(self) -> SurfaceParts<T> {
        self.parts
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

/// The orientation stage's part where the index cast the first votes itself
/// (`PointIndex::orientation_votes`): gathering the neighbours and casting them.
pub const ORIENTATION_VOTES_CAST_BY_THE_SEARCH: &str = "orientation: votes cast by the search";

/// `h` at half-float precision: the nearest normal half float (2⁻¹⁴ to 65504), so that a
/// cache stores every smoothing length exactly as a half float (format 8; format 9: the
/// header's one h, or half a word per ball where h is per point) and the fits
/// use what it stores. A relative change of at most 2⁻¹¹ to a smoothing length.
pub fn half_precision(h: f64) -> f64 {
    let nearest = half::f16::from_f64(h).clamp(half::f16::MIN_POSITIVE, half::f16::MAX);
    f64::from(nearest.to_f32())
}

/// The quantile of the radii that sets h, and of the nearest distances that sets the spray's
/// particle size: the median. A lower one (0.25 was tried) resists more spray but makes cubic
/// fits on noisy data ill-conditioned in f32 (`docs/accuracy.md`, f32 against f64).
const H_QUANTILE: f64 = 0.5;

/// The largest ball radius with a global h, in dense spacings (median nearest-neighbour
/// distances): no hit lies farther than this from its ball's particle.
pub const MAX_BALL_SPACINGS: f64 = 2.0;

/// How many distinct positions `points` hold (exactly equal coordinates are one; + 0.0 makes
/// −0 and +0 one).
fn distinct_positions(points: &[[f64; 3]]) -> usize {
    let mut bits: Vec<[u64; 3]> = points
        .par_iter()
        .map(|p| p.map(|c| (c + 0.0).to_bits()))
        .collect();
    bits.par_sort_unstable();
    bits.dedup();
    bits.len()
}

/// The rank (from 0) of the `q` quantile of `n` values ([`quantile`]); `n` at least 1.
fn quantile_rank(n: usize, q: f64) -> usize {
    ((q * n as f64) as usize).min(n - 1)
}

/// The `q` quantile of `values`: the ⌊q·n⌋-th smallest, counting from 0 (for the median of
/// an even count, the upper of the two middle values); 0 for none. The bake's rule for h
/// (docs/algorithm.md), not a statistic of measurements (`slosh_bench::stats`).
///
/// In parallel: a histogram of the values' top 16 bits in `f64::total_cmp`'s order finds the
/// bucket the rank falls in, and only that bucket's values are selected from (a copy and a
/// selection of a million values on one thread took milliseconds of every step).
fn quantile(values: &[f64], q: f64) -> f64 {
    const BUCKET_BITS: u32 = 16;
    if values.is_empty() {
        return 0.0;
    }
    let k = quantile_rank(values.len(), q);
    // The bits `f64::total_cmp` compares, as an unsigned key in the same order.
    let key = |v: f64| {
        let bits = v.to_bits() as i64;
        ((bits ^ (((bits >> 63) as u64) >> 1) as i64) as u64) ^ (1 << 63)
    };
    let bucket = |v: f64| (key(v) >> (64 - BUCKET_BITS)) as usize;
    let counts = values
        .par_chunks(1 << 16)
        .map(|chunk| {
            let mut counts = vec![0u32; 1 << BUCKET_BITS];
            for &v in chunk {
                counts[bucket(v)] += 1;
            }
            counts
        })
        .reduce(
            || vec![0u32; 1 << BUCKET_BITS],
            |mut a, b| {
                a.iter_mut().zip(&b).for_each(|(x, y)| *x += y);
                a
            },
        );
    let (mut below, mut b) = (0usize, 0usize);
    while below + counts[b] as usize <= k {
        below += counts[b] as usize;
        b += 1;
    }
    let mut within: Vec<f64> = values
        .par_iter()
        .copied()
        .filter(|&v| bucket(v) == b)
        .collect();
    *within.select_nth_unstable_by(k - below, f64::total_cmp).1
}

#[cfg(test)]
mod tests {
    use super::quantile;

    /// The histogram's narrowing finds the value a selection over all finds, by
    /// `f64::total_cmp` (−0 below +0, NaN at the ends): spread, clustered within one bucket,
    /// signed, duplicated, and single values.
    #[test]
    fn quantiles_are_the_selections_over_all_values() {
        let mut next = slosh_testkit::uniform(5);
        let spread: Vec<f64> = (0..200_000).map(|_| 1e-3 * (1.0 + next())).collect();
        let clustered: Vec<f64> = (0..100_000).map(|_| 0.5 + 1e-12 * next()).collect();
        let mut signed: Vec<f64> = (0..50_000).map(|_| next() - 0.5).collect();
        signed.extend([0.0, -0.0, f64::NAN, -f64::NAN, f64::INFINITY, 0.0, -0.0]);
        let duplicated: Vec<f64> = (0..30_000).map(|i| f64::from(i % 7)).collect();
        for values in [
            spread,
            clustered,
            signed,
            duplicated,
            vec![3.0],
            vec![2.0, 1.0],
        ] {
            for q in [0.0, 0.25, 0.5, 0.75, 0.999, 1.0] {
                let mut sorted = values.clone();
                sorted.sort_by(f64::total_cmp);
                let k = ((q * values.len() as f64) as usize).min(values.len() - 1);
                assert_eq!(
                    quantile(&values, q).to_bits(),
                    sorted[k].to_bits(),
                    "{} values, q {q}",
                    values.len()
                );
            }
        }
        assert_eq!(quantile(&[], 0.5), 0.0);
    }
}
