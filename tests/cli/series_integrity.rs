//! A cache directory holds one series, whole (issue 25, items 1 to 5): a bake never overwrites
//! another series, one bake holds a directory for its whole run, gaps and mixtures fail
//! verification with or without a manifest, and concurrent demos do not mix their inputs.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::util::{bake_case, generate, slosh};

fn verify(dir: &Path) -> (bool, String) {
    let (ok, out, err) = slosh(&["inspect", dir.to_str().unwrap(), "--verify"]);
    (ok, format!("{out}{err}"))
}

/// Item 1: another case with the same settings is refused before anything is written, even
/// for steps the run would rewrite; one case given by a relative and an absolute path is one
/// source.
#[test]
fn a_bake_never_overwrites_another_series() {
    let dir = tempfile::tempdir().unwrap();
    generate(
        &dir.path().join("tank"),
        &["tank", "--points", "1500", "--steps", "4"],
    );
    generate(
        &dir.path().join("sphere"),
        &["sphere", "--points", "800", "--steps", "4"],
    );
    let tank = dir.path().join("tank/tank.case");
    let mix = dir.path().join("mix");
    let (ok, out, err) = bake_case(&tank, &mix, &["--quiet"]);
    assert!(ok, "{out}{err}");
    let before = std::fs::read(mix.join("step-00000.slc")).unwrap();
    let manifest = std::fs::read(mix.join("manifest.json")).unwrap();
    let sphere = dir.path().join("sphere/sphere.case");
    let (ok, out, err) = bake_case(&sphere, &mix, &["--steps", "0..3", "--quiet"]);
    assert!(!ok, "{out}");
    assert!(
        err.contains("another series") && err.contains("nothing was written"),
        "{err}"
    );
    assert!(
        err.contains("tank.case") && err.contains("sphere.case"),
        "{err}"
    );
    assert_eq!(std::fs::read(mix.join("step-00000.slc")).unwrap(), before);
    assert_eq!(std::fs::read(mix.join("manifest.json")).unwrap(), manifest);
    // The whole series of another case is refused too.
    let (ok, _, err) = bake_case(&sphere, &mix, &["--quiet"]);
    assert!(!ok && err.contains("another series"), "{err}");
    // The tank again, by a relative path from its own directory: the same source, kept.
    let out = Command::new(env!("CARGO_BIN_EXE_slosh"))
        .current_dir(dir.path().join("tank"))
        .args([
            "bake",
            "tank.case",
            "--out",
            mix.to_str().unwrap(),
            "--quiet",
        ])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success() && text.contains("kept 4"), "{text}");
    let (ok, text) = verify(&mix);
    assert!(ok, "{text}");
}

/// Item 3: a series records its steps; a shard's gap fails the manifest rebuild and
/// verification, until the other shard fills it.
#[test]
fn shard_gaps_fail_every_check_until_filled() {
    let dir = tempfile::tempdir().unwrap();
    generate(
        &dir.path().join("in"),
        &["sphere", "--points", "600", "--steps", "5"],
    );
    let case = dir.path().join("in/sphere.case");
    let sh = dir.path().join("sh");
    let (ok, out, err) = bake_case(&case, &sh, &["--shard", "0/2", "--quiet"]);
    assert!(ok && out.contains("baked 3 steps"), "{out}{err}");
    let (ok, out, err) = slosh(&["bake", "--manifest-only", sh.to_str().unwrap()]);
    assert!(!ok, "{out}");
    assert!(
        err.contains("2 of the series' steps 0..=4 (5 steps) are missing: 1, 3"),
        "{err}"
    );
    let (ok, text) = verify(&sh);
    assert!(!ok && text.contains("are missing: 1, 3"), "{text}");
    // Without a manifest the steps' own record tells the same.
    std::fs::remove_file(sh.join("manifest.json")).unwrap();
    let (ok, text) = verify(&sh);
    assert!(!ok && text.contains("are missing: 1, 3"), "{text}");
    let (ok, out, err) = bake_case(&case, &sh, &["--shard", "1/2", "--quiet"]);
    assert!(ok && out.contains("baked 2 steps"), "{out}{err}");
    let (ok, out, err) = slosh(&["bake", "--manifest-only", sh.to_str().unwrap()]);
    assert!(ok && out.contains("5 steps"), "{out}{err}");
    let (ok, text) = verify(&sh);
    assert!(ok, "{text}");
    // A step deleted later is a gap again.
    std::fs::remove_file(sh.join("step-00002.slc")).unwrap();
    let (ok, text) = verify(&sh);
    assert!(!ok && text.contains("missing"), "{text}");
}

