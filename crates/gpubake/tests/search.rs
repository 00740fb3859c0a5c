#![allow(clippy::unwrap_used)]
//! The GPU's neighbour search against the CPU's k-d tree (the reference), on lavapipe here and
//! any adapter elsewhere: the same nearest points and the same lists, but where two distances
//! tie within f32's resolution of them (`docs/algorithm.md`, "Neighbour search").

use std::num::NonZero;
use std::sync::Arc;

use slosh_gpubake::GpuStages;
use slosh_mls::{
    KdSearch, ListRequest, NEIGHBOUR_CLUSTER, NeighbourLists, NeighbourSearch, Neighbours,
    cluster_lists, component_roots, morton_order,
};
use slosh_render::Gpu;
use slosh_scenes::{HardCases, Scene, SceneKind, SceneSpec};
use slosh_testkit::{adapter, gpu_or_skip};

/// Two squared distances within this relative difference tie: the GPU measures in f32 (from
/// positions split into two f32s each, so to about 2⁻²³ of the distance itself), the CPU in
/// f64.
const TIE: f64 = 1e-6;

fn d2(a: [f64; 3], b: [f64; 3]) -> f64 {
    (0..3).map(|k| (a[k] - b[k]).powi(2)).sum()
}

fn near(a: f64, b: f64) -> bool {
    (a - b).abs() <= TIE * a.abs().max(b.abs())
}

fn gpu_search() -> Option<GpuStages> {
    let gpu = gpu_or_skip(Gpu::new(adapter().as_deref()))?;
    Some(GpuStages::new(Arc::new(gpu)).expect("the search passes compile"))
}

/// The search's unions of the bake's clusters as CSR (offsets, ids), where it made them.
fn unions_csr(lists: &NeighbourLists) -> Option<(Vec<u32>, Vec<u32>)> {
    lists.run_unions.as_ref().map(|u| {
        assert_eq!(u.run(), NEIGHBOUR_CLUSTER as usize);
        let (mut start, mut ids) = (vec![0u32], Vec::new());
        for r in 0..u.len() {
            ids.extend_from_slice(u.union(r));
            start.push(ids.len() as u32);
        }
        (start, ids)
    })
}

/// Every list a search kept (each test here asks for them all).
fn every_list(lists: &NeighbourLists) -> &Neighbours {
    lists.lists.whole().expect("every list kept")
}

/// The GPU's cluster unions are the unions of its own lists (`slosh_mls::cluster_lists`), made
/// wherever the points came in Morton order, and only there.
fn check_unions(name: &str, gpu: &NeighbourLists, morton: bool) {
    match unions_csr(gpu) {
        Some(unions) => {
            assert!(morton, "{name}: unions of points not in Morton order");
            assert_eq!(
                unions,
                cluster_lists(every_list(gpu), NEIGHBOUR_CLUSTER as usize),
                "{name}: cluster unions"
            );
        }
        None => assert!(!morton, "{name}: no cluster unions"),
    }
}

/// A point set, its reaches, data normals (some opposing, some missing) and link distance.
struct Case {
    name: String,
    points: Vec<[f64; 3]>,
    reach: Vec<f64>,
    normals: Vec<Option<[f64; 3]>>,
    link2: f64,
    cap: usize,
    /// Distances tie in f32 where they do not in f64, so that the lists differ at many cuts
    /// (each difference still a tie).
    tied_in_f32: bool,
    /// The points come in Morton order (as a bake's do).
    morton: bool,
}

impl Case {
    /// The case's lists, with links within `link2` (the case's link distance, in a closure
    /// the request borrows).
    fn request<'a>(&'a self, link2: &'a (dyn Fn(usize) -> f64 + Sync)) -> ListRequest<'a> {
        ListRequest {
            reach: &self.reach,
            cap: self.cap,
            normals: Some(&self.normals),
            link_distance2: Some(link2),
            fits: None,
            near_reach_band: None,
        }
    }
}

