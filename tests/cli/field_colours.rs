//! `slosh render --field` over a sequence: every frame's colours span the series' range (read
//! from the caches' own values), or a fixed one, or each step's; a vector field colours by a
//! component, where a view the cache lacks is refused with those it has; and the CPU tracer
//! colours a field as the GPU does.

use std::path::{Path, PathBuf};

use slosh_cache::CacheFile;

use slosh_testkit::psnr_db;

use crate::util::{bake_case, generate, in_ci, png_rgb, slosh};

/// The finite range of field `name` (an `f32` section) of a cache step, decoded here.
fn step_range(path: &Path, name: &str) -> (f32, f32) {
    let file = CacheFile::open(path).unwrap();
    let entry = file.section(&format!("field.{name}")).unwrap();
    let mut bytes = vec![0u8; entry.raw as usize];
    file.decode_into(entry, &mut bytes, &mut Vec::new())
        .unwrap();
    bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .filter(|v| v.is_finite())
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        })
}

/// A generated tank of `steps` steps under `dir`, baked with `fields` into `dir`/cache.
fn tank_cache(dir: &Path, steps: &str, fields: &str) -> PathBuf {
    let case_dir = dir.join("tank");
    generate(&case_dir, &["tank", "--points", "6000", "--steps", steps]);
    let cache = dir.join("cache");
    let (ok, _, err) = bake_case(
        &case_dir.join("tank.case"),
        &cache,
        &["--fields", fields, "--quiet"],
    );
    assert!(ok, "bake failed: {err}");
    cache
}

/// `slosh render` of the tank's `cache` into `out` with `args`, through one camera for every
/// frame (a step drawn alone is framed by itself, a sequence by all of its steps).
fn render_tank(cache: &Path, out: &Path, args: &[&str]) -> (bool, String, String) {
    let camera = ["--eye", "1,-3,2", "--target", "0.5,0.25,0.2"];
    let (cache, out) = (cache.to_str().unwrap(), out.to_str().unwrap());
    slosh(&[&["render", cache, "--out", out][..], &camera, args].concat())
}

#[test]
fn a_sequence_colours_every_step_on_one_range() {
    let dir = tempfile::tempdir().unwrap();
    let cache = tank_cache(dir.path(), "3", "pressure,normal");
    let ranges: Vec<(f32, f32)> = (0..3)
        .map(|s| step_range(&cache.join(format!("step-{s:05}.slc")), "pressure"))
        .collect();
    assert!(
        ranges.windows(2).any(|w| w[0] != w[1]),
        "the steps' ranges are alike, so the test could not fail: {ranges:?}"
    );
    let (lo, hi) = ranges
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), r| {
            (a.min(r.0), b.max(r.1))
        });
    // The manifest records that range, which the player's colours span from the first frame.
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(cache.join("manifest.json")).unwrap())
            .unwrap();
    let recorded = &manifest["field_ranges"]["pressure"];
    // (f32s written as the shortest decimals that read back as them.)
    let as_f32 = |v: &serde_json::Value| v.as_f64().map(|v| v as f32);
    assert_eq!(
        (as_f32(&recorded[0]), as_f32(&recorded[1])),
        (Some(lo), Some(hi)),
        "{manifest}"
    );
    let render_field = |field: &str, out: &Path, extra: &[&str]| {
        let args = [&["--field", field, "--size", "96x64"][..], extra].concat();
        render_tank(&cache, out, &args)
    };
    let render = |out: &Path, extra: &[&str]| render_field("pressure", out, extra);
    let series = dir.path().join("series");
    std::fs::create_dir_all(&series).unwrap();
    let (ok, out, err) = render(&series.join("{:05}.png"), &["--steps", "0..3"]);
    if !ok && !in_ci() && err.contains("adapter") {
        eprintln!("skipping: {err}");
        return;
    }
    assert!(ok, "render failed: {out}{err}");
    assert!(
        out.contains(&format!(
            "span {lo:e} to {hi:e}, its range over the 3 steps"
        )),
        "{out}"
    );
    // Each step alone, fixed at that range: the same frames, byte for byte.
    let fixed = format!("{lo:e},{hi:e}");
    for s in 0..3 {
        let alone = dir.path().join(format!("alone-{s}.png"));
        let (ok, out, err) = render(&alone, &["--step", &s.to_string(), "--field-range", &fixed]);
        assert!(ok, "render failed: {out}{err}");
        assert!(
            std::fs::read(&alone).unwrap()
                == std::fs::read(series.join(format!("{s:05}.png"))).unwrap(),
            "step {s} alone on the series' range differs from the sequence's frame"
        );
    }
    // Each step's own range: some frame differs.
    let own = dir.path().join("own");
    std::fs::create_dir_all(&own).unwrap();
    let (ok, out, err) = render(
        &own.join("{:05}.png"),
        &["--steps", "0..3", "--field-range", "step"],
    );
    assert!(ok, "render failed: {out}{err}");
    assert!(!out.contains("its range over"), "{out}");
    let differ = (0..3)
        .filter(|s| {
            let name = format!("{s:05}.png");
            std::fs::read(own.join(&name)).unwrap() != std::fs::read(series.join(&name)).unwrap()
        })
        .count();
    assert!(differ > 0, "no frame changed with each step's own range");
    // A range that is not one.
    let (ok, _, err) = render(&own.join("x.png"), &["--field-range", "2,1"]);
    assert!(
        !ok && err.contains("--field-range 2,1: LO must lie below HI"),
        "{err}"
    );

    // A vector field, by component; a view the cache lacks is refused with those it has.
    let (ok, out, err) = render_field("normal.y", &own.join("normal-y.png"), &[]);
    assert!(ok, "render failed: {out}{err}");
    let (ok, out, err) = render_field("normal.w", &own.join("normal-w.png"), &[]);
    assert!(!ok, "{out}");
    assert!(
        err.contains("no field 'normal.w' in this cache; baked fields: pressure, normal, normal.x, normal.y, normal.z")
            || err.contains("no field 'normal.w' in this cache; baked fields: normal, normal.x, normal.y, normal.z, pressure"),
        "{err}"
    );
}

