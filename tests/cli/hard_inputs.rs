//! Inputs a real user brings that earlier broke or misled (issue 25, items 9, 14 and 15):
//! geometry at any scale, EnSight cases slosh cannot read said as such, clouds of bare OBJ
//! vertices.

use std::path::Path;

use crate::util::{aov_hits, bake_case, slosh};

/// A unit sphere of `n` points (a Fibonacci lattice) with outward normals, scaled by
/// `scale`, as an ASCII PLY of doubles.
fn sphere_ply(path: &Path, n: usize, scale: f64) {
    let mut text = format!(
        "ply\nformat ascii 1.0\nelement vertex {n}\nproperty double x\nproperty double y\n\
         property double z\nproperty double nx\nproperty double ny\nproperty double nz\n\
         end_header\n"
    );
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    for i in 0..n {
        let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
        let r = (1.0 - z * z).sqrt();
        let (x, y) = (r * (golden * i as f64).cos(), r * (golden * i as f64).sin());
        text += &format!(
            "{:e} {:e} {:e} {x} {y} {z}\n",
            x * scale,
            y * scale,
            z * scale
        );
    }
    std::fs::write(path, text).unwrap();
}

/// Hit pixels of a 64×64 render of step 0 of `cache` with the CPU tracer.
fn hit_pixels(cache: &Path, npy: &Path) -> usize {
    let (ok, out, err) = slosh(&[
        "render",
        cache.to_str().unwrap(),
        "--cpu",
        "--step",
        "0",
        "--size",
        "64x64",
        "--aov",
        npy.to_str().unwrap(),
    ]);
    assert!(ok, "{out}{err}");
    let bytes = std::fs::read(npy).unwrap();
    let values: &[f32] = bytemuck::cast_slice(&bytes[128..]);
    values.chunks_exact(8).filter(|p| p[7] != 0.0).count()
}

/// Item 9: a sphere frames and renders alike at any scale: the framing camera has no
/// absolute floor on the length it frames.
#[test]
fn tiny_and_huge_geometry_render_like_unit_geometry() {
    let dir = tempfile::tempdir().unwrap();
    let mut counts = Vec::new();
    for scale in [1.0, 1e-10, 1e-15, 1e4] {
        let tag = format!("{scale:e}");
        let ply = dir.path().join(format!("s{tag}.ply"));
        sphere_ply(&ply, 3000, scale);
        let run = dir.path().join(format!("run{tag}"));
        let (ok, _, err) = slosh(&[
            "gen",
            "from-file",
            ply.to_str().unwrap(),
            "--out",
            run.to_str().unwrap(),
        ]);
        assert!(ok, "{err}");
        let case = std::fs::read_dir(&run)
            .unwrap()
            .flatten()
            .map(|e| e.path())
            .find(|p| p.extension().is_some_and(|e| e == "case"))
            .unwrap();
        let cache = dir.path().join(format!("cache{tag}"));
        let (ok, out, err) = bake_case(&case, &cache, &["--quiet"]);
        assert!(ok, "{out}{err}");
        counts.push((
            scale,
            hit_pixels(&cache, &dir.path().join(format!("{tag}.npy"))),
        ));
    }
    let unit = counts[0].1;
    assert!(unit > 500, "{counts:?}");
    for (scale, n) in &counts {
        assert!(
            n.abs_diff(unit) * 50 <= unit,
            "scale {scale}: {n} hit pixels, {unit} at unit scale ({counts:?})"
        );
    }
}

fn write(path: &Path, text: &str) {
    std::fs::write(path, text).unwrap();
}

