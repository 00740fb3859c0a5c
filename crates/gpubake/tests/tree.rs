//! The GPU's BVH tree (a linear BVH over the CPU's leaves): node for node the CPU's linear
//! BVH, and against obvhs's PLOC on the CPU: the same leaves, every inner box the exact union of its children's, within the tracer's
//! depth, and the same nearest sphere for every ray a walk of either tree finds (a brute
//! force over every item agrees); the expected inner nodes a random ray tests (the sum of
//! inner boxes' areas over the root's) is reported, and bounded against PLOC's.

#![allow(clippy::unwrap_used)] // a test fails loudly

use std::sync::Arc;

use slosh_bake::{PlocTree, TreeBuild, bvh_leaves, linear_bvh};
use slosh_cache::{Bvh, BvhNode};
use slosh_gpubake::GpuStages;
use slosh_mls::{BallIndex, morton_order};
use slosh_render::{Gpu, MAX_BVH_DEPTH};
use slosh_scenes::{HardCases, Scene, SceneKind, SceneSpec};
use slosh_testkit::{adapter, gpu_or_skip};

/// The linear BVH's inner boxes may sum to at most this many times PLOC's: a random ray tests
/// about that many more inner nodes (measured on lavapipe: at most 1.08, the hard sphere's).
const MOST_INNER_AREA_RATIO: f64 = 1.15;

/// Items as the bake gives them: (id, centre, radius) in Morton order, ids ascending.
type Items = Vec<(u32, [f64; 3], f64)>;

fn scene_items(kind: SceneKind, points: usize, hard: &HardCases) -> (String, Items) {
    let mut spec = SceneSpec::new(kind, points, 5);
    spec.hard = hard.clone();
    let scene = Scene::new(spec).unwrap();
    let (points, _) = scene.particles(0).surface_arrays();
    let order = morton_order(&points);
    let spacing = scene.spacing();
    let n = points.len();
    let mut items: Items = order
        .iter()
        .enumerate()
        // Every seventh ball is not a candidate (a gap in the ids, as unfitted balls make).
        .filter(|(k, _)| k % 7 != 3)
        .map(|(k, &i)| {
            (
                k as u32,
                points[i as usize],
                spacing * (1.0 + (k % 3) as f64 * 0.5),
            )
        })
        .collect();
    // Droplet spheres after the balls: far out, of several sizes.
    for d in 0..40 {
        let a = d as f64 * 0.7;
        items.push((
            (n + d) as u32,
            [3.0 * a.cos(), 3.0 * a.sin(), 0.2 * d as f64],
            spacing * (1.0 + d as f64 * 0.1),
        ));
    }
    (
        format!(
            "{}{}",
            kind.name(),
            if hard.isolated { ", hard" } else { "" }
        ),
        items,
    )
}

fn ray_sphere(origin: [f64; 3], dir: [f64; 3], centre: [f64; 3], radius: f64) -> Option<f64> {
    let oc: [f64; 3] = std::array::from_fn(|a| origin[a] - centre[a]);
    let b: f64 = (0..3).map(|a| oc[a] * dir[a]).sum();
    let c: f64 = (0..3).map(|a| oc[a] * oc[a]).sum::<f64>() - radius * radius;
    let disc = b * b - c;
    if disc < 0.0 {
        return None;
    }
    let t = -b - disc.sqrt();
    (t >= 0.0).then_some(t)
}

/// The nearest (t, item) a walk of `bvh` finds.
fn nearest(bvh: &Bvh, items: &Items, origin: [f64; 3], dir: [f64; 3]) -> Option<(f64, u32)> {
    let mut best: Option<(f64, u32)> = None;
    bvh.walk(origin, dir, &mut |ids| {
        for &id in ids {
            if let Ok(k) = items.binary_search_by_key(&id, |it| it.0) {
                let (_, c, r) = items[k];
                if let Some(t) = ray_sphere(origin, dir, c, r)
                    && best.is_none_or(|b| (t, id) < b)
                {
                    best = Some((t, id));
                }
            }
        }
        best.map_or(f64::INFINITY, |b| b.0)
    });
    best
}

