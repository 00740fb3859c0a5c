#![allow(clippy::unwrap_used)]
//! The orientation check's first-pass votes cast on the GPU (`shaders/orient_votes.wgsl`)
//! against the CPU's (`slosh_mls::repair_orientation`, the reference): the same repaired
//! normals and the same counts, on clean, reversed, sheet-like and degenerate normals, with
//! most votes taken from the GPU and those rounding could decide cast again on the host.

use std::num::NonZero;
use std::sync::Arc;

use slosh_gpubake::GpuStages;
use slosh_mls::{
    NO_POINT, NearestIds, NeighbourSearch, ORIENT_NEIGHBOURS, morton_order, repair_orientation,
    vote_word,
};
use slosh_render::Gpu;
use slosh_testkit::{adapter, gpu_or_skip};

/// A small xorshift, so the cases are the same on every run.
struct Random(u64);

impl Random {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

fn unit(v: [f64; 3]) -> [f64; 3] {
    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    v.map(|c| c / l)
}

/// A jittered sphere of `n` points (Fibonacci), with its outward normals tilted a little.
fn sphere(n: usize, random: &mut Random) -> (Vec<[f64; 3]>, Normals) {
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let phi = i as f64 * 2.399_963_229_728_653;
            let r = (1.0 - z * z).sqrt();
            let p = [r * phi.cos(), r * phi.sin(), z];
            let jitter = 1.0 + 0.01 * (random.next() - 0.5);
            let tilt = [
                0.1 * (random.next() - 0.5),
                0.1 * (random.next() - 0.5),
                0.0,
            ];
            (
                p.map(|c| c * jitter),
                Some(unit([p[0] + tilt[0], p[1] + tilt[1], p[2] + tilt[2]])),
            )
        })
        .unzip()
}

/// Unit normals, or none.
type Normals = Vec<Option<[f64; 3]>>;

/// The cases: (name, points in Morton order, their normals).
fn cases() -> Vec<(&'static str, Vec<[f64; 3]>, Normals)> {
    let mut random = Random(0x9e37_79b9_7f4a_7c15);
    let mut out = Vec::new();
    let (points, normals) = sphere(20_000, &mut random);
    out.push(("clean sphere", points.clone(), normals.clone()));
    // A sixth reversed one by one, and a cap reversed whole.
    let reversed: Normals = points
        .iter()
        .zip(&normals)
        .map(|(p, n)| {
            let flip = p[2] > 0.93 || random.next() < 0.16;
            n.map(|v| if flip { v.map(|c| -c) } else { v })
        })
        .collect();
    out.push(("reversed singly and a cap", points.clone(), reversed));
    // Two faces of a thin sheet, each with its own outward normal; some normals missing, and
    // points written twice (coincident, which f32 cannot tell from f64's near ones).
    let mut sheet_points = Vec::new();
    let mut sheet_normals = Vec::new();
    for i in 0..6_000 {
        let (x, y) = ((i % 80) as f64 * 0.01, (i / 80) as f64 * 0.01);
        for (z, nz) in [(0.0, -1.0), (0.004, 1.0)] {
            sheet_points.push([x + 0.002 * random.next(), y + 0.002 * random.next(), z]);
            sheet_normals.push((i % 37 != 0).then_some([0.0, 0.0, nz]));
        }
    }
    for k in 0..200 {
        sheet_points.push(sheet_points[k * 7]);
        sheet_normals.push(sheet_normals[k * 7]);
    }
    out.push(("thin sheet, gaps and twins", sheet_points, sheet_normals));
    // Stragglers far from a sphere: the nearest pass leaves some of them to coarser grids,
    // whose ids only the host has, so the host casts their votes.
    let (mut far_points, mut far_normals) = sphere(5_000, &mut random);
    for k in 0..40 {
        let at = [30.0 + 2.0 * random.next(), -20.0, 10.0 * random.next()];
        far_points.push(at);
        far_normals.push(Some(unit([1.0, random.next(), (k % 3) as f64 - 1.0])));
    }
    out.push(("sphere and far stragglers", far_points, far_normals));
    // Droplets of 8 particles on unit spheres 5 apart: a point's edges reach 1.75 times its
    // 6th nearest place, short of the next droplets' particles, whose normals face it; with
    // those, the votes reversed 584 of the 2400 normals (as a shader that left the reach out
    // cast them), without them none.
    let (mut drop_points, mut drop_normals) = (Vec::new(), Vec::new());
    for d in 0..300 {
        let centre = [
            5.0 * (d % 2) as f64,
            5.0 * (d / 2 % 10) as f64,
            5.0 * (d / 20) as f64,
        ];
        let (points, normals) = sphere(8, &mut random);
        let turn = random.next() * std::f64::consts::TAU;
        let (c, s) = (turn.cos(), turn.sin());
        for (p, n) in points.iter().zip(normals) {
            let p = [c * p[0] - s * p[1], s * p[0] + c * p[1], p[2]];
            drop_points.push([centre[0] + p[0], centre[1] + p[1], centre[2] + p[2]]);
            drop_normals.push(n.map(|n| [c * n[0] - s * n[1], s * n[0] + c * n[1], n[2]]));
        }
    }
    out.push(("droplets apart", drop_points, drop_normals));
    out.into_iter()
        .map(|(name, points, normals)| {
            let order = morton_order(&points);
            let points: Vec<[f64; 3]> = order.iter().map(|&i| points[i as usize]).collect();
            let normals = order.iter().map(|&i| normals[i as usize]).collect();
            (name, points, normals)
        })
        .collect()
}