fn scene_case(kind: SceneKind, points: usize, hard: HardCases, shuffle: bool) -> Case {
    let mut spec = SceneSpec::new(kind, points, 7);
    spec.hard = hard;
    let scene = Scene::new(spec).unwrap();
    let (mut points, mut normals) = scene.particles(0).surface_arrays();
    // The bake's order (then the search needs no sort), or a fixed shuffle of it.
    let order = morton_order(&points);
    points = order.iter().map(|&i| points[i as usize]).collect();
    normals = order.iter().map(|&i| normals[i as usize]).collect();
    let n = points.len();
    if shuffle {
        assert_ne!(n % 7919, 0);
        points = (0..n).map(|i| points[i * 7919 % n]).collect();
        normals = (0..n).map(|i| normals[i * 7919 % n]).collect();
    }
    // (A shuffle by 7919 is none where n divides 7918.)
    let morton = morton_order(&points)
        .iter()
        .enumerate()
        .all(|(i, &j)| i == j as usize);
    let spacing = scene.spacing();
    Case {
        name: format!("{}{}", kind.name(), if shuffle { ", shuffled" } else { "" }),
        reach: (0..n)
            // Some lists within the cap, most cut.
            .map(|i| spacing * (1.5 + (i % 5) as f64))
            .collect(),
        normals: (0..n)
            .map(|i| match i % 11 {
                0 => None,
                3 => Some(normals[i].map(|c| -c)),
                _ => Some(normals[i]),
            })
            .collect(),
        points,
        link2: (1.5 * spacing).powi(2),
        cap: 48,
        tied_in_f32: false,
        morton,
    }
}

/// A lattice: every distance tied many times, so the cap cuts through ties (broken by index),
/// with duplicates, and a pile of 150 copies of one point (more ties at the cut than the
/// shader sorts in private memory: its radix selection decides); shuffled.
fn lattice_case() -> Case {
    let mut points = slosh_scenes::tied_lattice(14, 14, 6, 40);
    let pile = points[77];
    points.extend(std::iter::repeat_n(pile, 150));
    let n = points.len();
    Case {
        name: "lattice".into(),
        reach: (0..n).map(|i| 2.2 * (1.0 + (i % 5) as f64 * 0.1)).collect(),
        normals: (0..n)
            .map(|i| match i % 11 {
                0 => None,
                3 => Some([0.0, 0.0, -1.0]),
                _ => Some([0.0, 0.0, 1.0]),
            })
            .collect(),
        points,
        link2: 1.1f64.powi(2),
        cap: 40,
        tied_in_f32: false,
        morton: false,
    }
}

/// Where the lists of point i differ, each point in only one of them ties: its distance with
/// the reach, with the CPU's cut (where the cap cut), or its normal is perpendicular.
fn differences_tie(case: &Case, i: usize, cpu: &NeighbourLists, gpu: &NeighbourLists) -> usize {
    let (a, b) = (every_list(cpu).of(i), every_list(gpu).of(i));
    let p = case.points[i];
    let cut2 = cpu.reach[i].powi(2);
    let mut differing = 0;
    for &j in a
        .iter()
        .filter(|j| b.binary_search(j).is_err())
        .chain(b.iter().filter(|j| a.binary_search(j).is_err()))
    {
        differing += 1;
        let d = d2(p, case.points[j as usize]);
        let perpendicular = match (case.normals[i], case.normals[j as usize]) {
            (Some(u), Some(v)) => (u[0] * v[0] + u[1] * v[1] + u[2] * v[2]).abs() < TIE,
            _ => false,
        };
        assert!(
            near(d, case.reach[i].powi(2)) || near(d, cut2) || perpendicular,
            "{}: point {i}'s lists differ at {j} (d² {d}, reach² {}, cut² {cut2})",
            case.name,
            case.reach[i].powi(2)
        );
    }
    differing
}

