//! What the test suites and the bench harness share, defined once: a scene's step as bake
//! input, a scene's surface written as an EnSight case, a step baked into an in-memory cache file, the cameras that frame a point set, the
//! mask of silhouette pixels that comparisons leave out, a seeded uniform stream, and the rule
//! for a test that cannot run here (skipped with a message, except under `CI=true`).

use std::path::{Path, PathBuf};

mod exact;
mod uniform;
pub mod wgsl;

pub use exact::bake_exact_and_stored;
pub use uniform::uniform;

use slosh_bake::{BakeError, BakeParams, StepInput, bake_step};
use slosh_cache::{CacheFile, encode_step};
use slosh_fileio::FileBytes;
use slosh_mls::Camera;
use slosh_scenes::Scene;

/// Step `step` of `scene` as a bake takes it: the surface particles with their normals,
/// the step's index and time, `source` as the series' source.
pub fn scene_step(scene: &Scene, step: usize, source: &str) -> StepInput {
    let (positions, normals) = scene.particles(step).surface_arrays();
    StepInput {
        index: step,
        time: scene.time(step),
        source: source.to_string(),
        positions,
        normals: Some(normals),
        ..StepInput::default()
    }
}

/// Steps `0..steps` of `scene`'s surface particles with their normals (a vector variable
/// `normal`), as [`scene_step`] gives them, written as the EnSight 6 binary case `name` under
/// `dir`; the case file.
pub fn write_surface_case(
    dir: &Path,
    name: &str,
    scene: &Scene,
    steps: usize,
) -> Result<PathBuf, slosh_ensight::Error> {
    use slosh_ensight::{CaseWriter, Placement, VarData, VarType, WriteFormat};
    let mut writer = CaseWriter::create(
        dir,
        name,
        WriteFormat::E6Binary,
        Placement::PointPart,
        &[("normal", VarType::Vector)],
    )?;
    let f32x3 =
        |v: &[[f64; 3]]| -> Vec<[f32; 3]> { v.iter().map(|p| p.map(|c| c as f32)).collect() };
    for step in 0..steps {
        let input = scene_step(scene, step, name);
        let normals = f32x3(input.normals.as_deref().unwrap_or_default());
        writer.write_step(
            input.time,
            &f32x3(&input.positions),
            &[VarData::Vector("normal", &normals)],
        )?;
    }
    Ok(writer.case_path())
}

