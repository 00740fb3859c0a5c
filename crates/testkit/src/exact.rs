//! A step baked and stored in the compact layout, beside the same step as the bake computed
//! it, before the layout stored it: what the compact layout costs is the difference.

use std::path::Path;

use slosh_bake::{BakeParams, StepInput, bake_step_parts};
use slosh_cache::{CacheFile, LoadedStep, encode_step};
use slosh_fileio::FileBytes;
use slosh_mls::{Surface, V3};

use crate::KitError;

/// The compact cache of `input` read back (as [`crate::bake_in_memory`]), and its step
/// "stored exactly": the same surface with the bake's f64 support normals, coefficients and
/// data normals, radii of trust and reaches rounded once to f32 and its own neighbour lists,
/// in place of what the layout stores (octahedral normals, half-float coefficients, radii
/// and reaches rounded up to half floats, lists recovered from the stored values).
/// Positions, h, droplets and the BVH are the cache's in both.
pub fn bake_exact_and_stored(
    input: &StepInput,
    params: &BakeParams,
    name: &Path,
) -> Result<(LoadedStep, CacheFile), KitError> {
    let (baked, parts) = bake_step_parts(input, params)?;
    let bytes = encode_step(baked.header, &baked.sections, params.compression)?;
    let file = CacheFile::from_bytes(FileBytes::from_vec(name, bytes))?;
    let stored = LoadedStep::load(&file)?;
    let f32x3 = |v: V3<f64>| V3::new(v.x as f32, v.y as f32, v.z as f32);
    let mut exact = stored.surface.into_parts();
    // The radii of trust and the reaches as computed, not rounded up to the stored half
    // floats (the stored BVH's boxes hold the smaller balls too).
    for ((ball, own), &radius) in exact.balls.iter_mut().zip(&parts.balls).zip(&parts.radii) {
        ball.normal = f32x3(own.normal);
        ball.poly.c = own.poly.c.map(|c| c as f32);
        ball.radius = radius as f32;
    }
    exact.radii = parts.radii.iter().map(|&r| r as f32).collect();
    exact.reach = parts.reach.iter().map(|&r| r as f32).collect();
    exact.normals = parts
        .normals
        .as_ref()
        .map(|ns| ns.iter().map(|&n| f32x3(n)).collect());
    exact.neighbours = parts.neighbours.clone();
    let surface = Surface::from_parts(exact).map_err(|e| {
        KitError::Cache(slosh_cache::Error::Invalid {
            path: name.to_path_buf(),
            problem: format!("the exact parts do not fit together: {e}"),
        })
    })?;
    Ok((
        LoadedStep {
            surface,
            bvh: stored.bvh,
            transform: stored.transform,
        },
        file,
    ))
}
