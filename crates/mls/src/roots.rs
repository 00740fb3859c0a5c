//! Exact real roots of the ray–polynomial equation h(s) = c0 + c1 s + c2 s² + c3 s³ = 0 on an
//! interval: closed form (cancellation free) up to degree 2, root isolation at the critical
//! points plus safeguarded Newton–bisection for degree 3. No sampling, so close roots are not
//! missed.

use crate::real::Real;

/// Evaluates c0 + c1 s + c2 s² + c3 s³ (Horner).
pub fn eval<T: Real>(c: &[T; 4], s: T) -> T {
    ((c[3] * s + c[2]) * s + c[1]) * s + c[0]
}

fn derivative<T: Real>(c: &[T; 4], s: T) -> T {
    (T::c(3.0) * c[3] * s + T::c(2.0) * c[2]) * s + c[1]
}

/// Real roots of a s² + b s + c, ascending, without cancellation; handles a = 0 (linear) and
/// a = b = 0 (none, or every s when c = 0 — reported as none: a ray lying in the surface has
/// no single crossing).
pub fn quadratic_roots<T: Real>(a: T, b: T, c: T) -> ([T; 2], usize) {
    let zero = T::zero();
    if a == zero {
        if b == zero {
            return ([zero; 2], 0);
        }
        return ([-c / b, zero], 1);
    }
    let disc = b * b - T::c(4.0) * a * c;
    if disc < zero {
        return ([zero; 2], 0);
    }
    let q = -(b + b.signum() * disc.sqrt()) * T::c(0.5);
    if q == zero {
        // b = 0 and c = 0: a double root at zero.
        return ([zero, zero], 2);
    }
    let (r1, r2) = (q / a, c / q);
    ([r1.min(r2), r1.max(r2)], 2)
}

/// The smallest root of h in [lo, hi], or `None`.
pub fn first_root_in<T: Real>(c: [T; 4], lo: T, hi: T) -> Option<T> {
    if !(lo <= hi) || !c.iter().all(|v| v.is_finite()) {
        return None;
    }
    if c[3] == T::zero() {
        let (roots, count) = quadratic_roots(c[2], c[1], c[0]);
        return roots[..count].iter().copied().find(|&s| s >= lo && s <= hi);
    }
    // Critical points split [lo, hi] into pieces where h is monotone: each holds at most one
    // root, found by bracketing.
    let (crit, count) = quadratic_roots(T::c(3.0) * c[3], T::c(2.0) * c[2], c[1]);
    let mut points = [lo, hi, hi, hi];
    let mut k = 1;
    for &s in &crit[..count] {
        if s > lo && s < hi {
            points[k] = s;
            k += 1;
        }
    }
    points[k] = hi;
    let scale = c[0].abs() + c[1].abs() + c[2].abs() + c[3].abs();
    let touch = T::c(64.0) * T::epsilon() * scale.max(T::min_positive_value());
    for i in 0..k {
        let (a, b) = (points[i], points[i + 1]);
        let (fa, fb) = (eval(&c, a), eval(&c, b));
        if fa == T::zero() {
            return Some(a);
        }
        if fa.signum() != fb.signum() {
            return Some(bracketed_root(&c, a, b, fa));
        }
        // A critical point that touches zero without a sign change: a double root (grazing).
        if i + 1 < k && fb.abs() <= touch {
            return Some(b);
        }
    }
    (eval(&c, hi) == T::zero()).then_some(hi)
}

/// Root of h in [a, b] where h(a) has sign of `fa` and h(b) the other: Newton steps kept
/// inside the bracket, bisection when Newton leaves it or stalls.
fn bracketed_root<T: Real>(c: &[T; 4], mut a: T, mut b: T, fa: T) -> T {
    let sa = fa.signum();
    let mut s = (a + b) * T::c(0.5);
    for _ in 0..100 {
        let f = eval(c, s);
        if f == T::zero() {
            return s;
        }
        if f.signum() == sa {
            a = s;
        } else {
            b = s;
        }
        let df = derivative(c, s);
        let newton = s - f / df;
        let next = if newton > a && newton < b && newton.is_finite() {
            newton
        } else {
            (a + b) * T::c(0.5)
        };
        if next == s || b - a <= T::epsilon() * (a.abs() + b.abs()) {
            return next;
        }
        s = next;
    }
    s
}
