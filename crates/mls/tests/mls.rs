//! The MLS maths against closed forms, nalgebra's decompositions and brute force.

#![allow(clippy::unwrap_used)] // helpers of tests, where a failed unwrap is a failed test

use nalgebra::{DMatrix, DVector, Matrix3};
use proptest::prelude::*;
use slosh_mls::*;

type V = V3<f64>;

fn v(x: f64, y: f64, z: f64) -> V {
    V3::new(x, y, z)
}

proptest! {
    #[test]
    fn frames_are_orthonormal_and_right_handed(x in -1.0..1.0f64, y in -1.0..1.0f64, z in -1.0..1.0f64) {
        let Some(n) = v(x, y, z).normalized() else { return Ok(()) };
        let f = LocalFrame::from_normal(n);
        for (a, b) in [(f.u, f.v), (f.u, f.n), (f.v, f.n)] {
            prop_assert!(a.dot(b).abs() < 1e-12);
        }
        for a in [f.u, f.v] {
            prop_assert!((a.length() - 1.0).abs() < 1e-12);
        }
        prop_assert!((f.u.cross(f.v) - f.n).length() < 1e-12);
    }

    #[test]
    fn jacobi_matches_nalgebra(a in proptest::array::uniform6(-10.0..10.0f64)) {
        let m = [[a[0], a[1], a[2]], [a[1], a[3], a[4]], [a[2], a[4], a[5]]];
        let (values, vectors) = jacobi_eigen(m);
        let mut ours = values.to_vec();
        ours.sort_by(f64::total_cmp);
        let na = Matrix3::new(a[0], a[1], a[2], a[1], a[3], a[4], a[2], a[4], a[5]).symmetric_eigen();
        let mut theirs: Vec<f64> = na.eigenvalues.iter().copied().collect();
        theirs.sort_by(f64::total_cmp);
        for (x, y) in ours.iter().zip(&theirs) {
            prop_assert!((x - y).abs() < 1e-9 * (1.0 + y.abs()), "{ours:?} vs {theirs:?}");
        }
        // Each column is an eigenvector: A v = λ v.
        for k in 0..3 {
            let e = [vectors[0][k], vectors[1][k], vectors[2][k]];
            for i in 0..3 {
                let av: f64 = (0..3).map(|j| m[i][j] * e[j]).sum();
                prop_assert!((av - values[k] * e[i]).abs() < 1e-8 * (1.0 + values[k].abs()));
            }
        }
    }

    /// Every returned root is a root, and dense sampling finds no sign change before it.
    #[test]
    fn first_root_is_a_root_and_none_is_missed(c in proptest::array::uniform4(-5.0..5.0f64), lo in -3.0..0.0f64, width in 0.01..6.0f64) {
        let hi = lo + width;
        let root = first_root_in(c, lo, hi);
        let scale = c.iter().map(|x| x.abs()).sum::<f64>() * (1.0 + lo.abs().max(hi.abs())).powi(3);
        let n = 20_000;
        let sample = |i: usize| lo + (hi - lo) * i as f64 / n as f64;
        let first_change = (0..n).find(|&i| {
            let (a, b) = (eval_cubic(&c, sample(i)), eval_cubic(&c, sample(i + 1)));
            a == 0.0 || a.signum() != b.signum()
        });
        match root {
            Some(s) => {
                prop_assert!(s >= lo && s <= hi);
                prop_assert!(eval_cubic(&c, s).abs() <= 1e-9 * scale, "h({s}) = {}", eval_cubic(&c, s));
                if let Some(i) = first_change {
                    // No sign change strictly before the returned root (beyond sampling width).
                    prop_assert!(sample(i) <= s + 1e-9, "missed a root near {} before {s}", sample(i));
                }
            }
            None => prop_assert!(first_change.is_none(), "a sign change near {:?} was missed", first_change.map(sample)),
        }
    }
}

