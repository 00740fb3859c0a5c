//! Analytic surfaces: exact ray intersection and distance. Serialised into `truth.json`.

use glam::{DMat3, DVec3};
use serde::{Deserialize, Serialize};

use crate::ray::{Hit, TrueRay, first_root_lipschitz, quadratic_roots};

/// One standing wave of the tank: a cos(kx x) cos(ky y) cos(ω t + phase), ω² = g k tanh(k d).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Wave {
    pub amplitude: f64,
    pub kx: f64,
    pub ky: f64,
    pub omega: f64,
    pub phase: f64,
}

impl Wave {
    pub fn k(&self) -> f64 {
        self.kx.hypot(self.ky)
    }
}

/// A closed-form surface at one instant.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum Truth {
    Sphere {
        center: DVec3,
        radius: f64,
    },
    /// Ring about `axis` through `center`.
    Torus {
        center: DVec3,
        /// Columns: the torus's local x, y and z (= axis) in world space.
        rotation: DMat3,
        major: f64,
        minor: f64,
    },
    Ellipsoid {
        center: DVec3,
        rotation: DMat3,
        radii: DVec3,
    },
    /// Free surface z = origin.z + depth + Σ waves over [0, size.x] × [0, size.y] (in local
    /// coordinates relative to `origin`), at `time`.
    HeightField {
        origin: DVec3,
        size: [f64; 2],
        depth: f64,
        time: f64,
        waves: Vec<Wave>,
    },
    /// Axis-aligned square patch of half size `half` in the plane through `center` with
    /// normal `normal` (one of ±x, ±y, ±z is not required: any unit normal).
    Square {
        center: DVec3,
        normal: DVec3,
        half: f64,
    },
    /// Everything in the list; the nearest hit wins.
    Union {
        parts: Vec<Truth>,
    },
}

/// Both ray parameters where a ray meets a sphere, ascending.
fn ray_sphere(ray: &TrueRay, center: DVec3, radius: f64) -> Option<(f64, f64)> {
    let oc = ray.origin - center;
    quadratic_roots(
        1.0,
        2.0 * oc.dot(ray.dir),
        oc.length_squared() - radius * radius,
    )
}

fn local_frame(n: DVec3) -> (DVec3, DVec3) {
    let u = n.any_orthonormal_vector();
    (u, n.cross(u))
}

impl Truth {
    /// Exact first intersection with t in (t_min, t_max).
    pub fn intersect(&self, ray: &TrueRay, t_min: f64, t_max: f64) -> Option<Hit> {
        match self {
            Truth::Sphere { center, radius } => {
                let (t0, t1) = ray_sphere(ray, *center, *radius)?;
                let t = [t0, t1].into_iter().find(|&t| t > t_min && t < t_max)?;
                let p = ray.at(t);
                Some(Hit {
                    t,
                    position: p,
                    normal: (p - *center) / *radius,
                })
            }
            Truth::Ellipsoid {
                center,
                rotation,
                radii,
            } => {
                // In the frame where the ellipsoid is the unit sphere the problem is a quadratic.
                let inv = rotation.transpose();
                let o = inv * (ray.origin - *center) / *radii;
                let d = inv * ray.dir / *radii;
                let (t0, t1) =
                    quadratic_roots(d.length_squared(), 2.0 * o.dot(d), o.length_squared() - 1.0)?;
                let t = [t0, t1].into_iter().find(|&t| t > t_min && t < t_max)?;
                let p = ray.at(t);
                let local = inv * (p - *center);
                let n = (*rotation * (local / (*radii * *radii))).normalize();
                Some(Hit {
                    t,
                    position: p,
                    normal: n,
                })
            }
            Truth::Torus {
                center,
                major,
                minor,
                ..
            } => {
                // Sphere tracing on the exact signed distance never steps over the surface.
                // Padded so that the march starts strictly outside.
                let bound = (major + minor) * (1.0 + 1e-6);
                let (b0, b1) = ray_sphere(ray, *center, bound)?;
                let lo = b0.max(t_min);
                let hi = b1.min(t_max);
                if lo >= hi {
                    return None;
                }
                let sdf = |t: f64| self.signed_distance(ray.at(t));
                let t = first_root_lipschitz(sdf, 1.0, lo, hi)?;
                let p = ray.at(t);
                Some(Hit {
                    t,
                    position: p,
                    normal: self.normal_at(p),
                })
            }
            Truth::HeightField {
                origin,
                size,
                depth,
                time,
                waves,
            } => {
                let slope: f64 = waves
                    .iter()
                    .map(|w| w.amplitude.abs() * (w.kx.abs() + w.ky.abs()))
                    .sum();
                let amp: f64 = waves.iter().map(|w| w.amplitude.abs()).sum();
                // Clip the ray to the box over the footprint that holds the surface.
                let lo_b = *origin + DVec3::new(0.0, 0.0, depth - amp - 1e-9);
                let hi_b = *origin + DVec3::new(size[0], size[1], depth + amp + 1e-9);
                let (mut lo, mut hi) = (t_min, t_max);
                for a in 0..3 {
                    if ray.dir[a].abs() < 1e-300 {
                        if ray.origin[a] < lo_b[a] || ray.origin[a] > hi_b[a] {
                            return None;
                        }
                        continue;
                    }
                    let t0 = (lo_b[a] - ray.origin[a]) / ray.dir[a];
                    let t1 = (hi_b[a] - ray.origin[a]) / ray.dir[a];
                    lo = lo.max(t0.min(t1));
                    hi = hi.min(t0.max(t1));
                }
                if lo >= hi {
                    return None;
                }
                let g = |t: f64| {
                    let p = ray.at(t) - *origin;
                    p.z - depth - height(waves, *time, p.x, p.y)
                };
                let lipschitz = ray.dir.z.abs() + slope * ray.dir.truncate().length() + 1e-300;
                let t = first_root_lipschitz(g, lipschitz, lo, hi)?;
                let p = ray.at(t);
                Some(Hit {
                    t,
                    position: p,
                    normal: self.normal_at(p),
                })
            }
            Truth::Square {
                center,
                normal,
                half,
            } => {
                let denom = ray.dir.dot(*normal);
                if denom.abs() < 1e-300 {
                    return None;
                }
                let t = (*center - ray.origin).dot(*normal) / denom;
                if t <= t_min || t >= t_max {
                    return None;
                }
                let p = ray.at(t);
                let (u, v) = local_frame(*normal);
                let q = p - *center;
                (q.dot(u).abs() <= *half && q.dot(v).abs() <= *half).then_some(Hit {
                    t,
                    position: p,
                    normal: *normal,
                })
            }
            Truth::Union { parts } => {
                let mut best: Option<Hit> = None;
                for part in parts {
                    let hi = best.map_or(t_max, |h| h.t);
                    if let Some(h) = part.intersect(ray, t_min, hi) {
                        best = Some(h);
                    }
                }
                best
            }
        }
    }