/// Item 14: EnSight cases slosh cannot read say what slosh reads, and what the case holds.
#[test]
fn unreadable_cases_say_what_slosh_reads() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A surface mesh: triangles, no point elements, no measured file.
    write(
        &d.join("tri.geo"),
        "tri\ngeometry\nnode id off\nelement id off\npart\n1\nmesh\ncoordinates\n3\n0\n1\n0\n\
         0\n0\n1\n0\n0\n0\ntria3\n1\n1 2 3\n",
    );
    write(
        &d.join("tri.case"),
        "FORMAT\ntype: ensight gold\nGEOMETRY\nmodel: tri.geo\n",
    );
    let (ok, _, err) = bake_case(&d.join("tri.case"), &d.join("c1"), &["--quiet"]);
    assert!(!ok);
    assert!(
        err.contains("slosh reads particles from `point` elements or a measured file")
            && err.contains("only tria3 elements")
            && !err.contains("ask for all nodes"),
        "{err}"
    );
    // change_coords_only: the steps after the first are refused by name.
    let geo = |x: f64| {
        let xs: String = (0..4)
            .map(|i| format!("{}\n", x + i as f64 * 0.1))
            .collect();
        format!(
            "p\ngeometry\nnode id off\nelement id off\npart\n1\nparticles\ncoordinates\n4\n\
             {xs}0\n0.1\n0\n0.1\n0\n0\n0.1\n0.1\npoint\n4\n1\n2\n3\n4\n"
        )
    };
    write(&d.join("p.0000.geo"), &geo(0.0));
    write(&d.join("p.0001.geo"), &geo(0.5));
    write(
        &d.join("p.case"),
        "FORMAT\ntype: ensight gold\nGEOMETRY\nmodel: 1 p.****.geo change_coords_only\nTIME\n\
         time set: 1\nnumber of steps: 2\nfilename start number: 0\nfilename increment: 1\n\
         time values: 0 1\n",
    );
    let (ok, _, err) = bake_case(&d.join("p.case"), &d.join("c2"), &["--quiet"]);
    assert!(!ok);
    assert!(
        err.contains("step 1") && err.contains("change_coords_only"),
        "{err}"
    );
    // Coincident particles: said as such, not as a point without a radius.
    let ply = d.join("same.ply");
    let mut text = "ply\nformat ascii 1.0\nelement vertex 50\nproperty float x\nproperty float y\n\
                    property float z\nend_header\n"
        .to_string();
    text += &"0.5 0.5 0.5\n".repeat(50);
    write(&ply, &text);
    let (ok, _, err) = bake_case(&ply, &d.join("c3"), &["--quiet"]);
    assert!(!ok);
    assert!(
        err.contains("coincide") && !err.contains("no positive radius"),
        "{err}"
    );
}

