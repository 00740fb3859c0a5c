//! `slosh render --steps`: one camera frames the whole sequence, the union of its steps'
//! extents, so that fluid which spreads (a dam break's column over the floor) stays in the
//! frame after the first step.

use crate::util::{aov_hits, bake_case, generate, slosh};

#[test]
fn a_sequence_is_framed_by_every_step_it_draws() {
    let dir = tempfile::tempdir().unwrap();
    // Step 1 lies 3 radii from step 0: a unit sphere moved by (3, 3, 3).
    let (near, far) = (dir.path().join("near"), dir.path().join("far"));
    generate(&near, &["sphere", "--points", "3000", "--steps", "2"]);
    generate(
        &far,
        &[
            "sphere", "--points", "3000", "--steps", "2", "--offset", "3",
        ],
    );
    for variable in ["geo", "normal", "pressure", "surface"] {
        let name = format!("sphere.{variable}00001");
        std::fs::copy(far.join(&name), near.join(&name)).unwrap();
    }
    let cache = dir.path().join("cache");
    let (ok, _, err) = bake_case(&near.join("sphere.case"), &cache, &["--quiet"]);
    assert!(ok, "bake failed: {err}");
    let (ok, out, err) = slosh(&[
        "render",
        cache.to_str().unwrap(),
        "--cpu",
        "--steps",
        "0..2",
        "--size",
        "64x64",
        "--aov",
        dir.path().join("h{:05}.npy").to_str().unwrap(),
    ]);
    assert!(ok, "{out}{err}");
    // Each sphere whole in the frame: hit pixels, none on the frame's edge.
    let hits = |i: usize| {
        let hit = aov_hits(&dir.path().join(format!("h{i:05}.npy")), 64);
        let on_edge = hit
            .iter()
            .filter(|&&(x, y)| x == 0 || y == 0 || x == 63 || y == 63)
            .count();
        (hit.len(), on_edge)
    };
    let (first, last) = (hits(0), hits(1));
    for (step, (n, on_edge)) in [(0, first), (1, last)] {
        assert!(n > 40, "step {step}: {n} hit pixels");
        assert_eq!(
            on_edge, 0,
            "step {step}: {on_edge} hit pixels on the frame's edge"
        );
    }
    // Alike in size: the camera frames both from afar, neither from up close.
    assert!(
        first.0 * 2 > last.0 && last.0 * 2 > first.0,
        "{} and {} hit pixels",
        first.0,
        last.0
    );
}
