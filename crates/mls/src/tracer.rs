//! The CPU reference tracer: camera rays, candidate balls front to back through an index
//! (the surface's grid or a cache's BVH), first accepted hit. rayon-parallel over image rows.

use rayon::prelude::*;

use crate::grid::BallIndex;
use crate::intersect::{HitStatus, InitialHit, Params, Ray, initial_hit, ray_ball, refine};
use crate::real::{Real, V3};
use crate::surface::{BallFit, Surface, gather};

/// Candidates refined per ray before it counts as a miss: each one that leaves its ball hands
/// over to the next initial hit, and a grazing ray could otherwise try hundreds.
pub const MAX_CANDIDATES: u32 = 16;

/// An initial hit, ordered by the key (t, item): nearer first, an exact tie to the lower
/// item, so the result does not depend on the order an index visits items in.
struct Candidate<T> {
    t: T,
    item: u32,
    kind: CandidateKind<T>,
}

enum CandidateKind<T> {
    Ball(InitialHit<T>),
    Droplet { normal: V3<T> },
}

/// A pinhole camera.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    pub eye: [f64; 3],
    pub target: [f64; 3],
    pub up: [f64; 3],
    /// Vertical field of view in degrees.
    pub fov_y: f64,
    pub width: u32,
    pub height: u32,
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn normalize(a: [f64; 3]) -> [f64; 3] {
    let l = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
    if l > 0.0 {
        [a[0] / l, a[1] / l, a[2] / l]
    } else {
        [0.0, 0.0, 1.0]
    }
}

/// A camera's ray basis: the ray through image-plane point (sx, sy) ∈ [−1, 1]² has direction
/// normalize(forward + sx · right + sy · up).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraBasis {
    pub forward: [f64; 3],
    /// Unit right × tan(fov/2) × aspect.
    pub right: [f64; 3],
    /// Unit up × tan(fov/2).
    pub up: [f64; 3],
}

/// How much room a framing leaves around what it frames: it fills 1 / this of the frame.
const FRAMING_MARGIN: f64 = 1.1;

