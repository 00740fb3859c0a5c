//! What the CLI test suites share: running the binary, generating a case, baking it.

#![allow(dead_code, clippy::unwrap_used)] // each suite uses its own part of the kit

use std::path::Path;
use std::process::Command;

/// Runs `slosh ARGS…`: (success, stdout, stderr).
pub fn slosh(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_slosh"))
        .args(args)
        .output()
        .expect("run slosh");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// `slosh gen ARGS… --out DIR`, which must succeed.
pub fn generate(dir: &Path, args: &[&str]) {
    let mut all = vec!["gen"];
    all.extend_from_slice(args);
    all.extend_from_slice(&["--out", dir.to_str().unwrap()]);
    let (ok, _, err) = slosh(&all);
    assert!(ok, "slosh gen failed: {err}");
}

/// `slosh bake CASE --out OUT EXTRA…`.
pub fn bake_case(case: &Path, out: &Path, extra: &[&str]) -> (bool, String, String) {
    let mut args = vec![
        "bake",
        case.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    slosh(&args)
}

#[allow(unused_imports)] // not every suite asks
pub use slosh_testkit::in_ci;