#[test]
fn quadratic_formula_has_no_cancellation() {
    let (r, n) = quadratic_roots(1.0f64, 1e8, 1.0);
    assert_eq!(n, 2);
    assert!((r[1] - (-1e-8)).abs() < 1e-22, "small root {}", r[1]);
    let (r, n) = quadratic_roots(1.0f32, 1e4, 1.0);
    assert_eq!(n, 2);
    assert!((r[1] - (-1e-4)).abs() < 1e-10, "small root in f32 {}", r[1]);
    // Close roots of a cubic are both found: (s − 0.5)(s − 0.5001)(s + 3).
    let (a, b, c3): (f64, f64, f64) = (0.5, 0.5001, -3.0);
    let c = [-a * b * c3, a * b + a * c3 + b * c3, -(a + b + c3), 1.0];
    let s = first_root_in(c, 0.0, 1.0).unwrap();
    assert!((s - 0.5).abs() < 1e-9, "{s}");
    let s = first_root_in(c, 0.50005, 1.0).unwrap();
    assert!((s - 0.5001).abs() < 1e-9, "{s}");
}

/// Height field z = P(x, y) sampled on a jittered grid in a rotated frame.
fn samples(
    poly: &[f64; 10],
    degree: u8,
    n_side: usize,
    frame: &LocalFrame<f64>,
    origin: V,
    spacing: f64,
) -> Vec<V> {
    let p = Poly { degree, c: *poly };
    let mut out = Vec::new();
    for i in 0..n_side {
        for j in 0..n_side {
            let x = (i as f64 - (n_side - 1) as f64 / 2.0) * spacing
                + 0.1 * spacing * ((i * 7 + j * 3) % 5) as f64 / 5.0;
            let y = (j as f64 - (n_side - 1) as f64 / 2.0) * spacing
                + 0.1 * spacing * ((i * 3 + j * 11) % 7) as f64 / 7.0;
            out.push(origin + frame.to_world(v(x, y, p.eval(x, y))));
        }
    }
    out
}

#[test]
fn fit_reproduces_polynomials_and_matches_svd() {
    let frame = LocalFrame::from_normal(v(0.3, -0.2, 0.9).normalized().unwrap());
    let origin = v(1.0, 2.0, -0.5);
    let h = 0.3;
    for degree in 1..=3u8 {
        let mut coeffs = [0.0; 10];
        let truth = [0.01, 0.2, -0.1, 0.5, -0.3, 0.2, 0.4, -0.2, 0.1, 0.3];
        coeffs[..coefficient_count(degree)].copy_from_slice(&truth[..coefficient_count(degree)]);
        let points = samples(&coeffs, degree, 9, &frame, origin, 0.1);
        let f = fit(origin, &frame, &points, h, degree);
        assert_eq!(f.status, FitStatus::Full);
        // The fit is in coordinates scaled by 1/h: a_k (h) scaled = a_k · h^(deg_k − 1).
        let powers = [0, 1, 1, 2, 2, 2, 3, 3, 3, 3];
        for k in 0..coefficient_count(degree) {
            let expected = coeffs[k] * h.powi(powers[k] - 1);
            assert!(
                (f.poly.c[k] - expected).abs() < 1e-9,
                "degree {degree} coefficient {k}: {} vs {expected}",
                f.poly.c[k]
            );
        }
        // Noisy data: same as a weighted least squares solve by SVD.
        let noisy: Vec<V> = points
            .iter()
            .enumerate()
            .map(|(i, p)| *p + frame.n * (0.003 * (((i * 37) % 11) as f64 - 5.0)))
            .collect();
        let f = fit(origin, &frame, &noisy, h, degree);
        let m = coefficient_count(degree);
        let mut a = DMatrix::zeros(noisy.len(), m);
        let mut b = DVector::zeros(noisy.len());
        for (row, p) in noisy.iter().enumerate() {
            let q = *p - origin;
            let w = weight(q.length_squared(), h * h).sqrt();
            let l = frame.to_local(q) * (1.0 / h);
            let mono = monomials(l.x, l.y);
            for k in 0..m {
                a[(row, k)] = w * mono[k];
            }
            b[row] = w * l.z;
        }
        let svd = a.svd(true, true).solve(&b, 1e-14).unwrap();
        for k in 0..m {
            assert!(
                (f.poly.c[k] - svd[k]).abs() < 1e-8 * (1.0 + svd[k].abs()),
                "degree {degree} noisy coefficient {k}: {} vs SVD {}",
                f.poly.c[k],
                svd[k]
            );
        }
    }
}

