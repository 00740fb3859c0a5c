//! The CPU reference tracer on analytic scenes: hits against the exact surface, hit/miss
//! agreement away from silhouettes, f32 against f64.

#![allow(clippy::unwrap_used)] // helpers of tests, where a failed unwrap is a failed test

use slosh_mls::*;
use slosh_scenes::{DVec3, Scene, SceneKind, SceneSpec, TrueRay};

struct Report {
    hits: usize,
    rms: f64,
    max: f64,
    disagree: usize,
    compared: usize,
}

/// Renders `scene` at step 0 and compares with the truth. Pixels whose 3×3 neighbourhood
/// disagrees with the truth about hit/miss are silhouettes and are not compared.
fn compare<T: Real>(
    kind: SceneKind,
    points: usize,
    degree: u8,
    iterations: u32,
    size: u32,
) -> Report {
    let scene = Scene::new(SceneSpec::new(kind, points, 3)).unwrap();
    let p = scene.particles(0);
    let (pos, nrm) = p.surface_arrays();
    let params = SurfaceParams {
        degree,
        ..SurfaceParams::default()
    };
    let surface = Surface::<T>::build(&pos, Some(&nrm), &params).unwrap();
    let truth = scene.truth(0.0);
    let camera = slosh_testkit::analytic_camera(&pos, kind == SceneKind::Tank, size);
    let mut tp = Params::new();
    tp.degree = degree;
    tp.iterations = iterations;
    let ours = surface.render(&camera, &tp);
    let exact: Vec<Option<f64>> = (0..size)
        .flat_map(|y| (0..size).map(move |x| (x, y)))
        .map(|(x, y)| {
            let (o, d) = camera.ray(x, y);
            truth
                .intersect(
                    &TrueRay::new(DVec3::from(o), DVec3::from(d)),
                    0.0,
                    f64::INFINITY,
                )
                .map(|h| h.t)
        })
        .collect();
    let spacing = scene.spacing();
    let silhouette = slosh_testkit::silhouette_mask(&exact, size as usize, None);
    let (mut sq, mut max, mut hits, mut disagree, mut compared) = (0.0, 0.0f64, 0, 0, 0);
    for y in 0..size as i64 {
        for x in 0..size as i64 {
            if silhouette[(y * size as i64 + x) as usize] {
                continue;
            }
            compared += 1;
            let i = (y * size as i64 + x) as usize;
            match (ours[i], exact[i]) {
                (Some(h), Some(_)) => {
                    let d = truth.signed_distance(DVec3::from(h.position)).abs() / spacing;
                    assert!(h.normal.iter().all(|c| c.is_finite()));
                    sq += d * d;
                    max = max.max(d);
                    hits += 1;
                }
                (None, None) => {}
                _ => disagree += 1,
            }
        }
    }
    Report {
        hits,
        rms: (sq / hits.max(1) as f64).sqrt(),
        max,
        disagree,
        compared,
    }
}

#[test]
fn sphere_torus_and_tank_match_the_truth() {
    for (kind, n) in [
        (SceneKind::Sphere, 4000),
        (SceneKind::Torus, 6000),
        (SceneKind::Tank, 20_000),
    ] {
        let r = compare::<f64>(kind, n, 2, 4, 48);
        eprintln!(
            "{kind:?}: {} hits, RMS {:.2e}, max {:.2e} spacings, {} of {} pixels disagree",
            r.hits, r.rms, r.max, r.disagree, r.compared
        );
        assert!(r.hits > 200, "{kind:?}: {} hits", r.hits);
        // Measured 4.1e-3 (torus) or less: 1.5 times that.
        assert!(r.rms < 6e-3, "{kind:?}: RMS {} spacings", r.rms);
        assert!(
            (r.disagree as f64) < 0.01 * r.compared as f64,
            "{kind:?}: {} of {} pixels disagree",
            r.disagree,
            r.compared
        );
    }
}

