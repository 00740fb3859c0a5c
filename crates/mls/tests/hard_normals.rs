//! Hard cases of orientation: flipped normals, NaN and zero normals, a thin sheet whose two
//! faces have opposing normals, and no normals at all.

mod common;

use common::*;
use slosh_mls::*;
use slosh_scenes::{SceneKind, SceneSpec};

fn spec(kind: SceneKind, n: usize) -> SceneSpec {
    SceneSpec::new(kind, n, 11)
}

#[test]
fn flipped_normals_fall_back_to_the_covariance() {
    let mut s = spec(SceneKind::Sphere, 3000);
    s.hard.flip_normals = 0.3;
    let sc = scene(s);
    for degree in [2, 3] {
        let surface = surface_of::<f64>(
            &sc,
            0,
            &SurfaceParams {
                degree,
                ..Default::default()
            },
            true,
        );
        let st = render_stats(
            &sc,
            &surface,
            &framing_camera(&sc, 32),
            &params(&surface, degree, 4),
            0.5,
        );
        eprintln!("flips, degree {degree}: {st:?}");
        assert_eq!(st.non_finite, 0);
        assert!(st.hits > 100);
        assert!(
            st.rms < 0.05 && st.max < 0.3,
            "flipped normals: RMS {} max {} spacings",
            st.rms,
            st.max
        );
    }
}

#[test]
fn nan_and_zero_normals_never_reach_the_output() {
    let mut s = spec(SceneKind::Torus, 4000);
    s.hard.bad_normals = 0.3;
    let sc = scene(s);
    let surface = surface_of::<f32>(&sc, 0, &SurfaceParams::default(), true);
    assert!(
        surface
            .balls
            .iter()
            .all(|b| b.normal.is_finite() && b.poly.c.iter().all(|c| c.is_finite()))
    );
    let st = render_stats(
        &sc,
        &surface,
        &framing_camera(&sc, 32),
        &params(&surface, 2, 3),
        0.5,
    );
    eprintln!("bad normals: {st:?}");
    assert_eq!(st.non_finite, 0);
    assert!(st.rms < 0.05, "RMS {} spacings", st.rms);
}

#[test]
fn thin_sheet_faces_do_not_mix() {
    let sc = scene(spec(SceneKind::Sheet, 6000));
    let surface = surface_of::<f64>(&sc, 0, &SurfaceParams::default(), true);
    // The orientation check leaves both faces as they are.
    assert_eq!(surface.orientation.flipped_points, 0);
    // Neighbour lists never pair the two faces (opposing normals).
    let normals = surface.normals.as_ref().unwrap();
    for i in 0..surface.len() {
        assert!(
            surface
                .neighbours_of(i)
                .iter()
                .all(|&j| normals[j as usize].dot(normals[i]) >= 0.0)
        );
    }
    // Rays from above hit the top face, from below the bottom face, within a small fraction of
    // the gap.
    let gap = sc.sheet_gap();
    for (z, face) in [(2.0, gap / 2.0), (-2.0, -gap / 2.0)] {
        let p = params(&surface, 2, 4);
        for k in 0..20 {
            let x = -0.6 + 0.06 * k as f64;
            let hit = surface
                .trace([x, 0.1, z], [0.0, 0.0, -z.signum()], &p)
                .unwrap();
            assert!(hit.position.iter().all(|c| c.is_finite()));
            assert!(
                (hit.position[2] - face).abs() < 0.1 * gap,
                "hit z {} for face at {face}",
                hit.position[2]
            );
        }
    }
}

/// The thin sheet (two faces half a spacing apart, opposing normals) with 10 % and 20 % of
/// its normals reversed: a neighbour across the sheet lies 27° off a point's tangent plane,
/// and voting with its tangent weight (0.8) it outvoted the point's own face, so the repair
/// made more normals wrong than it found (1980 reversed in, 3754 wrong out; 3942 and 6744).
/// Against the truth (the face a point lies on gives its normal), the repair leaves fewer
/// wrong than it was given: at 10 %, fewer than a third (449 with the 4th power of the
/// weight); at 20 %, fewer than two thirds (2431).
#[test]
fn a_thin_sheets_reversed_normals_are_repaired_face_by_face() {
    for (flip, share) in [(0.1, 1.0 / 3.0), (0.2, 2.0 / 3.0)] {
        let mut s = SceneSpec::new(SceneKind::Sheet, 20_000, 1);
        s.hard.flip_normals = flip;
        let sc = scene(s);
        let (points, given) = sc.particles(0).surface_arrays();
        let surface = surface_of::<f64>(&sc, 0, &SurfaceParams::default(), true);
        let repaired = surface.normals.as_ref().unwrap();
        assert_eq!(repaired.len(), points.len());
        let face = |p: [f64; 3]| p[2].signum();
        let wrong_in = (0..points.len())
            .filter(|&i| given[i][2] * face(points[i]) < 0.0)
            .count();
        let wrong_out = (0..points.len())
            .filter(|&i| repaired[i].z * face(points[i]) < 0.0)
            .count();
        eprintln!(
            "{flip}: {wrong_in} wrong in, {wrong_out} wrong out, {:?}",
            surface.orientation
        );
        assert!(wrong_in > 1500, "{wrong_in} reversed");
        assert!(
            (wrong_out as f64) < share * wrong_in as f64,
            "{flip}: {wrong_out} wrong after the repair, {wrong_in} before"
        );
    }
}