/// The tree's structure: root first, children adjacent, in range and after their parent, every leaf of `leaves`
/// once, inner boxes the exact unions; returns the inner boxes' area over the root's.
fn check_tree(name: &str, bvh: &Bvh, leaves: &[BvhNode]) -> f64 {
    bvh.depth().unwrap_or_else(|| panic!("{name}: not a tree"));
    let mut found: Vec<(u32, u32)> = Vec::new();
    let area = |n: &BvhNode| {
        let e: [f64; 3] = std::array::from_fn(|a| f64::from(n.hi[a] - n.lo[a]));
        e[0] * e[1] + e[1] * e[2] + e[2] * e[0]
    };
    let mut inner_area = 0.0;
    for (k, node) in bvh.nodes.iter().enumerate() {
        if node.count > 0 {
            found.push((node.first, node.count));
            let leaf = leaves
                .iter()
                .find(|l| l.first == node.first)
                .unwrap_or_else(|| panic!("{name}: leaf {node:?} is none of the CPU's"));
            assert_eq!(leaf, node, "{name}: a leaf changed");
            continue;
        }
        inner_area += area(node);
        // The tracer only walks down.
        assert!(
            node.first as usize > k,
            "{name}: node {k}'s children come before it"
        );
        let (a, b) = (
            bvh.nodes[node.first as usize],
            bvh.nodes[node.first as usize + 1],
        );
        for axis in 0..3 {
            assert_eq!(
                node.lo[axis],
                a.lo[axis].min(b.lo[axis]),
                "{name}: node {k}"
            );
            assert_eq!(
                node.hi[axis],
                a.hi[axis].max(b.hi[axis]),
                "{name}: node {k}"
            );
        }
    }
    found.sort_unstable();
    let mut expected: Vec<(u32, u32)> = leaves.iter().map(|l| (l.first, l.count)).collect();
    expected.sort_unstable();
    assert_eq!(found, expected, "{name}: the leaves");
    assert_eq!(bvh.nodes.len(), 2 * leaves.len() - 1, "{name}: node count");
    inner_area / area(&bvh.nodes[0])
}

#[test]
fn the_gpu_tree_finds_what_the_cpu_tree_finds() {
    let Some(gpu) = gpu_or_skip(Gpu::new(adapter().as_deref())) else {
        return;
    };
    let stages = GpuStages::new(Arc::new(gpu)).unwrap();
    let hard = HardCases {
        noise: 0.1,
        duplicates: 0.05,
        isolated: true,
        density_jump: 10.0,
        collinear: 50,
        coplanar: 50,
        ..HardCases::default()
    };
    let mut cases: Vec<(String, Items)> = SceneKind::ALL
        .iter()
        .map(|&kind| scene_items(kind, 20_000, &HardCases::default()))
        .collect();
    cases.push(scene_items(SceneKind::Sphere, 20_000, &hard));
    cases.push(scene_items(SceneKind::Droplets, 5_000, &hard));
    // Every item at one point (every key ties: the index decides), a line, and the
    // smallest trees.
    cases.push((
        "coincident".into(),
        (0..500).map(|i| (i, [0.25; 3], 0.1)).collect(),
    ));
    cases.push((
        "line".into(),
        (0..3000)
            .map(|i| (i, [f64::from(i).powf(1.5), 0.0, 0.0], 1.0))
            .collect(),
    ));
    for leaves in [2u32, 3] {
        cases.push((
            format!("{leaves} leaves"),
            (0..leaves)
                .map(|i| (i, [f64::from(i) * 100.0, 0.0, 0.0], 1.0))
                .collect(),
        ));
    }
    eprintln!(
        "| set | items | leaves | depth CPU / GPU | inner area / root, CPU / GPU | rays | nearest differing |"
    );
    eprintln!("|---|---|---|---|---|---|---|");
    for (name, items) in &cases {
        let leaves = bvh_leaves(items);
        let cpu = PlocTree.build(&leaves).unwrap();
        let gpu = stages
            .build(&leaves)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(
            gpu.nodes,
            linear_bvh(&leaves).nodes,
            "{name}: the GPU's linear BVH is not the CPU's"
        );
        let cpu_area = check_tree(name, &cpu, &leaves);
        let gpu_area = check_tree(name, &gpu, &leaves);
        // Rays through the set's box from outside, in many directions.
        let root = &cpu.nodes[0];
        let centre: [f64; 3] = std::array::from_fn(|a| 0.5 * f64::from(root.lo[a] + root.hi[a]));
        let size = (0..3)
            .map(|a| f64::from(root.hi[a] - root.lo[a]))
            .fold(0.0, f64::max)
            .max(1.0);
        let rays = 2000;
        let mut differing = 0;
        for r in 0..rays {
            let (u, v) = (
                (r as f64 * 0.618_034).fract(),
                (r as f64 * 0.754_878).fract(),
            );
            let (theta, z) = (u * std::f64::consts::TAU, 2.0 * v - 1.0);
            let s = (1.0 - z * z).sqrt();
            let dir = [-s * theta.cos(), -s * theta.sin(), -z];
            let jitter = |k: f64| ((r as f64 * k).fract() - 0.5) * 0.5 * size;
            let origin = [
                centre[0] - dir[0] * 2.0 * size + jitter(0.37),
                centre[1] - dir[1] * 2.0 * size + jitter(0.71),
                centre[2] - dir[2] * 2.0 * size + jitter(0.13),
            ];
            let a = nearest(&cpu, items, origin, dir);
            let b = nearest(&gpu, items, origin, dir);
            if r % 10 == 0 {
                let brute = items
                    .iter()
                    .filter_map(|&(id, c, rad)| ray_sphere(origin, dir, c, rad).map(|t| (t, id)))
                    .min_by(|x, y| x.partial_cmp(y).unwrap());
                assert_eq!(a, brute, "{name}: ray {r}: the CPU tree's walk");
            }
            differing += usize::from(a != b);
        }
        eprintln!(
            "| {name} | {} | {} | {} / {} | {cpu_area:.1} / {gpu_area:.1} | {rays} | {differing} |",
            items.len(),
            leaves.len(),
            cpu.depth().unwrap(),
            gpu.depth().unwrap()
        );
        assert_eq!(differing, 0, "{name}: rays whose nearest sphere differs");
        let depth = gpu.depth().unwrap() as u64;
        assert!(
            depth <= MAX_BVH_DEPTH,
            "{name}: the GPU tree is {depth} deep"
        );
        assert!(
            gpu_area <= MOST_INNER_AREA_RATIO * cpu_area,
            "{name}: the linear BVH's inner boxes sum to {gpu_area:.1} root areas, PLOC's {cpu_area:.1}"
        );
    }
}