#[test]
fn fits_degrade_when_the_data_cannot_support_them() {
    let frame = LocalFrame::from_normal(v(0.0, 0.0, 1.0));
    let o = v(0.0, 0.0, 0.0);
    // 3 × 3 grid: enough for a quadratic, not for a cubic.
    let grid: Vec<V> = (0..9)
        .map(|k| v((k % 3) as f64 * 0.1 - 0.1, (k / 3) as f64 * 0.1 - 0.1, 0.0))
        .collect();
    assert_eq!(
        fit(o, &frame, &grid, 0.3, 3).status,
        FitStatus::Degraded {
            requested: 3,
            used: 2
        }
    );
    // Collinear points: only a constant.
    let line: Vec<V> = (0..20)
        .map(|k| v(k as f64 * 0.02 - 0.2, 0.0, 0.01))
        .collect();
    let f = fit(o, &frame, &line, 0.3, 2);
    assert_eq!(
        f.status,
        FitStatus::Degraded {
            requested: 2,
            used: 0
        }
    );
    assert!((f.poly.c[0] - 0.01 / 0.3).abs() < 1e-12);
    // Coincident points, and a single point: a constant through them.
    let same = vec![v(0.05, 0.05, 0.02); 12];
    assert_eq!(fit(o, &frame, &same, 0.3, 2).poly.degree, 0);
    assert_eq!(fit(o, &frame, &same[..1], 0.3, 3).poly.degree, 0);
    // Nothing within reach of the weight.
    assert_eq!(
        fit(o, &frame, &[v(1e3, 0.0, 0.0)], 0.3, 2).status,
        FitStatus::Failed
    );
    assert_eq!(fit(o, &frame, &[], 0.3, 2).status, FitStatus::Failed);
}

#[test]
fn support_plane_falls_back_when_normals_cancel() {
    let pts: Vec<V> = (0..25)
        .map(|k| v((k % 5) as f64 * 0.1 - 0.2, (k / 5) as f64 * 0.1 - 0.2, 0.0))
        .collect();
    let up = vec![v(0.0, 0.0, 1.0); 25];
    let s = support_normal(
        v(0.0, 0.0, 0.05),
        &pts,
        Some(&up),
        0.2,
        NormalsMode::Mean,
        v(0.0, 0.0, 5.0),
    )
    .unwrap();
    assert_eq!(s.status, SupportStatus::MeanNormal);
    assert!((s.normal - v(0.0, 0.0, 1.0)).length() < 1e-12);
    // Half the normals flipped: they cancel; the covariance gives ±z, oriented toward the ray.
    let mixed: Vec<V> = (0..25)
        .map(|k| {
            if k % 2 == 0 {
                v(0.0, 0.0, 1.0)
            } else {
                v(0.0, 0.0, -1.0)
            }
        })
        .collect();
    let s = support_normal(
        v(0.0, 0.0, 0.05),
        &pts,
        Some(&mixed),
        0.2,
        NormalsMode::Mean,
        v(0.0, 0.0, -5.0),
    )
    .unwrap();
    assert_eq!(s.status, SupportStatus::CovarianceAfterCancellation);
    assert!(s.normal.z.abs() > 1.0 - 1e-12);
    // NaN and zero normals are ignored, never propagated.
    let bad: Vec<V> = (0..25)
        .map(|k| {
            if k % 3 == 0 {
                v(f64::NAN, 0.0, 0.0)
            } else if k % 3 == 1 {
                V::zero()
            } else {
                v(0.0, 0.0, 1.0)
            }
        })
        .collect();
    let s = support_normal(
        v(0.0, 0.0, 0.0),
        &pts,
        Some(&bad),
        0.2,
        NormalsMode::Mean,
        v(0.0, 0.0, 5.0),
    )
    .unwrap();
    assert!(s.normal.is_finite() && s.normal.z > 0.99);
    // No point within reach.
    assert!(
        support_normal(
            v(100.0, 0.0, 0.0),
            &pts,
            Some(&up),
            0.2,
            NormalsMode::Mean,
            V::zero()
        )
        .is_none()
    );
}