/// The thin sheet with a tenth of its particles written twice, every normal correct: a twin
/// counts once in its neighbours' votes, so (almost) no normal is reversed. Counted as often
/// as written, twins crowded the votes, and 83 of this sheet's 21980 normals were reversed
/// (as `slosh gen sheet --points 20000 --duplicates 0.1`, seed 1); now 2.
#[test]
fn a_thin_sheet_written_twice_in_part_keeps_its_normals() {
    let mut s = SceneSpec::new(SceneKind::Sheet, 20_000, 1);
    s.hard.duplicates = 0.1;
    let sc = scene(s);
    let surface = surface_of::<f64>(&sc, 0, &SurfaceParams::default(), true);
    let repair = surface.orientation;
    eprintln!("{} points: {repair:?}", surface.len());
    assert!(surface.len() > 21_000, "{} points", surface.len());
    // 0.05 % of the points.
    assert!(repair.flipped_points <= 10, "{repair:?}");
}

#[test]
fn without_normals_the_covariance_plane_still_finds_the_surface() {
    let sc = scene(spec(SceneKind::Sphere, 3000));
    let sp = SurfaceParams {
        normals: NormalsMode::Covariance,
        ..Default::default()
    };
    let surface = surface_of::<f64>(&sc, 0, &sp, false);
    let mut p = params(&surface, 2, 4);
    p.normals = NormalsMode::Covariance;
    let st = render_stats(&sc, &surface, &framing_camera(&sc, 32), &p, 0.5);
    eprintln!("no normals: {st:?}");
    assert_eq!(st.non_finite, 0);
    assert!(st.rms < 0.05, "RMS {} spacings", st.rms);
}

/// Cluster lists lose nothing: each point's own list comes back exactly from its cluster's
/// union by the reach and normal rule, capped lists included, across both faces of a sheet.
#[test]
fn cluster_lists_expand_to_the_neighbour_lists() {
    for (kind, cap) in [
        (SceneKind::Sphere, 128),
        (SceneKind::Sphere, 40),
        (SceneKind::Sheet, 128),
    ] {
        let sc = scene(spec(kind, 3000));
        let surface = surface_of::<f64>(
            &sc,
            0,
            &SurfaceParams {
                neighbour_cap: cap,
                ..Default::default()
            },
            true,
        );
        let lists = surface
            .neighbours
            .whole()
            .expect("the CPU keeps every list");
        let (cs, ci) = cluster_lists(lists, 32);
        let candidates = ClusterCandidates {
            points: &surface.points,
            normals: surface.normals.as_deref(),
            reach: &surface.reach,
            size: 32,
            cluster_start: &cs,
            cluster_ids: &ci,
        };
        let (start, ids) = candidates.expand();
        eprintln!(
            "{kind:?} cap {cap}: {} capped, {:.1} ids per point in lists, {:.1} in clusters",
            surface.capped,
            lists.total() as f64 / surface.len() as f64,
            ci.len() as f64 / surface.len() as f64
        );
        assert_eq!(start, lists.start(), "{kind:?} cap {cap}");
        assert_eq!(ids, lists.ids().collect::<Vec<_>>(), "{kind:?} cap {cap}");
        // The counts alone (what `slosh inspect` summarises) by the same rule.
        let counts = candidates.neighbour_counts();
        let expected: Vec<u32> = start.windows(2).map(|w| w[1] - w[0]).collect();
        assert_eq!(counts, expected, "{kind:?} cap {cap}");
    }
}

