//! Cost per ray of the CPU reference tracer: 1 and 2 iterations, quadratic and cubic, f64 and
//! f32, on a 5000-point sphere (`cargo bench -p slosh-mls --bench ray_cost`). Accuracy at the
//! same settings is in docs/accuracy.md.

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use slosh_mls::{Camera, Params, Real, Surface, SurfaceParams};
use slosh_scenes::{Scene, SceneKind, SceneSpec};

fn rays(c: &mut Criterion) {
    let scene = Scene::new(SceneSpec::new(SceneKind::Sphere, 5000, 7)).expect("scene");
    let p = scene.particles(0);
    let pos: Vec<[f64; 3]> = p.positions.iter().map(|q| q.to_array()).collect();
    let nrm: Vec<[f64; 3]> = p.normals.iter().map(|q| q.to_array()).collect();
    // 32 × 32 rays, all aimed inside the sphere's silhouette.
    let camera = Camera {
        eye: [0.0, -3.0, 0.0],
        target: [0.0, 0.0, 0.0],
        up: [0.0, 0.0, 1.0],
        fov_y: 18.0,
        width: 32,
        height: 32,
    };
    let mut group = c.benchmark_group("ray");
    group.throughput(Throughput::Elements(u64::from(
        camera.width * camera.height,
    )));
    group.sample_size(20);
    fn bench<T: Real>(
        group: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
        name: &str,
        pos: &[[f64; 3]],
        nrm: &[[f64; 3]],
        camera: &Camera,
    ) {
        for degree in [2u8, 3] {
            let surface = Surface::<T>::build(
                pos,
                Some(nrm),
                &SurfaceParams {
                    degree,
                    ..SurfaceParams::default()
                },
            )
            .expect("surface");
            for iterations in [1u32, 2] {
                let params = Params {
                    degree,
                    iterations,
                    ..Params::new()
                };
                group.bench_function(format!("{name}/degree{degree}/iter{iterations}"), |b| {
                    b.iter(|| {
                        let mut hits = 0;
                        for y in 0..camera.height {
                            for x in 0..camera.width {
                                let (o, d) = camera.ray(x, y);
                                hits += usize::from(surface.trace(o, d, &params).is_some());
                            }
                        }
                        hits
                    })
                });
            }
        }
    }
    bench::<f64>(&mut group, "f64", &pos, &nrm, &camera);
    bench::<f32>(&mut group, "f32", &pos, &nrm, &camera);
    group.finish();
}

criterion_group!(benches, rays);
criterion_main!(benches);