fn fibonacci_sphere(n: usize) -> Vec<V> {
    let golden = 0.618_033_988_749_894_8f64;
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).sqrt();
            let phi = std::f64::consts::TAU * (i as f64 * golden).fract();
            v(r * phi.cos(), r * phi.sin(), z)
        })
        .collect()
}

/// Rays into a sampled unit sphere: the converged hit lies on the sphere to a small fraction
/// of the spacing, f32 agrees with f64, and more iterations do not hurt; with the surface
/// offset by δ, on the sphere of radius 1 + δ just as closely.
#[test]
fn sphere_hits_converge_onto_the_surface() {
    let n = 3000;
    let spacing = (4.0 * std::f64::consts::PI / n as f64).sqrt();
    for offset in [0.0, 0.4 * spacing] {
        sphere_hits_converge_onto_the_sphere_offset_by(n, spacing, offset);
    }
}

fn sphere_hits_converge_onto_the_sphere_offset_by(n: usize, spacing: f64, offset: f64) {
    let pts = fibonacci_sphere(n);
    let radius_of_trust = 1.6 * spacing;
    let h = 1.5 * radius_of_trust;
    let mut worst: f64 = 0.0;
    let mut worst32: f64 = 0.0;
    for k in 0..40 {
        let target = pts[(k * 71) % n];
        let origin = target * 4.0 + v(0.013 * k as f64, -0.007 * k as f64, 0.0);
        let dir = (target - origin).normalized().unwrap();
        let ray = Ray { origin, dir };
        // The ball of the sample nearest the ray's closest approach to the sphere.
        let (idx, _) = pts
            .iter()
            .enumerate()
            .map(|(i, p)| (i, ((*p - origin) - dir * (*p - origin).dot(dir)).length()))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .unwrap();
        let centre = pts[idx];
        let neighbours: Vec<V> = pts
            .iter()
            .copied()
            .filter(|p| (*p - centre).length() < radius_of_trust + 3.0 * h)
            .collect();
        let normals: Vec<V> = neighbours.clone();
        let mut params = Params::new();
        params.degree = 2;
        params.iterations = 5;
        let (normal, f) =
            initial_fit(centre, &neighbours, Some(&normals), h, &params, origin).unwrap();
        let ball = Ball {
            h,
            centre,
            radius: radius_of_trust,
            normal,
            poly: f.poly,
        };
        let out = intersect_ball(&ray, &ball, offset, &neighbours, Some(&normals), &params);
        assert!(out.status.is_hit(), "ray {k}: {:?}", out.status);
        assert!(out.t.is_finite() && out.normal.is_finite());
        let err = (out.position.length() - (1.0 + offset)).abs() / spacing;
        worst = worst.max(err);
        assert!(
            out.normal.dot(out.position.normalized().unwrap()) > 0.999,
            "normal off"
        );

        // The same in f32.
        let c32 = |p: V| V3::<f32>::new(p.x as f32, p.y as f32, p.z as f32);
        let n32: Vec<V3<f32>> = neighbours.iter().map(|p| c32(*p)).collect();
        let mut p32 = Params::new();
        p32.iterations = 5;
        let (normal32, f32fit) =
            initial_fit(c32(centre), &n32, Some(&n32), h as f32, &p32, c32(origin)).unwrap();
        let ball32 = Ball {
            h: h as f32,
            centre: c32(centre),
            radius: radius_of_trust as f32,
            normal: normal32,
            poly: f32fit.poly,
        };
        let out32 = intersect_ball(
            &Ray {
                origin: c32(origin),
                dir: c32(dir),
            },
            &ball32,
            offset as f32,
            &n32,
            Some(&n32),
            &p32,
        );
        assert!(out32.status.is_hit());
        worst32 = worst32.max((f64::from(out32.t) - out.t).abs() / spacing);
    }
    eprintln!(
        "sphere, offset {offset:.3}: worst distance {worst:.2e} spacings, f32 vs f64 worst |Δt| {worst32:.2e} spacings"
    );
    // Modelling error of a converged quadratic MLS on a clean sphere, in spacings.
    assert!(
        worst < 0.01,
        "worst distance to the sphere {worst} spacings"
    );
    assert!(worst32 < 1e-3, "f32 vs f64 |Δt| up to {worst32} spacings");
}
