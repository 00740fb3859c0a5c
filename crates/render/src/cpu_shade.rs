//! The CPU's picture of a frame, beside the GPU's: the colours `shade.wgsl` gives a hit, the
//! background, and the hit buffer both write to `.npy`, with the status codes of
//! `layout::status` (one source for both tracers).

use slosh_mls::{Camera, HitStatus, TraceHit};

use crate::layout::{GpuHit, status};
use crate::tracer::ShadeMode;
use crate::upload::GpuStep;

/// The status code of a CPU hit, as the GPU writes it (`layout::status`).
pub fn status_code(status: HitStatus) -> u32 {
    match status {
        HitStatus::Converged => status::CONVERGED,
        HitStatus::IterationLimit => status::ITERATION_LIMIT,
        HitStatus::NoSupport => status::NO_SUPPORT,
        HitStatus::DegenerateFit => status::DEGENERATE_FIT,
        HitStatus::Droplet => status::DROPLET,
        // Not hits; never stored for a hit pixel.
        HitStatus::LeftTrustRegion | HitStatus::NoInitialRoot | HitStatus::MissedBall => {
            status::MISS
        }
    }
}

/// 8-bit sRGB of a linear value in [0, 1].
pub fn srgb(v: f64) -> u8 {
    let v = v.clamp(0.0, 1.0);
    let s = if v <= 0.0031308 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0).round() as u8
}

/// The CPU's colour of a hit seen along `dir`, as `shade.wgsl` colours it: Blinn–Phong under
/// a key light and a fill, water-blue, back faces lit as front faces; or the diagnostic modes.
pub fn shade(hit: &TraceHit, dir: [f64; 3], mode: ShadeMode) -> [f64; 3] {
    shade_coloured(hit, dir, mode, None)
}

/// [`shade`], the shaded modes lighting `base` (a field's colour) where given instead of the
/// surface's own colour, as `shade.wgsl` lights a field's.
pub fn shade_coloured(
    hit: &TraceHit,
    dir: [f64; 3],
    mode: ShadeMode,
    base: Option<[f64; 3]>,
) -> [f64; 3] {
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    match mode {
        ShadeMode::Normals => hit.normal.map(|c| 0.5 + 0.5 * c),
        ShadeMode::Backfaces => {
            let facing = dot(hit.normal, dir);
            let base = if facing > 0.0 {
                [0.95, 0.1, 0.85]
            } else {
                [0.6; 3]
            };
            base.map(|c| c * (0.4 + 0.6 * facing.abs()))
        }
        ShadeMode::Status => match hit.status {
            HitStatus::Converged => [0.1, 0.7, 0.2],
            HitStatus::IterationLimit => [0.9, 0.8, 0.1],
            HitStatus::Droplet => [0.2, 0.4, 0.95],
            _ => [0.9, 0.15, 0.1],
        },
        // Water needs secondary rays through the GPU's BVH: the CPU path refuses it before it
        // gets here, so it is shaded as the plain mode would be.
        ShadeMode::Shade | ShadeMode::Water => {
            let mut n = hit.normal;
            if dot(n, dir) > 0.0 {
                n = n.map(|c| -c);
            }
            let view = dir.map(|c| -c);
            let norm = |v: [f64; 3]| {
                let l = dot(v, v).sqrt();
                v.map(|c| c / l)
            };
            let key = crate::layout::DEFAULT_KEY_LIGHT.map(f64::from);
            let fill = norm([-0.6, 0.5, 0.3]);
            let base = base.unwrap_or(crate::colormap::SURFACE_COLOUR.map(f64::from));
            let half = norm([key[0] + view[0], key[1] + view[1], key[2] + view[2]]);
            let diffuse = 0.85 * dot(n, key).max(0.0) + 0.25 * dot(n, fill).max(0.0);
            let spec = 0.6 * dot(n, half).max(0.0).powf(60.0);
            // A rim term reads the silhouette of thin sheets against the background.
            let rim = 0.25 * (1.0 - dot(n, view).max(0.0)).powi(3);
            std::array::from_fn(|c| base[c] * (0.12 + diffuse) + spec + rim)
        }
    }
}

/// The CPU's hits as the `.npy` layout: 8 floats per pixel (position, normal, t, status),
/// zeros for a miss.
/// The CPU tracer's frame as sRGB bytes: each hit shaded as `shade.wgsl` shades it, the
/// background elsewhere.
pub fn cpu_frame_rgb(hits: &[Option<TraceHit>], camera: &Camera, mode: ShadeMode) -> Vec<u8> {
    cpu_frame_rgb_coloured(hits, camera, mode, |_| None)
}

/// [`cpu_frame_rgb`], hit `i` lit in `base(i)` where that is given (a field's colour,
/// [`shade_coloured`]).
pub fn cpu_frame_rgb_coloured(
    hits: &[Option<TraceHit>],
    camera: &Camera,
    mode: ShadeMode,
    base: impl Fn(usize) -> Option<[f64; 3]>,
) -> Vec<u8> {
    let (width, height) = (camera.width, camera.height);
    let mut rgb = Vec::with_capacity(hits.len() * 3);
    for (i, hit) in hits.iter().enumerate() {
        let (x, y) = (i as u32 % width, i as u32 / width);
        let colour = match hit {
            Some(hit) => shade_coloured(hit, camera.ray(x, y).1, mode, base(i)),
            None => background(y, height),
        };
        rgb.extend(colour.map(srgb));
    }
    rgb
}

pub fn cpu_hit_buffer(hits: &[Option<TraceHit>]) -> Vec<f32> {
    let mut out = vec![0f32; hits.len() * 8];
    for (px, hit) in out.chunks_exact_mut(8).zip(hits) {
        if let Some(h) = hit {
            let v = [
                h.position[0],
                h.position[1],
                h.position[2],
                h.normal[0],
                h.normal[1],
                h.normal[2],
                h.t,
            ];
            for (o, x) in px.iter_mut().zip(v) {
                *o = x as f32;
            }
            px[7] = status_code(h.status) as f32;
        }
    }
    out
}

/// The background of row `y` of `height`, as `shade.wgsl` draws it.
pub fn background(y: u32, height: u32) -> [f64; 3] {
    let t = f64::from(y) / f64::from(height);
    [0.03 + 0.05 * t, 0.035 + 0.05 * t, 0.05 + 0.06 * t]
}

/// The GPU's hits in world coordinates, as the `.npy` layout.
pub fn gpu_hit_buffer(step: &GpuStep, hits: &[GpuHit]) -> Vec<f32> {
    let mut out = vec![0f32; hits.len() * 8];
    for (px, h) in out.chunks_exact_mut(8).zip(hits) {
        if h.status == status::MISS {
            continue;
        }
        let p = step.info.transform.to_world(h.position.map(f64::from));
        let t = f64::from(h.t) * step.info.transform.scale;
        let v = [p[0], p[1], p[2]];
        for (o, x) in px.iter_mut().zip(v) {
            *o = x as f32;
        }
        px[3..6].copy_from_slice(&h.normal);
        px[6] = t as f32;
        px[7] = h.status as f32;
    }
    out
}
