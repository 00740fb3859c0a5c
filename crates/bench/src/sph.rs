//! The SPH section of `slosh bench accuracy --sph DIR`: particles from a real SPH solver
//! (SPlisHSPlasH's dam break, written by `scripts/sph_reference.py`), baked as a user would
//! bake them (`--surface estimate`, no normals), and traced along the same camera rays as
//! the field's reference: splashsurf's mesh of the same particles. Each case directory holds
//! `particles.ply`, `meta.json`, and the reference as `splashsurf.ply` (a triangle mesh) or,
//! for the small fixture the tests keep, `reference-depth.npy` (its ray depths, a miss NaN).

use std::io::BufReader;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use obvhs::BvhBuildParams;
use obvhs::ray::{Ray, RayHit};
use obvhs::triangle::Triangle;
use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{Property, PropertyAccess};
use slosh_bake::{BakeParams, NormalSource, StepInput, SurfaceSelect, bake_step};
use slosh_cache::{CacheFile, LoadedStep, encode_step};
use slosh_fileio::FileBytes;
use slosh_mls::{Camera, Params, TraceHit};

use crate::stats::percentile;

/// Image size of every comparison.
pub const SPH_WIDTH: u32 = 320;
pub const SPH_HEIGHT: u32 = 240;

/// One case's measurements. Distances are in particle spacings (twice the particle radius).
#[derive(Debug, Clone, serde::Serialize)]
pub struct SphResult {
    pub name: String,
    pub particles: usize,
    pub particle_radius: f64,
    pub time: f64,
    /// Pixels away from the reference's silhouettes, and the hits of each there.
    pub compared: usize,
    pub reference_hits: usize,
    pub slosh_hits: usize,
    /// Reference hit, slosh misses: % of the reference's hits.
    pub holes_pct: f64,
    /// Slosh hits, the reference misses: % of slosh's hits.
    pub false_pct: f64,
    /// |Δt| over pixels both hit.
    pub dt_p50: f64,
    pub dt_p90: f64,
    pub dt_p99: f64,
    /// Slosh's hits farther than 4 particle radii from every particle: % of its hits.
    pub far_pct: f64,
    pub spheres: u64,
    pub bake_seconds: f64,
    pub splashsurf_seconds: Option<f64>,
}

struct Vertex([f32; 3]);

impl PropertyAccess for Vertex {
    fn new() -> Self {
        Vertex([0.0; 3])
    }
    fn set_property(
        &mut self,
        key: &str,
        property: Property,
    ) -> ply_rs_bw::ply::PropertyAccessResult {
        let v = match property {
            Property::Float(v) => v,
            Property::Double(v) => v as f32,
            _ => return ply_rs_bw::ply::PropertyAccessResult::Ignored,
        };
        match key {
            "x" => self.0[0] = v,
            "y" => self.0[1] = v,
            "z" => self.0[2] = v,
            _ => return ply_rs_bw::ply::PropertyAccessResult::Ignored,
        }
        ply_rs_bw::ply::PropertyAccessResult::Set
    }
}

struct Face(Vec<i64>);

impl PropertyAccess for Face {
    fn new() -> Self {
        Face(Vec::new())
    }
    fn set_property(
        &mut self,
        key: &str,
        property: Property,
    ) -> ply_rs_bw::ply::PropertyAccessResult {
        if key != "vertex_indices" && key != "vertex_index" {
            return ply_rs_bw::ply::PropertyAccessResult::Ignored;
        }
        self.0 = match property {
            Property::ListInt(v) => v.into_iter().map(i64::from).collect(),
            Property::ListUInt(v) => v.into_iter().map(i64::from).collect(),
            _ => return ply_rs_bw::ply::PropertyAccessResult::Ignored,
        };
        ply_rs_bw::ply::PropertyAccessResult::Set
    }
}

/// A triangle mesh (or, without faces, a point set).
type Mesh = (Vec<[f32; 3]>, Vec<[u32; 3]>);

/// The first surface along each ray: depth t and unit normal, or `None` for a miss.
type RayHits = Vec<Option<(f64, [f64; 3])>>;

