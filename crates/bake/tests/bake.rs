#![allow(clippy::unwrap_used)]
//! The bake against its truths: tracing a cache gives the hits of tracing the in-memory
//! surface; every byte of a cache is protected; selection, order and fields stay consistent;
//! batches resume, shard and survive bad steps.

use std::path::Path;

use slosh_bake::*;
use slosh_cache::{
    CacheFile, Compression, GpuPoint, LoadedStep, Manifest, encode_step, names, step_file_name,
};
use slosh_ensight::FieldValues;
use slosh_fileio::FileBytes;
use slosh_mls::{NormalsMode, Params, Surface};
use slosh_scenes::{Scene, SceneKind, SceneSpec};

fn scene_input(kind: SceneKind, points: usize, step: usize) -> (Scene, StepInput) {
    let scene = Scene::new(SceneSpec::new(kind, points, 7)).unwrap();
    let input = slosh_testkit::scene_step(&scene, step, &format!("{kind:?}"));
    (scene, input)
}

fn params() -> BakeParams {
    BakeParams::new(SurfaceSelect::All, NormalSource::Variable("normal".into()))
}

fn bake_to_file(input: &StepInput, params: &BakeParams) -> CacheFile {
    slosh_testkit::bake_in_memory(input, params, Path::new("memory.slc")).unwrap()
}

#[test]
fn tracing_a_cache_gives_the_hits_of_the_in_memory_surface() {
    for (kind, points, iterations) in [
        (SceneKind::Sphere, 3000, 1u32),
        (SceneKind::Sphere, 3000, 3),
        (SceneKind::Torus, 4000, 3),
        (SceneKind::Droplets, 3000, 1),
    ] {
        let (_, input) = scene_input(kind, points, 1);
        let p = params();
        let file = bake_to_file(&input, &p);
        file.verify().unwrap();
        let step = LoadedStep::load(&file).unwrap();
        let camera = slosh_testkit::framing_camera(&input.positions, 72);
        let f32_params = Params::<f32> {
            degree: 2,
            iterations,
            epsilon: 1e-4,
            normals: NormalsMode::Mean,
            h_factor: 1.0,
        };
        // The baked BVH and the grid over the same loaded surface find identical hits.
        let via_bvh = step.render(&camera, &f32_params);
        let via_grid: Vec<_> = step
            .surface
            .render(&step.local_camera(&camera), &f32_params)
            .into_iter()
            .map(|h| h.map(|h| step.to_world(h)))
            .collect();
        let differ: Vec<usize> = (0..via_bvh.len())
            .filter(|&i| via_bvh[i] != via_grid[i])
            .collect();
        if let Some(&i) = differ.first() {
            panic!(
                "{kind:?}: BVH and grid disagree at {} pixels, first {i}: {:?} vs {:?}",
                differ.len(),
                via_bvh[i],
                via_grid[i]
            );
        }

        // The in-memory f64 oracle over the unscaled, unordered points.
        let oracle =
            Surface::<f64>::build(&input.positions, input.normals.as_deref(), &p.mls).unwrap();
        let f64_params = Params::<f64> {
            degree: 2,
            iterations,
            epsilon: 1e-4,
            normals: NormalsMode::Mean,
            h_factor: 1.0,
        };
        let reference = oracle.render(&camera, &f64_params);
        // The lists come back from the clusters with nothing lost; the reach, stored rounded
        // up to a half float (at most 2⁻¹⁰ of it), may admit the candidates of that thin
        // shell: 3 × 2⁻¹⁰ of a list's points at most where they are spread evenly in 3D.
        let total = |lists: &slosh_mls::KeptLists| lists.whole().expect("every list").total();
        let (stored, exact) = (total(&step.surface.neighbours), total(&oracle.neighbours));
        assert!(
            stored >= exact && stored * 1000 <= exact * 1003,
            "{kind:?}: {stored} neighbours from the cache, {exact} in memory"
        );
        let spacing = oracle.spacing;
        let (mut away, mut disagree, mut shared, mut close, mut worst) = (0, 0, 0, 0, 0.0f64);
        let depth: Vec<Option<f64>> = reference.iter().map(|h| h.map(|h| h.t)).collect();
        let silhouette = slosh_testkit::silhouette_mask(&depth, 72, None);
        for i in 0..reference.len() {
            if silhouette[i] {
                continue;
            }
            away += 1;
            match (reference[i], via_bvh[i]) {
                (Some(a), Some(b)) => {
                    shared += 1;
                    let dt = (a.t - b.t).abs() / spacing;
                    worst = worst.max(dt);
                    close += usize::from(dt <= 1e-3);
                }
                (None, None) => {}
                _ => disagree += 1,
            }
        }
        eprintln!(
            "{kind:?} {iterations} it: {disagree} of {away} pixels disagree, {close} of {shared} shared hits within 1e-3 spacing, worst {worst:.2e}"
        );
        assert!(shared > 500, "{kind:?}: only {shared} hits");
        assert!(
            disagree * 1000 <= away,
            "{kind:?}: {disagree} of {away} hit/miss disagree"
        );
        assert!(
            close * 1000 >= shared * 999,
            "{kind:?}: {close} of {shared} within 1e-3 spacing"
        );
    }
}

#[test]
fn droplets_are_stored_as_spheres_and_hit_as_spheres() {
    let (scene, mut input) = scene_input(SceneKind::Sphere, 3000, 0);
    let spacing = scene.spacing();
    // Three lone particles and one pair, far from the body and from each other.
    let lone = [[3.0, 0.0, 0.0], [0.0, 3.0, 0.0], [0.0, 0.0, 3.0]];
    let pair = [[-3.0, 0.0, 0.0], [-3.0, 0.5 * spacing, 0.0]];
    for p in lone.iter().chain(&pair) {
        input.positions.push(*p);
        input.normals.as_mut().unwrap().push([1.0, 0.0, 0.0]);
    }
    let file = bake_to_file(&input, &params());
    file.verify().unwrap();
    let h = file.header();
    // Spray of fewer than 4 points is drawn particle by particle: five spheres.
    assert_eq!((h.stats.droplets, h.stats.droplet_points), (5, 5));
    let step = LoadedStep::load(&file).unwrap();
    let mls = Params::<f32> {
        iterations: 3,
        ..Params::new()
    };
    // A lone particle is a sphere of a particle's radius, half the dense spacing, around it.
    let scale = step.transform.scale;
    let radius = f64::from(step.surface.spheres[0].radius) * scale;
    let spacing_here = step.surface.spacing as f64 * scale;
    assert!(
        (radius / (0.5 * spacing_here) - 1.0).abs() < 0.1,
        "sphere radius {radius}, mean spacing {spacing_here}"
    );
    let to_local = |p: [f64; 3]| step.transform.to_local(p);
    let hit = step
        .surface
        .trace_in(&step.bvh, to_local([3.0, -1.0, 0.0]), [0.0, 1.0, 0.0], &mls)
        .map(|h| step.to_world(h))
        .unwrap();
    assert_eq!(hit.status, slosh_mls::HitStatus::Droplet);
    let expected = 1.0 - radius;
    assert!(
        (hit.t - expected).abs() < 1e-5 * expected,
        "{} vs {expected}",
        hit.t
    );
    assert!((hit.normal[1] + 1.0).abs() < 1e-5);
}

