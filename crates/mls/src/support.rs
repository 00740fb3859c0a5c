//! Weights and the support plane at a reference point (thesis eq. 2.1–2.4).

use crate::real::{Real, V3};

/// θ(d) = exp(−d²/h²), from the squared distance.
pub fn weight<T: Real>(d2: T, h2: T) -> T {
    (-d2 / h2).exp()
}

/// How the support plane normal is found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NormalsMode {
    /// Normalised weighted mean of the data normals (eq. 2.1), falling back to the covariance
    /// when they cancel.
    Mean,
    /// Smallest-eigenvalue eigenvector of the weighted covariance (eq. 2.4).
    Covariance,
}

/// What the support plane computation did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SupportStatus {
    /// Weighted mean of the data normals.
    MeanNormal,
    /// Covariance eigenvector, as asked.
    Covariance,
    /// The data normals cancelled (|n̄| < CANCELLATION · Σθ|n_j|) or were unusable; the
    /// covariance eigenvector was used instead.
    CovarianceAfterCancellation,
}

/// Below this ratio |Σθ n_j| / Σθ |n_j| the mean normal is considered cancelled.
pub const CANCELLATION: f64 = 0.5;
/// Below this total weight no point is close enough to define a plane.
pub const MIN_WEIGHT: f64 = 1e-6;

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Support<T> {
    pub normal: V3<T>,
    pub status: SupportStatus,
    /// Ratio of the two smallest covariance eigenvalues (λ₀/λ₁ ∈ [0, 1]) when the covariance
    /// was used: near 1 the plane's orientation is ill-defined (collinear or isotropic points).
    pub ambiguity: T,
}

/// The neighbours' data normals, as the caller has them.
#[derive(Debug, Clone, Copy)]
pub(crate) enum DataNormals<'a, T> {
    /// As the data gives them: each is normalised where it is used, unusable ones skipped.
    Raw(&'a [V3<T>]),
    /// Normalised already by [`V3::normalized`], zero where that gave none: a build that fits
    /// every point normalises each normal once instead of once per list it is in.
    Unit(&'a [V3<T>]),
}

impl<T: Real> DataNormals<'_, T> {
    /// Normal j normalised, or `None` where it is unusable.
    fn unit(&self, j: usize) -> Option<V3<T>> {
        match self {
            DataNormals::Raw(ns) => ns.get(j).and_then(|n| n.normalized()),
            DataNormals::Unit(ns) => ns.get(j).copied().filter(|n| *n != V3::zero()),
        }
    }
}

/// The support plane normal at `r` from the neighbours `points` (with `normals` if the data has
/// them), smoothing length `h`. Without usable data normals the normal is turned toward
/// `toward` (the ray origin). `None` when no point has weight at `r`.
pub fn support_normal<T: Real>(
    r: V3<T>,
    points: &[V3<T>],
    normals: Option<&[V3<T>]>,
    h: T,
    mode: NormalsMode,
    toward: V3<T>,
) -> Option<Support<T>> {
    let h2 = h * h;
    support_weighted(
        r,
        points,
        normals.map(DataNormals::Raw),
        h,
        mode,
        toward,
        |_, q| weight(q.length_squared(), h2),
    )
}

/// [`support_normal`] with the weight of point j (offset q = p_j − r) from `weight_of`, so
/// that a caller fitting at the same point computes each weight once.
pub(crate) fn support_weighted<T: Real>(
    r: V3<T>,
    points: &[V3<T>],
    normals: Option<DataNormals<'_, T>>,
    h: T,
    mode: NormalsMode,
    toward: V3<T>,
    weight_of: impl Fn(usize, V3<T>) -> T,
) -> Option<Support<T>> {
    let mut weight_sum = T::zero();
    let mut mean = V3::zero();
    let mut magnitude = T::zero();
    for (j, &p) in points.iter().enumerate() {
        let w = weight_of(j, p - r);
        weight_sum = weight_sum + w;
        if let Some(n) = normals.and_then(|ns| ns.unit(j)) {
            mean = mean + n * w;
            magnitude = magnitude + w;
        }
    }
    if !(weight_sum > T::c(MIN_WEIGHT)) {
        return None;
    }
    if mode == NormalsMode::Mean {
        let len = mean.length();
        if magnitude > T::zero() && len >= T::c(CANCELLATION) * magnitude {
            return Some(Support {
                normal: mean * (T::one() / len),
                status: SupportStatus::MeanNormal,
                ambiguity: T::zero(),
            });
        }
    }
    let (normal, ambiguity) = covariance_normal(r, points, h * h, weight_sum, &weight_of);
    // Orientation: the weighted majority of the data normals, else toward the ray origin.
    let mut vote = T::zero();
    if let Some(ns) = normals {
        for (j, &p) in points.iter().enumerate() {
            if let Some(n) = ns.unit(j) {
                let w = weight_of(j, p - r);
                vote = vote + w * n.dot(normal).signum();
            }
        }
    }
    let flip = if vote != T::zero() {
        vote < T::zero()
    } else {
        (toward - r).dot(normal) < T::zero()
    };
    let normal = if flip { -normal } else { normal };
    let status = if mode == NormalsMode::Covariance {
        SupportStatus::Covariance
    } else {
        SupportStatus::CovarianceAfterCancellation
    };
    Some(Support {
        normal,
        status,
        ambiguity,
    })
}