/// A PLY file's vertices and (triangle) faces.
fn read_ply(path: &Path) -> Result<Mesh> {
    let file =
        std::fs::File::open(path).with_context(|| format!("{}: cannot open", path.display()))?;
    let mut reader = Reader::new(BufReader::new(file));
    let vertex_parser = Parser::<Vertex>::new();
    let face_parser = Parser::<Face>::new();
    let bad = |e: ply_rs_bw::parser::ParseError| {
        anyhow::anyhow!("{}: not a readable PLY file: {e}", path.display())
    };
    let header = vertex_parser.read_header(&mut reader).map_err(bad)?;
    let (mut vertices, mut faces) = (Vec::new(), Vec::new());
    for element in header.elements.values() {
        match element.name.as_str() {
            "vertex" => {
                vertices = vertex_parser
                    .read_payload_for_element(&mut reader, element, &header)
                    .map_err(bad)?
                    .into_iter()
                    .map(|v| v.0)
                    .collect();
            }
            "face" => {
                for (i, f) in face_parser
                    .read_payload_for_element(&mut reader, element, &header)
                    .map_err(bad)?
                    .into_iter()
                    .enumerate()
                {
                    let ok = f.0.len() == 3
                        && f.0.iter().all(|&v| v >= 0 && (v as usize) < vertices.len());
                    if !ok {
                        bail!(
                            "{}: face {i} is not a triangle of the {} vertices: {:?}",
                            path.display(),
                            vertices.len(),
                            f.0
                        );
                    }
                    faces.push([f.0[0] as u32, f.0[1] as u32, f.0[2] as u32]);
                }
            }
            other => bail!("{}: unexpected PLY element '{other}'", path.display()),
        }
    }
    Ok((vertices, faces))
}

/// Per-pixel depth (ray t) and unit normal of the first triangle of `mesh` each ray meets.
fn trace_mesh(
    vertices: &[[f32; 3]],
    faces: &[[u32; 3]],
    camera: &Camera,
) -> Vec<Option<(f64, [f64; 3])>> {
    use rayon::prelude::*;
    let v = |i: u32| glam::Vec3A::from(vertices[i as usize]);
    let triangles: Vec<Triangle> = faces
        .iter()
        .map(|f| Triangle {
            v0: v(f[0]),
            v1: v(f[1]),
            v2: v(f[2]),
        })
        .collect();
    // The 8-wide tree: a BVH2 over a million small triangles grows deeper than obvhs's
    // BVH2 traversal stack, which then loses rays.
    let bvh = obvhs::cwbvh::builder::build_cwbvh_from_tris(
        &triangles,
        BvhBuildParams::medium_build(),
        &mut std::time::Duration::default(),
    );
    (0..camera.width * camera.height)
        .into_par_iter()
        .map(|i| {
            let (o, d) = camera.ray(i % camera.width, i / camera.width);
            let f = |a: [f64; 3]| glam::Vec3A::new(a[0] as f32, a[1] as f32, a[2] as f32);
            let ray = Ray::new_inf(f(o), f(d));
            let mut hit = RayHit::none();
            bvh.ray_traverse(ray, &mut hit, |ray, id| {
                triangles[bvh.primitive_indices[id] as usize].intersect(ray)
            })
            .then(|| {
                let tri = &triangles[bvh.primitive_indices[hit.primitive_id as usize] as usize];
                let n = tri.compute_normal();
                (
                    f64::from(hit.t),
                    [f64::from(n.x), f64::from(n.y), f64::from(n.z)],
                )
            })
        })
        .collect()
}

/// The case's particles' camera: the product's framing, y up (SPH solvers' convention).
pub fn sph_camera(particles: &[[f64; 3]]) -> Camera {
    let (lo, hi) = slosh_mls::bounds(particles);
    Camera::framing(&[lo, hi], 40.0, SPH_WIDTH, SPH_HEIGHT, [0.0, 1.0, 0.0])
}

/// A light over the camera's shoulder, unit length.
fn shoulder_light(camera: &Camera) -> [f64; 3] {
    let b = camera.basis();
    let l: [f64; 3] = std::array::from_fn(|a| -b.forward[a] + 0.3 * b.up[a]);
    let len = l.iter().map(|c| c * c).sum::<f64>().sqrt();
    l.map(|c| c / len)
}

/// Grey by the angle to `light`; a miss black.
fn shade(normal: Option<[f64; 3]>, light: [f64; 3]) -> [u8; 3] {
    let Some(n) = normal else { return [0, 0, 0] };
    let lit = (n[0] * light[0] + n[1] * light[1] + n[2] * light[2]).abs();
    let g = (40.0 + 200.0 * lit) as u8;
    [g, g, g]
}