#[test]
fn every_single_byte_flip_is_detected() {
    let (_, input) = scene_input(SceneKind::Sphere, 60, 0);
    let baked = bake_step(&input, &params()).unwrap();
    let bytes = encode_step(baked.header, &baked.sections, Compression::Level(1)).unwrap();
    let path = Path::new("flip.slc");
    CacheFile::from_bytes(FileBytes::from_vec(path, bytes.clone()))
        .unwrap()
        .verify()
        .unwrap();
    let mut undetected = Vec::new();
    for offset in 0..bytes.len() {
        let mut b = bytes.clone();
        b[offset] ^= 0x5a;
        let caught = match CacheFile::from_bytes(FileBytes::from_vec(path, b)) {
            Err(_) => true,
            Ok(f) => f.verify().is_err(),
        };
        if !caught {
            undetected.push(offset);
        }
    }
    eprintln!("{} byte flips tried", bytes.len());
    assert!(undetected.is_empty(), "undetected flips at {undetected:?}");
}

/// Format 6's leaves are ranges of items (at most 15, which format 9's four count bits hold
/// by construction): the verifier refuses two leaves that share an item, a leaf past the item
/// list, and a fitted ball no leaf holds.
#[test]
fn bvh_leaves_that_overrun_overlap_or_drop_a_candidate_are_refused() {
    let (_, input) = scene_input(SceneKind::Sphere, 2000, 0);
    let baked = bake_step(&input, &params()).unwrap();
    let at = baked
        .sections
        .iter()
        .position(|s| s.name == names::BVH_NODES)
        .unwrap();
    let nodes: Vec<slosh_cache::GpuBvhNode> = baked.sections[at]
        .bytes
        .chunks_exact(size_of::<slosh_cache::GpuBvhNode>())
        .map(bytemuck::pod_read_unaligned)
        .collect();
    let leaves: Vec<usize> = (0..nodes.len()).filter(|&i| nodes[i].count() > 0).collect();
    let link = |first: u32, count: u32| first | count << slosh_cache::LINK_FIRST_BITS;
    let verify_with = |header: &slosh_cache::Header, nodes: &[slosh_cache::GpuBvhNode]| {
        let mut sections = baked.sections.clone();
        sections[at].bytes = bytemuck::cast_slice(nodes).to_vec();
        let bytes = encode_step(header.clone(), &sections, Compression::None).unwrap();
        let file =
            CacheFile::from_bytes(FileBytes::from_vec(Path::new("leaves.slc"), bytes)).unwrap();
        file.verify().map_err(|e| e.to_string())
    };
    let verify = |nodes: &[slosh_cache::GpuBvhNode]| verify_with(&baked.header, nodes);
    verify(&nodes).unwrap();
    // Format 9's grid: one that is not a grid, and one moved off the boxes the bake built
    // (the walk would miss what the boxes no longer hold: a wrong picture).
    let mut header = baked.header.clone();
    header.bvh_grid.step[1] = 0.0;
    let err = verify_with(&header, &nodes).unwrap_err();
    assert!(err.contains("not finite with power-of-two steps"), "{err}");
    let mut header = baked.header.clone();
    header.bvh_grid.origin[2] += 64.0 * header.bvh_grid.step[2];
    let err = verify_with(&header, &nodes).unwrap_err();
    assert!(err.contains("lies outside its leaf's box"), "{err}");
    // Every leaf ends at a candidate: the bake groups candidates, and a range reaches its last.
    let items = (input.positions.len() + 1) as u32;
    let mut past = nodes.clone();
    past[leaves[0]].link = link(items, 3);
    let err = verify(&past).unwrap_err();
    assert!(err.contains(&format!("holds items {items}..")), "{err}");
    let mut overlap = nodes.clone();
    overlap[leaves[1]].link = link(nodes[leaves[0]].first(), 1);
    let err = verify(&overlap).unwrap_err();
    assert!(
        err.contains(&format!(
            "BVH item {} is in two leaves",
            nodes[leaves[0]].first()
        )),
        "{err}"
    );
    let mut short = nodes.clone();
    let leaf = *leaves.iter().find(|&&l| nodes[l].count() > 1).unwrap();
    short[leaf].link = link(nodes[leaf].first(), nodes[leaf].count() - 1);
    let last = nodes[leaf].first() + nodes[leaf].count() - 1;
    let err = verify(&short).unwrap_err();
    assert!(
        err.contains(&format!("ball {last} (")) && err.contains("is missing from the BVH"),
        "{err}"
    );
}