/// Item 2: steps that disagree with each other fail verification even where no manifest
/// says what the series is.
#[test]
fn mixed_steps_fail_verification_without_a_manifest() {
    let dir = tempfile::tempdir().unwrap();
    generate(
        &dir.path().join("in"),
        &["sphere", "--points", "600", "--steps", "3"],
    );
    let case = dir.path().join("in/sphere.case");
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    assert!(bake_case(&case, &a, &["--quiet"]).0);
    assert!(bake_case(&case, &b, &["--quiet", "--degree", "1"]).0);
    std::fs::copy(b.join("step-00001.slc"), a.join("step-00001.slc")).unwrap();
    std::fs::remove_file(a.join("manifest.json")).unwrap();
    let (ok, text) = verify(&a);
    assert!(!ok, "{text}");
    assert!(
        text.contains("NOT OF THIS SERIES") && text.contains("parameter hash"),
        "{text}"
    );
}

/// Waits until a bake started in the background holds `dir` (its lock names its series).
fn wait_for_hold(dir: &Path, child: &mut std::process::Child) {
    let start = Instant::now();
    loop {
        let held = std::fs::read(dir.join(".bake.lock")).is_ok_and(|b| !b.is_empty());
        if held {
            return;
        }
        assert!(
            child.try_wait().unwrap().is_none(),
            "the bake ended before it was seen holding the directory"
        );
        assert!(start.elapsed() < Duration::from_secs(60));
        std::thread::sleep(Duration::from_millis(5));
    }
}

fn background_bake(case: &Path, out: &Path, extra: &[&str]) -> std::process::Child {
    Command::new(env!("CARGO_BIN_EXE_slosh"))
        .args([
            "bake",
            case.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
        .args(["--quiet", "--jobs", "1"])
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// Item 2: one bake holds a directory for its whole run: a second bake with other settings
/// is refused while it runs and writes nothing; a SIGKILLed holder blocks nobody.
#[test]
fn one_bake_holds_a_directory_for_its_whole_run() {
    let dir = tempfile::tempdir().unwrap();
    generate(
        &dir.path().join("in"),
        &["tank", "--points", "30000", "--steps", "6"],
    );
    let case = dir.path().join("in/tank.case");
    let cc = dir.path().join("cc");
    let mut first = background_bake(&case, &cc, &[]);
    wait_for_hold(&cc, &mut first);
    let (ok, out, err) = bake_case(&case, &cc, &["--quiet", "--jobs", "1", "--degree", "1"]);
    let finished_first = first.wait_with_output().unwrap();
    assert!(!ok, "{out}");
    assert!(
        err.contains("is writing this directory now") && err.contains("nothing was written"),
        "{err}"
    );
    assert!(
        finished_first.status.success(),
        "{}",
        String::from_utf8_lossy(&finished_first.stderr)
    );
    let (ok, text) = verify(&cc);
    assert!(ok, "{text}");
    // A holder killed mid-run releases the directory with its process.
    let mut killed = background_bake(&case, &cc, &["--degree", "1"]);
    wait_for_hold(&cc, &mut killed);
    killed.kill().unwrap();
    killed.wait().unwrap();
    let (ok, out, err) = bake_case(&case, &cc, &["--quiet", "--degree", "1"]);
    assert!(ok, "{out}{err}");
    let (ok, text) = verify(&cc);
    assert!(ok, "{text}");
}

/// Item 4: demos started together on one directory take turns: one prepares the series, the
/// other waits and reuses it; neither bakes a mixture.
#[test]
fn concurrent_demos_on_one_directory_take_turns() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("demo");
    let run = || {
        Command::new(env!("CARGO_BIN_EXE_slosh"))
            .args(["demo", "--headless", "--steps", "6", "--points", "1500"])
            .args(["--frames", "1", "--dir", root.to_str().unwrap()])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    let (a, b) = (run(), run());
    let (a, b) = (a.wait_with_output().unwrap(), b.wait_with_output().unwrap());
    let texts: Vec<String> = [&a, &b]
        .iter()
        .map(|o| {
            format!(
                "{}{}",
                String::from_utf8_lossy(&o.stdout),
                String::from_utf8_lossy(&o.stderr)
            )
        })
        .collect();
    assert!(a.status.success() && b.status.success(), "{texts:?}");
    let generated = texts
        .iter()
        .filter(|t| t.contains("generating the demo series"))
        .count();
    assert_eq!(generated, 1, "{texts:?}");
    assert!(
        texts.iter().any(|t| t.contains("already baked")),
        "{texts:?}"
    );
    let (ok, text) = verify(&root.join("cache"));
    assert!(ok && text.contains("6 steps"), "{text}");
}
