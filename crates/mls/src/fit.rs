//! Weighted least squares fit of the height field over the support plane (thesis eq. 2.5),
//! in coordinates scaled by 1/h, with rank detection and degree degradation.

use crate::frame::LocalFrame;
use crate::poly::{Poly, coefficient_count, monomials};
use crate::real::{Real, V3};
use crate::support::weight;

/// A pivot of the LDLᵀ factorisation smaller than this fraction of its diagonal entry means
/// the monomial is (numerically) a combination of the earlier ones: the neighbourhood cannot
/// support that degree (too few points with weight, collinear, coincident, coplanar-for-cubic).
pub const PIVOT_TOLERANCE: f64 = 1e-5;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FitStatus {
    /// The requested degree was fitted.
    Full,
    /// The data supports only a lower degree; `used` < `requested`.
    Degraded { requested: u8, used: u8 },
    /// Not even a constant could be fitted (no weight).
    Failed,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fit<T> {
    /// In scaled local coordinates: x, y and heights divided by h.
    pub poly: Poly<T>,
    pub status: FitStatus,
}

/// Fits a polynomial of degree ≤ `degree` at reference point `r` in `frame`, from `points`
/// weighted by θ(|p − r|) with smoothing length `h`.
pub fn fit<T: Real>(r: V3<T>, frame: &LocalFrame<T>, points: &[V3<T>], h: T, degree: u8) -> Fit<T> {
    let h2 = h * h;
    fit_weighted(r, frame, points, h, degree, |_, q| {
        weight(q.length_squared(), h2)
    })
}

/// [`fit`] with the weight of point j (offset q = p_j − r) from `weight_of`: a caller that
/// already has the weights (the support plane computed them) passes them on.
pub(crate) fn fit_weighted<T: Real>(
    r: V3<T>,
    frame: &LocalFrame<T>,
    points: &[V3<T>],
    h: T,
    degree: u8,
    weight_of: impl Fn(usize, V3<T>) -> T,
) -> Fit<T> {
    let degree = degree.min(3);
    let inv_h = T::one() / h;
    // The coefficient count as a constant, so that the sums below unroll.
    let (mut a, mut b, total) = match coefficient_count(degree) {
        1 => normal_equations::<T, 1>(r, frame, points, inv_h, &weight_of),
        3 => normal_equations::<T, 3>(r, frame, points, inv_h, &weight_of),
        6 => normal_equations::<T, 6>(r, frame, points, inv_h, &weight_of),
        _ => normal_equations::<T, 10>(r, frame, points, inv_h, &weight_of),
    };
    let n = coefficient_count(degree);
    if !(total > T::zero()) {
        return Fit {
            poly: Poly::zero(0),
            status: FitStatus::Failed,
        };
    }
    // Normalise so that a[0][0] = 1 whatever the number of points.
    let inv_total = T::one() / total;
    for i in 0..n {
        b[i] = b[i] * inv_total;
        for j in i..n {
            a[i][j] = a[i][j] * inv_total;
            a[j][i] = a[i][j];
        }
    }
    let (l, d, rank) = ldlt(&a, n);
    // Monomials are ordered by degree, so the leading block of a lower degree is the lower
    // degree's own system: keep the highest degree whose coefficients all have good pivots.
    let used = (0..=degree).rev().find(|&g| coefficient_count(g) <= rank);
    let Some(used) = used else {
        return Fit {
            poly: Poly::zero(0),
            status: FitStatus::Failed,
        };
    };
    let m = coefficient_count(used);
    // Solve L D Lᵀ c = b on the leading m × m block.
    let mut z = [T::zero(); 10];
    for i in 0..m {
        let mut s = b[i];
        for k in 0..i {
            s = s - l[i][k] * z[k];
        }
        z[i] = s;
    }
    for i in 0..m {
        z[i] = z[i] / d[i];
    }
    let mut c = [T::zero(); 10];
    for i in (0..m).rev() {
        let mut s = z[i];
        for k in i + 1..m {
            s = s - l[k][i] * c[k];
        }
        c[i] = s;
    }
    let status = if used == degree {
        FitStatus::Full
    } else {
        FitStatus::Degraded {
            requested: degree,
            used,
        }
    };
    Fit {
        poly: Poly { degree: used, c },
        status,
    }
}

/// LDLᵀ of the leading n × n block of a symmetric matrix, stopping at the first pivot below
/// `PIVOT_TOLERANCE` × its diagonal entry; returns L (unit lower), D and the count of good
/// pivots.
fn ldlt<T: Real>(a: &[[T; 10]; 10], n: usize) -> ([[T; 10]; 10], [T; 10], usize) {
    let mut l = [[T::zero(); 10]; 10];
    let mut d = [T::zero(); 10];
    let tol = T::c(PIVOT_TOLERANCE);
    for j in 0..n {
        let mut dj = a[j][j];
        for k in 0..j {
            dj = dj - l[j][k] * l[j][k] * d[k];
        }
        if !(dj > tol * a[j][j]) || !dj.is_finite() {
            return (l, d, j);
        }
        d[j] = dj;
        l[j][j] = T::one();
        for i in j + 1..n {
            let mut s = a[i][j];
            for k in 0..j {
                s = s - l[i][k] * l[j][k] * d[k];
            }
            l[i][j] = s / dj;
        }
    }
    (l, d, n)
}

/// The weighted sums of the normal equations (upper triangle of A, b) and the total weight,
/// for `N` monomials.
fn normal_equations<T: Real, const N: usize>(
    r: V3<T>,
    frame: &LocalFrame<T>,
    points: &[V3<T>],
    inv_h: T,
    weight_of: &impl Fn(usize, V3<T>) -> T,
) -> ([[T; 10]; 10], [T; 10], T) {
    let mut a = [[T::zero(); 10]; 10];
    let mut b = [T::zero(); 10];
    let mut total = T::zero();
    for (k, &p) in points.iter().enumerate() {
        let q = p - r;
        let w = weight_of(k, q);
        if !(w > T::zero()) {
            continue;
        }
        let l = frame.to_local(q) * inv_h;
        let m = monomials(l.x, l.y);
        total = total + w;
        for i in 0..N {
            let wm = w * m[i];
            b[i] = b[i] + wm * l.z;
            for j in i..N {
                a[i][j] = a[i][j] + wm * m[j];
            }
        }
    }
    (a, b, total)
}