#[test]
fn gpu_neighbours_equal_the_k_d_trees_where_no_distances_tie() {
    let Some(search) = gpu_search() else { return };
    let mut cases: Vec<Case> = SceneKind::ALL
        .iter()
        .map(|&kind| scene_case(kind, 3000, HardCases::default(), false))
        .collect();
    let hard = HardCases {
        noise: 0.1,
        duplicates: 0.02,
        flip_normals: 0.05,
        isolated: true,
        density_jump: 10.0,
        ..HardCases::default()
    };
    cases.push(scene_case(SceneKind::Sphere, 3000, hard.clone(), false));
    // An isolated particle whose reach spans the whole set (h per point makes an isolated
    // particle's reach that wide): its cells are cut on coarser grids.
    let mut wide = scene_case(
        SceneKind::Sphere,
        12000,
        HardCases {
            isolated: true,
            ..HardCases::default()
        },
        false,
    );
    let (lo, hi) = slosh_mls::bounds(&wide.points);
    let diagonal = d2(lo, hi).sqrt();
    let centre: [f64; 3] = std::array::from_fn(|a| 0.5 * (lo[a] + hi[a]));
    let far = (0..wide.points.len())
        .max_by(|&a, &b| d2(wide.points[a], centre).total_cmp(&d2(wide.points[b], centre)))
        .unwrap();
    wide.reach[far] = 1.01 * diagonal;
    wide.name = "sphere, isolated, reach over all".into();
    cases.push(wide);
    cases.push(scene_case(SceneKind::Wave, 3000, hard, true));
    cases.push(lattice_case());
    // The lattice moved by a billionth of its spacing: distances that tie in f32 but not in
    // f64, so that a cut list's farthest member in f64 may be another than the one the cut
    // fell on (the pass marks those near the cut for the host to measure).
    let mut jittered = lattice_case();
    for (k, p) in jittered.points.iter_mut().enumerate() {
        for (a, c) in p.iter_mut().enumerate() {
            *c += 1e-9 * (((k * 7 + a * 3) % 11) as f64 - 5.0);
        }
    }
    jittered.name = "lattice, jittered by 1e-9".into();
    jittered.tied_in_f32 = true;
    cases.push(jittered);
    let (mut some_capped, mut some_uncapped) = (false, false);
    let mut most_components = 0;
    for case in &cases {
        let n = case.points.len();
        let link2 = |_: usize| case.link2;
        let request = case.request(&link2);
        let cpu_index = KdSearch.index(&case.points).unwrap();
        let gpu_index = search.index(&case.points).unwrap();

        // The nearest 9: the same distances in f64, the same points but where they tie.
        let count = NonZero::new(9).unwrap();
        let (cpu_near, gpu_near) = (
            cpu_index.nearest(count).unwrap(),
            gpu_index.nearest(count).unwrap(),
        );
        assert_eq!(gpu_near.len(), n * 9, "{}", case.name);
        for i in 0..n {
            let dist = |ids: &[u32], slot: usize| {
                d2(case.points[i], case.points[ids[i * 9 + slot] as usize])
            };
            for slot in 0..9 {
                let (c, g) = (dist(&cpu_near, slot), dist(&gpu_near, slot));
                assert!(
                    near(c, g) || c.max(g) < 1e-300,
                    "{}: point {i}'s nearest {slot}: d² {c} (CPU) against {g} (GPU)",
                    case.name
                );
            }
        }

        let (cpu, gpu) = (
            cpu_index.lists(request).unwrap(),
            gpu_index.lists(request).unwrap(),
        );
        check_unions(&case.name, &gpu, case.morton);
        let entries: usize = (0..n).map(|i| every_list(&cpu).of(i).len()).sum();
        let differing: usize = (0..n).map(|i| differences_tie(case, i, &cpu, &gpu)).sum();
        // Ties within 1e-6 are rare in generated data (exact ties, as in the lattice, are
        // broken alike).
        assert!(
            differing * 1000 <= entries || case.tied_in_f32,
            "{}: {differing} of {entries} entries differ",
            case.name
        );
        assert!(entries > n * 5, "{}: lists too short to test", case.name);
        for i in 0..n {
            // The same reach where the lists agree (a cut list's, its farthest point's f64
            // distance rounded up alike); one that holds every member in f64 regardless.
            let (c, g) = (cpu.reach[i], gpu.reach[i]);
            // (Where distances tie in f32 only, the point each cut fell on may differ, and
            // with it the reach, by the tie.)
            if every_list(&cpu).of(i) == every_list(&gpu).of(i) && !case.tied_in_f32 {
                assert_eq!(g, c, "{}: point {i}'s reach", case.name);
            }
            for &j in every_list(&gpu).of(i) {
                assert!(d2(case.points[i], case.points[j as usize]) <= g * g);
            }
        }
        some_capped |= cpu.capped > n / 10;
        assert!(
            cpu.capped.abs_diff(gpu.capped) <= differing,
            "{}",
            case.name
        );
        // Links: the same pairs, but where a list differs or a pair ties with the link
        // distance.
        let links = |l: &NeighbourLists| {
            let mut all: Vec<(u32, u32)> = l.links.concat();
            all.sort_unstable();
            all.dedup();
            all
        };
        let (cpu_links, gpu_links) = (links(&cpu), links(&gpu));
        assert!(!cpu_links.is_empty(), "{}: no links to test", case.name);
        match &gpu.components {
            // Joined on the GPU (points in Morton order): the components the CPU's links make.
            Some(roots) => {
                assert!(case.morton && gpu_links.is_empty(), "{}", case.name);
                assert_eq!(
                    roots,
                    &component_roots(n, &cpu.links),
                    "{}: spray components",
                    case.name
                );
                let mut distinct = roots.clone();
                distinct.sort_unstable();
                distinct.dedup();
                most_components = most_components.max(distinct.len());
            }
            None => assert!(!case.morton, "{}: no components", case.name),
        }
        for (a, b) in [(&cpu_links, &gpu_links), (&gpu_links, &cpu_links)] {
            if gpu.components.is_some() {
                break;
            }
            for &(i, j) in a.iter().filter(|l| b.binary_search(l).is_err()) {
                let (i, j) = (i as usize, j as usize);
                let d = d2(case.points[i], case.points[j]);
                let lists_differ = every_list(&cpu).of(i) != every_list(&gpu).of(i);
                assert!(
                    lists_differ || near(d, case.link2),
                    "{}: link ({i}, {j}) found by one search only (d² {d})",
                    case.name
                );
            }
        }
        eprintln!(
            "{}: {n} points, {entries} entries, {differing} differ at ties, {} capped",
            case.name, cpu.capped
        );
        some_uncapped |= cpu.capped < n / 2;
    }
    assert!(
        some_capped && some_uncapped,
        "the cap must cut some lists, not all"
    );
    assert!(
        most_components > 10,
        "some case must have many components ({most_components} at most)"
    );
}