/// Compares one case directory; with `image`, writes slosh | reference | difference there
/// (difference: holes red, false surface blue, shared hits grey by |Δt|, slosh's hits far
/// from every particle yellow).
pub fn compare_case(dir: &Path, image: Option<&Path>) -> Result<SphResult> {
    let meta_path = dir.join("meta.json");
    let meta: serde_json::Value = serde_json::from_slice(
        &std::fs::read(&meta_path).with_context(|| format!("reading {}", meta_path.display()))?,
    )
    .with_context(|| format!("{}: not JSON", meta_path.display()))?;
    let radius = meta["particle_radius"]
        .as_f64()
        .filter(|r| *r > 0.0)
        .with_context(|| format!("{}: no positive particle_radius", meta_path.display()))?;
    let (points, _) = read_ply(&dir.join("particles.ply"))?;
    let particles: Vec<[f64; 3]> = points.iter().map(|p| p.map(f64::from)).collect();
    if particles.len() < 2 {
        bail!("{}: {} particles", dir.display(), particles.len());
    }
    let camera = sph_camera(&particles);
    let mesh = dir.join("splashsurf.ply");
    let reference: RayHits = if mesh.exists() {
        let (vertices, faces) = read_ply(&mesh)?;
        trace_mesh(&vertices, &faces, &camera)
    } else {
        read_depth(&dir.join("reference-depth.npy"), &camera)?
    };
    // Baked as a user bakes SPH particles: surface and normals estimated from all particles.
    let params = BakeParams::new(SurfaceSelect::Estimate, NormalSource::Estimate);
    let input = StepInput {
        index: 0,
        time: meta["time"].as_f64().unwrap_or(0.0),
        source: dir.display().to_string(),
        positions: particles.clone(),
        normals: None,
        ..StepInput::default()
    };
    let start = Instant::now();
    let baked = bake_step(&input, &params)?;
    let bake_seconds = start.elapsed().as_secs_f64();
    let spheres = baked.header.stats.droplets;
    let bytes = encode_step(baked.header, &baked.sections, params.compression)?;
    let file = CacheFile::from_bytes(FileBytes::from_vec(&dir.join("memory.slc"), bytes))?;
    let step = LoadedStep::load(&file)?;
    let mls = Params::<f32> {
        iterations: 3,
        ..Params::new()
    };
    let ours: Vec<Option<TraceHit>> = step.render(&camera, &mls);
    let spacing = 2.0 * radius;
    let depth: Vec<Option<f64>> = reference.iter().map(|r| r.map(|(t, _)| t)).collect();
    let silhouette = slosh_testkit::silhouette_mask(&depth, camera.width as usize, Some(0.05));
    let tree: ImmutableKdTree<f64, 3> = ImmutableKdTree::new_from_slice(&particles)
        .map_err(|e| anyhow::anyhow!("particle index: {e:?}"))?;
    let (mut compared, mut ref_hits, mut our_hits, mut holes, mut false_hits, mut far) =
        (0, 0, 0, 0, 0, 0);
    let mut dt = Vec::new();
    let mut far_from_particles = vec![false; ours.len()];
    for i in 0..ours.len() {
        if silhouette[i] {
            continue;
        }
        compared += 1;
        ref_hits += usize::from(reference[i].is_some());
        if let Some(h) = ours[i] {
            our_hits += 1;
            let nearest = tree
                .query(&h.position)
                .nearest_one::<SquaredEuclidean<f64>>()
                .execute();
            far_from_particles[i] = nearest.distance.sqrt() > 4.0 * radius;
            far += usize::from(far_from_particles[i]);
        }
        match (reference[i], ours[i]) {
            (Some(_), None) => holes += 1,
            (None, Some(_)) => false_hits += 1,
            (Some((t, _)), Some(h)) => dt.push((h.t - t).abs() / spacing),
            (None, None) => {}
        }
    }
    if let Some(path) = image {
        let w = camera.width as usize;
        let light = shoulder_light(&camera);
        let mut rgb = Vec::with_capacity(3 * w * 3 * camera.height as usize);
        for y in 0..camera.height as usize {
            for panel in 0..3 {
                for x in 0..w {
                    let i = y * w + x;
                    let px = match panel {
                        0 => shade(ours[i].map(|h| h.normal), light),
                        1 => shade(reference[i].map(|r| r.1), light),
                        _ if far_from_particles[i] => [240, 200, 30],
                        _ => match (reference[i], ours[i]) {
                            (Some(_), None) => [220, 40, 40],
                            (None, Some(_)) => [40, 90, 230],
                            (Some((t, _)), Some(h)) => {
                                let g =
                                    (230.0 - 180.0 * ((h.t - t).abs() / spacing).min(1.0)) as u8;
                                [g, g, g]
                            }
                            (None, None) => [0, 0, 0],
                        },
                    };
                    rgb.extend_from_slice(&px);
                }
            }
        }
        slosh_render::write_rgb_png(path, 3 * camera.width, camera.height, &rgb)?;
    }
    let pct = |a: usize, b: usize| 100.0 * a as f64 / b.max(1) as f64;
    Ok(SphResult {
        name: dir.file_name().map_or_else(
            || dir.display().to_string(),
            |n| n.to_string_lossy().into_owned(),
        ),
        particles: particles.len(),
        particle_radius: radius,
        time: meta["time"].as_f64().unwrap_or(0.0),
        compared,
        reference_hits: ref_hits,
        slosh_hits: our_hits,
        holes_pct: pct(holes, ref_hits),
        false_pct: pct(false_hits, our_hits),
        dt_p50: percentile(dt.clone(), 0.5),
        dt_p90: percentile(dt.clone(), 0.9),
        dt_p99: percentile(dt, 0.99),
        far_pct: pct(far, our_hits),
        spheres,
        bake_seconds,
        splashsurf_seconds: meta["splashsurf"]["seconds"].as_f64(),
    })
}