    /// Signed distance where it has a closed form (negative inside); for the others the
    /// unsigned distance to the closest point, found numerically.
    pub fn signed_distance(&self, p: DVec3) -> f64 {
        match self {
            Truth::Sphere { center, radius } => (p - *center).length() - radius,
            Truth::Torus {
                center,
                rotation,
                major,
                minor,
            } => {
                let q = rotation.transpose() * (p - *center);
                DVec3::new(q.truncate().length() - major, q.z, 0.0).length() - minor
            }
            Truth::Ellipsoid {
                center,
                rotation,
                radii,
            } => {
                let q = rotation.transpose() * (p - *center);
                let d = ellipsoid_distance(*radii, q.abs());
                if (q / *radii).length_squared() < 1.0 {
                    -d
                } else {
                    d
                }
            }
            Truth::HeightField {
                origin,
                depth,
                time,
                waves,
                ..
            } => {
                let q = p - *origin;
                let d = heightfield_distance(waves, *time, *depth, q);
                if q.z < depth + height(waves, *time, q.x, q.y) {
                    -d
                } else {
                    d
                }
            }
            Truth::Square {
                center,
                normal,
                half,
            } => {
                let (u, v) = local_frame(*normal);
                let q = p - *center;
                let du = (q.dot(u).abs() - half).max(0.0);
                let dv = (q.dot(v).abs() - half).max(0.0);
                DVec3::new(du, dv, q.dot(*normal)).length()
            }
            Truth::Union { parts } => parts
                .iter()
                .map(|t| t.signed_distance(p))
                .min_by(|a, b| a.abs().total_cmp(&b.abs()))
                .unwrap_or(f64::INFINITY),
        }
    }

    /// Outward unit normal of the surface point closest to `p` (p on or near the surface).
    pub fn normal_at(&self, p: DVec3) -> DVec3 {
        match self {
            Truth::Sphere { center, .. } => (p - *center).normalize(),
            Truth::Torus {
                center,
                rotation,
                major,
                ..
            } => {
                let q = rotation.transpose() * (p - *center);
                let ring = q.truncate().normalize_or(glam::DVec2::X) * *major;
                (*rotation * (q - ring.extend(0.0))).normalize()
            }
            Truth::Ellipsoid {
                center,
                rotation,
                radii,
            } => {
                let q = rotation.transpose() * (p - *center);
                (*rotation * (q / (*radii * *radii))).normalize()
            }
            Truth::HeightField {
                origin,
                time,
                waves,
                ..
            } => {
                let q = p - *origin;
                let (hx, hy) = height_gradient(waves, *time, q.x, q.y);
                DVec3::new(-hx, -hy, 1.0).normalize()
            }
            Truth::Square { normal, .. } => *normal,
            Truth::Union { parts } => parts
                .iter()
                .min_by(|a, b| {
                    a.signed_distance(p)
                        .abs()
                        .total_cmp(&b.signed_distance(p).abs())
                })
                .map_or(DVec3::Z, |t| t.normal_at(p)),
        }
    }