#[test]
fn the_search_params_mirror_the_wgsl_layout() {
    use slosh_gpubake::{SearchParams, lists_source, nearest_source, orient_votes_source};
    use slosh_testkit::check_layout;
    for (name, source) in [
        ("nearest", nearest_source()),
        ("lists", lists_source()),
        ("orientation votes", orient_votes_source()),
    ] {
        let module = slosh_testkit::wgsl::validate(name, &source);
        check_layout!(
            &module,
            "SearchParams",
            SearchParams,
            [
                lo,
                count,
                first,
                side,
                wanted,
                flags,
                out_base,
                row_threads,
                margin,
                shells,
                band,
                _pad1,
                _pad2
            ]
        );
    }
}

#[test]
fn the_fit_settings_mirror_the_wgsl_layout() {
    use slosh_gpubake::{FitSettings, fits_source};
    use slosh_testkit::check_layout;
    let module = slosh_testkit::wgsl::validate("initial fits", &fits_source());
    check_layout!(
        &module,
        "Settings",
        FitSettings,
        [
            count,
            first,
            row_threads,
            list_base,
            has_normals,
            normals_mode,
            _pad0,
            _pad1
        ]
    );
}

#[test]
fn the_component_params_mirror_the_wgsl_layout() {
    use slosh_gpubake::{ComponentParams, components_source};
    use slosh_testkit::check_layout;
    let module = slosh_testkit::wgsl::validate("spray components", &components_source());
    check_layout!(
        &module,
        "ComponentParams",
        ComponentParams,
        [first, count, list_base, row_threads]
    );
}