/// Item 15: an OBJ of bare `v` and `vn` lines (a scanner's or solver's export) is a point
/// cloud, its normals paired by order; a malformed line is named.
#[test]
fn obj_clouds_without_faces_are_read() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("cloud.obj");
    write(
        &obj,
        "# scanner export\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nvn 0 0 2\nvn 1 0 0\nvn 0 1 0\n\
         vn 0 0 1\n",
    );
    let out = dir.path().join("cloud");
    let (ok, _, err) = slosh(&[
        "gen",
        "from-file",
        obj.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let case = slosh_ensight::Case::open(out.join("cloud.case")).unwrap();
    let step = case
        .read_step(
            0,
            &slosh_ensight::StepRequest {
                normals: Some("normal".into()),
                ..slosh_ensight::StepRequest::default()
            },
        )
        .unwrap();
    assert_eq!(step.positions.len(), 4);
    assert_eq!(step.positions[1], [1.0, 0.0, 0.0]);
    let normals = step.normals.unwrap();
    assert_eq!(normals[0], [0.0, 0.0, 1.0]);
    assert_eq!(normals[1], [1.0, 0.0, 0.0]);
    // A malformed vertex line is named by its line number.
    let bad = dir.path().join("bad.obj");
    write(&bad, "v 0 0 0\nv 1 x 0\n");
    let (ok, _, err) = slosh(&[
        "gen",
        "from-file",
        bad.to_str().unwrap(),
        "--out",
        dir.path().join("bad").to_str().unwrap(),
    ]);
    assert!(!ok && err.contains("bad.obj: line 2"), "{err}");
}

/// `slosh gen sphere` of 500 particles and `steps` steps, as Gold ASCII, into `run`.
fn gold_sphere(run: &Path, steps: usize) {
    let (ok, _, err) = slosh(&[
        "gen",
        "sphere",
        "--points",
        "500",
        "--steps",
        &steps.to_string(),
        "--format",
        "gold-ascii",
        "--out",
        run.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
}

/// Step `index` of the `gold_sphere` run replaced by `points` (x, y, z as written), each a
/// surface particle whose normal is its position: in Gold ASCII every x, then every y, then
/// every z, and each variable likewise per component.
fn write_gold_step(run: &Path, index: usize, points: &[[&str; 3]]) {
    let n = points.len();
    let column = |c: usize| -> String { points.iter().map(|p| format!("{}\n", p[c])).collect() };
    let xyz = format!("{}{}{}", column(0), column(1), column(2));
    let ids: String = (1..=n).map(|i| format!("{i}\n")).collect();
    write(
        &run.join(format!("sphere.geo{index:05}")),
        &format!(
            "particles\nEnSight point data\nnode id assign\nelement id assign\npart\n1\n\
             particles\ncoordinates\n{n}\n{xyz}point\n{n}\n{ids}"
        ),
    );
    let ones = "1.0\n".repeat(n);
    for (v, values) in [
        ("normal", xyz.clone()),
        ("pressure", ones.clone()),
        ("surface", ones),
    ] {
        write(
            &run.join(format!("sphere.{v}{index:05}")),
            &format!("{v}\npart\n1\ncoordinates\n{values}"),
        );
    }
}

/// A step whose particles lie in two piles (a solver parking them at two places) fails with
/// what it is and the file it came from; the steps around it bake.
#[test]
fn a_step_of_two_piles_fails_by_name_and_file() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    gold_sphere(&run, 3);
    let mut piles = vec![["0.25", "0.5", "0.5"]; 30];
    piles.extend(vec![["1.25", "0.5", "0.5"]; 40]);
    write_gold_step(&run, 1, &piles);
    let (ok, out, err) = bake_case(&run.join("sphere.case"), &dir.path().join("cache"), &[]);
    assert!(!ok, "{out}");
    assert!(
        out.contains("baked 2 steps") && out.contains("1 failed"),
        "{out}"
    );
    let expected = format!(
        "step 1: {}: all 70 points lie in piles of coincident points (2 distinct positions)",
        run.join("sphere.geo00001").display()
    );
    assert!(err.contains(&expected), "{err}");
    assert!(!err.contains("no positive radius"), "{err}");
}

/// Item 16: a step without particles (a Lagrangian run before its first injection: a point
/// part of no elements) is a valid step: baked as empty, verified, reported in the summary
/// and by `inspect`, rendered as background, and the series framed by its other steps.
#[test]
fn empty_steps_are_valid_steps() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    gold_sphere(&run, 3);
    // Step 0 before the injection: a point part of no elements, and variables of no values.
    write_gold_step(&run, 0, &[]);
    let cache = dir.path().join("cache");
    let (ok, out, err) = bake_case(&run.join("sphere.case"), &cache, &["--fields", "pressure"]);
    assert!(ok, "{out}{err}");
    assert!(
        out.contains("baked 3 steps") && out.contains("0 failed"),
        "{out}"
    );
    assert!(
        out.contains("1 step holds no particles and was baked as an empty step: 0"),
        "{out}"
    );
    let (ok, out, err) = slosh(&["inspect", cache.to_str().unwrap(), "--verify"]);
    assert!(ok, "{out}{err}");
    let row = out
        .lines()
        .find(|l| l.trim_start().starts_with("0 "))
        .unwrap();
    assert!(row.contains(" 0 ") && row.ends_with("verified"), "{row}");
    // No bytes per point where there are no points: the row says "-", the step "no points".
    let columns: Vec<&str> = row.split_whitespace().collect();
    assert_eq!(columns[4], "-", "{row}");
    let (ok, out, err) = slosh(&["inspect", cache.join("step-00000.slc").to_str().unwrap()]);
    assert!(ok, "{out}{err}");
    assert!(
        out.contains("no points:") && !out.contains("bytes per point"),
        "{out}"
    );
    // Rendered: step 0 is background; the others are framed by their extents together.
    let (ok, out, err) = slosh(&[
        "render",
        cache.to_str().unwrap(),
        "--cpu",
        "--steps",
        "0..3",
        "--size",
        "48x48",
        "--aov",
        dir.path().join("h{:05}.npy").to_str().unwrap(),
    ]);
    assert!(ok, "{out}{err}");
    let hits = |i: usize| aov_hits(&dir.path().join(format!("h{i:05}.npy")), 48).len();
    assert_eq!(hits(0), 0);
    for i in [1, 2] {
        let n = hits(i);
        assert!(n > 200 && n < 48 * 48 * 9 / 10, "step {i}: {n} hit pixels");
    }
}

/// A step whose particles, once selected, are too few to size a surface (an injection's first
/// particle; one finite among non-finite ones) is baked as an empty step that records what it
/// dropped, not a failure; one with no finite particle at all is a failure that says so, and
/// the batch goes on past it.
#[test]
fn a_lone_particle_is_an_empty_step_and_no_finite_one_a_failure() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    gold_sphere(&run, 4);
    write_gold_step(&run, 0, &[["0.1", "0.2", "0.9"]]);
    write_gold_step(
        &run,
        1,
        &[
            ["0.1", "0.2", "0.9"],
            ["nan", "0.2", "0.9"],
            ["0.3", "inf", "0.9"],
        ],
    );
    write_gold_step(&run, 2, &[["nan", "0.2", "0.9"], ["0.3", "0.2", "nan"]]);
    let cache = dir.path().join("cache");
    let (ok, out, err) = bake_case(&run.join("sphere.case"), &cache, &[]);
    assert!(!ok, "{out}{err}");
    assert!(
        out.contains("baked 3 steps") && out.contains("1 failed"),
        "{out}"
    );
    assert!(
        out.contains(
            "2 steps keep fewer than two particles after selection (too few to size a surface) \
             and were baked as empty steps: 0, 1"
        ),
        "{out}"
    );
    // Step 2 failed, so only step 1's dropped particles are a baked step's.
    assert!(
        out.contains("particles with a non-finite coordinate were dropped in 1 step: 1 (2 of 3)"),
        "{out}"
    );
    assert!(
        err.contains("step 2: ") && err.contains("none of the 2 particles has finite coordinates"),
        "{err}"
    );
    assert!(!cache.join("step-00002.slc").exists());
    for (index, says) in [
        (
            0,
            "0 kept of 1 read (0 non-finite, 0 not on the surface, 1 too few to size a surface dropped)",
        ),
        (
            1,
            "0 kept of 3 read (2 non-finite, 0 not on the surface, 1 too few to size a surface dropped)",
        ),
    ] {
        let file = cache.join(format!("step-{index:05}.slc"));
        let (ok, out, err) = slosh(&["inspect", file.to_str().unwrap(), "--verify"]);
        assert!(
            ok && out.contains(says) && out.contains("ok: footer checksum, every section"),
            "{out}{err}"
        );
    }
    // The steps around them bake as before.
    let (ok, out, err) = slosh(&["inspect", cache.join("step-00003.slc").to_str().unwrap()]);
    assert!(ok && out.contains("500 kept of 500 read"), "{out}{err}");
}

