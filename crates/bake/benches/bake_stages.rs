//! Bake cost against its bare core (kiddo kNN, neighbour lists and fits), and load cost, for
//! one 10k-point step. `slosh bench bake` gives the full table up to 1M points.

#![allow(clippy::unwrap_used)]

use std::path::Path;

use criterion::{Criterion, criterion_group, criterion_main};
use slosh_bake::{BakeParams, NormalSource, SurfaceSelect, bake_step};
use slosh_cache::{CacheFile, encode_step};
use slosh_mls::{Surface, SurfaceParams};
use slosh_scenes::{Scene, SceneKind, SceneSpec};

fn bench(c: &mut Criterion) {
    let scene = Scene::new(SceneSpec::new(SceneKind::Sphere, 10_000, 1)).unwrap();
    let input = slosh_testkit::scene_step(&scene, 0, "");
    let params = BakeParams::new(SurfaceSelect::All, NormalSource::Variable("normal".into()));
    let bare = SurfaceParams {
        droplet_below: 0,
        ..params.mls.clone()
    };
    let mut g = c.benchmark_group("bake_10k");
    g.sample_size(10);
    g.bench_function("bare_knn_lists_fits", |b| {
        b.iter(|| Surface::<f64>::build(&input.positions, input.normals.as_deref(), &bare).unwrap())
    });
    g.bench_function("bake_and_encode", |b| {
        b.iter(|| {
            let baked = bake_step(&input, &params).unwrap();
            encode_step(baked.header, &baked.sections, params.compression).unwrap()
        })
    });
    let baked = bake_step(&input, &params).unwrap();
    let bytes = encode_step(baked.header, &baked.sections, params.compression).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("step.slc");
    std::fs::write(&path, &bytes).unwrap();
    let file = CacheFile::open(&path).unwrap();
    let mut buffers = file.section_buffers();
    g.bench_function("load_decode_all_sections", |b| {
        b.iter(|| {
            let f = CacheFile::open(Path::new(&path)).unwrap();
            f.decode_all_into(&mut buffers).unwrap();
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