#[test]
fn the_union_params_mirror_the_wgsl_layout() {
    use slosh_gpubake::{UNION_SPAN_WORDS, UnionParams, unions_source};
    use slosh_testkit::check_layout;
    let module = slosh_testkit::wgsl::validate("cluster unions", &unions_source(UNION_SPAN_WORDS));
    check_layout!(
        &module,
        "UnionParams",
        UnionParams,
        [
            first_cluster,
            clusters,
            points,
            size,
            list_base,
            row_groups,
            write,
            _pad0
        ]
    );
}

/// Outputs larger than a binding go in batches: with bindings of 64 KiB, a 4000-point sphere's
/// nearest points, lists and fits take many dispatches each, and give what one dispatch gives
/// (lists equal to the k-d tree's; fits equal to an unlimited device's). A set whose positions
/// exceed one binding is refused with the way out, not a panic.
#[test]
fn batches_of_bounded_output_give_what_one_dispatch_gives() {
    let Some(mut gpu) = gpu_or_skip(Gpu::new(adapter().as_deref())) else {
        return;
    };
    gpu.limit_bindings(1 << 16);
    let small = GpuStages::new(Arc::new(gpu)).unwrap();
    let whole = gpu_search().unwrap();
    let scene = Scene::new(SceneSpec::new(SceneKind::Sphere, 4000, 11)).unwrap();
    let (points, normals) = scene.particles(0).surface_arrays();
    let order = morton_order(&points);
    let points: Vec<[f64; 3]> = order.iter().map(|&i| points[i as usize]).collect();
    let normals: Vec<Option<[f64; 3]>> = order.iter().map(|&i| Some(normals[i as usize])).collect();
    let n = points.len();
    assert!(n * 16 <= 1 << 16, "the positions must fit one binding here");
    let reach = vec![4.0 * scene.spacing(); n];
    let h = 1.5 * scene.spacing();
    let ball_h = |_: usize| h;
    let link2 = |_: usize| (1.5 * scene.spacing()).powi(2);
    let request = ListRequest {
        reach: &reach,
        cap: 40,
        normals: Some(&normals),
        link_distance2: Some(&link2),
        fits: Some(slosh_mls::FitRequest {
            h: &ball_h,
            degree: 2,
            normals: slosh_mls::NormalsMode::Mean,
        }),
        near_reach_band: None,
    };
    let cpu = KdSearch.index(&points).unwrap().lists(request).unwrap();
    let before = whole.gpu_seconds();
    let (small_index, whole_index) = (small.index(&points).unwrap(), whole.index(&points).unwrap());
    let (batched, once) = (
        small_index.lists(request).unwrap(),
        whole_index.lists(request).unwrap(),
    );
    let entries: usize = (0..n).map(|i| every_list(&cpu).of(i).len()).sum();
    assert!(
        entries * 4 > 4 << 16,
        "the lists must need several batches ({entries} ids)"
    );
    for i in 0..n {
        assert_eq!(
            every_list(&batched).of(i),
            every_list(&cpu).of(i),
            "point {i}"
        );
    }
    check_unions("batched", &batched, true);
    assert_eq!(
        batched.components,
        Some(component_roots(n, &cpu.links)),
        "spray components over batches"
    );
    assert_eq!(unions_csr(&batched), unions_csr(&once));
    assert_eq!(batched.reach, cpu.reach);
    assert_eq!(batched.fits, once.fits);
    // The same points shuffled (the path for points not in Morton order): each point's fit
    // as before, but for the order its neighbours are summed in.
    assert_ne!(n % 7919, 0);
    let shuffle = |i: usize| i * 7919 % n;
    let shuffled: Vec<[f64; 3]> = (0..n).map(|i| points[shuffle(i)]).collect();
    let shuffled_normals: Vec<Option<[f64; 3]>> = (0..n).map(|i| normals[shuffle(i)]).collect();
    let shuffled_reach: Vec<f64> = (0..n).map(|i| reach[shuffle(i)]).collect();
    let shuffled_fits = whole
        .index(&shuffled)
        .unwrap()
        .lists(ListRequest {
            reach: &shuffled_reach,
            normals: Some(&shuffled_normals),
            ..request
        })
        .unwrap()
        .fits
        .unwrap();
    let fits = once.fits.as_ref().unwrap();
    for (i, f) in shuffled_fits.iter().enumerate() {
        let (a, b) = (f.unwrap(), fits[shuffle(i)].unwrap());
        let apart = (0..3)
            .map(|k| (a.normal[k] - b.normal[k]).abs())
            .fold(0.0, f32::max);
        assert!(
            apart < 1e-5,
            "point {i}: normals {:?} and {:?}",
            a.normal,
            b.normal
        );
        assert_eq!(a.poly.degree, b.poly.degree, "point {i}");
    }
    // The passes' GPU time is counted, where the device writes timestamps.
    if let (Some(a), Some(b)) = (before, whole.gpu_seconds()) {
        assert!(b > a, "no GPU time counted ({a} then {b} s)");
    }
    assert!(batched.fits.as_ref().unwrap().iter().all(Option::is_some));
    let count = NonZero::new(9).unwrap();
    assert_eq!(
        small_index.nearest(count).unwrap(),
        whole_index.nearest(count).unwrap()
    );
    // Twice the points: their positions no longer fit one binding.
    let doubled: Vec<[f64; 3]> = points
        .iter()
        .chain(points.iter())
        .map(|p| [p[0] * 1.5, p[1], p[2]])
        .collect();
    let refused = small.index(&doubled).err().expect("refused").to_string();
    assert!(refused.contains("--device cpu"), "{refused}");
}

