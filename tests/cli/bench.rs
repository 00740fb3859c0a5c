//! The CLI end to end: the harnesses (accuracy, SPH against splashsurf, scrub) and the demo.

use serde_json::Value;

use crate::util::{in_ci, slosh};

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

/// Real SPH data (the fixture: SPlisHSPlasH's dam break, 6859 particles, as the column
/// collapses at t = 0.4 s, as its splash falls at 0.6 s, and at 1 s; splashsurf's ray depths
/// through the same camera). Measured when the fixture was made: far 0 % at each, p90 |Δt|
/// 1.31, 0.97, 0.96, holes 1.92, 2.35, 0.65 %, false 0.54, 0.94, 0.29 %: a change that opens
/// holes, stretches sheets or fins, or moves the surface fails here.
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
    let cases = m.as_array().unwrap();
    let names: Vec<&str> = cases.iter().map(|c| c["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["coarse-t0.4", "coarse-t0.6", "coarse-t1"], "{m}");
    for case in cases {
        let name = case["name"].as_str().unwrap();
        let get = |k: &str| {
            case[k]
                .as_f64()
                .unwrap_or_else(|| panic!("{name}: {k} missing: {m}"))
        };
        assert!(get("reference_hits") > 3000.0, "{name}: {m}");
        // Issue 28's goals at every step: no surface more than two spacings from every
        // particle (0.5 % of the hits at most), p90 |Δt| ≤ 1.5 spacing.
        assert!(get("far_pct") <= 0.5, "{name}: {m}");
        assert!(get("dt_p90") <= 1.5, "{name}: {m}");
        // Issue 15's, set at t = 1 s: holes ≤ 1 %, false surface ≤ 5 %. While the column
        // collapses, splashsurf's blobs around spray are wider than slosh's particle-radius
        // spheres: holes measured up to 2.35 % there.
        let holes = if get("time") >= 1.0 { 1.0 } else { 2.5 };
        assert!(get("holes_pct") <= holes, "{name}: {m}");
        assert!(get("false_pct") <= 2.5, "{name}: {m}");
        assert!(
            std::fs::read(dir.path().join(format!("sph-{name}.png")))
                .unwrap()
                .starts_with(b"\x89PNG")
        );
    }
}

/// `slosh bench scrub --quick FLAGS --out MD --dir SERIES`: (success, stdout, stderr), or
/// `None` where no adapter was found outside CI (the benchmark is skipped there).
fn quick_scrub(
    flags: &[&str],
    md: &std::path::Path,
    series: &std::path::Path,
) -> Option<(bool, String, String)> {
    let mut args = vec!["bench", "scrub", "--quick"];
    args.extend_from_slice(flags);
    args.extend([
        "--out",
        md.to_str().unwrap(),
        "--dir",
        series.to_str().unwrap(),
    ]);
    let (ok, out, err) = slosh(&args);
    if !ok && !in_ci() && err.contains("adapter") {
        eprintln!("skipping the scrub benchmark: {err}");
        return None;
    }
    Some((ok, out, err))
}

/// `slosh bench scrub --quick`: the engine streams a small baked series on the adapter there
/// is (lavapipe in CI), and the report holds every table with measured, positive figures.
#[test]
fn scrub_bench_streams_a_series_on_the_engine() {
    let dir = tempfile::tempdir().unwrap();
    let md = dir.path().join("scrub.md");
    let series = dir.path().join("series");
    let Some((ok, out, err)) = quick_scrub(&["--raw-case"], &md, &series) else {
        return;
    };
    assert!(ok, "{out}{err}");
    let report = std::fs::read_to_string(&md).unwrap();
    let rows: Vec<Vec<&str>> = report
        .lines()
        .filter(|l| l.starts_with("| 2000 points, 12 steps ("))
        .map(|l| l.split('|').map(str::trim).collect())
        .collect();
    // Throughput, the resident-jump goal, where the jumps' time went, step costs, five codec
    // levels.
    assert_eq!(rows.len(), 9, "{report}");
    assert!(rows[1][2].contains("jump to a resident step"), "{report}");
    let number = |s: &str| -> f64 { s.split_whitespace().next().unwrap().parse().unwrap() };
    let throughput = &rows[0];
    assert!(number(throughput[3]) > 0.0, "steps/s: {report}");
    for cell in &throughput[4..8] {
        for part in cell.split('/') {
            assert!(number(part) > 0.0, "{cell}: {report}");
        }
    }
    // A jump loads the step asked for after it is asked for: its halves were found, and they
    // lie within the jump (the rest is not negative).
    let parts = |cell: &str| -> Vec<f64> { cell.split('/').map(number).collect() };
    let (median, slowest) = (parts(rows[2][2]), parts(rows[2][3]));
    assert!(median[0] > 0.0 && median[1] > 0.0, "halves: {report}");
    assert!(median[2] >= 0.0 && slowest[3] >= 0.0, "rest: {report}");
    assert!(
        (slowest[0] - slowest[1] - slowest[2] - slowest[3]).abs() <= 0.025,
        "the parts add up, to the decimals shown: {report}"
    );
    let (sections, all) = rows[3][2].split_once('/').unwrap();
    assert!(
        number(all) > number(sections),
        "derived buffers count: {report}"
    );
    // Bytes per point on the GPU: the step's bytes over its 2000 points, to the decimal shown.
    let per_point = number(throughput[2]);
    assert!(
        (per_point - number(all) / 2000.0).abs() <= 0.05,
        "{per_point} B/pt against {all} bytes: {report}"
    );
    // The series it wrote is a verified cache series.
    let cache = series.join("sphere-2000-12");
    let (ok, out, err) = slosh(&["inspect", cache.to_str().unwrap(), "--verify"]);
    assert!(ok, "{out}{err}");
    // The raw case, baked as played: measured figures, and every step baked and verified.
    let raw: Vec<&str> = report
        .lines()
        .find(|l| l.starts_with("| 2000 points, 12 steps |"))
        .unwrap_or_else(|| panic!("no raw-case row: {report}"))
        .split('|')
        .map(str::trim)
        .collect();
    for cell in [raw[3], raw[5], raw[7]] {
        for part in cell.split('/') {
            assert!(number(part) > 0.0, "{cell}: {report}");
        }
    }
    // The jumps' run starts from an empty cache: what it baked is there, each file verified.
    let baked = series.join("case-2000-12/cache");
    let files: Vec<std::path::PathBuf> = std::fs::read_dir(&baked)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "slc"))
        .collect();
    assert!(files.len() >= 2, "{files:?}");
    for file in files {
        let (ok, out, err) = slosh(&["inspect", file.to_str().unwrap(), "--verify"]);
        assert!(ok, "{out}{err}");
    }
}

