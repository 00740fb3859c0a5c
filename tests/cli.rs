//! End-to-end tests of the `slosh` binary: gen → EnSight files → info, VTK reading what we
//! write, PLY/OBJ conversion, and errors that name the file.

#![allow(clippy::unwrap_used)] // helpers of tests, where a failed unwrap is a failed test

use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::Value;
use slosh_ensight::{Case, FieldValues, StepRequest};

mod common;

use common::{bake_case, generate, in_ci, slosh};

#[test]
fn gen_then_info_agree_with_truth_json() {
    let dir = tempfile::tempdir().unwrap();
    generate(
        dir.path(),
        &[
            "tank",
            "--points",
            "5000",
            "--steps",
            "4",
            "--format",
            "e6-binary",
            "--droplets",
            "10",
        ],
    );
    let truth: Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("truth.json")).unwrap()).unwrap();
    let (ok, json, err) = slosh(&[
        "info",
        dir.path().join("tank.case").to_str().unwrap(),
        "--json",
    ]);
    assert!(ok, "{err}");
    let info: Value = serde_json::from_str(&json).unwrap();
    assert_eq!(info["format"], "ensight6");
    assert_eq!(info["encoding"], "cbinary");
    assert_eq!(info["byte_order"], "little");
    let steps = info["steps"].as_array().unwrap();
    assert_eq!(steps.len(), 4);
    for (s, t) in steps.iter().zip(truth["steps"].as_array().unwrap()) {
        assert_eq!(s["points"], t["points"]);
        assert_eq!(s["time"], t["time"]);
        let hi_z = s["bounds"][1][2].as_f64().unwrap();
        assert!(
            hi_z > 0.5,
            "surface above the still level somewhere: {hi_z}"
        );
    }
    let (ok, human, _) = slosh(&["info", dir.path().join("tank.case").to_str().unwrap()]);
    assert!(
        ok && human.contains("EnSight 6, C Binary, little-endian") && human.contains("pressure")
    );
}

#[test]
fn gen_is_deterministic_and_big_endian_reads_the_same() {
    let a = tempfile::tempdir().unwrap();
    let b = tempfile::tempdir().unwrap();
    let c = tempfile::tempdir().unwrap();
    generate(
        a.path(),
        &[
            "torus", "--points", "3000", "--steps", "2", "--noise", "0.1", "--seed", "5",
        ],
    );
    generate(
        b.path(),
        &[
            "torus", "--points", "3000", "--steps", "2", "--noise", "0.1", "--seed", "5",
        ],
    );
    generate(
        c.path(),
        &[
            "torus",
            "--points",
            "3000",
            "--steps",
            "2",
            "--noise",
            "0.1",
            "--seed",
            "5",
            "--byte-order",
            "big",
        ],
    );
    for f in ["torus.geo00001", "torus.normal00001", "truth.json"] {
        assert_eq!(
            std::fs::read(a.path().join(f)).unwrap(),
            std::fs::read(b.path().join(f)).unwrap(),
            "{f} differs between runs"
        );
    }
    let req = StepRequest {
        normals: Some("normal".into()),
        ..Default::default()
    };
    let sa = Case::open(a.path().join("torus.case"))
        .unwrap()
        .read_step(1, &req)
        .unwrap();
    let sc = Case::open(c.path().join("torus.case"))
        .unwrap()
        .read_step(1, &req)
        .unwrap();
    assert_eq!(sa, sc);
}

#[test]
fn bad_case_is_an_error_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    generate(dir.path(), &["sphere", "--points", "500", "--steps", "3"]);
    std::fs::remove_file(dir.path().join("sphere.geo00001")).unwrap();
    // Truncate another step.
    let p = dir.path().join("sphere.geo00002");
    let bytes = std::fs::read(&p).unwrap();
    std::fs::write(&p, &bytes[..bytes.len() - 7]).unwrap();
    let (ok, out, err) = slosh(&["info", dir.path().join("sphere.case").to_str().unwrap()]);
    assert!(!ok, "a case with broken steps must fail");
    assert!(
        out.contains("step") && err.contains("2 of 3 steps"),
        "{err}"
    );
    assert!(
        err.contains("sphere.geo00001")
            && err.contains("sphere.geo00002")
            && err.contains("byte offset"),
        "{err}"
    );
    let (ok, _, err) = slosh(&["gen", "cube", "--out", dir.path().to_str().unwrap()]);
    assert!(!ok && err.contains("unknown scene \"cube\""), "{err}");
}