/// Where the caller keeps of each list only its members near the reach (a bake:
/// `ListRequest::near_reach_band`), no list comes back: each point keeps every member of its
/// list within the band of the reach it records (the cut's distance, where the cap cut it),
/// and only members of its list; the reaches, unions, spray components and fits are those of
/// the same search keeping every list. With a band wider than every list the members are the
/// lists themselves (a batch's room for them overflows, and its lists are read back instead).
/// Over many batches too (bindings of 64 KiB), and with duplicates and noise.
#[test]
fn lists_kept_near_their_reach_measure_the_same_reaches() {
    let Some(mut gpu) = gpu_or_skip(Gpu::new(adapter().as_deref())) else {
        return;
    };
    gpu.limit_bindings(1 << 16);
    let small = GpuStages::new(Arc::new(gpu)).unwrap();
    let full = gpu_search().unwrap();
    let hard = HardCases {
        noise: 0.1,
        duplicates: 0.02,
        flip_normals: 0.05,
        ..HardCases::default()
    };
    for case in [
        scene_case(SceneKind::Sphere, 3000, HardCases::default(), false),
        scene_case(SceneKind::Wave, 3000, hard, false),
    ] {
        assert!(case.morton, "{}", case.name);
        let link2 = |_: usize| case.link2;
        let h = |_: usize| case.link2.sqrt();
        let every_request = ListRequest {
            fits: Some(slosh_mls::FitRequest {
                h: &h,
                degree: 2,
                normals: slosh_mls::NormalsMode::Mean,
            }),
            ..case.request(&link2)
        };
        let median_reach = {
            let mut r = case.reach.clone();
            r.sort_by(f64::total_cmp);
            r[r.len() / 2]
        };
        for (search, name) in [(&small, "64 KiB bindings"), (&full, "one batch")] {
            let index = search.index(&case.points).unwrap();
            let every = index.lists(every_request).unwrap();
            let lists = every_list(&every);
            let n = case.points.len();
            for band in [0.002 * median_reach, 1e30] {
                let near = index
                    .lists(ListRequest {
                        near_reach_band: Some(band),
                        ..every_request
                    })
                    .unwrap();
                let what = format!("{}, {name}, band {band:e}", case.name);
                let slosh_mls::KeptLists::NearReach { members, .. } = &near.lists else {
                    panic!("{what}: every list kept");
                };
                assert_eq!(near.reach, every.reach, "{what}: reaches");
                assert_eq!(unions_csr(&near), unions_csr(&every), "{what}: unions");
                assert!(near.run_unions.is_some(), "{what}: no unions");
                assert_eq!(near.components, every.components, "{what}: components");
                assert_eq!(near.fits, every.fits, "{what}: fits");
                assert_eq!(near.capped, every.capped, "{what}: capped");
                let mut kept = 0;
                for i in 0..n {
                    let (list, mine) = (lists.of(i), members.of(i));
                    if band > 1.0 {
                        assert_eq!(mine, list, "{what}: point {i}");
                        continue;
                    }
                    assert!(mine.is_sorted(), "{what}: point {i}: {mine:?}");
                    for j in mine {
                        assert!(
                            list.binary_search(j).is_ok(),
                            "{what}: {i}: {j} not a member"
                        );
                    }
                    // Clear of the band's edge: f32 decides there.
                    let inner = near.reach[i] - 0.5 * band;
                    for &j in list {
                        if d2(case.points[i], case.points[j as usize]).sqrt() >= inner {
                            assert!(
                                mine.contains(&j),
                                "{what}: {i}: {j} near the reach, not kept"
                            );
                        }
                    }
                    kept += mine.len();
                }
                if band < 1.0 {
                    assert!(
                        kept > 0 && kept * 4 < lists.total(),
                        "{what}: {kept} of {} members kept",
                        lists.total()
                    );
                }
            }
        }
    }
}