impl Camera {
    /// A camera looking at the centre of `bounds` from the front-left and above, framing
    /// them, with `up` (a unit axis, e.g. `[0, 0, 1]`) up: the view direction is fixed in the
    /// frame of `up`, so y-up and z-up data are seen alike.
    pub fn framing(
        bounds: &[[f64; 3]; 2],
        fov_y: f64,
        width: u32,
        height: u32,
        up: [f64; 3],
    ) -> Camera {
        let centre: [f64; 3] = std::array::from_fn(|a| 0.5 * (bounds[0][a] + bounds[1][a]));
        let extent = (0..3)
            .map(|a| (bounds[1][a] - bounds[0][a]).powi(2))
            .sum::<f64>()
            .sqrt()
            * 0.5;
        // No absolute floor: data in any unit (a droplet of 1e-15 m, a dam of 1e4 m) frames
        // alike. Only bounds of no extent (one point) need one, relative to where they are.
        let radius = if extent > 0.0 && extent.is_finite() {
            extent
        } else {
            let at = centre.iter().fold(0.0f64, |m, c| m.max(c.abs()));
            (at * 1e-6).max(f64::MIN_POSITIVE.sqrt())
        };
        // (right, front, up) = (0.45, -0.8, 0.4) in the frame whose third axis is `up`:
        // for z up that is x, y, z; for another axis the two others follow cyclically.
        let axis = crate::geometry::dominant_axis(up);
        let sign = if up[axis] < 0.0 { -1.0 } else { 1.0 };
        let mut dir = [0.0f64; 3];
        dir[(axis + 1) % 3] = 0.45 * sign;
        dir[(axis + 2) % 3] = -0.8;
        dir[axis] = 0.4 * sign;
        let len = (dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]).sqrt();
        let distance = FRAMING_MARGIN * radius / (fov_y.to_radians() * 0.5).sin();
        let mut unit = [0.0; 3];
        unit[axis] = sign;
        Camera {
            eye: std::array::from_fn(|a| centre[a] + dir[a] / len * distance),
            target: centre,
            up: unit,
            fov_y,
            width,
            height,
        }
    }

    /// [`Camera::framing`]'s view, brought near enough that the eight corners of `bounds`
    /// fill the frame of `width` × `height` with a tenth to spare in its tighter direction,
    /// instead of the sphere around them: a long, low tank fills a wide window. What the
    /// player opens with.
    pub fn filling(
        bounds: &[[f64; 3]; 2],
        fov_y: f64,
        width: u32,
        height: u32,
        up: [f64; 3],
    ) -> Camera {
        let framed = Camera::framing(bounds, fov_y, width, height, up);
        let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let unit = |v: [f64; 3]| {
            let l = dot(v, v).sqrt();
            v.map(|x| x / l)
        };
        let cross = |a: [f64; 3], b: [f64; 3]| {
            [
                a[1] * b[2] - a[2] * b[1],
                a[2] * b[0] - a[0] * b[2],
                a[0] * b[1] - a[1] * b[0],
            ]
        };
        let centre = framed.target;
        let view = unit(std::array::from_fn(|a| framed.eye[a] - centre[a]));
        let right = unit(cross(view.map(|v| -v), framed.up));
        let screen_up = cross(right, view.map(|v| -v));
        let aspect = if width > 0 && height > 0 {
            f64::from(width) / f64::from(height)
        } else {
            1.0
        };
        let tan_v = (fov_y.to_radians() * 0.5).tan();
        let tan_h = tan_v * aspect;
        // The distance at which every corner is inside the frame, shrunk by the margin.
        let distance = (0..8)
            .map(|k| {
                let corner: [f64; 3] = std::array::from_fn(|a| bounds[(k >> a) & 1][a]);
                let q: [f64; 3] = std::array::from_fn(|a| corner[a] - centre[a]);
                let (x, y) = (dot(q, right).abs(), dot(q, screen_up).abs());
                dot(q, view) + FRAMING_MARGIN * (x / tan_h).max(y / tan_v)
            })
            .fold(0.0f64, f64::max);
        if !(distance.is_finite() && distance > 0.0) {
            // Bounds of no extent: the framing's own distance.
            return framed;
        }
        Camera {
            eye: std::array::from_fn(|a| centre[a] + view[a] * distance),
            ..framed
        }
    }

    /// The ray basis, shared by the CPU tracer and the GPU's uniforms.
    pub fn basis(&self) -> CameraBasis {
        let w = normalize(sub(self.target, self.eye));
        let u = normalize(cross(w, self.up));
        let v = cross(u, w);
        let half = (self.fov_y.to_radians() * 0.5).tan();
        let aspect = f64::from(self.width) / f64::from(self.height.max(1));
        CameraBasis {
            forward: w,
            right: u.map(|c| c * half * aspect),
            up: v.map(|c| c * half),
        }
    }

    /// Origin and unit direction of the ray through the centre of pixel (x, y), y down.
    pub fn ray(&self, x: u32, y: u32) -> ([f64; 3], [f64; 3]) {
        let b = self.basis();
        let sx = (f64::from(x) + 0.5) / f64::from(self.width) * 2.0 - 1.0;
        let sy = 1.0 - (f64::from(y) + 0.5) / f64::from(self.height) * 2.0;
        let d = normalize(std::array::from_fn(|a| {
            b.forward[a] + sx * b.right[a] + sy * b.up[a]
        }));
        (self.eye, d)
    }
}

/// The first accepted hit of a ray, in world coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TraceHit {
    pub t: f64,
    pub position: [f64; 3],
    pub normal: [f64; 3],
    /// The ball (point index) whose candidate produced the hit.
    pub ball: u32,
    pub iterations: u32,
    pub status: HitStatus,
    pub degree: u8,
}

impl<T: Real> Surface<T> {
    /// Traces one world-space ray (`dir` unit length) through the surface's own grid.
    pub fn trace(&self, origin: [f64; 3], dir: [f64; 3], params: &Params<T>) -> Option<TraceHit> {
        self.trace_in(&self.grid, origin, dir, params)
    }