#[test]
fn ply_and_obj_point_clouds_convert() {
    let dir = tempfile::tempdir().unwrap();
    let ply = dir.path().join("pts.ply");
    std::fs::write(&ply, "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\nend_header\n0 0 0 0 0 2\n1 0 0 0 3 0\n0 1 0 4 0 0\n").unwrap();
    let obj = dir.path().join("tri.obj");
    std::fs::write(
        &obj,
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 5\nf 1//1 2//1 3//1\n",
    )
    .unwrap();
    for (input, n) in [
        (&ply, [[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]),
        (&obj, [[0.0, 0.0, 1.0]; 3]),
    ] {
        let out = dir.path().join(input.file_stem().unwrap());
        let (ok, _, err) = slosh(&[
            "gen",
            "from-file",
            input.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--format",
            "gold-binary",
        ]);
        assert!(ok, "{err}");
        let case = Case::open(out.join(format!(
            "{}.case",
            input.file_stem().unwrap().to_str().unwrap()
        )))
        .unwrap();
        let step = case
            .read_step(
                0,
                &StepRequest {
                    normals: Some("normal".into()),
                    ..Default::default()
                },
            )
            .unwrap();
        assert_eq!(
            step.positions,
            vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
        );
        assert_eq!(step.normals.unwrap(), n.to_vec());
    }
}

/// The classic models from the pymeshlab/pymeshfix wheels, fetched by `.ci/run` into
/// `$SLOSH_DATA`.
#[test]
fn classic_models_convert() {
    let Some(data) = std::env::var_os("SLOSH_DATA")
        .map(PathBuf::from)
        .filter(|d| d.join("bunny.obj").exists())
    else {
        assert!(
            !in_ci(),
            "CI=true but $SLOSH_DATA/bunny.obj is missing (.ci/run fetches it)"
        );
        eprintln!(
            "skipping: set SLOSH_DATA to a folder with bunny.obj, face000.ply, StanfordBunny.ply"
        );
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    for (file, points, normals) in [
        ("bunny.obj", 28088, true),
        ("face000.ply", 85849, false),
        ("StanfordBunny.ply", 50000, false),
    ] {
        let out = dir.path().join(file);
        let (ok, stdout, err) = slosh(&[
            "gen",
            "from-file",
            data.join(file).to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(ok, "{err}");
        assert!(stdout.contains(&format!("{points} points")), "{stdout}");
        let stem = file.split('.').next().unwrap();
        let case = Case::open(out.join(format!("{stem}.case"))).unwrap();
        let req = StepRequest {
            normals: normals.then(|| "normal".to_string()),
            ..Default::default()
        };
        let step = case.read_step(0, &req).unwrap();
        assert_eq!(step.positions.len(), points);
        if let Some(n) = step.normals {
            assert!(
                n.iter()
                    .all(|v| ((v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt() - 1.0).abs() < 1e-5),
                "normals are unit length"
            );
        }
    }
    // The bunny stands on its base: baked, its cache says y is up (the framing camera's up).
    let cache = dir.path().join("bunny-cache");
    let case = dir.path().join("bunny.obj").join("bunny.case");
    let (ok, out, err) = bake_case(&case, &cache, &["--quiet"]);
    assert!(ok, "{out}{err}");
    let file = slosh_cache::CacheFile::open(&cache.join("step-00000.slc")).unwrap();
    assert_eq!(file.header().up, Some([0.0, 1.0, 0.0]));
}

fn vtk_available() -> bool {
    Command::new("python3")
        .args(["-c", "import vtk"])
        .output()
        .is_ok_and(|o| o.status.success())
}

/// VTK 9.7 reads what we write with the same counts and values (EnSight 6 binary and Gold
/// binary; point parts and measured particles).
#[test]
fn vtk_reads_what_we_write() {
    if !vtk_available() {
        assert!(
            !in_ci(),
            "CI=true but python3 cannot import vtk (.ci/run installs it)"
        );
        eprintln!("skipping: python3 with vtk (pip install vtk) not available");
        return;
    }
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/vtk_read.py");
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        ("tank", "e6-binary", false),
        ("tank", "gold-binary", false),
        ("droplets", "gold-binary", true),
        ("sphere", "e6-binary", true),
    ];
    for (scene, format, measured) in cases {
        let out = dir.path().join(format!("{scene}-{format}-{measured}"));
        let mut args = vec![
            scene, "--points", "1500", "--steps", "3", "--format", format,
        ];
        if measured {
            args.push("--measured");
        }
        generate(&out, &args);
        let case_path = out.join(format!("{scene}.case"));
        let vtk = Command::new("python3")
            .arg(&script)
            .arg(&case_path)
            .arg("--values")
            .output()
            .unwrap();
        assert!(
            vtk.status.success(),
            "{}",
            String::from_utf8_lossy(&vtk.stderr)
        );
        let vtk: Value = serde_json::from_slice(&vtk.stdout).unwrap();
        let case = Case::open(&case_path).unwrap();
        let req = StepRequest {
            normals: Some("normal".into()),
            fields: vec!["pressure".into(), "surface".into()],
            ..Default::default()
        };
        let vsteps = vtk["steps"].as_array().unwrap();
        assert_eq!(vsteps.len(), case.step_count());
        for (i, v) in vsteps.iter().enumerate() {
            let ours = case.read_step(i, &req).unwrap();
            assert_eq!(
                v["points"].as_u64().unwrap() as usize,
                ours.positions.len(),
                "{scene} {format} step {i}: point count"
            );
            let same = |name: &str, vtk_values: &Value, ours: Vec<f32>| {
                let vv: Vec<f64> = vtk_values
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|x| x.as_f64().unwrap_or(f64::NAN))
                    .collect();
                assert_eq!(
                    vv.len(),
                    ours.len(),
                    "{scene} {format} step {i} {name}: length"
                );
                for (k, (a, b)) in vv.iter().zip(&ours).enumerate() {
                    assert!(
                        *a == f64::from(*b) || (a.is_nan() && b.is_nan()),
                        "{scene} {format} step {i} {name}[{k}]: VTK {a} vs slosh {b}"
                    );
                }
            };
            same(
                "positions",
                &v["positions"],
                ours.positions.iter().flatten().copied().collect(),
            );
            same(
                "normal",
                &v["arrays"]["normal"],
                ours.normals.unwrap().iter().flatten().copied().collect(),
            );
            for f in ours.fields {
                let FieldValues::Scalar(values) = f.values else {
                    panic!("scalar")
                };
                same(&f.name, &v["arrays"][&f.name], values);
            }
        }
    }
}

/// `slosh bench accuracy --quick` writes its report and plot; the measurements it writes as
/// JSON meet this test's own bounds (not the report's verdicts) on the clean sphere.
#[test]
fn accuracy_harness_reports_goals() {
    let dir = tempfile::tempdir().unwrap();
    let md = dir.path().join("accuracy.md");
    let png = dir.path().join("img/accuracy.png");
    let json = dir.path().join("accuracy.json");
    let (ok, _, err) = slosh(&[
        "bench",
        "accuracy",
        "--quick",
        "--out",
        md.to_str().unwrap(),
        "--plot",
        png.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let report = std::fs::read_to_string(&md).unwrap();
    assert!(report.contains("## Reversed normals"), "{report}");
    let m: Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let get = |k: &str| m[k].as_f64().unwrap_or_else(|| panic!("{k} missing: {m}"));
    // The clean sphere (5000 points, 32×32): RMS in spacings, f32 agreement in %.
    assert!(get("worst_converged_rms") <= 0.01, "{m}");
    assert!(get("worst_one_iteration_rms") <= 0.05, "{m}");
    assert!(get("f32_within_pct") >= 99.9, "{m}");
    assert!(get("worst_reversed_rms_ratio") <= 1.5, "{m}");
    assert!(std::fs::read(&png).unwrap().starts_with(b"\x89PNG"));
}

/// Real SPH data (the fixture: SPlisHSPlasH's dam break, 6859 particles at t = 1 s, and
/// splashsurf's ray depths through the same camera): the goals (holes ≤ 1 %, p90
/// |Δt| ≤ 1.5 spacings), and near what slosh measured when the fixture was made (false
/// surface 1.95 %, p90 1.27, hits far from particles 1.25 %): a change that opens holes,
/// stretches sheets or moves the surface fails here.
#[test]
fn sph_dam_break_stays_close_to_splashsurf() {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("sph.json");
    let fixture = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/sph");
    let (ok, _, err) = slosh(&[
        "bench",
        "accuracy",
        "--sph",
        fixture,
        "--sph-only",
        "--out",
        dir.path().join("sph.md").to_str().unwrap(),
        "--plot",
        dir.path().join("accuracy.png").to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let m: Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let case = &m[0];
    let get = |k: &str| {
        case[k]
            .as_f64()
            .unwrap_or_else(|| panic!("{k} missing: {m}"))
    };
    assert!(get("reference_hits") > 3000.0, "{m}");
    assert!(get("holes_pct") <= 1.0, "{m}");
    assert!(get("false_pct") <= 2.5, "{m}");
    assert!(get("dt_p90") <= 1.4, "{m}");
    assert!(get("far_pct") <= 1.75, "{m}");
    assert!(
        std::fs::read(dir.path().join("sph-coarse.png"))
            .unwrap()
            .starts_with(b"\x89PNG")
    );
}

fn step_sums(dir: &Path) -> Vec<(String, Vec<String>)> {
    let mut names: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| slosh_cache::parse_step_file_name(n).is_some())
        .collect();
    names.sort();
    names
        .into_iter()
        .map(|n| {
            let f = slosh_cache::CacheFile::open(&dir.join(&n)).unwrap();
            let sums = f.header().sections.iter().map(|s| s.xxh3.clone()).collect();
            (n, sums)
        })
        .collect()
}

#[test]
fn bake_then_inspect_and_render_a_tank() {
    let dir = tempfile::tempdir().unwrap();
    let case_dir = dir.path().join("tank");
    generate(&case_dir, &["tank", "--points", "20000", "--steps", "4"]);
    let case = case_dir.join("tank.case");
    let cache = dir.path().join("cache");
    let (ok, out, err) = bake_case(&case, &cache, &["--fields", "pressure", "--quiet"]);
    assert!(ok, "bake failed: {err}");
    assert!(out.contains("baked 4 steps"), "{out}");
    let (ok, out, err) = slosh(&["inspect", cache.to_str().unwrap(), "--verify"]);
    assert!(ok, "{out}{err}");
    assert_eq!(out.matches("verified").count(), 4, "{out}");

    let step1 = cache.join("step-00001.slc");
    let (ok, out, _) = slosh(&["inspect", step1.to_str().unwrap(), "--json", "--verify"]);
    assert!(ok);
    let v: Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["verify"]["ok"], true);
    assert_eq!(v["header"]["source"]["step"], 1);
    let points = v["header"]["points"].as_u64().unwrap();
    // The tank flags its free surface; only those particles are baked.
    let read = v["header"]["stats"]["input_points"].as_u64().unwrap();
    assert!(points > 100 && points < read / 4, "{points} of {read}");
    assert!(v["statistics"]["neighbours"]["mean"].as_f64().unwrap() > 10.0);
    let names: Vec<&str> = v["header"]["sections"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["name"].as_str().unwrap())
        .collect();
    assert!(names.contains(&"field.pressure") && names.contains(&"bvh_nodes"));

    let (ok, out, _) = slosh(&["inspect", step1.to_str().unwrap(), "--point", "7"]);
    assert!(ok);
    let rec: Value = serde_json::from_str(&out).unwrap();
    assert!(!rec["neighbours"].as_array().unwrap().is_empty());
    assert!(rec["fields"]["pressure"].as_f64().is_some());

    let png = dir.path().join("frame.png");
    let npy = dir.path().join("hits.npy");
    let (ok, out, err) = slosh(&[
        "render",
        cache.to_str().unwrap(),
        "--step",
        "1",
        "--cpu",
        "--size",
        "48x32",
        "--iterations",
        "2",
        "--out",
        png.to_str().unwrap(),
        "--aov",
        npy.to_str().unwrap(),
    ]);
    assert!(ok, "render failed: {err}");
    assert!(out.contains("hit pixels"), "{out}");
    let npy_bytes = std::fs::read(&npy).unwrap();
    assert_eq!(npy_bytes.len(), 128 + 48 * 32 * 8 * 4);
    assert!(String::from_utf8_lossy(&npy_bytes[..128]).contains("'shape': (32, 48, 8)"));
    let values: &[f32] = bytemuck::cast_slice(&npy_bytes[128..]);
    let hits = values.chunks_exact(8).filter(|px| px[7] > 0.0).count();
    assert!(hits > 48 * 32 / 10, "{hits} hit pixels");
    assert!(values.iter().all(|v| v.is_finite()));
    assert!(std::fs::read(&png).unwrap().starts_with(b"\x89PNG"));

    // Water needs secondary rays, which only the GPU traces.
    let (ok, _, err) = slosh(&[
        "render",
        cache.to_str().unwrap(),
        "--step",
        "1",
        "--cpu",
        "--mode",
        "water",
        "--out",
        png.to_str().unwrap(),
    ]);
    assert!(!ok && err.contains("--mode water"), "{err}");
    // The GPU renders a sequence in it (required when CI=true).
    let pattern = dir.path().join("frames").join("{:05}.png");
    let (ok, out, err) = slosh(&[
        "render",
        cache.to_str().unwrap(),
        "--steps",
        "0..=1",
        "--size",
        "48x32",
        "--iterations",
        "2",
        "--mode",
        "water",
        "--out",
        pattern.to_str().unwrap(),
    ]);
    if ok {
        for name in ["00000.png", "00001.png"] {
            let frame = std::fs::read(dir.path().join("frames").join(name)).unwrap();
            assert!(frame.starts_with(b"\x89PNG"), "{name}: {out}");
        }
    } else if in_ci() {
        panic!("GPU render failed: {err}");
    } else {
        eprintln!("skipping the GPU render: {err}");
    }

    // A flipped byte is caught by --verify, naming the file.
    let mut bytes = std::fs::read(&step1).unwrap();
    let mid = bytes.len() / 3;
    bytes[mid] ^= 0x10;
    std::fs::write(&step1, bytes).unwrap();
    let (ok, out, err) = slosh(&["inspect", step1.to_str().unwrap(), "--verify"]);
    assert!(!ok);
    assert!(
        format!("{out}{err}").contains("step-00001.slc"),
        "{out}{err}"
    );

    // A missing step file: the batch goes on, reports it, exits non-zero.
    std::fs::remove_file(case_dir.join("tank.geo00002")).unwrap();
    let cache2 = dir.path().join("cache2");
    let (ok, out, err) = bake_case(&case, &cache2, &["--quiet"]);
    assert!(!ok);
    assert!(out.contains("baked 3 steps"), "{out}");
    assert!(
        err.contains("step 2") && err.contains("tank.geo00002"),
        "{err}"
    );
    let manifest: Value =
        serde_json::from_slice(&std::fs::read(cache2.join("manifest.json")).unwrap()).unwrap();
    assert_eq!(manifest["steps"].as_array().unwrap().len(), 3);
}

#[test]
fn shards_make_the_caches_of_one_run() {
    let dir = tempfile::tempdir().unwrap();
    let case_dir = dir.path().join("sphere");
    generate(&case_dir, &["sphere", "--points", "1500", "--steps", "7"]);
    let case = case_dir.join("sphere.case");
    let one = dir.path().join("one");
    let (ok, _, err) = bake_case(&case, &one, &["--quiet"]);
    assert!(ok, "{err}");
    let sharded = dir.path().join("sharded");
    for shard in ["0/3", "1/3", "2/3"] {
        let (ok, out, err) = bake_case(&case, &sharded, &["--shard", shard, "--quiet"]);
        assert!(ok, "{err}");
        let expect = if shard == "0/3" {
            "baked 3 steps"
        } else {
            "baked 2 steps"
        };
        assert!(out.contains(expect), "{shard}: {out}");
    }
    let (ok, out, _) = slosh(&["bake", "--manifest-only", sharded.to_str().unwrap()]);
    assert!(ok && out.contains("7 steps"), "{out}");
    assert_eq!(step_sums(&one), step_sums(&sharded));
    let (ok, _, err) = slosh(&[
        "bake",
        case.to_str().unwrap(),
        "--out",
        "x",
        "--shard",
        "3/3",
    ]);
    assert!(!ok && err.contains("--shard 3/3"), "{err}");
}

#[test]
fn a_killed_bake_leaves_only_valid_caches_and_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let case_dir = dir.path().join("sphere");
    generate(&case_dir, &["sphere", "--points", "4000", "--steps", "16"]);
    let case = case_dir.join("sphere.case");
    let reference = dir.path().join("reference");
    let (ok, _, err) = bake_case(&case, &reference, &["--quiet"]);
    assert!(ok, "{err}");
    let cache = dir.path().join("cache");
    let mut child = Command::new(env!("CARGO_BIN_EXE_slosh"))
        .args([
            "bake",
            case.to_str().unwrap(),
            "--out",
            cache.to_str().unwrap(),
            "--quiet",
            "--jobs",
            "1",
        ])
        .spawn()
        .unwrap();
    // Kill -9 once the first steps are written, in the middle of the series.
    let start = std::time::Instant::now();
    while !cache.join("step-00002.slc").exists() && start.elapsed().as_secs() < 120 {
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    let present = step_sums(&cache);
    eprintln!("killed with {} of 16 step files written", present.len());
    assert!(
        present.len() >= 3 && present.len() < 16,
        "killed with {} of 16 steps written",
        present.len()
    );
    // Everything that looks like a step verifies and equals the reference bake; the series
    // as a whole fails verification, naming the steps still missing (issue 25, item 3).
    let (ok, out, err) = slosh(&["inspect", cache.to_str().unwrap(), "--verify"]);
    assert!(!ok, "{out}{err}");
    assert!(
        out.contains(&format!(
            "{} of the series' steps 0..=15 (16 steps) are missing",
            16 - present.len()
        )),
        "{out}"
    );
    assert_eq!(
        out.lines().filter(|l| l.ends_with("verified")).count(),
        present.len(),
        "{out}"
    );
    let full = step_sums(&reference);
    for (name, sums) in &present {
        assert_eq!(
            Some(sums),
            full.iter().find(|(n, _)| n == name).map(|(_, s)| s),
            "{name}"
        );
    }
    // A manifest write killed half-way leaves its temporary file (a process long gone).
    std::fs::write(cache.join(".manifest.json.tmp-4194300-0"), b"{\"half\": ").unwrap();
    let (ok, out, err) = bake_case(&case, &cache, &["--quiet"]);
    assert!(ok, "{err}");
    assert!(
        out.contains(&format!(
            "baked {} steps, kept {}",
            16 - present.len(),
            present.len()
        )),
        "{out}"
    );
    assert_eq!(step_sums(&cache), full);
    // No temporary files are left behind.
    let leftovers: Vec<_> = std::fs::read_dir(&cache)
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains(".tmp-"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

/// `slosh bench scrub --quick`: the engine streams a small baked series on the adapter there
/// is (lavapipe in CI), and the report holds every table with measured, positive figures.
#[test]
fn scrub_bench_streams_a_series_on_the_engine() {
    let dir = tempfile::tempdir().unwrap();
    let md = dir.path().join("scrub.md");
    let series = dir.path().join("series");
    let (ok, out, err) = slosh(&[
        "bench",
        "scrub",
        "--quick",
        "--out",
        md.to_str().unwrap(),
        "--dir",
        series.to_str().unwrap(),
    ]);
    if !ok && !in_ci() && err.contains("adapter") {
        eprintln!("skipping the scrub benchmark: {err}");
        return;
    }
    assert!(ok, "{out}{err}");
    let report = std::fs::read_to_string(&md).unwrap();
    let rows: Vec<Vec<&str>> = report
        .lines()
        .filter(|l| l.starts_with("| 2000 points"))
        .map(|l| l.split('|').map(str::trim).collect())
        .collect();
    // Throughput, the resident-jump goal, step costs, five codec levels.
    assert_eq!(rows.len(), 8, "{report}");
    assert!(rows[1][2].contains("jump to a resident step"), "{report}");
    let number = |s: &str| -> f64 { s.split_whitespace().next().unwrap().parse().unwrap() };
    let throughput = &rows[0];
    assert!(number(throughput[2]) > 0.0, "steps/s: {report}");
    for cell in &throughput[3..7] {
        for part in cell.split('/') {
            assert!(number(part) > 0.0, "{cell}: {report}");
        }
    }
    let (sections, all) = rows[2][2].split_once('/').unwrap();
    assert!(
        number(all) > number(sections),
        "derived buffers count: {report}"
    );
    // The series it wrote is a verified cache series.
    let cache = series.join("sphere-2000-12");
    let (ok, out, err) = slosh(&["inspect", cache.to_str().unwrap(), "--verify"]);
    assert!(ok, "{out}{err}");
}

/// `slosh demo --headless`: generates and bakes the series once (a second run reuses it) and
/// renders frames, on the GPU where there is one, else with the CPU tracer.
#[test]
fn demo_headless_renders_frames_and_reuses_its_series() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("demo");
    let args = [
        "demo",
        "--headless",
        "--steps",
        "4",
        "--points",
        "3000",
        "--frames",
        "3",
        "--dir",
        root.to_str().unwrap(),
    ];
    let (ok, out, err) = slosh(&args);
    assert!(ok, "{out}{err}");
    assert!(out.contains("generating the demo series"), "{out}");
    for i in 0..3 {
        let frame = std::fs::read(root.join("frames").join(format!("{i:05}.png"))).unwrap();
        assert!(frame.starts_with(b"\x89PNG"), "{out}");
    }
    let (ok, out, err) = slosh(&args);
    assert!(ok, "{out}{err}");
    assert!(out.contains("already baked"), "{out}");
    assert!(out.contains("frames: "), "{out}");
    let (ok, out, err) = slosh(&["inspect", root.join("cache").to_str().unwrap(), "--verify"]);
    assert!(ok, "{out}{err}");
}

/// A closed or full stdout never panics a command: a reader that went away is fine (exit 0,
/// the work done), a full device is an error after the work (issue 14, item 7).
#[test]
fn closed_or_full_stdout_is_not_a_panic() {
    let dir = tempfile::tempdir().unwrap();
    generate(
        &dir.path().join("case"),
        &["sphere", "--points", "1500", "--steps", "2"],
    );
    let case = dir.path().join("case/sphere.case");
    let cache = dir.path().join("cache");
    // stdout a pipe whose reader is gone before the first line.
    let mut child = Command::new(env!("CARGO_BIN_EXE_slosh"))
        .args([
            "bake",
            case.to_str().unwrap(),
            "--out",
            cache.to_str().unwrap(),
        ])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("panicked"), "{err}");
    assert!(out.status.success(), "{err}");
    assert!(cache.join("step-00001.slc").exists());
    // stdout on a full device: the frame is written, then the error, no panic.
    if let Ok(full) = std::fs::OpenOptions::new().write(true).open("/dev/full") {
        let png = dir.path().join("x.png");
        let out = Command::new(env!("CARGO_BIN_EXE_slosh"))
            .args([
                "render",
                cache.to_str().unwrap(),
                "--cpu",
                "--size",
                "32x32",
                "--out",
                png.to_str().unwrap(),
            ])
            .stdout(full)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!err.contains("panicked"), "{err}");
        assert_eq!(out.status.code(), Some(1), "{err}");
        assert!(err.contains("writing to stdout"), "{err}");
        assert!(png.exists());
    }
}

/// A stored precision outside 8 to 23 mantissa bits is refused by name.
#[test]
fn impossible_mantissa_bits_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    generate(
        &dir.path().join("case"),
        &["sphere", "--points", "500", "--steps", "1"],
    );
    let case = dir.path().join("case/sphere.case");
    for bits in ["7", "24"] {
        let cache = dir.path().join("cache");
        let (ok, _, err) = bake_case(&case, &cache, &["--mantissa-bits", bits]);
        assert!(!ok, "--mantissa-bits {bits} was accepted");
        assert!(
            err.contains(&format!("--mantissa-bits {bits}: expected 8 to 23")),
            "{err}"
        );
        assert!(!cache.join("step-00000.slc").exists());
    }
}

/// `--jobs` outside what the machine can use is refused by name, not obeyed (issue 14,
/// item 10).
#[test]
fn absurd_job_counts_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    generate(
        &dir.path().join("case"),
        &["sphere", "--points", "500", "--steps", "1"],
    );
    let case = dir.path().join("case/sphere.case");
    for jobs in ["0", "100000", "18446744073709551615"] {
        let start = std::time::Instant::now();
        let (ok, _, err) = bake_case(&case, &dir.path().join("cache"), &["--jobs", jobs]);
        assert!(!ok, "--jobs {jobs} was accepted");
        assert!(
            err.contains(&format!("--jobs {jobs}: expected 1 to")),
            "{err}"
        );
        assert!(
            start.elapsed().as_secs() < 10,
            "--jobs {jobs} took {:?}",
            start.elapsed()
        );
    }
}

/// Without `--jobs`, the bake says how many steps it bakes at once and why: from the cores
/// and the memory the first step needs.
#[test]
fn the_jobs_default_comes_from_cores_and_memory() {
    let dir = tempfile::tempdir().unwrap();
    generate(
        &dir.path().join("case"),
        &["sphere", "--points", "500", "--steps", "2"],
    );
    let case = dir.path().join("case/sphere.case");
    let (ok, out, err) = bake_case(&case, &dir.path().join("cache"), &[]);
    assert!(ok, "{err}");
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let expected = format!("baking {} steps at once ({cores} cores", (cores / 2).max(1));
    assert!(out.contains(&expected), "{out}");
    assert!(out.contains("a step of 500 points needs about"), "{out}");
    assert!(out.contains("baked 2 steps"), "{out}");
}

/// Render settings without a meaning, or that would destroy the input, are refused by name
/// (issue 14, item 11).
#[test]
fn meaningless_or_destructive_render_settings_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    generate(
        &dir.path().join("case"),
        &["sphere", "--points", "800", "--steps", "1"],
    );
    let cache = dir.path().join("cache");
    let (ok, _, err) = bake_case(&dir.path().join("case/sphere.case"), &cache, &["--quiet"]);
    assert!(ok, "{err}");
    let before = std::fs::read(cache.join("step-00000.slc")).unwrap();
    let png = dir.path().join("x.png");
    let c = cache.to_str().unwrap();
    let p = png.to_str().unwrap();
    let input = cache.join("step-00000.slc");
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["--fov", "0"], "--fov 0"),
        (vec!["--fov", "180"], "--fov 180"),
        (vec!["--fov", "nan"], "--fov NaN"),
        (vec!["--eye", "1,1,1", "--target", "1,1,1"], "same point"),
        (
            vec!["--eye=0,0,5", "--target", "0,0,0", "--up", "0,0,1"],
            "parallel",
        ),
        (vec!["--aov", p], "--out and --aov are both"),
    ];
    for (extra, expected) in cases {
        let mut args = vec!["render", c, "--cpu", "--size", "16x16", "--out", p];
        args.extend(extra.iter().copied());
        let (ok, _, err) = slosh(&args);
        assert!(!ok, "{extra:?} accepted");
        assert!(err.contains(expected), "{extra:?}: {err}");
    }
    let (ok, _, err) = slosh(&[
        "render",
        c,
        "--cpu",
        "--size",
        "16x16",
        "--out",
        input.to_str().unwrap(),
    ]);
    assert!(!ok);
    assert!(err.contains("a file of the cache being rendered"), "{err}");
    // A frame larger than memory is refused by its size, not by running out (about 32 GB at
    // 16384×16384; the test machines have less available).
    let (ok, _, err) = slosh(&["render", c, "--cpu", "--size", "16384x16384", "--out", p]);
    assert!(!ok && err.contains("GB available"), "{err}");
    assert_eq!(
        std::fs::read(&input).unwrap(),
        before,
        "the input was touched"
    );
}