    /// The same surface moved by `offset`.
    pub fn translated(&self, offset: DVec3) -> Truth {
        let mut t = self.clone();
        match &mut t {
            Truth::Sphere { center, .. }
            | Truth::Torus { center, .. }
            | Truth::Ellipsoid { center, .. }
            | Truth::Square { center, .. } => *center += offset,
            Truth::HeightField { origin, .. } => *origin += offset,
            Truth::Union { parts } => {
                for p in parts.iter_mut() {
                    *p = p.translated(offset);
                }
            }
        }
        t
    }
}

/// Surface height above the still level at (x, y), tank-local coordinates.
pub fn height(waves: &[Wave], t: f64, x: f64, y: f64) -> f64 {
    waves
        .iter()
        .map(|w| w.amplitude * (w.kx * x).cos() * (w.ky * y).cos() * (w.omega * t + w.phase).cos())
        .sum()
}

pub fn height_gradient(waves: &[Wave], t: f64, x: f64, y: f64) -> (f64, f64) {
    waves.iter().fold((0.0, 0.0), |(gx, gy), w| {
        let c = w.amplitude * (w.omega * t + w.phase).cos();
        (
            gx - c * w.kx * (w.kx * x).sin() * (w.ky * y).cos(),
            gy - c * w.ky * (w.kx * x).cos() * (w.ky * y).sin(),
        )
    })
}

/// Distance from q to the height field: minimises |q − (x, y, d + h(x, y))|² by Newton's
/// method with a finite-difference Hessian, started below q.
fn heightfield_distance(waves: &[Wave], t: f64, depth: f64, q: DVec3) -> f64 {
    let dist2 = |x: f64, y: f64| {
        let z = depth + height(waves, t, x, y);
        (q.x - x).powi(2) + (q.y - y).powi(2) + (q.z - z).powi(2)
    };
    let grad = |x: f64, y: f64| {
        let z = depth + height(waves, t, x, y);
        let (hx, hy) = height_gradient(waves, t, x, y);
        (
            -2.0 * (q.x - x) - 2.0 * (q.z - z) * hx,
            -2.0 * (q.y - y) - 2.0 * (q.z - z) * hy,
        )
    };
    let (mut x, mut y) = (q.x, q.y);
    for _ in 0..50 {
        let (gx, gy) = grad(x, y);
        let e = 1e-7;
        let (gxx, gxy) = {
            let (a, b) = grad(x + e, y);
            ((a - gx) / e, (b - gy) / e)
        };
        let gyy = (grad(x, y + e).1 - gy) / e;
        let det = gxx * gyy - gxy * gxy;
        let (dx, dy) = if det > 1e-12 && gxx > 0.0 {
            ((gyy * gx - gxy * gy) / det, (gxx * gy - gxy * gx) / det)
        } else {
            (0.25 * gx, 0.25 * gy)
        };
        // Only accept steps that do not increase the distance.
        let before = dist2(x, y);
        let mut s = 1.0;
        while s > 1e-6 && dist2(x - s * dx, y - s * dy) > before {
            s *= 0.5;
        }
        x -= s * dx;
        y -= s * dy;
        if (s * dx).abs() + (s * dy).abs() < 1e-15 {
            break;
        }
    }
    dist2(x, y).sqrt()
}

/// Distance from a point in the first octant to an axis-aligned ellipsoid (Eberly's
/// bisection on the Lagrange parameter).
fn ellipsoid_distance(radii: DVec3, q: DVec3) -> f64 {
    // Sort so that e0 ≥ e1 ≥ e2, keeping q with its axis.
    let mut pairs = [(radii.x, q.x), (radii.y, q.y), (radii.z, q.z)];
    pairs.sort_by(|a, b| b.0.total_cmp(&a.0));
    let e = DVec3::new(pairs[0].0, pairs[1].0, pairs[2].0);
    // Points on a coordinate plane are nudged off it by 1e-12 of the size (error of that order).
    let floor = 1e-12 * e.x;
    let y = DVec3::new(
        pairs[0].1.max(floor),
        pairs[1].1.max(floor),
        pairs[2].1.max(floor),
    );
    let z = y / e;
    let g = z.length_squared() - 1.0;
    if g == 0.0 {
        return 0.0;
    }
    let r = DVec3::new((e.x / e.z).powi(2), (e.y / e.z).powi(2), 1.0);
    let f = |s: f64| (r * z / (s + r)).length_squared() - 1.0;
    let (mut lo, mut hi) = (
        -1.0 + z.z,
        if g < 0.0 { 0.0 } else { (r * z).length() - 1.0 },
    );
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if f(mid) > 0.0 { lo = mid } else { hi = mid }
    }
    let s = 0.5 * (lo + hi);
    let x = r * y / (s + r);
    (x - y).length()
}