/// `--cpu` colours a field as the GPU's shade pass does: a one-iteration frame by each hit
/// ball's own value, a refined one by the weighted mean over its neighbours, both on the same
/// range and map; the frames agree within 60 dB PSNR (they differ where the two tracers'
/// f32 arithmetic puts a silhouette pixel's hit a little apart).
#[test]
fn the_cpu_tracer_colours_a_field_as_the_gpu_does() {
    let dir = tempfile::tempdir().unwrap();
    let cache = tank_cache(dir.path(), "2", "pressure");
    let render = |out: &Path, extra: &[&str]| {
        let args = [&["--step", "1", "--size", "192x128"][..], extra].concat();
        let (ok, stdout, err) = render_tank(&cache, out, &args);
        (ok, format!("{stdout}{err}"))
    };
    let plain = dir.path().join("plain.png");
    let (ok, said) = render(&plain, &["--cpu", "--iterations", "3"]);
    assert!(ok, "{said}");
    for iterations in ["1", "3"] {
        let field = ["--field", "pressure", "--iterations", iterations];
        let (gpu, cpu) = (dir.path().join("gpu.png"), dir.path().join("cpu.png"));
        let (ok, said) = render(&gpu, &field);
        if !ok && !in_ci() && said.contains("adapter") {
            eprintln!("skipping: {said}");
            return;
        }
        assert!(ok, "{said}");
        let (ok, said) = render(&cpu, &[&field[..], &["--cpu"]].concat());
        assert!(ok, "{said}");
        let db = psnr_db(&png_rgb(&gpu).2, &png_rgb(&cpu).2);
        eprintln!("{iterations} iterations: the CPU's frame against the GPU's: {db:.1} dB PSNR");
        assert!(db >= 60.0, "{iterations} iterations: {db:.1} dB");
        // The colours show: the field's frame is not the plain one.
        let apart = psnr_db(&png_rgb(&plain).2, &png_rgb(&cpu).2);
        assert!(
            apart < 30.0,
            "{iterations} iterations: {apart:.1} dB from the plain frame"
        );
    }
}

/// A raw case drawn by a vector's component (`slosh render CASE.case --field normal.z`)
/// bakes the vector it reads, where the bake was asked for a variable `normal.z` the case
/// does not have; the cache then offers every view of it.
#[test]
fn a_raw_case_coloured_by_a_component_bakes_its_vector() {
    let dir = tempfile::tempdir().unwrap();
    let case_dir = dir.path().join("tank");
    generate(&case_dir, &["tank", "--points", "6000", "--steps", "2"]);
    let cache = dir.path().join("raw-cache");
    let out = dir.path().join("z.png");
    let (ok, stdout, err) = slosh(&[
        "render",
        case_dir.join("tank.case").to_str().unwrap(),
        "--cache",
        cache.to_str().unwrap(),
        "--step",
        "1",
        "--field",
        "normal.z",
        "--size",
        "96x64",
        "--out",
        out.to_str().unwrap(),
    ]);
    if !ok && !in_ci() && err.contains("adapter") {
        eprintln!("skipping: {err}");
        return;
    }
    assert!(ok, "{stdout}{err}");
    let file = CacheFile::open(&cache.join("step-00001.slc")).unwrap();
    assert_eq!(
        slosh_cache::field_views(file.header()),
        ["normal", "normal.x", "normal.y", "normal.z"]
    );
}