/// Negative values are read as values where they make sense (issue 14, item 12).
#[test]
fn negative_values_are_values() {
    let dir = tempfile::tempdir().unwrap();
    let (ok, out, err) = slosh(&[
        "gen",
        "sphere",
        "--points",
        "300",
        "--steps",
        "1",
        "--offset",
        "-1",
        "--out",
        dir.path().join("case").to_str().unwrap(),
    ]);
    assert!(ok, "{out}{err}");
    let case = Case::open(dir.path().join("case/sphere.case")).unwrap();
    let step = case.read_step(0, &StepRequest::default()).unwrap();
    let mean_x =
        step.positions.iter().map(|p| f64::from(p[0])).sum::<f64>() / step.positions.len() as f64;
    assert!(mean_x < -0.5, "the offset moved the points by {mean_x}");
}

/// A step whose cache the verifier would reject is reported and never written, so a re-run
/// cannot keep it (issue 14, item 2): at an offset of 1e8 the points of a small sphere
/// coincide in f32.
#[test]
fn a_bake_never_writes_what_its_verifier_rejects() {
    let dir = tempfile::tempdir().unwrap();
    let case_dir = dir.path().join("case");
    generate(
        &case_dir,
        &[
            "sphere", "--points", "2000", "--steps", "1", "--offset", "1e8",
        ],
    );
    let cache = dir.path().join("cache");
    for _ in 0..2 {
        let (ok, out, err) = bake_case(&case_dir.join("sphere.case"), &cache, &[]);
        assert!(!ok, "{out}");
        // In f32 at 1e8 every particle of the unit sphere lands on one position: refused by
        // name (issue 25, item 14) before anything is encoded, and nothing is written.
        assert!(err.contains("step 0") && err.contains("coincide"), "{err}");
        assert!(!cache.join("step-00000.slc").exists());
    }
}

