//! What the CLI and window suites share: running the binary, generating a case, baking it,
//! and whether a tool is on the PATH.

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

/// Runs `slosh ARGS…`, which must succeed: its stdout and stderr together.
pub fn slosh_ok(args: &[&str]) -> String {
    let (ok, out, err) = slosh(args);
    let text = format!("{out}{err}");
    assert!(ok, "slosh {args:?}: {text}");
    text
}

/// Whether `tool` is on the PATH.
pub fn have(tool: &str) -> bool {
    Command::new("sh")
        .args(["-c", &format!("command -v {tool}")])
        .output()
        .is_ok_and(|o| o.status.success())
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

/// The hit pixels (x, y) of a hit buffer `slosh render --aov` wrote for a frame `width`
/// pixels wide (8 f32s a pixel, the last one its status, 0 for a miss).
pub fn aov_hits(path: &Path, width: usize) -> Vec<(usize, usize)> {
    let bytes = std::fs::read(path).unwrap();
    let values: &[f32] = bytemuck::cast_slice(&bytes[128..]);
    values
        .chunks_exact(8)
        .enumerate()
        .filter(|(_, p)| p[7] != 0.0)
        .map(|(k, _)| (k % width, k / width))
        .collect()
}

/// RGB8 pixels of a PNG.
pub fn png_rgb(path: &Path) -> (u32, u32, Vec<u8>) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgb, "{}", path.display());
    buf.truncate(info.buffer_size());
    (info.width, info.height, buf)
}
