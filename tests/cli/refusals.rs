//! The CLI end to end: flags and inputs refused with a clear message, and stdout that goes away.

use std::process::Command;

use crate::util::{bake_case, generate, in_ci, slosh};

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

/// A k the GPU's nearest-point search cannot hold is refused before anything is baked (or a
/// GPU opened), naming the flag and the way out.
#[test]
fn a_k_beyond_the_gpu_search_is_refused_up_front() {
    let dir = tempfile::tempdir().unwrap();
    generate(
        &dir.path().join("case"),
        &["sphere", "--points", "500", "--steps", "1"],
    );
    let case = dir.path().join("case/sphere.case");
    let cache = dir.path().join("cache");
    let (ok, _, err) = bake_case(&case, &cache, &["--device", "gpu", "--k", "40"]);
    assert!(!ok, "--k 40 on the GPU was accepted");
    assert!(
        err.contains("--k 40") && err.contains("--device cpu"),
        "{err}"
    );
    assert!(
        !cache.exists(),
        "the refused bake wrote {}",
        cache.display()
    );
}

/// Without `--jobs`, the bake says how many steps it bakes at once and why: from the cores
/// and the memory the first step needs, on the host and, baking on a device, there.
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
    let steps = |jobs: usize| match jobs {
        1 => "1 step".to_string(),
        n => format!("{n} steps"),
    };
    let expected = format!(
        "baking up to {} at once ({cores} cores",
        steps((cores / 2).max(1))
    );
    assert!(out.contains(&expected), "{out}");
    assert!(out.contains("a step of 500 points needs about"), "{out}");
    assert!(out.contains("baked 2 steps"), "{out}");
    // On a device, three jobs for every two cores (lavapipe here: its heap is the host's
    // memory).
    let (ok, out, err) = bake_case(&case, &dir.path().join("gpu-cache"), &["--device", "gpu"]);
    if !ok && !in_ci() && err.contains("adapter") {
        eprintln!("skipping the device's default: {err}");
        return;
    }
    assert!(ok, "{err}");
    let expected = format!(
        "baking up to {} at once ({cores} cores, three steps for every two cores",
        steps((cores * 3 / 2).max(1))
    );
    assert!(out.contains(&expected), "{out}");
    assert!(out.contains("of the device's"), "{out}");
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
    // A size the flag cannot take says which bound it breaks.
    for (size, expected) in [
        ("16X", "expected WxH"),
        ("0x16", "both sides of at least one pixel"),
        (
            "100000x100000",
            "10000000000 pixels, expected at most 268435456",
        ),
    ] {
        let (ok, _, err) = slosh(&["render", c, "--cpu", "--size", size, "--out", p]);
        assert!(!ok && err.contains(expected), "{size}: {err}");
    }
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

/// A bake's `--out` that is a file, not a directory, is named as such and left as it was.
#[test]
fn a_bake_into_a_file_is_refused_and_the_file_kept() {
    let dir = tempfile::tempdir().unwrap();
    generate(
        &dir.path().join("case"),
        &["sphere", "--points", "1500", "--steps", "2"],
    );
    let out = dir.path().join("notes.txt");
    std::fs::write(&out, "kept").unwrap();
    let (ok, _, err) = bake_case(&dir.path().join("case/sphere.case"), &out, &["--quiet"]);
    assert!(!ok);
    assert!(
        err.contains("notes.txt") && err.contains("is not a directory"),
        "{err}"
    );
    assert_eq!(std::fs::read_to_string(&out).unwrap(), "kept");
}

/// Counts a benchmark or a scene cannot take are refused by flag, before any work: `bench
/// bake --points 0` and `--runs 0` panicked.
#[test]
fn point_and_run_counts_out_of_range_are_refused_by_flag() {
    for (line, expected) in [
        (
            "bench bake --points 0",
            "'--points <POINTS>': expected 1 to 200000000 points",
        ),
        (
            "bench bake --runs 0",
            "'--runs <RUNS>': expected at least 1",
        ),
        (
            "bench bake --threads 2,0",
            "'--threads <THREADS>': expected at least 1",
        ),
        (
            "bench scrub --points 1000,0",
            "expected 1 to 200000000 points",
        ),
        (
            "bench gpu --points x",
            "expected a count of points, found 'x'",
        ),
        ("bench precision --points 300000000", "found 300000000"),
        (
            "gen sphere --points 0 --out unused",
            "expected 1 to 200000000",
        ),
        ("demo --points 0", "expected 1 to 200000000"),
    ] {
        let args: Vec<&str> = line.split_whitespace().collect();
        let (ok, _, err) = slosh(&args);
        assert!(!ok, "{line} accepted");
        assert!(
            err.contains(expected) && !err.contains("panicked"),
            "{line}: {err}"
        );
    }
}