/// Resume keeps a step only when its input is the same: another case or regenerated data
/// into the same directory is baked again (issue 14, item 1).
#[test]
fn resume_rebakes_when_the_input_changed() {
    let dir = tempfile::tempdir().unwrap();
    let cache = dir.path().join("cache");
    let bake = |case: &Path| {
        let (ok, out, err) = bake_case(case, &cache, &["--quiet"]);
        assert!(ok, "{out}{err}");
        out
    };
    let sphere = dir.path().join("in");
    generate(&sphere, &["sphere", "--points", "1500", "--steps", "3"]);
    assert!(bake(&sphere.join("sphere.case")).contains("baked 3 steps, kept 0"));
    assert!(bake(&sphere.join("sphere.case")).contains("baked 0 steps, kept 3"));
    // The same case path, regenerated with other data.
    std::fs::remove_dir_all(&sphere).unwrap();
    generate(&sphere, &["sphere", "--points", "2500", "--steps", "3"]);
    assert!(bake(&sphere.join("sphere.case")).contains("baked 3 steps, kept 0"));
}

/// A partial re-bake with other settings is refused before anything is written, naming the
/// step it would leave behind (issue 14, item 3).
#[test]
fn a_partial_rebake_with_other_settings_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let case_dir = dir.path().join("in");
    generate(&case_dir, &["sphere", "--points", "1500", "--steps", "2"]);
    let case = case_dir.join("sphere.case");
    let cache = dir.path().join("cache");
    let (ok, _, err) = bake_case(&case, &cache, &["--quiet"]);
    assert!(ok, "{err}");
    let before = std::fs::read(cache.join("step-00000.slc")).unwrap();
    let (ok, out, err) = bake_case(&case, &cache, &["--steps", "0..=0", "--k", "8"]);
    assert!(!ok, "{out}");
    assert!(
        err.contains("step-00001.slc") && err.contains("nothing was written"),
        "{err}"
    );
    assert_eq!(std::fs::read(cache.join("step-00000.slc")).unwrap(), before);
}