/// `slosh bench scrub --raw-case-only` with `--cold` or `--raw`, which are about the baked
/// series it leaves out, is refused before anything runs. (What it reports is the report's
/// own unit test.)
#[test]
fn scrub_bench_raw_case_only_refuses_the_series_flags() {
    let dir = tempfile::tempdir().unwrap();
    let md = dir.path().join("scrub.md");
    let series = dir.path().join("series");
    for flag in ["--cold", "--raw"] {
        let (ok, out, err) = quick_scrub(&["--raw-case-only", flag], &md, &series)
            .expect("refused before any adapter is looked for");
        assert!(
            !ok && err.contains("--raw-case-only leaves out the baked series"),
            "{out}{err}"
        );
        assert!(!md.exists() && !series.exists(), "{flag}: nothing runs");
    }
}

/// `slosh bench scrub` holds its folder: a second run there (which would empty the raw
/// case's cache, and rewrite the series, under the first) is refused at once, with the folder
/// and the way out named.
#[test]
fn scrub_bench_refuses_a_folder_another_run_holds() {
    let dir = tempfile::tempdir().unwrap();
    let series = dir.path().join("series");
    std::fs::create_dir_all(&series).unwrap();
    // Held here as the other run would hold it: the lock file's first byte.
    let locks = slosh_fileio::RangeLocks::open(&series.join(".scrub.lock")).unwrap();
    let _held = locks.try_lock(0).unwrap().expect("free before the run");
    let md = dir.path().join("scrub.md");
    let Some((ok, out, err)) = quick_scrub(&["--raw-case-only"], &md, &series) else {
        return;
    };
    assert!(
        !ok && err.contains("another `slosh bench scrub` is running there now")
            && err.contains(series.to_str().unwrap())
            && err.contains("--dir"),
        "{out}{err}"
    );
    assert!(!md.exists(), "no report");
    let left: Vec<_> = std::fs::read_dir(&series).unwrap().collect();
    assert_eq!(left.len(), 1, "only the lock file: {left:?}");
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
    demo_fills_the_view(&root.join("cache"), dir.path());
}

/// The player's first frame of the demo (issue 28, item 3): the camera it frames the series
/// with for the viewport of its default 1280×800 window (1020×720 beside the controls), the
/// step traced: the water spans at least half the viewport's width.
fn demo_fills_the_view(cache: &std::path::Path, dir: &std::path::Path) {
    let manifest: Value =
        serde_json::from_str(&std::fs::read_to_string(cache.join("manifest.json")).unwrap())
            .unwrap();
    let corner = |k: usize| -> [f64; 3] {
        std::array::from_fn(|a| manifest["bounds"][k][a].as_f64().unwrap())
    };
    let (w, h) = (1020u32, 720u32);
    let camera = slosh_mls::Camera::filling(&[corner(0), corner(1)], 40.0, w, h, [0.0, 0.0, 1.0]);
    let v = |p: [f64; 3]| format!("{},{},{}", p[0], p[1], p[2]);
    let npy = dir.join("first.npy");
    let (ok, out, err) = slosh(&[
        "render",
        cache.to_str().unwrap(),
        "--step",
        "0",
        "--size",
        &format!("{w}x{h}"),
        "--eye",
        &v(camera.eye),
        "--target",
        &v(camera.target),
        "--up",
        "0,0,1",
        "--fov",
        "40",
        "--out",
        dir.join("first.png").to_str().unwrap(),
        "--aov",
        npy.to_str().unwrap(),
    ]);
    assert!(ok, "{out}{err}");
    let bytes = std::fs::read(&npy).unwrap();
    let values: &[f32] = bytemuck::cast_slice(&bytes[128..]);
    let hit_columns: Vec<usize> = (0..w as usize)
        .filter(|&x| (0..h as usize).any(|y| values[(y * w as usize + x) * 8 + 7] != 0.0))
        .collect();
    let span = hit_columns.last().unwrap() - hit_columns.first().unwrap() + 1;
    eprintln!(
        "the demo's first frame: water across {span} of {w} columns ({:.0} %)",
        100.0 * span as f64 / f64::from(w)
    );
    assert!(
        2 * span >= w as usize,
        "the water spans {span} of {w} columns"
    );
}