/// How the shader takes each cluster union of `lists` with a bitset of `words` words: the
/// clusters over one span, over the bitset's split halves, and left to the host (an id
/// between the halves).
fn union_kinds(lists: &NeighbourLists, words: u32) -> [usize; 3] {
    let (start, ids) = cluster_lists(every_list(lists), NEIGHBOUR_CLUSTER as usize);
    let mut kinds = [0; 3];
    for w in start.windows(2) {
        let union = &ids[w[0] as usize..w[1] as usize];
        let (Some(&lo), Some(&hi)) = (union.first(), union.last()) else {
            continue;
        };
        let base = lo & !31;
        let half = words / 2;
        let high_base = (hi & !31).saturating_sub((half - 1) * 32);
        kinds[if (hi - base) / 32 < words {
            0
        } else if union
            .iter()
            .all(|&id| id < base + half * 32 || id >= high_base)
        {
            1
        } else {
            2
        }] += 1;
    }
    kinds
}

/// Clusters whose ids span more than the shader's bitset are taken by its halves, or where an
/// id falls between them, merged on the host in their place among the GPU's: with a bitset
/// narrowed so that a 3000-point sphere has clusters of all three kinds, the unions are those
/// of the lists.
#[test]
fn clusters_wider_than_the_bitset_are_merged_in_their_place() {
    let Some(mut narrow) = gpu_search() else {
        return;
    };
    let case = scene_case(SceneKind::Sphere, 3000, HardCases::default(), false);
    assert!(case.morton);
    let link2 = |_: usize| case.link2;
    let request = case.request(&link2);
    let cpu = KdSearch
        .index(&case.points)
        .unwrap()
        .lists(request)
        .unwrap();
    let words = (2..64u32)
        .map(|w| 2 * w)
        .find(|&w| union_kinds(&cpu, w).iter().all(|&k| k > 0))
        .expect("a bitset width with clusters of all three kinds");
    narrow.narrow_union_span(words).unwrap();
    let lists = narrow.index(&case.points).unwrap().lists(request).unwrap();
    check_unions("a narrow bitset", &lists, true);
    let kinds = union_kinds(&lists, words);
    assert!(
        kinds.iter().all(|&k| k > 0),
        "one span, split, host: {kinds:?} with {words} words"
    );
}
