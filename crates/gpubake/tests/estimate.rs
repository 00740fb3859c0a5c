//! The surface estimate with the GPU's nearest points against the k-d tree's: the same
//! surface flags and outward normals, bit for bit, at every particle whose neighbourhood does
//! not tie at its last neighbour (the SPH fixtures' dam breaks, a jittered block of fluid far
//! from the origin, and that block in a shuffled order).

#![allow(clippy::unwrap_used)] // a test fails loudly

use std::num::NonZero;
use std::path::Path;
use std::sync::Arc;

use slosh_bake::{ESTIMATE_NEIGHBOURS, estimate_surface_normals_with, read_point_cloud};
use slosh_gpubake::GpuStages;
use slosh_mls::{KdSearch, NeighbourSearch, distance2};
use slosh_render::Gpu;
use slosh_testkit::{adapter, gpu_or_skip};

/// Particle i's 25th and 26th nearest distances tie within this (relative): which of them is
/// a neighbour is then the search's choice.
const TIE: f64 = 1e-6;

#[test]
fn the_surface_estimate_with_gpu_neighbours_is_the_k_d_trees() {
    let Some(gpu) = gpu_or_skip(Gpu::new(adapter().as_deref())) else {
        return;
    };
    let stages = GpuStages::new(Arc::new(gpu)).unwrap();
    let mut sets: Vec<(String, Vec<[f64; 3]>)> =
        ["sph/coarse-t0.4", "sph/coarse-t1", "sph-fine/t0.4"]
            .iter()
            .map(|name| {
                let path = format!(
                    "{}/../../tests/data/{name}/particles.ply",
                    env!("CARGO_MANIFEST_DIR")
                );
                (
                    format!("dam break {name}"),
                    read_point_cloud(Path::new(&path)).unwrap().positions,
                )
            })
            .collect();
    let far = slosh_scenes::jittered_block(24, 0.01, [1e5, 0.0, 0.0]);
    let n = far.len();
    assert_ne!(n % 7919, 0);
    sets.push((
        "block at 1e5, shuffled".into(),
        (0..n).map(|i| far[i * 7919 % n]).collect(),
    ));
    sets.push(("block at 1e5".into(), far));
    eprintln!(
        "| set | particles | on the surface | flags differing | normals differing | of those, at a tie |"
    );
    eprintln!("|---|---|---|---|---|---|");
    for (name, points) in &sets {
        let cpu = estimate_surface_normals_with(points, &KdSearch).unwrap();
        let gpu = estimate_surface_normals_with(points, &stages).unwrap();
        // The 25th and 26th nearest (itself first) of every particle, by the k-d tree.
        let k = ESTIMATE_NEIGHBOURS + 2;
        let nearest = KdSearch
            .index(points)
            .unwrap()
            .nearest(NonZero::new(k).unwrap())
            .unwrap();
        let ties = |i: usize| {
            let d = |slot: usize| distance2(points[i], points[nearest[i * k + slot] as usize]);
            let (last, next) = (d(k - 2), d(k - 1));
            next - last <= TIE * next
        };
        let (mut flags, mut normals, mut tied) = (0, 0, 0);
        for i in 0..points.len() {
            let (flag, normal) = (cpu[i].0 != gpu[i].0, cpu[i].1 != gpu[i].1);
            flags += usize::from(flag);
            normals += usize::from(normal);
            if flag || normal {
                assert!(
                    ties(i),
                    "{name}: particle {i} differs without a tie: {:?} / {:?}",
                    cpu[i],
                    gpu[i]
                );
                tied += 1;
            }
        }
        let surface = cpu.iter().filter(|e| e.0).count();
        eprintln!(
            "| {name} | {} | {surface} | {flags} | {normals} | {tied} |",
            points.len()
        );
        assert!(
            surface > points.len() / 20 && surface < points.len(),
            "{name}: {surface} on the surface"
        );
        assert!(
            flags + normals <= points.len() / 1000,
            "{name}: {flags} flags, {normals} normals differ"
        );
    }
}
