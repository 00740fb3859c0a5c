//! Iterative ray–MLS surface intersection (Adamson & Alexa 2003; thesis §2.2, §3.3.3) from a
//! ball's precomputed initial polynomial.

use crate::fit::{Fit, FitStatus, fit, fit_weighted};
use crate::frame::LocalFrame;
use crate::poly::Poly;
use crate::real::{Real, V3};
use crate::roots::first_root_in;
use crate::support::{DataNormals, NormalsMode, support_normal, support_weighted, weight};

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray<T> {
    pub origin: V3<T>,
    /// Unit direction.
    pub dir: V3<T>,
}

/// A region-of-trust ball with its initial support normal and polynomial (fitted at the
/// centre, in coordinates scaled by 1/h).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ball<T> {
    pub centre: V3<T>,
    pub radius: T,
    /// Smoothing length used inside this ball: the global h, or c·ρ_i for uneven sampling.
    pub h: T,
    pub normal: V3<T>,
    pub poly: Poly<T>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Params<T> {
    /// Requested polynomial degree (1–3); lower where the data cannot support it.
    pub degree: u8,
    /// Total iterations including the initial polynomial: 1 = the precomputed polynomial only.
    pub iterations: u32,
    /// Converged when successive hits differ by less than `epsilon` · h along the ray.
    pub epsilon: T,
    pub normals: NormalsMode,
    /// Multiplies each ball's baked smoothing length during refinement (1 = as fitted).
    pub h_factor: T,
}

impl<T: Real> Default for Params<T> {
    fn default() -> Self {
        Self::new()
    }
}

impl<T: Real> Params<T> {
    pub fn new() -> Self {
        Params {
            degree: 2,
            iterations: 3,
            epsilon: T::c(1e-4),
            normals: NormalsMode::Mean,
            h_factor: T::one(),
        }
    }
}

/// How an intersection attempt ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HitStatus {
    /// |Δt| < ε·h.
    Converged,
    /// Hit from the last allowed iteration (always so for iterations = 1).
    IterationLimit,
    /// No point had weight at an iterate; the previous iterate is the hit.
    NoSupport,
    /// The fit at an iterate failed (no weight at all); the previous iterate is the hit.
    DegenerateFit,
    /// A refined polynomial has no root inside the ball: this candidate ends without a hit.
    LeftTrustRegion,
    /// The initial polynomial has no root inside the ball: no hit.
    NoInitialRoot,
    /// The ray does not pass through the ball.
    MissedBall,
    /// A droplet sphere was hit (no MLS patch).
    Droplet,
}

