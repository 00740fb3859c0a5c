//! `slosh render`: a frame (PNG) and its hit buffer (.npy) from a cache. The CPU reference
//! tracer runs straight on the mapped cache through its baked BVH.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use slosh_cache::{CacheFile, LoadedStep, step_file_name};
use slosh_mls::{Camera, HitStatus, NormalsMode, Params, TraceHit};

use crate::cli::{ModeArg, RenderArgs};

/// Status codes in the hit buffer's 8th channel.
pub fn status_code(status: HitStatus) -> f32 {
    match status {
        HitStatus::Converged => 1.0,
        HitStatus::IterationLimit => 2.0,
        HitStatus::NoSupport => 3.0,
        HitStatus::DegenerateFit => 4.0,
        HitStatus::Droplet => 5.0,
        // Not hits; never stored for a hit pixel.
        HitStatus::LeftTrustRegion | HitStatus::NoInitialRoot | HitStatus::MissedBall => 0.0,
    }
}

fn parse_vec3(flag: &str, s: &str) -> Result<[f64; 3]> {
    let parts: Vec<&str> = s.split(',').collect();
    let bad = || anyhow::anyhow!("--{flag} {s}: expected X,Y,Z");
    if parts.len() != 3 {
        return Err(bad());
    }
    let mut v = [0.0f64; 3];
    for (o, p) in v.iter_mut().zip(&parts) {
        *o = p.trim().parse().map_err(|_| bad())?;
        if !o.is_finite() {
            return Err(bad());
        }
    }
    Ok(v)
}

pub fn parse_size(s: &str) -> Result<(u32, u32)> {
    let bad = || anyhow::anyhow!("--size {s}: expected WxH, e.g. 1280x800");
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(bad)?;
    let (w, h): (u32, u32) = (w.parse().map_err(|_| bad())?, h.parse().map_err(|_| bad())?);
    if w == 0 || h == 0 || u64::from(w) * u64::from(h) > 1 << 28 {
        return Err(bad());
    }
    Ok((w, h))
}

/// A camera looking at the centre of `bounds` from the front-left, above, framing them.
pub fn framing_camera(bounds: &[[f64; 3]; 2], fov_y: f64, width: u32, height: u32) -> Camera {
    let centre: [f64; 3] = std::array::from_fn(|a| 0.5 * (bounds[0][a] + bounds[1][a]));
    let radius = (0..3)
        .map(|a| (bounds[1][a] - bounds[0][a]).powi(2))
        .sum::<f64>()
        .sqrt()
        .max(1e-9)
        * 0.5;
    let dir: [f64; 3] = [0.45, -0.8, 0.4];
    let len = (dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]).sqrt();
    let distance = 1.1 * radius / (fov_y.to_radians() * 0.5).sin();
    Camera {
        eye: std::array::from_fn(|a| centre[a] + dir[a] / len * distance),
        target: centre,
        up: [0.0, 0.0, 1.0],
        fov_y,
        width,
        height,
    }
}

fn step_path(path: &Path, step: usize) -> PathBuf {
    if path.is_dir() {
        path.join(step_file_name(step))
    } else {
        path.to_path_buf()
    }
}

/// 8-bit sRGB of a linear value in [0, 1].
fn srgb(v: f64) -> u8 {
    let v = v.clamp(0.0, 1.0);
    let s = if v <= 0.0031308 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0).round() as u8
}

/// Blinn–Phong under a key light and a fill, water-blue; back faces lit as front faces.
fn shade(hit: &TraceHit, dir: [f64; 3], mode: ModeArg) -> [f64; 3] {
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    match mode {
        ModeArg::Normals => hit.normal.map(|c| 0.5 + 0.5 * c),
        ModeArg::Status => match hit.status {
            HitStatus::Converged => [0.1, 0.7, 0.2],
            HitStatus::IterationLimit => [0.9, 0.8, 0.1],
            HitStatus::Droplet => [0.2, 0.4, 0.95],
            _ => [0.9, 0.15, 0.1],
        },
        ModeArg::Shade => {
            let mut n = hit.normal;
            if dot(n, dir) > 0.0 {
                n = n.map(|c| -c);
            }
            let view = dir.map(|c| -c);
            let norm = |v: [f64; 3]| {
                let l = dot(v, v).sqrt();
                v.map(|c| c / l)
            };
            let key = norm([0.4, -0.3, 0.85]);
            let fill = norm([-0.6, 0.5, 0.3]);
            let base = [0.16, 0.42, 0.72];
            let half = norm([key[0] + view[0], key[1] + view[1], key[2] + view[2]]);
            let diffuse = 0.85 * dot(n, key).max(0.0) + 0.25 * dot(n, fill).max(0.0);
            let spec = 0.6 * dot(n, half).max(0.0).powf(60.0);
            // A rim term reads the silhouette of thin sheets against the background.
            let rim = 0.25 * (1.0 - dot(n, view).max(0.0)).powi(3);
            std::array::from_fn(|c| base[c] * (0.12 + diffuse) + spec + rim)
        }
    }
}

