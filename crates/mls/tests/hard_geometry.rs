//! Hard cases of placement and incidence: a far offset (1e5) and grazing rays.

mod common;

use common::*;
use slosh_mls::*;
use slosh_scenes::{DVec3, SceneKind, SceneSpec, TrueRay};

#[test]
fn far_offset_keeps_f32_accuracy() {
    let mut s = SceneSpec::new(SceneKind::Sphere, 3000, 9);
    s.hard.offset = 1e5;
    let sc = scene(s);
    let plain = scene(SceneSpec::new(SceneKind::Sphere, 3000, 9));
    let s32 = surface_of::<f32>(&sc, 0, &SurfaceParams::default(), true);
    let p32 = surface_of::<f32>(&plain, 0, &SurfaceParams::default(), true);
    let cam = framing_camera(&sc, 32);
    let cam_plain = framing_camera(&plain, 32);
    let st = render_stats(&sc, &s32, &cam, &params(&s32, 2, 4), 0.5);
    let st_plain = render_stats(&plain, &p32, &cam_plain, &params(&p32, 2, 4), 0.5);
    eprintln!("offset 1e5 in f32: {st:?}\nno offset: {st_plain:?}");
    assert_eq!(st.non_finite, 0);
    // Recentred before conversion: the same accuracy as without the offset.
    assert!(
        st.rms < 0.01 && (st.rms - st_plain.rms).abs() < 0.005,
        "offset RMS {} vs {}",
        st.rms,
        st_plain.rms
    );
}

#[test]
fn grazing_rays_hit_or_miss_cleanly() {
    let sc = scene(SceneSpec::new(SceneKind::Sphere, 4000, 4));
    let surface = surface_of::<f64>(&sc, 0, &SurfaceParams::default(), true);
    let truth = sc.truth(0.0);
    let p = params(&surface, 2, 5);
    let (mut hits, mut exact_hits) = (0usize, 0usize);
    // Rays tangent to the sphere at heights 1 ± a few spacings (the sphere's centre moves by
    // its scene motion; step 0 is at the origin). The MLS sphere lies within a few thousandths
    // of a spacing of the true one, so only rays within a tenth of a spacing of the tangent
    // may see it differently.
    let grazing = 0.1 * sc.spacing();
    for k in -20..=20 {
        let z = 1.0 + k as f64 * 0.1 * sc.spacing();
        let origin = [-3.0, 0.0, z];
        let dir = [1.0, 0.0, 0.0];
        let exact = truth.intersect(
            &TrueRay::new(DVec3::from(origin), DVec3::from(dir)),
            0.0,
            f64::INFINITY,
        );
        exact_hits += usize::from(exact.is_some());
        if let Some(h) = surface.trace(origin, dir, &p) {
            hits += 1;
            assert!(h.t.is_finite() && h.normal.iter().all(|c| c.is_finite()));
            let d = truth.signed_distance(DVec3::from(h.position)).abs() / sc.spacing();
            assert!(d < 0.5, "grazing hit {d} spacings off at z = {z}");
            assert!(
                exact.is_some() || z < 1.0 + grazing,
                "a hit above the sphere at z = {z}"
            );
        } else {
            assert!(exact.is_none() || z > 1.0 - grazing, "missed at z = {z}");
        }
    }
    eprintln!("{hits} hits, {exact_hits} for the truth");
    assert!(
        hits.abs_diff(exact_hits) <= 2,
        "{hits} hits, the truth {exact_hits}"
    );
}
