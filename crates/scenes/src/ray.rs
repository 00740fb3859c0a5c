//! Rays and hits in f64.

use glam::DVec3;

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrueRay {
    pub origin: DVec3,
    /// Unit direction.
    pub dir: DVec3,
}

impl TrueRay {
    pub fn new(origin: DVec3, dir: DVec3) -> TrueRay {
        TrueRay {
            origin,
            dir: dir.normalize(),
        }
    }

    pub fn at(&self, t: f64) -> DVec3 {
        self.origin + self.dir * t
    }
}

/// The first intersection of a ray with a true surface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    pub t: f64,
    pub position: DVec3,
    /// Outward unit normal at the hit.
    pub normal: DVec3,
}

/// Solves a t² + b t + c = 0 without cancellation; roots ascending.
pub(crate) fn quadratic_roots(a: f64, b: f64, c: f64) -> Option<(f64, f64)> {
    let disc = b * b - 4.0 * a * c;
    if disc < 0.0 || a == 0.0 {
        return None;
    }
    let q = -0.5 * (b + b.signum() * disc.sqrt());
    let (r1, r2) = if q == 0.0 { (0.0, 0.0) } else { (q / a, c / q) };
    Some((r1.min(r2), r1.max(r2)))
}

/// First root of `f` in (t_min, t_max) found by stepping with a Lipschitz bound (so no sign
/// change is stepped over) and then bisecting to machine precision.
pub(crate) fn first_root_lipschitz(
    f: impl Fn(f64) -> f64,
    lipschitz: f64,
    t_min: f64,
    t_max: f64,
) -> Option<f64> {
    let mut t = t_min;
    let mut v = f(t);
    let min_step = 1e-12 * (t_max - t_min).abs().max(1.0);
    for _ in 0..1_000_000 {
        if t >= t_max {
            return None;
        }
        let step = (v.abs() / lipschitz).max(min_step);
        let t_next = (t + step).min(t_max);
        let v_next = f(t_next);
        if v_next == 0.0 {
            return Some(t_next);
        }
        if v_next.signum() != v.signum() {
            return Some(bisect(&f, t, t_next, v));
        }
        t = t_next;
        v = v_next;
    }
    None
}

pub(crate) fn bisect(f: &impl Fn(f64) -> f64, mut lo: f64, mut hi: f64, f_lo: f64) -> f64 {
    let s_lo = f_lo.signum();
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        let fm = f(mid);
        if fm == 0.0 {
            return mid;
        }
        if fm.signum() == s_lo {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}