/// Smallest-eigenvalue eigenvector of B = Σθ (p−r)(p−r)ᵀ / (h² Σθ), and λ₀/λ₁.
fn covariance_normal<T: Real>(
    r: V3<T>,
    points: &[V3<T>],
    h2: T,
    weight_sum: T,
    weight_of: &impl Fn(usize, V3<T>) -> T,
) -> (V3<T>, T) {
    let mut b = [[T::zero(); 3]; 3];
    let scale = T::one() / (h2 * weight_sum);
    for (j, &p) in points.iter().enumerate() {
        let q = p - r;
        let w = weight_of(j, q) * scale;
        let c = [q.x, q.y, q.z];
        for k in 0..3 {
            for l in k..3 {
                b[k][l] = b[k][l] + w * c[k] * c[l];
            }
        }
    }
    b[1][0] = b[0][1];
    b[2][0] = b[0][2];
    b[2][1] = b[1][2];
    let (values, vectors) = jacobi_eigen(b);
    let mut order = [0, 1, 2];
    order.sort_by(|&i, &j| {
        values[i]
            .partial_cmp(&values[j])
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    let k = order[0];
    let normal = V3::new(vectors[0][k], vectors[1][k], vectors[2][k])
        .normalized()
        .unwrap_or(V3::new(T::zero(), T::zero(), T::one()));
    let (l0, l1) = (
        values[order[0]].max(T::zero()),
        values[order[1]].max(T::zero()),
    );
    let ambiguity = if l1 > T::zero() { l0 / l1 } else { T::one() };
    (normal, ambiguity)
}

/// Eigen-decomposition of a symmetric 3×3 matrix by cyclic Jacobi rotations: eigenvalues and
/// eigenvectors as the columns of the second result. Deterministic, branch-light, portable to
/// WGSL as written.
pub fn jacobi_eigen<T: Real>(mut a: [[T; 3]; 3]) -> ([T; 3], [[T; 3]; 3]) {
    let mut v = [[T::zero(); 3]; 3];
    for (i, row) in v.iter_mut().enumerate() {
        row[i] = T::one();
    }
    for _sweep in 0..16 {
        let off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
        let diag = a[0][0] * a[0][0] + a[1][1] * a[1][1] + a[2][2] * a[2][2];
        if !(off > T::epsilon() * T::epsilon() * diag) {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q] == T::zero() {
                continue;
            }
            // Rotation angle that zeroes a[p][q] (Numerical Recipes' stable form).
            let theta = (a[q][q] - a[p][p]) / (T::c(2.0) * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + T::one()).sqrt());
            let t = if theta.is_finite() { t } else { T::zero() };
            let c = T::one() / (t * t + T::one()).sqrt();
            let s = t * c;
            for k in 0..3 {
                let (akp, akq) = (a[k][p], a[k][q]);
                a[k][p] = c * akp - s * akq;
                a[k][q] = s * akp + c * akq;
            }
            for k in 0..3 {
                let (apk, aqk) = (a[p][k], a[q][k]);
                a[p][k] = c * apk - s * aqk;
                a[q][k] = s * apk + c * aqk;
            }
            for row in v.iter_mut() {
                let (vkp, vkq) = (row[p], row[q]);
                row[p] = c * vkp - s * vkq;
                row[q] = s * vkp + c * vkq;
            }
        }
    }
    ([a[0][0], a[1][1], a[2][2]], v)
}