/// Reversed normals are repaired before anything uses them: on the sphere, the torus and the
/// tank with 10 % and 30 % of normals reversed, traced at 256×256 with 5 iterations, every hit
/// (none excluded as off-surface) lies as close to the truth as the clean scene's, within
/// 1.5× its RMS, no droplet sphere appears that the clean scene lacks, and nothing is NaN.
#[test]
fn reversed_normals_are_repaired_before_use() {
    for kind in [SceneKind::Sphere, SceneKind::Torus, SceneKind::Tank] {
        let measure = |flip: f64| {
            let mut s = SceneSpec::new(kind, 20_000, 11);
            s.hard.flip_normals = flip;
            let sc = scene(s);
            let surface = surface_of::<f64>(&sc, 0, &SurfaceParams::default(), true);
            let st = render_stats(
                &sc,
                &surface,
                &framing_camera(&sc, 256),
                &params(&surface, 2, 5),
                f64::INFINITY,
            );
            (st, surface.spheres.len(), surface.orientation)
        };
        let (clean, clean_spheres, clean_repair) = measure(0.0);
        assert_eq!(clean_repair.flipped_points, 0, "{kind:?}: {clean_repair:?}");
        assert!(clean.hits > 10_000, "{kind:?}: {clean:?}");
        for flip in [0.1, 0.3] {
            let (st, spheres, repair) = measure(flip);
            eprintln!(
                "{kind:?} {:.0} % reversed: RMS {:.2e} (clean {:.2e}) spacings, max {:.3}, {} hits \
                 (clean {}), spheres {spheres} (clean {clean_spheres}), {repair:?}",
                flip * 100.0,
                st.rms,
                clean.rms,
                st.max,
                st.hits,
                clean.hits
            );
            assert_eq!(st.non_finite, 0, "{kind:?} {flip}");
            assert!(
                st.rms <= 1.5 * clean.rms,
                "{kind:?} {flip}: RMS {} against clean {}",
                st.rms,
                clean.rms
            );
            assert!(
                spheres <= clean_spheres,
                "{kind:?} {flip}: {spheres} spheres"
            );
            assert!(
                st.hits.abs_diff(clean.hits) <= clean.hits / 200,
                "{kind:?} {flip}: {} hits against {}",
                st.hits,
                clean.hits
            );
            assert!(repair.flipped_points > 0, "{kind:?} {flip}: {repair:?}");
        }
    }
}

/// A whole region reversed (a cap of the sphere, about 10 % of its points, every normal in it
/// pointing inward): votes cannot turn a patch from inside, so the patch goes back whole.
#[test]
fn a_reversed_patch_is_turned_back_whole() {
    let sc = scene(spec(SceneKind::Sphere, 20_000));
    let (pos, mut nrm) = sc.particles(0).surface_arrays();
    let top = pos.iter().map(|p| p[2]).fold(f64::MIN, f64::max);
    let mut reversed = 0;
    for (p, n) in pos.iter().zip(nrm.iter_mut()) {
        if p[2] > top - 0.2 {
            *n = n.map(|c| -c);
            reversed += 1;
        }
    }
    let surface = Surface::<f64>::build(&pos, Some(&nrm), &SurfaceParams::default()).unwrap();
    eprintln!("{reversed} reversed: {:?}", surface.orientation);
    assert_eq!(surface.orientation.flipped_points, reversed);
    let clean = surface_of::<f64>(&sc, 0, &SurfaceParams::default(), true);
    let normals = surface.normals.as_ref().unwrap();
    let clean_normals = clean.normals.as_ref().unwrap();
    assert!(
        normals
            .iter()
            .zip(clean_normals)
            .all(|(a, b)| a.dot(*b) > 0.0)
    );
}

/// A clean droplets scene (every normal the truth's): no more than 2.5 % of its normals end
/// reversed, no patch is reversed whole, and no more than 2.5 % of the hits (128×128, 3
/// iterations) turn their normal away from the true surface's. A droplet of a few particles
/// has no 16 nearest of its own; voting with others across the gap to the next droplet,
/// whose normals face it, reversed 164 of these 1663 normals (9.9 %), 169 in one patch, and
/// 109 of 3408 hits (3.2 %) faced away. Now 35 (where droplets touch) and 67 of 3405.
#[test]
fn a_clean_droplets_scene_keeps_its_normals() {
    let mut s = SceneSpec::new(SceneKind::Droplets, 20_000, 1);
    s.droplets = 200;
    let sc = scene(s);
    let (points, given) = sc.particles(0).surface_arrays();
    let surface = surface_of::<f64>(&sc, 0, &SurfaceParams::default(), true);
    let repaired = surface.normals.as_ref().unwrap();
    let reversed = (0..points.len())
        .filter(|&i| {
            let (g, r) = (given[i], repaired[i]);
            g[0] * r.x + g[1] * r.y + g[2] * r.z < 0.0
        })
        .count();
    let truth = sc.truth(0.0);
    let hits = surface.render(&framing_camera(&sc, 128), &params(&surface, 2, 3));
    let hits: Vec<_> = hits.iter().flatten().collect();
    let away = hits
        .iter()
        .filter(|h| {
            let n = truth.normal_at(slosh_scenes::DVec3::from(h.position));
            n.dot(slosh_scenes::DVec3::from(h.normal)) < 0.0
        })
        .count();
    eprintln!(
        "{} points, {reversed} reversed: {:?}; {away} of {} hits face away",
        points.len(),
        surface.orientation,
        hits.len()
    );
    assert!(points.len() > 1500, "{} points", points.len());
    assert!(reversed * 40 <= points.len(), "{reversed} reversed");
    assert_eq!(surface.orientation.flipped_patches, 0);
    assert!(hits.len() > 3000, "{} hits", hits.len());
    assert!(
        away * 40 <= hits.len(),
        "{away} of {} hits face away",
        hits.len()
    );
}