#[test]
fn gpu_votes_repair_the_normals_as_the_cpu_does() {
    let Some(gpu) = gpu_or_skip(Gpu::new(adapter().as_deref())) else {
        return;
    };
    let search = GpuStages::new(Arc::new(gpu)).expect("the search passes compile");
    let mut reversals = 0;
    for (name, points, normals) in cases() {
        let index = search.index(&points).unwrap();
        // As the surface's build gathers them: the nearest but the point itself.
        let count = ORIENT_NEIGHBOURS + 1;
        let nearest = index.nearest(NonZero::new(count).unwrap()).unwrap();
        let nearest = NearestIds::new(&nearest, count, ORIENT_NEIGHBOURS);
        let votes = index
            .orientation_votes(nearest, &normals)
            .unwrap()
            .expect("points in Morton order: the GPU casts the votes");
        assert!(
            index
                .orientation_votes(nearest, &normals)
                .unwrap()
                .is_none(),
            "{name}: the pass's ids go with the votes"
        );
        let recast = votes
            .iter()
            .filter(|&&w| w & vote_word::RECAST != 0)
            .count();
        // Stragglers the pass left to coarser grids carry nothing but the mark.
        let left: usize = (0..points.len())
            .filter(|&i| points[i][0] > 10.0 && votes[i] == vote_word::RECAST)
            .count();
        assert_eq!(
            left > 0,
            name == "sphere and far stragglers",
            "{name}: {left} votes left to the host whole"
        );
        // Points with a neighbour (with a normal) at their place or two neighbours at one
        // place (written twice): f32 cannot tell that place from f64's near ones, so each
        // such point's votes are cast on the host, and of the others few.
        let twinned: Vec<bool> = (0..points.len())
            .map(|i| {
                let around = nearest.around(i);
                let at = |k: usize| (around[k] != NO_POINT).then(|| points[around[k] as usize]);
                let beside =
                    |k: usize| at(k) == Some(points[i]) && normals[around[k] as usize].is_some();
                normals[i].is_some()
                    && (0..ORIENT_NEIGHBOURS)
                        .any(|k| at(k).is_some() && (beside(k) || (0..k).any(|m| at(m) == at(k))))
            })
            .collect();
        let twinned_cast_here = (0..points.len())
            .filter(|&i| twinned[i] && votes[i] & vote_word::RECAST == 0)
            .count();
        assert_eq!(
            twinned_cast_here, 0,
            "{name}: points with twins voted on the GPU"
        );
        let others = twinned.iter().filter(|&&t| !t).count();
        let others_recast = (0..points.len())
            .filter(|&i| !twinned[i] && votes[i] & vote_word::RECAST != 0)
            .count();
        assert!(
            others_recast * 20 < others,
            "{name}: {others_recast} of {others} votes without twins left to the host"
        );
        assert_eq!(
            twinned.iter().any(|&t| t),
            name == "thin sheet, gaps and twins",
            "{name}: which case has twins"
        );
        let (mut cpu, mut gpu) = (normals.clone(), normals.clone());
        let by_cpu = repair_orientation(&points, &mut cpu, nearest, None);
        let by_gpu = repair_orientation(&points, &mut gpu, nearest, Some(&votes));
        assert_eq!(by_gpu, by_cpu, "{name}");
        let bits = |ns: &[Option<[f64; 3]>]| -> Vec<Option<[u64; 3]>> {
            ns.iter().map(|n| n.map(|v| v.map(f64::to_bits))).collect()
        };
        assert!(
            bits(&gpu) == bits(&cpu),
            "{name}: the repaired normals differ"
        );
        reversals += by_cpu.flipped_points;
        eprintln!(
            "{name}: {by_cpu:?}, {recast} of {} votes cast again",
            votes.len()
        );
    }
    assert!(
        reversals > 1000,
        "the cases must reverse normals ({reversals})"
    );
}
