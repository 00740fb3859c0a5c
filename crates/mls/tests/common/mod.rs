//! Shared by the hard-case test files: build a surface from a scene, render it, and measure.

#![allow(dead_code, clippy::unwrap_used)]

use std::collections::BTreeMap;

use slosh_mls::*;
use slosh_scenes::{DVec3, Scene, SceneSpec, TrueRay};

#[derive(Debug, Default)]
pub struct Stats {
    pub pixels: usize,
    pub hits: usize,
    /// Hits farther than `far` spacings from the true surface (e.g. on hard-case extras).
    pub off_surface: usize,
    /// RMS and max distance of on-surface hits to the truth, in spacings.
    pub rms: f64,
    pub max: f64,
    pub statuses: BTreeMap<String, usize>,
    /// Hits with a NaN or Inf anywhere in t, position or normal (must stay 0).
    pub non_finite: usize,
    /// Pixels where truth and tracer disagree about hit/miss (silhouettes included).
    pub disagree: usize,
}

pub fn surface_of<T: Real>(
    scene: &Scene,
    step: usize,
    params: &SurfaceParams,
    with_normals: bool,
) -> Surface<T> {
    let p = scene.particles(step);
    let (pos, nrm) = p.surface_arrays();
    Surface::<T>::build(&pos, with_normals.then_some(nrm.as_slice()), params).unwrap()
}

pub fn render_stats<T: Real>(
    scene: &Scene,
    surface: &Surface<T>,
    camera: &Camera,
    params: &Params<T>,
    far: f64,
) -> Stats {
    let truth = scene.truth(0.0);
    let spacing = scene.spacing();
    let hits = surface.render(camera, params);
    let mut s = Stats {
        pixels: hits.len(),
        ..Stats::default()
    };
    let mut sq = 0.0;
    let mut on = 0;
    for (i, h) in hits.iter().enumerate() {
        let (x, y) = (i as u32 % camera.width, i as u32 / camera.width);
        let (o, d) = camera.ray(x, y);
        let exact = truth.intersect(
            &TrueRay::new(DVec3::from(o), DVec3::from(d)),
            0.0,
            f64::INFINITY,
        );
        if h.is_some() != exact.is_some() {
            s.disagree += 1;
        }
        let Some(h) = h else { continue };
        s.hits += 1;
        *s.statuses.entry(format!("{:?}", h.status)).or_default() += 1;
        let finite = h.t.is_finite() && h.position.iter().chain(&h.normal).all(|c| c.is_finite());
        if !finite {
            s.non_finite += 1;
            continue;
        }
        let dist = truth.signed_distance(DVec3::from(h.position)).abs() / spacing;
        if dist > far {
            s.off_surface += 1;
            continue;
        }
        sq += dist * dist;
        on += 1;
        s.max = s.max.max(dist);
    }
    s.rms = (sq / on.max(1) as f64).sqrt();
    s
}

/// The shared framing camera (`slosh_testkit`) over the scene's particles at step 0.
pub fn framing_camera(scene: &Scene, size: u32) -> Camera {
    let (positions, _) = scene.particles(0).surface_arrays();
    slosh_testkit::framing_camera(&positions, size)
}

pub fn scene(spec: SceneSpec) -> Scene {
    Scene::new(spec).unwrap()
}

pub fn params<T: Real>(_surface: &Surface<T>, degree: u8, iterations: u32) -> Params<T> {
    let mut p = Params::new();
    p.degree = degree;
    p.iterations = iterations;
    p
}