/// A pile of particles at one place on the surface (a solver parking particles, or writing a
/// source's inflow before it moves): PLOC chained the pile's equal leaf boxes one per level,
/// a tree 388 deep that verified, was written, and that the player then refused. The bake
/// keeps within the tracer's depth, the verifier holds it to that, and the step renders.
#[test]
fn a_pile_of_coincident_particles_on_the_surface_bakes_a_walkable_tree() {
    let dir = tempfile::tempdir().unwrap();
    let ply = dir.path().join("pile.ply");
    sphere_ply(&ply, 20_000, 1.0);
    let mut text = std::fs::read_to_string(&ply).unwrap();
    text = text.replace("element vertex 20000", "element vertex 23000");
    text += &"0 0 1 0 0 1\n".repeat(3000);
    std::fs::write(&ply, text).unwrap();
    let cache = dir.path().join("cache");
    let (ok, out, err) = bake_case(&ply, &cache, &["--quiet"]);
    assert!(ok, "{out}{err}");
    let (ok, out, err) = slosh(&["inspect", cache.join("step-00000.slc").to_str().unwrap()]);
    assert!(ok, "{out}{err}");
    let depth: u64 = out
        .lines()
        .find_map(|l| l.strip_prefix("bvh "))
        .and_then(|l| l.rsplit("depth ").next())
        .and_then(|d| d.trim().parse().ok())
        .unwrap_or_else(|| panic!("no BVH depth in {out}"));
    assert!(depth <= slosh_cache::MAX_BVH_DEPTH, "depth {depth}");
    let (ok, out, err) = slosh(&["inspect", cache.to_str().unwrap(), "--verify"]);
    assert!(ok && out.contains("verified"), "{out}{err}");
    assert!(hit_pixels(&cache, &dir.path().join("aov.npy")) > 500);
}

/// A sphere of 5000 particles with the `slosh gen` hard-case `flags`, one step, baked into
/// `DIR/cache-NAME`; the cache.
fn baked_sphere(dir: &Path, name: &str, flags: &[&str]) -> std::path::PathBuf {
    let run = dir.join(format!("run-{name}"));
    let mut args = vec!["sphere", "--points", "5000", "--steps", "1"];
    args.extend(flags);
    crate::util::generate(&run, &args);
    let cache = dir.join(format!("cache-{name}"));
    let (ok, out, err) = bake_case(&run.join("sphere.case"), &cache, &["--quiet"]);
    assert!(ok, "{out}{err}");
    cache
}