/// A stored reference: ray depths as a float32 .npy of the camera's height × width × 1, NaN
/// for a miss (normals are not kept: the fixture judges depths only).
fn read_depth(path: &Path, camera: &Camera) -> Result<RayHits> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let header_len = bytes
        .get(8..10)
        .map(|b| usize::from(u16::from_le_bytes([b[0], b[1]])))
        .with_context(|| format!("{}: not an .npy file", path.display()))?;
    let header = std::str::from_utf8(bytes.get(10..10 + header_len).unwrap_or_default())
        .with_context(|| format!("{}: unreadable .npy header", path.display()))?;
    let shape = format!("({}, {}, 1)", camera.height, camera.width);
    if !bytes.starts_with(b"\x93NUMPY") || !header.contains("'<f4'") || !header.contains(&shape) {
        bail!(
            "{}: expected a little-endian float32 array of shape {shape}, found header {header}",
            path.display()
        );
    }
    let data = &bytes[10 + header_len..];
    let n = (camera.width * camera.height) as usize;
    if data.len() != 4 * n {
        bail!(
            "{}: {} data bytes, expected {}",
            path.display(),
            data.len(),
            4 * n
        );
    }
    Ok(data
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .map(|t| t.is_finite().then_some((f64::from(t), [0.0, 0.0, 1.0])))
        .collect())
}

/// The reference's depths for a case directory (to store as a fixture): `depth.npy` in
/// the layout [`read_depth`] reads.
pub fn write_reference_depth(dir: &Path, out: &Path) -> Result<()> {
    let (points, _) = read_ply(&dir.join("particles.ply"))?;
    let particles: Vec<[f64; 3]> = points.iter().map(|p| p.map(f64::from)).collect();
    let camera = sph_camera(&particles);
    let (vertices, faces) = read_ply(&dir.join("splashsurf.ply"))?;
    let depth: Vec<f32> = trace_mesh(&vertices, &faces, &camera)
        .into_iter()
        .map(|r| r.map_or(f32::NAN, |(t, _)| t as f32))
        .collect();
    slosh_render::write_npy(out, camera.height, camera.width, 1, &depth)
        .map_err(anyhow::Error::from)
}

/// Every case under `root` (its subdirectories holding a `meta.json`), in name order.
pub fn cases(root: &Path) -> Result<Vec<PathBuf>> {
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(root)
        .with_context(|| format!("reading {}", root.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join("meta.json").is_file())
        .collect();
    dirs.sort();
    if dirs.is_empty() {
        bail!(
            "{}: no SPH cases (directories with meta.json); make them with scripts/sph_reference.py",
            root.display()
        );
    }
    Ok(dirs)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_mesh_is_hit_where_it_lies() {
        // A unit square (two triangles) in z = 0 under a camera looking down from z = 3.
        let vertices = [
            [-1.0, -1.0, 0.0],
            [1.0, -1.0, 0.0],
            [1.0, 1.0, 0.0],
            [-1.0, 1.0, 0.0],
        ];
        let faces = [[0, 1, 2], [0, 2, 3]];
        let camera = Camera {
            eye: [0.0, 0.0, 3.0],
            target: [0.0; 3],
            up: [0.0, 1.0, 0.0],
            fov_y: 30.0,
            width: 8,
            height: 8,
        };
        let hits = trace_mesh(&vertices, &faces, &camera);
        let centre = hits[4 * 8 + 4].expect("the centre ray meets the square");
        assert!((centre.0 - 3.0).abs() < 0.05, "{centre:?}");
        assert!((centre.1[2].abs() - 1.0).abs() < 1e-6);
    }
}