/// Format 8's and 9's half floats and ball states: a baked step with a point's radius or
/// reach made zero or subnormal (a GPU may flush those), the header's h not a half float, a
/// ball's own h (per-point h) made zero, its `ball_h` section missing, or state bits set past
/// the last ball, is refused by the verifier with its message; the steps as baked pass.
#[test]
fn radii_reaches_h_and_states_that_do_not_fit_are_refused() {
    let (_, input) = scene_input(SceneKind::Sphere, 2003, 0);
    let baked = bake_step(&input, &params()).unwrap();
    let verify_sections = |header: &slosh_cache::Header, sections: &[slosh_cache::SectionInput]| {
        let bytes = encode_step(header.clone(), sections, Compression::None).unwrap();
        let file =
            CacheFile::from_bytes(FileBytes::from_vec(Path::new("halves.slc"), bytes)).unwrap();
        file.verify().map_err(|e| e.to_string())
    };
    let index = |sections: &[slosh_cache::SectionInput], name: &str| {
        sections.iter().position(|s| s.name == name)
    };
    let points_at = index(&baked.sections, names::POINTS).unwrap();
    let points: Vec<GpuPoint> = bytemuck::pod_collect_to_vec(&baked.sections[points_at].bytes);
    let with_points = |points: &[GpuPoint]| {
        let mut sections = baked.sections.clone();
        sections[points_at].bytes = bytemuck::cast_slice(points).to_vec();
        verify_sections(&baked.header, &sections)
    };
    with_points(&points).unwrap();
    assert!(
        index(&baked.sections, names::BALL_H).is_none(),
        "one h for the step: no ball_h"
    );
    // A subnormal radius (the low half's smallest subnormal), then a zero reach.
    for (word, what) in [(0x0001, "radius"), (0x0000_ffff, "reach")] {
        let mut bad = points.clone();
        bad[7].radii &= word;
        let err = with_points(&bad).unwrap_err();
        assert!(
            err.contains("point 7 ") && err.contains("not a positive normal half float"),
            "{what}: {err}"
        );
    }
    let mut header = baked.header.clone();
    header.smoothing_length = 0.1;
    let err = verify_sections(&header, &baked.sections).unwrap_err();
    assert!(err.contains("the header's h (0.1)"), "{err}");
    // State bits past the last ball.
    let n = baked.header.points as usize;
    assert_ne!(n % 8, 0, "{n} points fill their last state word");
    let mut sections = baked.sections.clone();
    let states = index(&sections, names::BALL_STATES).unwrap();
    let last = sections[states].bytes.len() - 1;
    sections[states].bytes[last] |= 0x80;
    let err = verify_sections(&baked.header, &sections).unwrap_err();
    assert!(
        err.contains("'ball_states' sets bits past its last ball"),
        "{err}"
    );
    // A candidate without a normal (the walk would skip it), and a header that counts
    // degraded fits the states do not hold (the renderers would draw every ball at the
    // header's degree, or read states they need not).
    let balls_at = index(&baked.sections, names::BALLS).unwrap();
    let mut sections = baked.sections.clone();
    sections[balls_at].bytes[16 * 5..16 * 5 + 4].copy_from_slice(&0x8000_8000u32.to_le_bytes());
    let err = verify_sections(&baked.header, &sections).unwrap_err();
    assert!(err.contains("ball 5 is invalid"), "{err}");
    let mut header = baked.header.clone();
    header.stats.fit_degraded += 1;
    let err = verify_sections(&header, &baked.sections).unwrap_err();
    assert!(
        err.contains("balls are degraded; the header counts"),
        "{err}"
    );
    // h per point: each ball's in `ball_h`, two to a word.
    let mut per_point = params();
    per_point.mls.per_point_h = true;
    let baked = bake_step(&input, &per_point).unwrap();
    verify_sections(&baked.header, &baked.sections).unwrap();
    let at = index(&baked.sections, names::BALL_H).unwrap();
    let mut sections = baked.sections.clone();
    sections[at].bytes[20..22].copy_from_slice(&[0, 0]);
    let err = verify_sections(&baked.header, &sections).unwrap_err();
    assert!(err.contains("ball 10 is invalid"), "{err}");
    let mut sections = baked.sections.clone();
    sections.remove(at);
    let err = verify_sections(&baked.header, &sections).unwrap_err();
    assert!(err.contains("section 'ball_h' is missing"), "{err}");
}

#[test]
fn selection_drops_non_finite_and_interior_and_keeps_fields_aligned() {
    let (_, mut input) = scene_input(SceneKind::Sphere, 2000, 0);
    let n = input.positions.len();
    input.positions[5] = [f64::NAN, 0.0, 0.0];
    input.positions[9][2] = f64::INFINITY;
    // A field that names its particle: its x coordinate.
    let xs: Vec<f32> = input.positions.iter().map(|p| p[0] as f32).collect();
    input.fields.push(("x".into(), FieldValues::Scalar(xs)));
    input.surface_flags = Some((0..n).map(|i| i % 4 != 0).collect());
    let mut p = BakeParams::new(
        SurfaceSelect::Variable("surface".into()),
        NormalSource::Variable("normal".into()),
    );
    p.fields = vec!["x".into()];
    let file = bake_to_file(&input, &p);
    let h = file.header();
    assert_eq!(h.stats.dropped_non_finite, 2);
    // Every 4th particle unflagged; index 5 and 9 were already gone (neither is a multiple of 4).
    assert_eq!(h.stats.dropped_interior as usize, n.div_ceil(4));
    assert_eq!(h.points as usize, n - 2 - n.div_ceil(4));
    let points: Vec<GpuPoint> = file.decode(names::POINTS).unwrap();
    let field: Vec<f32> = file.decode("field.x").unwrap();
    for (p, x) in points.iter().zip(&field) {
        let world = h.transform.to_world(p.position.map(f64::from));
        assert!((world[0] - f64::from(*x)).abs() < 1e-5, "{world:?} vs {x}");
    }
    file.verify().unwrap();
}

#[test]
fn probes_read_the_nearest_input_particle_and_the_field_as_shaded() {
    let (_, mut input) = scene_input(SceneKind::Sphere, 3000, 0);
    let n = input.positions.len();
    let xs: Vec<f32> = input.positions.iter().map(|p| p[0] as f32).collect();
    input.fields.push(("x".into(), FieldValues::Scalar(xs)));
    input
        .fields
        .push(("c".into(), FieldValues::Scalar(vec![2.5; n])));
    let mut p = params();
    p.fields = vec!["x".into(), "c".into()];
    let file = bake_to_file(&input, &p);
    let h = file.header();
    let spacing = h.spacing * h.transform.scale;
    let probe = slosh_cache::SurfaceProbe::open(&file).unwrap();
    let points: Vec<GpuPoint> = file.decode(names::POINTS).unwrap();
    let c: Vec<f32> = file.decode("field.c").unwrap();
    let x: Vec<f32> = file.decode("field.x").unwrap();
    assert_eq!(probe.point_count(), points.len());
    let mut worst_x = 0.0f64;
    for i in (0..points.len()).step_by(37) {
        let at = points[i].position;
        // At a stored point: that point, a constant field exactly.
        let r = probe.read(at, Some(i), 1.0, Some(&c)).unwrap();
        assert_eq!((r.nearest, r.nearest_distance), (i, 0.0));
        assert_eq!(r.nearest_world, r.world);
        assert!((r.field.unwrap() - 2.5).abs() < 1e-5, "{r:?}");
        // A third of a spacing off: the nearest particle is the nearest input particle by
        // brute force in f64 (every particle is stored), and the field x is within a spacing
        // of the point's own x (the weighted mean of a linear field around it).
        let off = [at[0] + (h.spacing / 3.0) as f32, at[1], at[2]];
        let r = probe.read(off, Some(i), 1.0, Some(&x)).unwrap();
        let world = r.world;
        let brute = (0..n)
            .min_by(|&a, &b| {
                let d = |k: usize| {
                    (0..3)
                        .map(|ax| (input.positions[k][ax] - world[ax]).powi(2))
                        .sum::<f64>()
                };
                d(a).total_cmp(&d(b))
            })
            .unwrap();
        let d = (0..3)
            .map(|a| (input.positions[brute][a] - r.nearest_world[a]).abs())
            .fold(0.0, f64::max);
        assert!(
            d < 1e-5,
            "the nearest stored point is {d} from input particle {brute}"
        );
        let error = (f64::from(r.field.unwrap()) - world[0]).abs();
        worst_x = worst_x.max(error);
        assert!(error < spacing, "x read as {:?} at {world:?}", r.field);
        // A droplet's field is its nearest particle's.
        let r = probe.read(at, None, 1.0, Some(&x)).unwrap();
        assert_eq!(r.field, Some(x[i]));
    }
    eprintln!("linear field read within {:.3} spacings", worst_x / spacing);
}

