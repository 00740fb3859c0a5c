//! The CLI end to end: gen and conversion to EnSight, `slosh info`, and what VTK reads of what we write.

use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::Value;
use slosh_ensight::{Case, FieldValues, StepRequest};

use crate::util::{bake_case, generate, in_ci, slosh};

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
    assert!(ok && out.contains("baked 1 step,"), "{out}");
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
