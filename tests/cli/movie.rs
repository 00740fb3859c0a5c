//! `slosh render --steps A..B --out NAME.mp4`: an H.264 movie that Debian's ffprobe and
//! ffmpeg read back with one frame per step, the frame size asked for and the duration the
//! series' times give (slowed down), and whose decoded frames are within 35 dB PSNR of the
//! PNG `render` writes of the same step.

use std::process::Command;

use serde_json::Value;

use crate::util::{bake_case, generate, have, in_ci, png_rgb, slosh};

/// The camera of the movie and of its reference frames, over the generated tank.
const EYE: &str = "1,-3,2";
const TARGET: &str = "0.5,0.25,0.2";

#[test]
fn a_range_renders_into_an_mp4_that_ffmpeg_reads_back() {
    if !(have("ffprobe") && have("ffmpeg")) {
        assert!(!in_ci(), "ffprobe and ffmpeg are installed by .ci/run");
        eprintln!("skipping: no ffprobe/ffmpeg on the PATH");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let case_dir = dir.path().join("tank");
    generate(&case_dir, &["tank", "--points", "20000", "--steps", "6"]);
    let cache = dir.path().join("cache");
    let (ok, _, err) = bake_case(&case_dir.join("tank.case"), &cache, &["--quiet"]);
    assert!(ok, "bake failed: {err}");
    let cache_arg = cache.to_str().unwrap();
    let movie = dir.path().join("tank.mp4");
    let (ok, out, err) = slosh(&[
        "render",
        cache_arg,
        "--steps",
        "0..6",
        "--size",
        "320x240",
        // The reference frames below are drawn alone, which frames a step by its own
        // extent, where a sequence is framed by all of its steps': one camera for both.
        "--eye",
        EYE,
        "--target",
        TARGET,
        "--slowdown",
        "10",
        "--out",
        movie.to_str().unwrap(),
    ]);
    if !ok && !in_ci() && err.contains("adapter") {
        eprintln!("skipping the GPU movie: {err}");
        return;
    }
    assert!(ok, "render failed: {out}{err}");
    assert!(out.contains("wrote") && out.contains("6 frames"), "{out}");

    let manifest: Value =
        serde_json::from_str(&std::fs::read_to_string(cache.join("manifest.json")).unwrap())
            .unwrap();
    let times: Vec<f64> = manifest["steps"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["time"].as_f64().unwrap())
        .collect();
    // Each frame lasts until the next step's time, the last as long as the one before it.
    let expected = 10.0 * ((times[5] - times[0]) + (times[5] - times[4]));

    let probe = Command::new("ffprobe")
        .args([
            "-v",
            "error",
            "-select_streams",
            "v:0",
            "-count_frames",
            "-show_entries",
            "stream=codec_name,width,height,nb_read_frames,duration",
            "-of",
            "json",
        ])
        .arg(&movie)
        .output()
        .unwrap();
    assert!(
        probe.status.success(),
        "{}",
        String::from_utf8_lossy(&probe.stderr)
    );
    let probe: Value = serde_json::from_slice(&probe.stdout).unwrap();
    let stream = &probe["streams"][0];
    eprintln!("ffprobe: {stream}");
    assert_eq!(stream["codec_name"], "h264");
    assert_eq!(
        (stream["width"].as_u64(), stream["height"].as_u64()),
        (Some(320), Some(240))
    );
    assert_eq!(stream["nb_read_frames"].as_str(), Some("6"));
    let duration: f64 = stream["duration"].as_str().unwrap().parse().unwrap();
    assert!(
        (duration - expected).abs() < 1e-3,
        "{duration} s, expected {expected} s"
    );

    for step in [0usize, 3] {
        let decoded = dir.path().join(format!("decoded-{step}.png"));
        let status = Command::new("ffmpeg")
            .args(["-v", "error", "-y", "-i"])
            .arg(&movie)
            .args([
                "-vf",
                &format!("select=eq(n\\,{step})"),
                "-frames:v",
                "1",
                "-pix_fmt",
                "rgb24",
            ])
            .arg(&decoded)
            .status()
            .unwrap();
        assert!(status.success());
        let reference = dir.path().join(format!("reference-{step}.png"));
        let (ok, _, err) = slosh(&[
            "render",
            cache_arg,
            "--step",
            &step.to_string(),
            "--size",
            "320x240",
            "--eye",
            EYE,
            "--target",
            TARGET,
            "--out",
            reference.to_str().unwrap(),
        ]);
        assert!(ok, "{err}");
        let (w, h, got) = png_rgb(&decoded);
        let (_, _, want) = png_rgb(&reference);
        assert_eq!((w, h), (320, 240));
        let db = slosh_testkit::psnr_db(&got, &want);
        eprintln!("step {step}: decoded frame against the PNG render: {db:.2} dB PSNR");
        assert!(db >= 35.0, "step {step}: {db:.2} dB");
    }

    // An odd size is refused before anything is traced, naming the file and the fix.
    let (ok, _, err) = slosh(&[
        "render",
        cache_arg,
        "--steps",
        "0..2",
        "--size",
        "321x240",
        "--out",
        movie.to_str().unwrap(),
    ]);
    assert!(
        !ok && err.contains("even") && err.contains("tank.mp4"),
        "{err}"
    );
}