/// Bakes finishing side by side take turns at the manifest: one that finds the directory's
/// manifest lock held waits for it, then scans, so the last manifest written has seen every
/// step file (issue 14, item 5).
#[test]
fn manifest_rebuilds_take_turns() {
    let dir = tempfile::tempdir().unwrap();
    let case_dir = dir.path().join("in");
    generate(&case_dir, &["sphere", "--points", "800", "--steps", "1"]);
    let cache = dir.path().join("cache");
    std::fs::create_dir_all(&cache).unwrap();
    let lock = std::fs::File::create(cache.join(slosh_cache::MANIFEST_LOCK_NAME)).unwrap();
    lock.lock().unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_slosh"))
        .args([
            "bake",
            case_dir.join("sphere.case").to_str().unwrap(),
            "--out",
            cache.to_str().unwrap(),
            "--quiet",
        ])
        .spawn()
        .unwrap();
    // The step is baked, but the manifest waits for the lock.
    let start = std::time::Instant::now();
    while !cache.join("step-00000.slc").exists() && start.elapsed().as_secs() < 60 {
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    std::thread::sleep(std::time::Duration::from_millis(800));
    assert!(
        child.try_wait().unwrap().is_none(),
        "the bake did not wait for the lock"
    );
    assert!(!cache.join(slosh_cache::MANIFEST_NAME).exists());
    lock.unlock().unwrap();
    assert!(child.wait().unwrap().success());
    let manifest = slosh_cache::Manifest::read(&cache).unwrap();
    assert_eq!(manifest.steps.len(), 1);
}

/// A manifest that cannot be written does not hide the failed steps, and a bake with every
/// step current leaves an up-to-date manifest untouched (so read-only storage is fine)
/// (issue 14, item 8).
#[test]
fn manifest_failures_do_not_hide_step_failures() {
    let dir = tempfile::tempdir().unwrap();
    let case_dir = dir.path().join("in");
    generate(&case_dir, &["sphere", "--points", "800", "--steps", "3"]);
    let case = case_dir.join("sphere.case");
    let cache = dir.path().join("cache");
    let bake = || bake_case(&case, &cache, &["--quiet"]);
    let (ok, _, err) = bake();
    assert!(ok, "{err}");
    let manifest = cache.join(slosh_cache::MANIFEST_NAME);
    let written = std::fs::metadata(&manifest).unwrap().modified().unwrap();
    std::thread::sleep(std::time::Duration::from_millis(20));
    let (ok, out, err) = bake();
    assert!(ok && out.contains("kept 3"), "{out}{err}");
    assert_eq!(
        std::fs::metadata(&manifest).unwrap().modified().unwrap(),
        written,
        "an up-to-date manifest was rewritten"
    );
    // Step 1's geometry goes missing, and the manifest's place is taken by a directory.
    std::fs::remove_file(case_dir.join("sphere.geo00001")).unwrap();
    std::fs::remove_file(cache.join("step-00001.slc")).unwrap();
    std::fs::remove_file(&manifest).unwrap();
    std::fs::create_dir(&manifest).unwrap();
    let (ok, _, err) = bake();
    assert!(!ok);
    assert!(
        err.contains("step 1:") && err.contains("sphere.geo00001"),
        "{err}"
    );
    assert!(err.contains("manifest:"), "{err}");
    assert!(err.contains("the manifest was not written"), "{err}");
}

/// `inspect --verify DIR` verifies the series as a whole, and `render` refuses a step that
/// is not of its series (issue 14, item 6).
#[test]
fn a_series_is_verified_as_a_whole() {
    let dir = tempfile::tempdir().unwrap();
    let case_dir = dir.path().join("in");
    generate(&case_dir, &["sphere", "--points", "800", "--steps", "3"]);
    let case = case_dir.join("sphere.case");
    let bake = |out: &Path, extra: &[&str]| {
        let mut args = vec![
            "bake",
            case.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--quiet",
        ];
        args.extend_from_slice(extra);
        let (ok, _, err) = slosh(&args);
        assert!(ok, "{err}");
    };
    let cache = dir.path().join("cache");
    bake(&cache, &[]);
    let verify = |d: &Path| slosh(&["inspect", d.to_str().unwrap(), "--verify"]);
    assert!(verify(&cache).0);
    let step = |i: usize| cache.join(format!("step-0000{i}.slc"));
    let original = std::fs::read(step(1)).unwrap();

    // Step 2 copied over step 1.
    std::fs::copy(step(2), step(1)).unwrap();
    let (ok, out, _) = verify(&cache);
    assert!(
        !ok && out.contains("holds step 2 of its source, not step 1"),
        "{out}"
    );
    let (ok, _, err) = slosh(&[
        "render",
        cache.to_str().unwrap(),
        "--step",
        "1",
        "--cpu",
        "--size",
        "16x16",
        "--out",
        dir.path().join("x.png").to_str().unwrap(),
    ]);
    assert!(
        !ok && err.contains("step-00001.slc: not step 1 of the series"),
        "{err}"
    );

    // One step baked with other settings among the rest.
    let other = dir.path().join("other");
    bake(&other, &["--k", "8"]);
    std::fs::copy(other.join("step-00001.slc"), step(1)).unwrap();
    let (ok, out, _) = verify(&cache);
    assert!(!ok && out.contains("baked with parameter hash"), "{out}");
    std::fs::write(step(1), &original).unwrap();
    assert!(verify(&cache).0);

    // A manifest that is not one is invalid, not missing.
    let manifest = cache.join(slosh_cache::MANIFEST_NAME);
    let good = std::fs::read(&manifest).unwrap();
    std::fs::write(&manifest, b"{ not json").unwrap();
    let (ok, out, _) = verify(&cache);
    assert!(!ok && out.contains("manifest INVALID"), "{out}");
    std::fs::write(&manifest, good).unwrap();

    // A directory without steps verifies nothing, so it fails.
    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    let (ok, out, _) = verify(&empty);
    assert!(!ok && out.contains("holds no step files"), "{out}");
}

/// One `--steps` grammar for bake and render: `A..B` excludes B, `A..=B` includes it, `N` is
/// one step; an empty range is an error (issue 14, item 12).
#[test]
fn steps_read_the_same_everywhere() {
    let dir = tempfile::tempdir().unwrap();
    let case_dir = dir.path().join("in");
    generate(&case_dir, &["sphere", "--points", "600", "--steps", "4"]);
    let case = case_dir.join("sphere.case");
    let baked = |range: &str| {
        let cache = dir
            .path()
            .join(format!("c{}", range.replace('.', "_").replace('=', "e")));
        let (ok, out, err) = bake_case(&case, &cache, &["--steps", range, "--quiet"]);
        (ok, format!("{out}{err}"), cache)
    };
    let (ok, out, cache) = baked("0..2");
    assert!(ok && out.contains("baked 2 steps"), "{out}");
    let (ok, out, _) = baked("1..=3");
    assert!(ok && out.contains("baked 3 steps"), "{out}");
    let (ok, out, _) = baked("3");
    assert!(ok && out.contains("baked 1 steps"), "{out}");
    let (ok, out, _) = baked("2..2");
    assert!(!ok && out.contains("the range is empty"), "{out}");
    let (ok, out, _) = baked("50..60");
    assert!(!ok && out.contains("it has steps 0..=3"), "{out}");
    let pattern = dir.path().join("f{:05}.png");
    let (ok, out, err) = slosh(&[
        "render",
        cache.to_str().unwrap(),
        "--cpu",
        "--size",
        "8x8",
        "--steps",
        "0..2",
        "--out",
        pattern.to_str().unwrap(),
    ]);
    assert!(ok, "{out}{err}");
    assert!(dir.path().join("f00001.png").exists() && !dir.path().join("f00002.png").exists());
    let (ok, _, err) = slosh(&[
        "render",
        cache.to_str().unwrap(),
        "--cpu",
        "--steps",
        "1..1",
        "--out",
        pattern.to_str().unwrap(),
    ]);
    assert!(!ok && err.contains("the range is empty"), "{err}");
    // --steps and --step together are refused, not one silently ignored.
    let (ok, _, err) = slosh(&[
        "render",
        cache.to_str().unwrap(),
        "--cpu",
        "--step",
        "1",
        "--steps",
        "0..2",
        "--out",
        pattern.to_str().unwrap(),
    ]);
    assert!(!ok && err.contains("cannot be used with"), "{err}");
}

/// Inputs that never end or never open (a device, a FIFO) are refused at once, and an OS
/// error is said once (issue 14, items 10 and 12).
#[test]
fn endless_inputs_are_refused_and_errors_said_once() {
    let (ok, _, err) = slosh(&["info", "/dev/zero"]);
    assert!(
        !ok && err.contains("/dev/zero: not a regular file"),
        "{err}"
    );
    assert_eq!(err.matches("not a regular file").count(), 1, "{err}");
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("case.case");
    if Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .is_ok_and(|s| s.success())
    {
        let start = std::time::Instant::now();
        let (ok, _, err) = slosh(&["info", fifo.to_str().unwrap()]);
        assert!(!ok && err.contains("not a regular file"), "{err}");
        assert!(start.elapsed().as_secs() < 10);
    }
    let missing = dir.path().join("missing.case");
    let (ok, _, err) = slosh(&["info", missing.to_str().unwrap()]);
    assert!(!ok);
    assert_eq!(err.matches("(os error 2)").count(), 1, "{err}");
}

/// A case that promises far more steps than it has files fails with a summary, not a line
/// per missing step (issue 14, item 12).
#[test]
fn many_failed_steps_are_summarised() {
    let dir = tempfile::tempdir().unwrap();
    let case_dir = dir.path().join("in");
    generate(&case_dir, &["sphere", "--points", "300", "--steps", "3"]);
    let case = case_dir.join("sphere.case");
    let text = std::fs::read_to_string(&case).unwrap();
    let times: Vec<String> = (0..500)
        .map(|i| format!("{}", f64::from(i) * 0.05))
        .collect();
    let head = text.split("number of steps").next().unwrap();
    std::fs::write(
        &case,
        format!(
            "{head}number of steps: 500\nfilename start number: 0\nfilename increment: 1\ntime values:\n{}\n",
            times.join(" ")
        ),
    )
    .unwrap();
    let (ok, out, err) = bake_case(&case, &dir.path().join("cache"), &["--quiet"]);
    assert!(!ok);
    assert!(
        out.contains("baked 3 steps") && out.contains("497 failed"),
        "{out}"
    );
    assert!(err.contains("… and 477 more failed steps"), "{err}");
    assert!(err.contains("(497 in all)"), "{err}");
    assert!(err.lines().count() < 30, "{} lines", err.lines().count());
    assert!(err.len() < 8000, "{} bytes", err.len());
}

/// A case without geometry is refused once, naming what is missing; `info` reads the format
/// off the first step whose files are there (issue 14, item 12).
#[test]
fn cases_without_geometry_or_a_first_step_say_so() {
    let dir = tempfile::tempdir().unwrap();
    generate(dir.path(), &["sphere", "--points", "300", "--steps", "3"]);
    let case = dir.path().join("sphere.case");
    let text = std::fs::read_to_string(&case).unwrap();
    // Only the geometry of step 0 missing: the format is still known.
    std::fs::remove_file(dir.path().join("sphere.geo00000")).unwrap();
    let (_, out, err) = slosh(&["info", case.to_str().unwrap()]);
    assert!(
        out.contains("C Binary") && !out.contains("unknown"),
        "{out}{err}"
    );
    // No model: line at all.
    let bare = dir.path().join("bare.case");
    let without: String = text
        .lines()
        .filter(|l| !l.starts_with("model:"))
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(&bare, without).unwrap();
    let (ok, _, err) = slosh(&["info", bare.to_str().unwrap()]);
    assert!(!ok && err.contains("bare.case"), "{err}");
    assert!(err.contains("\"model:\" or \"measured:\" line"), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
}

/// A real SLURM on this machine (`scripts/slurm/test.sh`: munged, slurmctld and slurmd with a
/// private configuration): a 4-task job array bakes a series whose every section equals a
/// single-process bake, a dependent job rebuilds the manifest, and a task cancelled mid-way
/// resumes when the array is resubmitted, keeping the steps it finished. The daemons need
/// root and Debian's slurm-wlm and munge (`.ci/run` installs them); required when CI=true.
#[test]
fn slurm_job_arrays_bake_like_one_process_and_resume() {
    let has = |tool: &str| {
        Command::new("sh")
            .args(["-c", &format!("command -v {tool}")])
            .output()
            .is_ok_and(|o| o.status.success())
    };
    let root = Command::new("id")
        .arg("-u")
        .output()
        .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "0");
    let tools = ["slurmctld", "slurmd", "sbatch", "munged", "python3"]
        .iter()
        .all(|t| has(t));
    if !(tools && root) {
        assert!(
            !in_ci(),
            "CI=true but SLURM cannot run here (root: {root}, slurm-wlm and munge installed: \
             {tools}; .ci/run installs them)"
        );
        eprintln!("skipping: SLURM needs root and slurm-wlm, munge");
        return;
    }
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/slurm/test.sh");
    let out = Command::new("bash")
        .arg(&script)
        .env("SLOSH", env!("CARGO_BIN_EXE_slosh"))
        .output()
        .expect("run scripts/slurm/test.sh");
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    eprintln!("{stdout}");
    assert!(out.status.success(), "{stdout}\n{stderr}");
    assert!(stdout.contains("every section identical to the single-process bake"));
    assert!(stdout.contains("== SLURM test passed"));
}