/// Most particles written twice (a solver writing a block of its particles twice): every
/// step failed ("droplet sphere 0 … has no positive radius"), the dense spacing being the
/// median nearest distance, 0. It bakes, verifies and renders.
#[test]
fn mostly_duplicated_particles_bake() {
    let dir = tempfile::tempdir().unwrap();
    let cache = baked_sphere(dir.path(), "twice", &["--duplicates", "0.7"]);
    assert!(hit_pixels(&cache, &dir.path().join("aov.npy")) > 500);
}

/// The same particles written twice and then moved by noise (σ 0.1 spacings): twins a little
/// apart made the dense spacing a fraction of the spacing, and every particle was drawn as a
/// spray sphere with no surface and no error. Now the step's balls are fitted (none spray)
/// and it draws as many pixels as the particles written once.
#[test]
fn particles_written_twice_with_noise_draw_a_surface() {
    let dir = tempfile::tempdir().unwrap();
    let mut hits = Vec::new();
    for duplicates in ["0", "0.7"] {
        let cache = baked_sphere(
            dir.path(),
            duplicates,
            &["--noise", "0.1", "--duplicates", duplicates],
        );
        let (ok, out, err) = slosh(&["inspect", cache.join("step-00000.slc").to_str().unwrap()]);
        assert!(ok, "{err}");
        assert!(out.contains("droplets   0 spheres"), "{out}");
        hits.push(hit_pixels(
            &cache,
            &dir.path().join(format!("aov{duplicates}.npy")),
        ));
    }
    // Hit pixels within 2 % of the particles written once.
    assert!(hits[1].abs_diff(hits[0]) * 50 <= hits[0], "{hits:?}");
}

/// Particles a solver parked at sentinels (1e30, −9999) are dropped as far beyond the rest,
/// counted and named in the summary; kept, one would set the frame, and the sphere, in f32
/// local coordinates, would round to one point (the step was baked as two droplet spheres and
/// no fit). A droplet flung 50 sizes away stays.
#[test]
fn sentinel_particles_are_dropped_and_the_surface_kept() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    gold_sphere(&run, 2);
    let n = 500;
    let mut points: Vec<[String; 3]> = (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let phi = i as f64 * 2.399_963_229_728_653;
            let r = (1.0 - z * z).sqrt();
            [r * phi.cos(), r * phi.sin(), z].map(|c| format!("{c:.6e}"))
        })
        .collect();
    for p in [
        ["1e30", "1e30", "1e30"],
        ["-9999", "0.5", "0.5"],
        ["100", "0", "0"],
    ] {
        points.push(p.map(String::from));
    }
    let points: Vec<[&str; 3]> = points
        .iter()
        .map(|p| [p[0].as_str(), p[1].as_str(), p[2].as_str()])
        .collect();
    write_gold_step(&run, 1, &points);
    let cache = dir.path().join("cache");
    let (ok, out, err) = bake_case(&run.join("sphere.case"), &cache, &["--device", "cpu"]);
    assert!(ok, "{out}{err}");
    assert!(
        out.contains("particles far beyond the rest were dropped in 1 step: 1 (2 of 503)"),
        "{out}"
    );
    let file = cache.join("step-00001.slc");
    let (ok, out, err) = slosh(&["inspect", file.to_str().unwrap(), "--verify"]);
    assert!(ok, "{out}{err}");
    assert!(
        out.contains(
            "501 kept of 503 read (0 non-finite, 2 far beyond the rest, 0 not on the surface dropped)"
        ),
        "{out}"
    );
    // The sphere is fitted (the droplet at 100 is its own sphere), not lost to rounding.
    assert!(out.contains("fits       500 full, 0 degraded"), "{out}");
    assert!(out.contains("droplets   1 spheres from 1 points"), "{out}");
    // A render of the raw case says so for the step it bakes.
    let (ok, out, err) = slosh(&[
        "render",
        run.join("sphere.case").to_str().unwrap(),
        "--cache",
        dir.path().join("raw-cache").to_str().unwrap(),
        "--cpu",
        "--steps",
        "1..2",
        "--size",
        "32x32",
        "--out",
        dir.path().join("f{:05}.png").to_str().unwrap(),
    ]);
    assert!(ok, "{out}{err}");
    assert!(
        out.contains("baked step 1 (501 points, ")
            && out.contains("; dropped 2 far beyond the rest)"),
        "{out}"
    );
}