/// The f32 build (what the GPU port computes in) against the f64 oracle on the same scene and
/// camera: away from silhouettes, nearly every shared hit within 1e-3 spacing, and hardly a
/// pixel where one hits and the other misses.
#[test]
fn f32_matches_the_f64_oracle() {
    for (kind, n) in [(SceneKind::Sphere, 4000), (SceneKind::Torus, 6000)] {
        let scene = Scene::new(SceneSpec::new(kind, n, 3)).unwrap();
        let (pos, nrm) = scene.particles(0).surface_arrays();
        let params = SurfaceParams::default();
        let s64 = Surface::<f64>::build(&pos, Some(&nrm), &params).unwrap();
        let s32 = Surface::<f32>::build(&pos, Some(&nrm), &params).unwrap();
        let camera = slosh_testkit::framing_camera(&pos, 64);
        let mut p64 = Params::<f64>::new();
        p64.iterations = 3;
        let mut p32 = Params::<f32>::new();
        p32.iterations = 3;
        let (a, b) = (s64.render(&camera, &p64), s32.render(&camera, &p32));
        let depth: Vec<Option<f64>> = a.iter().map(|h| h.map(|h| h.t)).collect();
        let silhouette = slosh_testkit::silhouette_mask(&depth, 64, None);
        let spacing = scene.spacing();
        let (mut compared, mut shared, mut close, mut differ) = (0, 0, 0, 0);
        for i in 0..a.len() {
            if silhouette[i] {
                continue;
            }
            compared += 1;
            match (a[i], b[i]) {
                (Some(x), Some(y)) => {
                    shared += 1;
                    close += usize::from((x.t - y.t).abs() <= 1e-3 * spacing);
                }
                (None, None) => {}
                _ => differ += 1,
            }
        }
        eprintln!(
            "{kind:?}: {close} of {shared} shared hits within 1e-3 spacing, {differ} of {compared} differ"
        );
        assert!(shared > 500, "{kind:?}: {shared} shared hits");
        assert!(
            close * 1000 >= shared * 995,
            "{kind:?}: {close} of {shared}"
        );
        assert!(differ * 200 <= compared, "{kind:?}: {differ} of {compared}");
    }
}

/// `Camera::filling` looks from the framing's direction, at the distance where the bounds'
/// corners fill the frame's tighter direction with a tenth to spare: every corner in front of
/// the eye and inside the frame, the farthest out at 1 / 1.1 of its half-width or height.
#[test]
fn filling_puts_the_bounds_corners_just_inside_the_frame() {
    let bounds = [[0.0, 0.0, 0.0], [2.0, 1.0, 0.8]];
    for (w, h, up) in [
        (1020, 720, [0.0, 0.0, 1.0]),
        (400, 800, [0.0, 0.0, 1.0]),
        (640, 480, [0.0, 1.0, 0.0]),
    ] {
        let framed = Camera::framing(&bounds, 40.0, w, h, up);
        let filled = Camera::filling(&bounds, 40.0, w, h, up);
        assert_eq!((filled.target, filled.up), (framed.target, framed.up));
        let dir = |c: &Camera| {
            let d: [f64; 3] = std::array::from_fn(|a| c.eye[a] - c.target[a]);
            let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            (d.map(|v| v / l), l)
        };
        let ((a, near), (b, far)) = (dir(&filled), dir(&framed));
        assert!(
            (0..3).all(|k| (a[k] - b[k]).abs() < 1e-12),
            "{a:?} vs {b:?}"
        );
        // A long, low box in a landscape frame: nearer than the sphere around it allows (in a
        // portrait one the sphere's framing overflows the sides, and filling stands back).
        if w > h {
            assert!(near < far, "{near} not nearer than {far}");
        }
        // Each corner's place on the image plane, in units of the half-width and height.
        let basis = filled.basis();
        let dot = |u: [f64; 3], v: [f64; 3]| u[0] * v[0] + u[1] * v[1] + u[2] * v[2];
        let mut widest = 0.0f64;
        for k in 0..8 {
            let corner: [f64; 3] = std::array::from_fn(|ax| bounds[(k >> ax) & 1][ax]);
            let q: [f64; 3] = std::array::from_fn(|ax| corner[ax] - filled.eye[ax]);
            let z = dot(q, basis.forward);
            assert!(z > 0.0, "corner {corner:?} behind the eye");
            let norm = |v: [f64; 3]| dot(v, v);
            let sx = dot(q, basis.right) / norm(basis.right) / z;
            let sy = dot(q, basis.up) / norm(basis.up) / z;
            widest = widest.max(sx.abs()).max(sy.abs());
        }
        assert!(
            (widest - 1.0 / 1.1).abs() < 1e-9,
            "{w}×{h}: the farthest corner at {widest} of the frame"
        );
    }
}