impl HitStatus {
    pub fn is_hit(self) -> bool {
        matches!(
            self,
            HitStatus::Converged
                | HitStatus::IterationLimit
                | HitStatus::NoSupport
                | HitStatus::DegenerateFit
                | HitStatus::Droplet
        )
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BallHit<T> {
    pub status: HitStatus,
    /// Ray parameter, position and unit normal of the hit (meaningful when `status.is_hit()`).
    pub t: T,
    pub position: V3<T>,
    pub normal: V3<T>,
    /// Iterations used, counting the initial polynomial.
    pub iterations: u32,
    /// Degree of the polynomial that produced the hit.
    pub degree: u8,
    /// True when any fit on the way was degraded below the requested degree.
    pub degraded: bool,
}

impl<T: Real> BallHit<T> {
    /// No hit, for `status`.
    pub fn miss(status: HitStatus) -> BallHit<T> {
        BallHit {
            status,
            t: T::zero(),
            position: V3::zero(),
            normal: V3::zero(),
            iterations: 0,
            degree: 0,
            degraded: false,
        }
    }
}

/// Entry and exit parameters of the ray through a ball (t_in may be negative when the origin
/// is inside).
pub fn ray_ball<T: Real>(ray: &Ray<T>, centre: V3<T>, radius: T) -> Option<(T, T)> {
    let oc = centre - ray.origin;
    let tc = oc.dot(ray.dir);
    // Distance² of the centre from the ray, computed without cancellation against |oc|².
    let perp = oc - ray.dir * tc;
    let d2 = perp.length_squared();
    let r2 = radius * radius;
    if !(d2 <= r2) {
        return None;
    }
    let half = (r2 - d2).sqrt();
    Some((tc - half, tc + half))
}

/// Where the ray meets `poly` (set at reference point `r` in `frame`) raised by `offset`
/// along the frame's normal, for t in [t_lo, t_hi]: the first such t and the local (scaled)
/// coordinates there.
#[allow(clippy::too_many_arguments)]
fn intersect_poly<T: Real>(
    ray: &Ray<T>,
    r: V3<T>,
    frame: &LocalFrame<T>,
    poly: &Poly<T>,
    h: T,
    offset: T,
    t_lo: T,
    t_hi: T,
) -> Option<(T, T, T)> {
    // Shift the origin to the ray point nearest r (eq. 3.3) so the local problem is O(1).
    let rel = ray.origin - r;
    let t0 = (-rel.dot(ray.dir)).max(t_lo).min(t_hi);
    let inv_h = T::one() / h;
    let q0 = frame.to_local(rel + ray.dir * t0) * inv_h;
    let dl = frame.to_local(ray.dir);
    let mut c = poly.along_line(q0.x, q0.y, dl.x, dl.y);
    c[0] = c[0] + offset * inv_h - q0.z;
    c[1] = c[1] - dl.z;
    let s = first_root_in(c, (t_lo - t0) * inv_h, (t_hi - t0) * inv_h)?;
    Some((t0 + s * h, q0.x + s * dl.x, q0.y + s * dl.y))
}

fn hit_normal<T: Real>(frame: &LocalFrame<T>, poly: &Poly<T>, x: T, y: T) -> V3<T> {
    let (fx, fy) = poly.gradient(x, y);
    (frame.n - frame.u * fx - frame.v * fy)
        .normalized()
        .unwrap_or(frame.n)
}

/// The initial support normal and polynomial of a ball centred at `centre`.
pub fn initial_fit<T: Real>(
    centre: V3<T>,
    neighbours: &[V3<T>],
    normals: Option<&[V3<T>]>,
    h: T,
    params: &Params<T>,
    toward: V3<T>,
) -> Option<(V3<T>, Fit<T>)> {
    initial_fit_with(
        centre,
        neighbours,
        normals.map(DataNormals::Raw),
        h,
        params,
        toward,
        &mut Vec::new(),
    )
}

/// [`initial_fit`] with the normals as the caller has them and a buffer for the weights, for
/// a build that fits every point.
pub(crate) fn initial_fit_with<T: Real>(
    centre: V3<T>,
    neighbours: &[V3<T>],
    normals: Option<DataNormals<'_, T>>,
    h: T,
    params: &Params<T>,
    toward: V3<T>,
    weights: &mut Vec<T>,
) -> Option<(V3<T>, Fit<T>)> {
    // The support plane and the fit weigh the same points from the same centre: once.
    let h2 = h * h;
    weights.clear();
    weights.extend(
        neighbours
            .iter()
            .map(|&p| weight((p - centre).length_squared(), h2)),
    );
    let weights = weights.as_slice();
    let weight_of = |j: usize, _| weights[j];
    let support = support_weighted(
        centre,
        neighbours,
        normals,
        h,
        params.normals,
        toward,
        weight_of,
    )?;
    let frame = LocalFrame::from_normal(support.normal);
    let f = fit_weighted(centre, &frame, neighbours, h, params.degree, weight_of);
    (f.status != FitStatus::Failed).then_some((support.normal, f))
}

/// Where the ray first meets a ball's initial polynomial inside the ball: iteration 1 of
/// `intersect_ball`, and the key candidates are ordered by.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InitialHit<T> {
    pub t: T,
    /// The ray's interval inside the ball, t_lo ≥ 0: every refined hit must lie in it.
    pub t_lo: T,
    pub t_out: T,
    pub normal: V3<T>,
}

/// Iteration 1: the ball's initial polynomial, raised by the surface's `offset`, against the
/// ray inside the ball, or why not (`MissedBall`, `NoInitialRoot`).
pub fn initial_hit<T: Real>(
    ray: &Ray<T>,
    ball: &Ball<T>,
    offset: T,
) -> Result<InitialHit<T>, HitStatus> {
    let (t_in, t_out) = ray_ball(ray, ball.centre, ball.radius).ok_or(HitStatus::MissedBall)?;
    let t_lo = t_in.max(T::zero());
    if t_lo > t_out {
        return Err(HitStatus::MissedBall);
    }
    let frame = LocalFrame::from_normal(ball.normal);
    let (t, x, y) = intersect_poly(
        ray,
        ball.centre,
        &frame,
        &ball.poly,
        ball.h,
        offset,
        t_lo,
        t_out,
    )
    .ok_or(HitStatus::NoInitialRoot)?;
    Ok(InitialHit {
        t,
        t_lo,
        t_out,
        normal: hit_normal(&frame, &ball.poly, x, y),
    })
}

/// Intersects the ray with the MLS surface raised by `offset` inside `ball`, refining with
/// the ball centre's `neighbours` (and their `normals`, if any).
pub fn intersect_ball<T: Real>(
    ray: &Ray<T>,
    ball: &Ball<T>,
    offset: T,
    neighbours: &[V3<T>],
    normals: Option<&[V3<T>]>,
    params: &Params<T>,
) -> BallHit<T> {
    match initial_hit(ray, ball, offset) {
        Ok(initial) => refine(ray, ball, offset, &initial, neighbours, normals, params),
        Err(status) => BallHit::miss(status),
    }
}

/// Iterations 2 and on from a ball's initial hit, with the ball centre's `neighbours`: each
/// fit at the latest hit, raised by `offset`.
pub fn refine<T: Real>(
    ray: &Ray<T>,
    ball: &Ball<T>,
    offset: T,
    initial: &InitialHit<T>,
    neighbours: &[V3<T>],
    normals: Option<&[V3<T>]>,
    params: &Params<T>,
) -> BallHit<T> {
    let (t_lo, t_out) = (initial.t_lo, initial.t_out);
    let mut t = initial.t;
    let mut normal = initial.normal;
    let mut degree = ball.poly.degree;
    let mut degraded = ball.poly.degree < params.degree;
    let mut iterations = 1;
    let mut status = HitStatus::IterationLimit;
    // Refinement may use a different smoothing length than the baked initial fit.
    let h = ball.h * params.h_factor;
    while iterations < params.iterations.max(1) {
        let r = ray.origin + ray.dir * t;
        let Some(support) = support_normal(r, neighbours, normals, h, params.normals, ray.origin)
        else {
            status = HitStatus::NoSupport;
            break;
        };
        let frame = LocalFrame::from_normal(support.normal);
        let f = fit(r, &frame, neighbours, h, params.degree);
        if f.status == FitStatus::Failed {
            status = HitStatus::DegenerateFit;
            break;
        }
        degraded |= matches!(f.status, FitStatus::Degraded { .. });
        let Some((t_next, x, y)) = intersect_poly(ray, r, &frame, &f.poly, h, offset, t_lo, t_out)
        else {
            return BallHit {
                iterations: iterations + 1,
                degree: f.poly.degree,
                degraded,
                ..BallHit::miss(HitStatus::LeftTrustRegion)
            };
        };
        iterations += 1;
        let dt = (t_next - t).abs();
        t = t_next;
        normal = hit_normal(&frame, &f.poly, x, y);
        degree = f.poly.degree;
        if dt < params.epsilon * h {
            status = HitStatus::Converged;
            break;
        }
    }
    BallHit {
        status,
        t,
        position: ray.origin + ray.dir * t,
        normal,
        iterations,
        degree,
        degraded,
    }
}