#[test]
fn a_linear_bvh_deeper_than_the_tracer_walks_gives_way_to_plocs() {
    let Some(gpu) = gpu_or_skip(Gpu::new(adapter().as_deref())) else {
        return;
    };
    let stages = GpuStages::new(Arc::new(gpu)).unwrap();
    // Items halving their distance from the origin along x, y and z in turn split the
    // Morton codes one bit deeper each (a chain of 63 inner nodes), and a cluster below the
    // codes' resolution hangs at its end: a linear BVH about 70 deep.
    let mut centres: Vec<[f64; 3]> = Vec::new();
    for k in (0..21).rev() {
        let d = 0.5f64.powi(k);
        centres.extend([[0.0, 0.0, d], [0.0, d, 0.0], [d, 0.0, 0.0]]);
    }
    centres.reverse();
    let fine = 0.5f64.powi(24);
    for i in 0..1000 {
        let (x, y, z) = (i % 10, i / 10 % 10, i / 100);
        centres.push([x, y, z].map(|c| f64::from(c) * fine * 0.1));
    }
    let order = morton_order(&centres);
    let items: Items = order
        .iter()
        .enumerate()
        .map(|(k, &i)| (k as u32, centres[i as usize], fine * 0.01))
        .collect();
    let leaves = bvh_leaves(&items);
    let cpu = PlocTree.build(&leaves).unwrap();
    let built = stages.build(&leaves).unwrap();
    let depth = built.depth().unwrap() as u64;
    assert!(depth <= MAX_BVH_DEPTH, "the tree is {depth} deep");
    assert_eq!(built.nodes, cpu.nodes, "not PLOC's tree");
}

#[test]
fn the_tree_structs_mirror_the_wgsl_layout() {
    use slosh_gpubake::{TreeNode, TreeParams, tree_source};
    use slosh_testkit::check_layout;
    let module = slosh_testkit::wgsl::validate("bvh build", &tree_source());
    check_layout!(
        &module,
        "TreeParams",
        TreeParams,
        [leaves, row_threads, _pad0, _pad1]
    );
    check_layout!(&module, "TreeNode", TreeNode, [lo, count, hi, first]);
}

/// Leaves whose nodes exceed one binding (here 64 KiB: 1024 nodes) are linked on the CPU, not
/// refused; below it, on the GPU.
#[test]
fn a_tree_larger_than_a_binding_is_built_on_the_cpu() {
    let Some(mut gpu) = gpu_or_skip(Gpu::new(adapter().as_deref())) else {
        return;
    };
    gpu.limit_bindings(1 << 16);
    let small = GpuStages::new(Arc::new(gpu)).unwrap();
    for (points, by_gpu) in [(500u32, true), (3000, false)] {
        // A line of balls too far apart to share leaves: a leaf each.
        let items: Items = (0..points)
            .map(|i| (i, [f64::from(i) * 10.0, 0.0, 0.0], 1.0))
            .collect();
        let leaves = bvh_leaves(&items);
        assert_eq!(leaves.len(), points as usize);
        let built = small.build(&leaves).unwrap();
        let want = if by_gpu {
            linear_bvh(&leaves)
        } else {
            PlocTree.build(&leaves).unwrap()
        };
        assert_eq!(built.nodes, want.nodes, "{points} leaves");
    }
}