#[test]
fn surface_estimate_finds_the_free_surface_of_the_tank() {
    let scene = Scene::new(SceneSpec::new(SceneKind::Tank, 60_000, 3)).unwrap();
    let p = scene.particles(0);
    let positions: Vec<[f64; 3]> = p.positions.iter().map(|v| v.to_array()).collect();
    let estimate = estimate_surface(&positions);
    let flagged = p.surface.iter().filter(|s| **s).count();
    let found = p
        .surface
        .iter()
        .zip(&estimate)
        .filter(|(t, e)| **t && **e)
        .count();
    let interior = positions.len() - flagged;
    let false_pos = p
        .surface
        .iter()
        .zip(&estimate)
        .filter(|(t, e)| !**t && **e)
        .count();
    eprintln!(
        "estimate: {found} of {flagged} free-surface particles found; {false_pos} of {interior} others flagged"
    );
    assert!(found * 100 >= flagged * 95);
    // Walls and floor bound the fluid too and are flagged; the bulk below is not.
    assert!(false_pos * 5 <= interior);
}

#[test]
fn morton_order_is_a_permutation_that_clusters() {
    let (_, input) = scene_input(SceneKind::Sphere, 5000, 0);
    let order = morton_order(&input.positions);
    let mut seen = order.clone();
    seen.sort_unstable();
    assert!(seen.iter().enumerate().all(|(i, &v)| i as u32 == v));
    // Consecutive points are close: the mean step is far below the scene size.
    let step = |ids: &[u32]| {
        ids.windows(2)
            .map(|w| {
                let (a, b) = (
                    input.positions[w[0] as usize],
                    input.positions[w[1] as usize],
                );
                (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt()
            })
            .sum::<f64>()
            / ids.len() as f64
    };
    let shuffled: Vec<u32> = (0..order.len() as u32)
        .map(|i| (i * 7919) % order.len() as u32)
        .collect();
    assert!(step(&order) * 5.0 < step(&shuffled));
}

/// A series of sphere steps, one of which cannot be read.
struct Series {
    steps: usize,
    bad: Option<usize>,
}

impl StepSource for Series {
    fn source_path(&self) -> String {
        scene_input(SceneKind::Sphere, 800, 0).1.source
    }
    fn steps(&self) -> Vec<(usize, f64)> {
        (0..self.steps).map(|i| (i, i as f64 * 0.1)).collect()
    }
    fn read(&self, index: usize) -> Result<StepInput, String> {
        if Some(index) == self.bad {
            return Err(format!("step {index}: unreadable on purpose"));
        }
        Ok(scene_input(SceneKind::Sphere, 800, index).1)
    }
}

fn options(dir: &Path, shard: Shard) -> BatchOptions {
    BatchOptions {
        out: dir.to_path_buf(),
        steps: None,
        jobs: 2,
        threads: 2,
        shard,
        params: params(),
        stages: Stages::cpu(),
    }
}

fn section_sums(dir: &Path, steps: usize) -> Vec<Vec<String>> {
    (0..steps)
        .map(|i| {
            let f = CacheFile::open(&dir.join(step_file_name(i))).unwrap();
            f.header().sections.iter().map(|s| s.xxh3.clone()).collect()
        })
        .collect()
}

#[test]
fn batches_resume_shard_and_go_on_past_bad_steps() {
    let tmp = tempfile::tempdir().unwrap();
    let whole = tmp.path().join("whole");
    let series = Series {
        steps: 6,
        bad: Some(3),
    };
    let report = run_batch(&series, &options(&whole, Shard::WHOLE), &|_| {}).unwrap();
    assert_eq!((report.baked, report.kept), (5, 0));
    assert_eq!(report.failed.len(), 1);
    assert_eq!(report.failed[0].0, 3);
    let manifest = Manifest::read(&whole).unwrap();
    assert_eq!(
        manifest.steps.iter().map(|s| s.index).collect::<Vec<_>>(),
        vec![0, 1, 2, 4, 5]
    );

    // Resume: the good steps are kept, the bad one is retried (and now works).
    let fixed = Series {
        steps: 6,
        bad: None,
    };
    let report = run_batch(&fixed, &options(&whole, Shard::WHOLE), &|_| {}).unwrap();
    assert_eq!((report.baked, report.kept, report.failed.len()), (1, 5, 0));

    // A corrupted step is not kept: it is baked again.
    let victim = whole.join(step_file_name(2));
    let mut bytes = std::fs::read(&victim).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 1;
    std::fs::write(&victim, bytes).unwrap();
    let report = run_batch(&fixed, &options(&whole, Shard::WHOLE), &|_| {}).unwrap();
    assert_eq!((report.baked, report.kept), (1, 5));

    // Other parameters: every step is baked again.
    let mut other = options(&whole, Shard::WHOLE);
    other.params.mls.degree = 3;
    let report = run_batch(&fixed, &other, &|_| {}).unwrap();
    assert_eq!((report.baked, report.kept), (6, 0));

    // Three shards into one directory give the same caches as one run.
    let single = tmp.path().join("single");
    run_batch(&fixed, &options(&single, Shard::WHOLE), &|_| {}).unwrap();
    let sharded = tmp.path().join("sharded");
    let mut owned = Vec::new();
    for index in 0..3 {
        let shard = Shard { index, count: 3 };
        owned.push(plan(&fixed, &options(&sharded, shard)).len());
        run_batch(&fixed, &options(&sharded, shard), &|_| {}).unwrap();
    }
    assert_eq!(owned, vec![2, 2, 2]);
    let (manifest, problems) = Manifest::rebuild(&sharded).unwrap();
    assert!(problems.is_empty());
    assert_eq!(manifest.steps.len(), 6);
    assert_eq!(section_sums(&single, 6), section_sums(&sharded, 6));
}

/// A series that records the size of the rayon pool each step is read on.
struct PoolSizes {
    steps: usize,
    seen: std::sync::Mutex<Vec<(usize, usize)>>,
}

impl StepSource for PoolSizes {
    fn source_path(&self) -> String {
        "pool sizes".into()
    }
    fn steps(&self) -> Vec<(usize, f64)> {
        (0..self.steps).map(|i| (i, i as f64)).collect()
    }
    fn read(&self, index: usize) -> Result<StepInput, String> {
        let threads = rayon::current_num_threads();
        self.seen.lock().unwrap().push((index, threads));
        // Long enough that no job bakes every step before the others have started.
        std::thread::sleep(std::time::Duration::from_millis(30));
        Ok(scene_input(SceneKind::Sphere, 200, index).1)
    }
}

/// Each job bakes on a pool of its own, an equal share of the threads (the remainder to the
/// first jobs); with fewer steps than jobs, fewer jobs with larger shares.
#[test]
fn each_job_bakes_on_its_share_of_the_threads() {
    for (steps, jobs, threads, shares) in [
        (6, 2, 5, vec![2, 3]),
        (6, 3, 3, vec![1]),
        (1, 4, 5, vec![5]),
        (2, 4, 5, vec![2, 3]),
        (3, 8, 2, vec![1]),
    ] {
        let tmp = tempfile::tempdir().unwrap();
        let source = PoolSizes {
            steps,
            seen: Default::default(),
        };
        let mut opts = options(tmp.path(), Shard::WHOLE);
        opts.jobs = jobs;
        opts.threads = threads;
        let report = run_batch(&source, &opts, &|_| {}).unwrap();
        assert_eq!(report.baked, steps);
        let seen = source.seen.into_inner().unwrap();
        assert_eq!(seen.len(), steps);
        let mut sizes: Vec<usize> = seen.iter().map(|s| s.1).collect();
        sizes.sort_unstable();
        sizes.dedup();
        assert_eq!(
            sizes, shares,
            "{steps} steps, {jobs} jobs, {threads} threads"
        );
    }
}

/// The verifier reads each cluster's candidates from the runs they are stored as: a list
/// whose runs come out of order, or end past the points, is refused by its cluster, the
/// first in cluster order.
#[test]
fn the_verifier_refuses_candidate_lists_out_of_order_or_past_the_points() {
    let (_, input) = scene_input(SceneKind::Sphere, 2000, 0);
    let p = params();
    let baked = bake_step(&input, &p).unwrap();
    let n = baked.header.points as usize;
    let section = |name: &str| baked.sections.iter().position(|s| s.name == name).unwrap();
    let words_of =
        |k: usize| -> Vec<u32> { bytemuck::pod_collect_to_vec(&baked.sections[k].bytes) };
    let (base, at) = (
        words_of(section(names::CLUSTER_BASE)),
        section(names::CLUSTER_NEIGHBOURS),
    );
    let words = words_of(at);
    let verify_with = |words: &[u32]| {
        let mut sections = baked.sections.clone();
        sections[at].bytes = bytemuck::cast_slice(words).to_vec();
        let bytes = encode_step(baked.header.clone(), &sections, p.compression).unwrap();
        CacheFile::from_bytes(FileBytes::from_vec(Path::new("damaged.slc"), bytes))
            .unwrap()
            .verify()
            .map(|_| ())
            .map_err(|e| e.to_string())
    };
    verify_with(&words).unwrap();
    let narrow = |c: usize| base[c] & slosh_cache::candidates::WIDE_CLUSTER == 0;
    let end_of = |c: usize| {
        base.get(c + 1).map_or(words.len(), |&b| {
            (b & !slosh_cache::candidates::WIDE_CLUSTER) as usize
        })
    };
    let refused = |c: usize| {
        format!("the candidate list of cluster {c} is not sorted, distinct and in range")
    };
    // A narrow cluster's first two runs swapped: out of order.
    let c = (0..base.len())
        .find(|&c| narrow(c) && end_of(c) - base[c] as usize >= 2)
        .unwrap();
    let mut swapped = words.clone();
    swapped.swap(base[c] as usize, base[c] as usize + 1);
    assert!(verify_with(&swapped).unwrap_err().contains(&refused(c)));
    // The last narrow cluster's last run moved to start 32767 past its first point: past
    // the points.
    let last = (0..base.len()).rev().find(|&c| narrow(c)).unwrap();
    assert!(last as u32 * baked.header.neighbour_cluster + 32767 > n as u32);
    let mut far = words.clone();
    far[end_of(last) - 1] |= 0xffff;
    assert!(verify_with(&far).unwrap_err().contains(&refused(last)));
}

/// A series whose reads damage step files the batch wrote before: reading step 2 deletes
/// step 0's file, reading step 3 cuts step 1's to 100 bytes.
struct Vandal {
    out: std::path::PathBuf,
}

impl StepSource for Vandal {
    fn source_path(&self) -> String {
        "vandal".into()
    }
    fn steps(&self) -> Vec<(usize, f64)> {
        (0..4).map(|i| (i, i as f64)).collect()
    }
    fn read(&self, index: usize) -> Result<StepInput, String> {
        let file = |i| self.out.join(step_file_name(i));
        match index {
            2 => std::fs::remove_file(file(0)).unwrap(),
            3 => std::fs::File::options()
                .write(true)
                .open(file(1))
                .and_then(|f| f.set_len(100))
                .unwrap(),
            _ => {}
        }
        Ok(scene_input(SceneKind::Sphere, 200, index).1)
    }
}

/// Step files deleted or damaged after the batch wrote them, before its manifest, are
/// reported as gone (the manifest leaves them out); the next run bakes them again.
#[test]
fn steps_gone_before_the_manifest_are_reported() {
    let tmp = tempfile::tempdir().unwrap();
    let source = Vandal {
        out: tmp.path().to_path_buf(),
    };
    // One job: the steps go in order, so each is written before the read that damages it.
    let mut opts = options(tmp.path(), Shard::WHOLE);
    opts.jobs = 1;
    let report = run_batch(&source, &opts, &|_| {}).unwrap();
    assert_eq!((report.baked, report.failed.len()), (4, 0));
    assert_eq!(report.gone, [0, 1]);
    assert_eq!(report.manifest_problems.len(), 1, "the cut file");
    let held: Vec<usize> = Manifest::read(tmp.path())
        .unwrap()
        .steps
        .iter()
        .map(|s| s.index)
        .collect();
    assert_eq!(held, [2, 3]);
    // Steps 2 and 3 are current, so not read again: nothing is damaged, and 0 and 1 are
    // baked again.
    let report = run_batch(&source, &opts, &|_| {}).unwrap();
    assert_eq!((report.baked, report.kept), (2, 2));
    assert_eq!(report.gone, [] as [usize; 0]);
    assert_eq!(Manifest::read(tmp.path()).unwrap().steps.len(), 4);
}

/// Records what the stages are told of the steps in flight: at once, then left.
#[derive(Debug, Default)]
struct ToldSteps(std::sync::Mutex<Vec<usize>>, std::sync::Mutex<Vec<usize>>);

impl StepsInFlight for ToldSteps {
    fn steps_at_once(&self, steps: usize) {
        self.0.lock().unwrap().push(steps);
    }

    fn steps_left(&self, steps: usize) {
        self.1.lock().unwrap().push(steps);
    }
}

/// A batch tells its stages how many steps it bakes at once (its jobs, no more than its
/// steps) before the first, so that a device's stages keep transfer buffers for that many
/// and no more; then, as each job finds no step left, how many are still baked, down to
/// none, so that they can let go of what they kept for more.
#[test]
fn a_batch_tells_its_stages_the_steps_in_flight() {
    for (steps, jobs, told) in [(6, 2, 2), (2, 4, 2), (1, 1, 1)] {
        let tmp = tempfile::tempdir().unwrap();
        let series = Series { steps, bad: None };
        let watch = std::sync::Arc::new(ToldSteps::default());
        let mut opts = options(tmp.path(), Shard::WHOLE);
        opts.jobs = jobs;
        opts.stages.in_flight = Some(watch.clone());
        let report = run_batch(&series, &opts, &|_| {}).unwrap();
        assert_eq!(report.baked, steps);
        assert_eq!(
            *watch.0.lock().unwrap(),
            [told],
            "{steps} steps, {jobs} jobs"
        );
        let mut left = watch.1.lock().unwrap().clone();
        left.sort_unstable();
        assert_eq!(
            left,
            (0..told).collect::<Vec<_>>(),
            "{steps} steps, {jobs} jobs"
        );
    }
    // A viewer's bake: the steps baked ahead, and the one waited for.
    let tmp = tempfile::tempdir().unwrap();
    let watch = std::sync::Arc::new(ToldSteps::default());
    let mut opts = options(tmp.path(), Shard::WHOLE);
    opts.jobs = 3;
    opts.stages.in_flight = Some(watch.clone());
    let series = Series {
        steps: 4,
        bad: None,
    };
    let _bake = OnDemand::open(Box::new(series), opts).unwrap();
    assert_eq!(*watch.0.lock().unwrap(), [4]);
}

/// The isolated clusters of `points` (local coordinates): components of points linked within
/// `link` of each other, all but the largest (the body), each as its members.
fn isolated_clusters(points: &[[f32; 3]], link: f64) -> Vec<Vec<usize>> {
    let n = points.len();
    let mut parent: Vec<usize> = (0..n).collect();
    fn root(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    let d2 = |a: [f32; 3], b: [f32; 3]| -> f64 {
        (0..3)
            .map(|k| (f64::from(a[k]) - f64::from(b[k])).powi(2))
            .sum()
    };
    for i in 0..n {
        for j in i + 1..n {
            if d2(points[i], points[j]) <= link * link {
                let (a, b) = (root(&mut parent, i), root(&mut parent, j));
                parent[a.max(b)] = a.min(b);
            }
        }
    }
    let mut by_root: std::collections::BTreeMap<usize, Vec<usize>> = Default::default();
    for i in 0..n {
        let r = root(&mut parent, i);
        by_root.entry(r).or_default().push(i);
    }
    let mut clusters: Vec<Vec<usize>> = by_root.into_values().collect();
    clusters.sort_by_key(|c| std::cmp::Reverse(c.len()));
    clusters.split_off(1)
}

/// Traces every isolated cluster of a baked step from the 26 directions of a cube's faces,
/// edges and corners (CPU tracer, 3 iterations): the first hits on the cluster, and how many
/// of them face away from the ray.
fn back_facing_hits_on_clusters(file: &CacheFile) -> (usize, usize, usize) {
    let step = LoadedStep::load(file).unwrap();
    let h = file.header();
    let points: Vec<GpuPoint> = file.decode(names::POINTS).unwrap();
    let local: Vec<[f32; 3]> = points.iter().map(|p| p.position).collect();
    // Linked as the spray rule links them: within h.
    let clusters = isolated_clusters(&local, h.smoothing_length);
    let params = Params::<f32> {
        degree: 2,
        iterations: 3,
        epsilon: 1e-4,
        normals: NormalsMode::Mean,
        h_factor: 1.0,
    };
    let (mut hits, mut back) = (0, 0);
    for members in &clusters {
        let world: Vec<[f64; 3]> = members
            .iter()
            .map(|&i| h.transform.to_world(local[i].map(f64::from)))
            .collect();
        let c: [f64; 3] =
            std::array::from_fn(|a| world.iter().map(|p| p[a]).sum::<f64>() / world.len() as f64);
        let spacing = h.spacing * h.transform.scale;
        let radius = world
            .iter()
            .map(|p| (0..3).map(|a| (p[a] - c[a]).powi(2)).sum::<f64>().sqrt())
            .fold(0.0, f64::max)
            + 2.0 * spacing;
        for d in (0..27)
            .map(|k| [k % 3, k / 3 % 3, k / 9].map(|v| v as f64 - 1.0))
            .filter(|d| d != &[0.0; 3])
        {
            let length = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            let distance = 4.0 * radius;
            let eye: [f64; 3] = std::array::from_fn(|a| c[a] + d[a] / length * distance);
            let up = if d[0] == 0.0 && d[1] == 0.0 {
                [0.0, 1.0, 0.0]
            } else {
                [0.0, 0.0, 1.0]
            };
            let camera = slosh_mls::Camera {
                eye,
                target: c,
                up,
                fov_y: 2.0 * (radius / distance).atan().to_degrees() * 1.1,
                width: 24,
                height: 24,
            };
            for hit in step.render(&camera, &params).into_iter().flatten() {
                let on_cluster = if hit.status == slosh_mls::HitStatus::Droplet {
                    (0..3)
                        .map(|a| (hit.position[a] - c[a]).powi(2))
                        .sum::<f64>()
                        .sqrt()
                        <= radius
                } else {
                    members.contains(&(hit.ball as usize))
                };
                if !on_cluster {
                    continue;
                }
                hits += 1;
                let ray: [f64; 3] = std::array::from_fn(|a| hit.position[a] - eye[a]);
                if (0..3).map(|a| ray[a] * hit.normal[a]).sum::<f64>() > 0.0 {
                    back += 1;
                }
            }
        }
    }
    (clusters.len(), hits, back)
}

/// No open shells (issue 28, item 3): every isolated cluster of the droplets scene, traced
/// from 26 directions, shows only front faces: it is drawn as a closed surface or as spheres.
#[test]
fn every_isolated_cluster_is_closed_from_26_directions() {
    // The demo's droplets: `slosh gen droplets --points 20000 --dt 0.02`.
    let mut spec = SceneSpec::new(SceneKind::Droplets, 20_000, 1);
    spec.dt = 0.02;
    let scene = Scene::new(spec).unwrap();
    for step in [0, 10, 25, 40] {
        let input = slosh_testkit::scene_step(&scene, step, "droplets");
        let file = bake_to_file(&input, &params());
        let (clusters, hits, back) = back_facing_hits_on_clusters(&file);
        eprintln!(
            "droplets step {step}: {clusters} isolated clusters, {hits} first hits on them, {back} back-facing"
        );
        assert!(clusters > 0 && hits > 0);
        assert_eq!(
            back, 0,
            "step {step}: {back} of {hits} first hits face away"
        );
    }
}

/// The same of the demo: the wave scene, every particle read and the surface estimated from
/// them (`slosh demo` bakes `gen wave` with `--surface estimate`).
#[test]
fn every_isolated_cluster_of_the_demo_is_closed_from_26_directions() {
    let mut spec = SceneSpec::new(SceneKind::Wave, 20_000, 1);
    spec.dt = 0.02;
    let scene = Scene::new(spec).unwrap();
    let p = BakeParams::new(
        SurfaceSelect::Estimate,
        NormalSource::Variable("normal".into()),
    );
    let mut total = 0;
    for step in [0, 60, 130] {
        let particles = scene.particles(step);
        let input = StepInput {
            index: step,
            time: scene.time(step),
            source: "wave".into(),
            positions: particles.positions.iter().map(|v| v.to_array()).collect(),
            normals: Some(particles.normals.iter().map(|v| v.to_array()).collect()),
            ..StepInput::default()
        };
        let file = bake_to_file(&input, &p);
        let (clusters, hits, back) = back_facing_hits_on_clusters(&file);
        eprintln!(
            "wave step {step}: {clusters} isolated clusters, {hits} first hits on them, {back} back-facing"
        );
        total += clusters;
        assert_eq!(
            back, 0,
            "step {step}: {back} of {hits} first hits face away"
        );
    }
    assert!(total > 3, "{total} isolated clusters");
}

/// A holder of `cache` for the EnSight `case` (all points, the data's normals), on the CPU.
fn holder(case: &Path, cache: &Path) -> OnDemand {
    let params = BakeParams::new(SurfaceSelect::All, NormalSource::Variable("normal".into()));
    let opened = slosh_ensight::Case::open(case).unwrap();
    OnDemand::of_case(
        opened,
        case,
        cache.to_path_buf(),
        params,
        (1, 1),
        Stages::cpu(),
    )
    .unwrap()
}

/// Two holders of one raw case's directory (two players, or a player and a render) asking
/// for one step at once: it is baked once, the other finds it current, and the file the
/// first wrote stays in place.
#[test]
fn two_holders_of_a_case_bake_a_step_once() {
    let dir = tempfile::tempdir().unwrap();
    let scene = Scene::new(SceneSpec::new(SceneKind::Sphere, 20000, 3)).unwrap();
    let case =
        slosh_testkit::write_surface_case(&dir.path().join("case"), "sphere", &scene, 2).unwrap();
    let cache = dir.path().join("cache");
    let (a, b) = (holder(&case, &cache), holder(&case, &cache));
    let outcomes: Vec<StepOutcome> = std::thread::scope(|s| {
        let x = s.spawn(|| a.bake(1));
        let y = s.spawn(|| b.bake(1));
        vec![x.join().unwrap(), y.join().unwrap()]
    });
    let baked = outcomes
        .iter()
        .filter(|o| matches!(o, StepOutcome::Baked { .. }))
        .count();
    let kept = outcomes
        .iter()
        .filter(|o| matches!(o, StepOutcome::Kept))
        .count();
    assert_eq!((baked, kept), (1, 1), "{outcomes:?}");
    CacheFile::open(&cache.join(step_file_name(1)))
        .unwrap()
        .verify()
        .unwrap();
}

/// A 5,000-point sphere case of two steps written in `dir`, and a holder of its cache there.
fn small_case_holder(dir: &Path) -> (std::path::PathBuf, OnDemand) {
    let scene = Scene::new(SceneSpec::new(SceneKind::Sphere, 5000, 3)).unwrap();
    let case = slosh_testkit::write_surface_case(&dir.join("case"), "sphere", &scene, 2).unwrap();
    let cache = dir.join("cache");
    let holder = holder(&case, &cache);
    (cache, holder)
}

/// A viewer's bake withdrawn at any of the points where it is asked (before the read, before
/// each neighbour search, between stages, before the write) gives up there: a failed outcome
/// that says so, no step file and nothing left behind; the withdrawn bake asked at least
/// four times (before the read, two searches, after the surface), and a bake of the same
/// step not withdrawn then writes a file that verifies.
#[test]
fn a_withdrawn_on_demand_bake_gives_up_and_writes_nothing() {
    use std::sync::atomic::{AtomicUsize, Ordering};
    let dir = tempfile::tempdir().unwrap();
    let (cache, holder) = small_case_holder(dir.path());
    let step_file = cache.join(step_file_name(1));
    // How often an unwithdrawn bake asks.
    let asked = AtomicUsize::new(0);
    let counting = || {
        asked.fetch_add(1, Ordering::Relaxed);
        false
    };
    let outcome = holder.bake_unless_withdrawn(0, &counting);
    assert!(matches!(outcome, StepOutcome::Baked { .. }), "{outcome:?}");
    let asks = asked.load(Ordering::Relaxed);
    assert!(asks >= 4, "asked {asks} times");
    // Withdrawn at the k-th ask, for every k the bake reaches.
    for k in 1..=asks {
        let count = AtomicUsize::new(0);
        let withdrawn = || count.fetch_add(1, Ordering::Relaxed) + 1 >= k;
        let outcome = holder.bake_unless_withdrawn(1, &withdrawn);
        match &outcome {
            StepOutcome::Failed(why) => assert!(why.contains("withdrawn"), "{why}"),
            other => panic!("withdrawn at ask {k}: {other:?}"),
        }
        assert!(!step_file.exists(), "withdrawn at ask {k}: a step file");
        let left: Vec<_> = std::fs::read_dir(&cache)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|name| name.contains("00001"))
            .collect();
        assert!(
            left.is_empty(),
            "withdrawn at ask {k}: {left:?} left behind"
        );
    }
    let outcome = holder.bake(1);
    assert!(matches!(outcome, StepOutcome::Baked { .. }), "{outcome:?}");
    CacheFile::open(&step_file).unwrap().verify().unwrap();
}

/// A step baked ahead waits, at its first ask, while a waited-for step bakes (the bake someone
/// waits for has the cores and the device), and then bakes: held 300 ms inside the waited-for
/// bake, the bake ahead has not asked once; both steps are then baked and verify.
#[test]
fn a_bake_ahead_pauses_while_a_waited_for_step_bakes() {
    use slosh_bake::Urgency;
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::mpsc;
    let dir = tempfile::tempdir().unwrap();
    let (cache, holder) = small_case_holder(dir.path());
    let (inside_tx, inside_rx) = mpsc::channel::<()>();
    let (release_tx, release_rx) = mpsc::channel::<()>();
    let (inside_tx, release_rx) = (
        std::sync::Mutex::new(inside_tx),
        std::sync::Mutex::new(release_rx),
    );
    let first_ask = AtomicBool::new(true);
    // The waited-for bake's first ask (before its read, its lock held) says it is inside and
    // holds until released.
    let waited_asks = || {
        if first_ask.swap(false, Ordering::SeqCst) {
            inside_tx.lock().unwrap().send(()).unwrap();
            release_rx.lock().unwrap().recv().unwrap();
        }
        false
    };
    let ahead_asked = AtomicBool::new(false);
    let ahead_asks = || {
        ahead_asked.store(true, Ordering::SeqCst);
        false
    };
    let (waited, ahead, asked_while_held) = std::thread::scope(|s| {
        let waited = s.spawn(|| holder.bake_as(0, Urgency::Waited, &waited_asks));
        inside_rx.recv().unwrap();
        let ahead = s.spawn(|| holder.bake_as(1, Urgency::Ahead, &ahead_asks));
        std::thread::sleep(std::time::Duration::from_millis(300));
        let asked_while_held = ahead_asked.load(Ordering::SeqCst);
        release_tx.send(()).unwrap();
        (
            waited.join().unwrap(),
            ahead.join().unwrap(),
            asked_while_held,
        )
    });
    assert!(
        !asked_while_held,
        "the bake ahead went on beside the waited-for one"
    );
    assert!(
        ahead_asked.load(Ordering::SeqCst),
        "the bake ahead never asked"
    );
    for (step, outcome) in [(0, waited), (1, ahead)] {
        assert!(
            matches!(outcome, StepOutcome::Baked { .. }),
            "step {step}: {outcome:?}"
        );
        CacheFile::open(&cache.join(step_file_name(step)))
            .unwrap()
            .verify()
            .unwrap();
    }
}

/// Every point's stored reach holds its whole list as the GPU's expansion measures it: in
/// f32, on the stored positions. The bake raises a reach where those distances pass it and
/// measures only the lists whose stored half float lies within `REACH_SLACK` above the f64
/// reach; scenes with noise, spray, a density jump, per-point h and an offset of 1e5 (the
/// largest rounding before recentring). It also counts the lists whose f32 reach came within
/// a thousandth of the stored half float, so that the margin is seen to be exercised.
#[test]
fn every_list_lies_within_its_stored_reach_in_f32() {
    let mut close = 0usize;
    for (kind, points, noise, per_point_h) in [
        (SceneKind::Sphere, 6000, 0.3, false),
        (SceneKind::Droplets, 5000, 0.0, true),
        (SceneKind::Wave, 5000, 0.1, false),
        (SceneKind::Tank, 5000, 0.0, true),
    ] {
        let mut spec = SceneSpec::new(kind, points, 3);
        spec.hard.noise = noise;
        spec.hard.density_jump = if per_point_h { 20.0 } else { 1.0 };
        spec.hard.offset = 1e5;
        let scene = Scene::new(spec).unwrap();
        let input = slosh_testkit::scene_step(&scene, 1, &format!("{kind:?}"));
        let mut p = params();
        p.mls.per_point_h = per_point_h;
        let (_, parts) = bake_step_parts(&input, &p).unwrap();
        let file = bake_to_file(&input, &p);
        let stored: Vec<GpuPoint> = file.decode(names::POINTS).unwrap();
        assert_eq!(stored.len(), parts.points.len(), "{kind:?}");
        let at = |i: usize| stored[i].position;
        for (i, point) in stored.iter().enumerate() {
            let reach = point.reach();
            let far2 = parts
                .neighbours
                .whole()
                .expect("the CPU bake keeps every list")
                .of(i)
                .iter()
                .map(|&j| {
                    let (a, b) = (at(i), at(j as usize));
                    let d = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
                    d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
                })
                .fold(0.0f32, f32::max);
            assert!(
                far2 <= reach * reach,
                "{kind:?}: point {i}'s list reaches {} beyond its stored reach {reach}",
                far2.sqrt()
            );
            close += usize::from(far2.sqrt() > reach * 0.999);
        }
    }
    assert!(close > 0, "no list came near its stored reach");
}