    /// Traces one world-space ray through `index`: candidates in the order of their initial
    /// hits, the first whose refinement stays inside its ball wins (Adamson & Alexa 2003).
    pub fn trace_in(
        &self,
        index: &dyn BallIndex,
        origin: [f64; 3],
        dir: [f64; 3],
        params: &Params<T>,
    ) -> Option<TraceHit> {
        let rel = sub(origin, self.origin);
        let ray = Ray {
            origin: V3::from_f64(rel),
            dir: V3::from_f64(dir),
        };
        let to_world = |p: V3<T>| {
            let p = p.to_f64();
            std::array::from_fn(|a| p[a] + self.origin[a])
        };
        let (mut np, mut nn) = (Vec::new(), Vec::new());
        let mut after = None;
        for _ in 0..MAX_CANDIDATES {
            let candidate = self.next_candidate(index, &ray, (rel, dir), after)?;
            let item = candidate.item;
            let hit = |t: T, normal: V3<T>, status, iterations, degree| TraceHit {
                t: t.to_f64(),
                position: to_world(ray.origin + ray.dir * t),
                normal: normal.to_f64(),
                ball: item,
                iterations,
                status,
                degree,
            };
            let initial = match candidate.kind {
                CandidateKind::Droplet { normal } => {
                    return Some(hit(candidate.t, normal, HitStatus::Droplet, 0, 0));
                }
                CandidateKind::Ball(initial) => initial,
            };
            let i = item as usize;
            let ball = &self.balls[i];
            gather(
                &self.points,
                self.normals.as_deref(),
                self.neighbours_of(i),
                &mut np,
                &mut nn,
            );
            let normals = self.normals.as_ref().map(|_| nn.as_slice());
            let out = refine(&ray, ball, self.offset, &initial, &np, normals, params);
            if out.status.is_hit() && out.t.is_finite() {
                return Some(hit(
                    out.t,
                    out.normal,
                    out.status,
                    out.iterations,
                    out.degree,
                ));
            }
            after = Some((candidate.t, item));
        }
        None
    }

    /// The nearest initial hit along `ray` whose key (t, item) comes after `after`: a ball's
    /// initial polynomial or a droplet sphere.
    fn next_candidate(
        &self,
        index: &dyn BallIndex,
        ray: &Ray<T>,
        (origin, dir): ([f64; 3], [f64; 3]),
        after: Option<(T, u32)>,
    ) -> Option<Candidate<T>> {
        let mut best: Option<Candidate<T>> = None;
        let mut tested: Vec<u32> = Vec::new();
        let n = self.len();
        let later = |t: T, item: u32| after.is_none_or(|(a, b)| t > a || (t == a && item > b));
        let nearer = |t: T, item: u32, best: &Option<Candidate<T>>| {
            best.as_ref()
                .is_none_or(|c| t < c.t || (t == c.t && item < c.item))
        };
        index.walk(origin, dir, &mut |items| {
            for &b in items {
                let i = b as usize;
                if tested.contains(&b) {
                    continue;
                }
                tested.push(b);
                if i >= n {
                    let Some(sphere) = self.spheres.get(i - n) else {
                        continue;
                    };
                    let Some((t_in, t_out)) = ray_ball(ray, sphere.centre, sphere.radius) else {
                        continue;
                    };
                    // From inside a droplet the ray sees its far wall.
                    let t = if t_in >= T::zero() { t_in } else { t_out };
                    if !(t >= T::zero()) || !later(t, b) || !nearer(t, b, &best) {
                        continue;
                    }
                    let p = ray.origin + ray.dir * t;
                    let normal = (p - sphere.centre).normalized().unwrap_or(V3::new(
                        T::zero(),
                        T::zero(),
                        T::one(),
                    ));
                    best = Some(Candidate {
                        t,
                        item: b,
                        kind: CandidateKind::Droplet { normal },
                    });
                    continue;
                }
                if !matches!(self.ball_fits.get(i), Some(BallFit::Fitted(_))) {
                    continue;
                }
                let ball = &self.balls[i];
                let Some((t_in, t_out)) = ray_ball(ray, ball.centre, ball.radius) else {
                    continue;
                };
                if best.as_ref().is_some_and(|c| t_in > c.t)
                    || after.is_some_and(|(a, _)| t_out < a)
                {
                    continue;
                }
                let Ok(initial) = initial_hit(ray, ball, self.offset) else {
                    continue;
                };
                let t = initial.t;
                if t.is_finite() && later(t, b) && nearer(t, b, &best) {
                    best = Some(Candidate {
                        t,
                        item: b,
                        kind: CandidateKind::Ball(initial),
                    });
                }
            }
            best.as_ref().map_or(f64::INFINITY, |c| c.t.to_f64())
        });
        best
    }

    /// Traces every pixel of `camera`, row-major, through the surface's own grid.
    pub fn render(&self, camera: &Camera, params: &Params<T>) -> Vec<Option<TraceHit>> {
        self.render_in(&self.grid, camera, params)
    }

    /// Traces every pixel of `camera`, row-major, through `index`.
    pub fn render_in(
        &self,
        index: &dyn BallIndex,
        camera: &Camera,
        params: &Params<T>,
    ) -> Vec<Option<TraceHit>> {
        (0..camera.height)
            .into_par_iter()
            .flat_map_iter(|y| {
                (0..camera.width).map(move |x| {
                    let (o, d) = camera.ray(x, y);
                    self.trace_in(index, o, d, params)
                })
            })
            .collect()
    }
}