/// Why an in-memory bake failed: the bake, encoding the cache, or reading it back.
#[derive(Debug, thiserror::Error)]
pub enum KitError {
    #[error(transparent)]
    Bake(#[from] BakeError),
    #[error("encoding the step: {0}")]
    Encode(#[from] std::io::Error),
    #[error(transparent)]
    Cache(#[from] slosh_cache::Error),
}

/// `input` baked with `params`, encoded and read back as the cache file `name` that was
/// never written (checked as a file read from disk is).
pub fn bake_in_memory(
    input: &StepInput,
    params: &BakeParams,
    name: &Path,
) -> Result<CacheFile, KitError> {
    let baked = bake_step(input, params)?;
    let bytes = encode_step(baked.header, &baked.sections, params.compression)?;
    Ok(CacheFile::from_bytes(FileBytes::from_vec(name, bytes))?)
}

/// A square camera that frames `points` from a generic direction (front left, above): the
/// bounding box's centre, from 2.5 bounding radii away, 45° vertical field of view, z up.
pub fn framing_camera(points: &[[f64; 3]], size: u32) -> Camera {
    let (lo, hi) = slosh_mls::bounds(points);
    let c: [f64; 3] = std::array::from_fn(|a| 0.5 * (lo[a] + hi[a]));
    let r = (0..3).map(|a| (hi[a] - lo[a]).powi(2)).sum::<f64>().sqrt() * 0.5;
    Camera {
        eye: [c[0] + 0.9 * r, c[1] - 2.2 * r, c[2] + 1.1 * r],
        target: c,
        up: [0.0, 0.0, 1.0],
        fov_y: 45.0,
        width: size,
        height: size,
    }
}

/// The camera of the comparisons against analytic truth (the CPU tracer's tests and `slosh
/// bench accuracy`), square, 40° field of view, z up: the tank scene from its fixed viewpoint
/// over the fluid, anything else from the front left, above the particles' centroid.
pub fn analytic_camera(points: &[[f64; 3]], tank: bool, size: u32) -> Camera {
    let (eye, target) = if tank {
        ([1.0, -1.2, 1.4], [1.0, 0.5, 0.45])
    } else {
        let n = points.len().max(1) as f64;
        let c = points
            .iter()
            .fold([0.0; 3], |a, q| [a[0] + q[0], a[1] + q[1], a[2] + q[2]])
            .map(|v| v / n);
        ([c[0] + 2.2, c[1] - 2.6, c[2] + 1.8], c)
    };
    Camera {
        eye,
        target,
        up: [0.0, 0.0, 1.0],
        fov_y: 40.0,
        width: size,
        height: size,
    }
}

/// Silhouette pixels of an image of depths (`None`: a miss), `width` pixels wide: a pixel
/// whose 3×3 neighbourhood mixes hits and misses, or, with `depth_jump`, holds depths that
/// differ by more than that fraction (an occluding contour, such as a droplet in front of the
/// surface). There two tracers may pick different layers, or one may hit where the other
/// just misses, and both be right.
pub fn silhouette_mask(depth: &[Option<f64>], width: usize, depth_jump: Option<f64>) -> Vec<bool> {
    let height = depth.len() / width.max(1);
    (0..depth.len())
        .map(|i| {
            let (x, y) = ((i % width) as i64, (i / width) as i64);
            (-1..=1).any(|dy| {
                (-1..=1).any(|dx| {
                    let (nx, ny) = (x + dx, y + dy);
                    if nx < 0 || ny < 0 || nx as usize >= width || ny as usize >= height {
                        return false;
                    }
                    match (depth[i], depth[ny as usize * width + nx as usize]) {
                        (Some(a), Some(b)) => {
                            depth_jump.is_some_and(|f| (a - b).abs() > f * a.min(b))
                        }
                        (a, b) => a.is_some() != b.is_some(),
                    }
                })
            })
        })
        .collect()
}

/// Whether this is CI's run (`CI=true`), where every GPU, window, SLURM and peer test must
/// run: the one place the suites read `CI`.
pub fn in_ci() -> bool {
    std::env::var("CI").is_ok_and(|v| v == "true")
}

/// Says that a test cannot run here for `why` (no adapter, a missing tool), so that the
/// caller returns; under `CI=true`, where everything must run, fails the test instead.
pub fn skip(why: &str) {
    assert!(!in_ci(), "CI=true requires this test to run, but: {why}");
    eprintln!("skipping: {why}");
}

/// The GPU adapter the tests use: `SLOSH_ADAPTER` (a part of its name), else the default.
pub fn adapter() -> Option<String> {
    std::env::var("SLOSH_ADAPTER").ok()
}

/// The device `found` opened, or `None` once [`skip`] has said why there is none.
pub fn gpu_or_skip<T, E: std::fmt::Display>(found: Result<T, E>) -> Option<T> {
    match found {
        Ok(gpu) => Some(gpu),
        Err(e) => {
            skip(&format!("no GPU adapter: {e}"));
            None
        }
    }
}

/// Peak signal-to-noise ratio of two 8-bit images of equal length, in dB (peak 255): how
/// decoded video frames are compared with the frames encoded.
pub fn psnr_db(a: &[u8], b: &[u8]) -> f64 {
    assert_eq!(a.len(), b.len(), "images of different sizes");
    let mse = a
        .iter()
        .zip(b)
        .map(|(&x, &y)| (f64::from(x) - f64::from(y)).powi(2))
        .sum::<f64>()
        / a.len().max(1) as f64;
    10.0 * (255.0f64 * 255.0 / mse.max(1e-12)).log10()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn silhouettes_ring_the_edge_of_a_disc_and_a_depth_step() {
        // 7×7: a hit block in columns 2..5, depth 1, except column 4 at depth 2.
        let w = 7;
        let depth: Vec<Option<f64>> = (0..49)
            .map(|i| {
                let x = i % w;
                match x {
                    2 | 3 => Some(1.0),
                    4 => Some(2.0),
                    _ => None,
                }
            })
            .collect();
        let plain = silhouette_mask(&depth, w, None);
        let jumps = silhouette_mask(&depth, w, Some(0.05));
        let row: Vec<bool> = (0..w).map(|x| plain[3 * w + x]).collect();
        assert_eq!(row, [false, true, true, false, true, true, false]);
        // Column 3 lies beside column 4's depth step.
        assert!(jumps[3 * w + 3]);
        let inner = silhouette_mask(&[Some(1.0); 9], 3, Some(0.05));
        assert!(inner.iter().all(|s| !s));
    }
}