fn write_png(path: &Path, width: u32, height: u32, rgb: &[u8]) -> Result<()> {
    let mut bytes = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut bytes, width, height);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut w = enc.write_header()?;
        w.write_image_data(rgb)?;
    }
    slosh_fileio::atomic_write(path, &bytes)?;
    Ok(())
}

/// float32 H×W×C little-endian .npy.
pub fn write_npy(
    path: &Path,
    height: u32,
    width: u32,
    channels: usize,
    data: &[f32],
) -> Result<()> {
    let dict = format!(
        "{{'descr': '<f4', 'fortran_order': False, 'shape': ({height}, {width}, {channels}), }}"
    );
    // Magic (6) + version (2) + length (2) + dict + newline, padded to 64 bytes.
    let total = (10 + dict.len() + 1).div_ceil(64) * 64;
    let mut bytes = Vec::with_capacity(total + data.len() * 4);
    bytes.extend_from_slice(b"\x93NUMPY\x01\x00");
    bytes.extend_from_slice(&((total - 10) as u16).to_le_bytes());
    bytes.extend_from_slice(dict.as_bytes());
    bytes.resize(total - 1, b' ');
    bytes.push(b'\n');
    bytes.extend_from_slice(bytemuck::cast_slice(data));
    slosh_fileio::atomic_write(path, &bytes)?;
    Ok(())
}

/// The hit buffer of a render: 8 floats per pixel, zeros for a miss.
pub fn hit_buffer(hits: &[Option<TraceHit>]) -> Vec<f32> {
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
            px[7] = status_code(h.status);
        }
    }
    out
}

pub fn run(args: &RenderArgs) -> Result<()> {
    if !args.cpu {
        bail!(
            "this build traces on the CPU only: pass --cpu (the GPU tracer is not part of it yet)"
        );
    }
    if args.out.is_none() && args.aov.is_none() {
        bail!("nothing to write: give --out frame.png and/or --aov hits.npy");
    }
    if args.iterations == 0 {
        bail!("--iterations must be at least 1");
    }
    let (width, height) = parse_size(&args.size)?;
    let path = step_path(&args.path, args.step);
    let file = CacheFile::open(&path).with_context(|| format!("opening step {}", args.step))?;
    let step = LoadedStep::load(&file)?;
    let h = file.header();
    let mut camera = framing_camera(&h.bounds, args.fov, width, height);
    if let Some(e) = &args.eye {
        camera.eye = parse_vec3("eye", e)?;
    }
    if let Some(t) = &args.target {
        camera.target = parse_vec3("target", t)?;
    }
    if let Some(u) = &args.up {
        camera.up = parse_vec3("up", u)?;
    }
    let params = Params {
        degree: h.mls.degree,
        iterations: args.iterations,
        epsilon: 1e-4,
        normals: match h.mls.normals.as_str() {
            "covariance" => NormalsMode::Covariance,
            _ => NormalsMode::Mean,
        },
        h_factor: 1.0,
    };
    let start = std::time::Instant::now();
    let hits = step.render(&camera, &params);
    let seconds = start.elapsed().as_secs_f64();
    let hit_count = hits.iter().filter(|h| h.is_some()).count();
    if let Some(out) = &args.out {
        let mut rgb = Vec::with_capacity(hits.len() * 3);
        for (i, hit) in hits.iter().enumerate() {
            let (x, y) = (i as u32 % width, i as u32 / width);
            let colour = match hit {
                Some(hit) => shade(hit, camera.ray(x, y).1, args.mode),
                None => {
                    let t = f64::from(y) / f64::from(height);
                    [0.03 + 0.05 * t, 0.035 + 0.05 * t, 0.05 + 0.06 * t]
                }
            };
            rgb.extend(colour.map(srgb));
        }
        write_png(out, width, height, &rgb)?;
    }
    if let Some(aov) = &args.aov {
        write_npy(aov, height, width, 8, &hit_buffer(&hits))?;
    }
    println!(
        "step {} ({} points): {width}x{height}, {} iterations, {hit_count} hit pixels, traced in {seconds:.2} s on the CPU",
        h.source.step, h.points, args.iterations
    );
    Ok(())
}
