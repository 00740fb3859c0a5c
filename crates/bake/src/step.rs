//! One step in, one cache out: select → recentre and scale → Morton order → kNN, radii,
//! neighbour lists, initial fits, droplets (`slosh_mls::SurfaceParts::build`) → BVH → sections.

use rayon::prelude::*;
use slosh_cache::{
    BallBits, BallState, CubicWords, Element, Encoding, FieldRange, GpuBall, GpuPoint, GpuSphere,
    Header, MAX_SPHERES, MlsSettings, SectionInput, Source, StepStats, Transform, candidates,
    exact_half, names, octahedral, pack_h, stored_radius,
};
use slosh_ensight::FieldValues;
use slosh_mls::{
    BallFit, BesideFits, FitStatus, NEIGHBOUR_CLUSTER, Sphere, StageClock, SurfaceError,
    SurfaceParts,
};

use crate::device_turns::{TurnOrder, on_device};
use crate::params::{BakeParams, SurfaceSelect};
use crate::reach::stored_reach;
use crate::select::{StepInput, estimate_surface_normals_with};
use crate::stages::Stages;
use crate::withdrawable::{Withdrawable, Withdrawn};

#[derive(Debug, thiserror::Error)]
pub enum BakeError {
    #[error("step {step}: {problem}")]
    Input { step: usize, problem: String },
    #[error("step {step}: {source}")]
    Surface {
        step: usize,
        #[source]
        source: SurfaceError,
    },
    #[error("step {step}: the BVH: {problem}")]
    Tree { step: usize, problem: String },
    /// The caller withdrew the bake ([`bake_step_unless_withdrawn`]).
    #[error("step {step}: withdrawn by its caller")]
    Withdrawn { step: usize },
}

impl BakeError {
    /// What went wrong, without the step number (for reports that name the step already).
    pub fn problem(&self) -> String {
        match self {
            BakeError::Input { problem, .. } => problem.clone(),
            BakeError::Surface { source, .. } => source.to_string(),
            BakeError::Tree { problem, .. } => format!("the BVH: {problem}"),
            BakeError::Withdrawn { .. } => "withdrawn by its caller".into(),
        }
    }
}

/// A baked step: the header (sections still empty) and the sections to write.
#[derive(Debug)]
pub struct BakedStep {
    pub header: Header,
    pub sections: Vec<SectionInput>,
}

/// The BVH's items: every ball that `is_candidate` keeps (in index order), with the radius
/// its point stores (rounded up, [`stored_radius`]), then the droplet spheres (ids after the
/// balls').
fn bvh_items(
    is_candidate: impl Fn(usize) -> bool + Sync,
    centre: impl Fn(usize) -> [f64; 3] + Sync,
    radii: &[f64],
    spheres: &[Sphere<f64>],
) -> Vec<(u32, [f64; 3], f64)> {
    let n = radii.len();
    let mut items: Vec<(u32, [f64; 3], f64)> = (0..n)
        .into_par_iter()
        .filter(|&i| is_candidate(i))
        .map(|i| {
            let stored = stored_radius(radii[i]).map_or(radii[i], f64::from);
            (i as u32, centre(i), stored)
        })
        .collect();
    for (d, s) in spheres.iter().enumerate() {
        items.push((
            (n + d) as u32,
            [s.centre.x, s.centre.y, s.centre.z],
            s.radius,
        ));
    }
    items
}

/// Structs shuffled by their own size: a field's sign and exponent bytes side by side, a
/// padding or unused field one run of zeros (`docs/cache-format.md`).
fn by_element(element: Element) -> Encoding {
    Encoding::shuffled_elements(element.size())
}

/// The ranks in which sections are stored raw while the step stays within its budget
/// (`slosh_cache::RAW_BUDGET_BYTES_PER_POINT`, `docs/cache-format.md`): the BVH nodes, which
/// the host half reads on every load, then the bulk of what a step holds on the GPU that
/// compresses least (1.3–2.2×), then the balls. A raw section loads as a checksummed copy
/// from the map or a read in place; decoding was what bounded scrubbing from the page cache.
/// The balls compress 4× and more, but they are the largest section and the slowest to
/// decode (zstd and a 16-byte unshuffle: about three quarters of a 1M step's decoding), so
/// they go raw before the candidate runs where the budget holds both only compressed.
mod raw_rank {
    pub const BVH_NODES: u8 = 0;
    pub const POINTS: u8 = 1;
    pub const NORMALS: u8 = 2;
    pub const BALLS: u8 = 3;
    pub const CLUSTER_NEIGHBOURS: u8 = 4;
}

/// A step's sections in the GPU layouts, but for the BVH's, its field sections, each ball's
/// state as stored, and where the time went ("sections: …" laps).
type Sections = (
    Vec<SectionInput>,
    Vec<SectionInput>,
    Vec<BallState>,
    Vec<(&'static str, f64)>,
);

/// A step's sections in the GPU layouts, but for the BVH's, and its field sections.
fn gpu_sections(
    surface: &SurfaceParts<f64>,
    input: &StepInput,
    source_index: &[u32],
    params: &BakeParams,
) -> Result<Sections, BakeError> {
    let mut parts = StageClock::start();
    let n = surface.len();
    let input_err = |problem: String| BakeError::Input {
        step: input.index,
        problem,
    };
    let f32x3 = |v: slosh_mls::V3<f64>| [v.x as f32, v.y as f32, v.z as f32];
    // The compact layout (`docs/cache-format.md`, "Balls"): a fit whose coefficients a half
    // float cannot hold is stored unfitted, and the BVH is rebuilt without it.
    if surface.spheres.len() as u64 > u64::from(MAX_SPHERES) {
        return Err(input_err(format!(
            "{} droplets; a cache holds at most {MAX_SPHERES}",
            surface.spheres.len()
        )));
    }
    // Straight into the three arrays: an array of all three between was 128 MB of fresh
    // memory at 4M points.
    let (balls, (bits, cubic)): (Vec<GpuBall>, (Vec<BallBits>, Vec<CubicWords>)) = (0..n)
        .into_par_iter()
        .map(|i| {
            let b = &surface.balls[i];
            let (kind, sphere) = match surface.ball_fits[i] {
                BallFit::Fitted(FitStatus::Full) => (BallState::Full, 0),
                BallFit::Fitted(FitStatus::Degraded { .. }) => (BallState::Degraded, 0),
                BallFit::Fitted(FitStatus::Failed) | BallFit::None => (BallState::Unfitted, 0),
                BallFit::Droplet(d) => (BallState::Droplet, d),
            };
            let normal = [b.normal.x, b.normal.y, b.normal.z];
            let coeffs = b.poly.c.map(|c| c as f32);
            let (ball, bits, cubic) = GpuBall::new(normal, coeffs, b.poly.degree, kind, sphere)
                .unwrap_or_else(|| {
                    let (ball, bits) = GpuBall::unfitted();
                    (ball, bits, [0; 2])
                });
            (ball, (bits, cubic))
        })
        .unzip();
    // h is at half precision already (`slosh_mls::half_precision`), so exact in f32: per
    // point in `ball_h`, or the header's one value, which every ball then has.
    let per_point_h = if params.mls.per_point_h {
        let h: Vec<f32> = surface.balls.iter().map(|b| b.h as f32).collect();
        Some(pack_h(&h).ok_or_else(|| input_err("a ball's h is not a half float".into()))?)
    } else {
        if let Some(i) = surface.balls.iter().position(|b| b.h != surface.h) {
            return Err(input_err(format!(
                "ball {i} has h = {} where the step's is {}",
                surface.balls[i].h, surface.h
            )));
        }
        // A step without particles has no h.
        if n > 0 && exact_half(surface.h as f32).is_none() {
            return Err(input_err(format!("h = {} is not a half float", surface.h)));
        }
        None
    };
    parts.lap("sections: balls");
    // Neighbour lists shared per cluster of consecutive (Morton-ordered) points; a reach
    // rounded up to f32 keeps every stored list within its distance filter.
    let (cluster_start, cluster_ids) =
        surface
            .cluster_lists(NEIGHBOUR_CLUSTER as usize)
            .map_err(|source| BakeError::Surface {
                step: input.index,
                source,
            })?;
    let (cluster_base, cluster_words) =
        candidates::pack(&cluster_start, &cluster_ids, NEIGHBOUR_CLUSTER).ok_or_else(|| {
            input_err(format!(
                "{} cluster candidates exceed the cache's 31-bit word offsets",
                cluster_ids.len()
            ))
        })?;
    parts.lap("sections: cluster lists");
    // The reach as f32, raised where needed so that the expansion, which measures distances
    // in f32 on the stored positions, keeps every neighbour the f64 lists hold; the point
    // stores the half float at or above it.
    let stored: Vec<slosh_mls::V3<f32>> = (0..n)
        .into_par_iter()
        .map(|i| {
            let [x, y, z] = f32x3(surface.points[i]);
            slosh_mls::V3::new(x, y, z)
        })
        .collect();
    let points: Vec<GpuPoint> = (0..n)
        .into_par_iter()
        .map(|i| {
            let r = stored_reach(surface.reach[i], || {
                surface
                    .neighbours
                    .farthest_of(i)
                    .iter()
                    .map(|&j| (stored[j as usize] - stored[i]).length_squared())
                    .fold(0.0f32, f32::max)
            });
            let p = stored[i];
            GpuPoint::new([p.x, p.y, p.z], surface.radii[i], f64::from(r)).ok_or_else(|| {
                input_err(format!(
                    "point {i}: radius {} or reach {r} (local units) is not a half float",
                    surface.radii[i]
                ))
            })
        })
        .collect::<Result<_, _>>()?;
    parts.lap("sections: points");
    let spheres: Vec<GpuSphere> = surface
        .spheres
        .iter()
        .map(|s| GpuSphere {
            centre: f32x3(s.centre),
            radius: s.radius as f32,
        })
        .collect();
    let mut sections = vec![
        SectionInput::new(
            names::POINTS,
            Element::Point,
            &points,
            by_element(Element::Point),
        )
        .raw_within_budget(raw_rank::POINTS),
        SectionInput::new(
            names::BALLS,
            Element::Ball,
            &balls,
            by_element(Element::Ball),
        )
        .raw_within_budget(raw_rank::BALLS),
        SectionInput::new(
            names::BALL_STATES,
            Element::U32,
            &BallBits::pack(&bits),
            Encoding::Shuffle4Zstd,
        ),
        SectionInput::new(
            names::CLUSTER_START,
            Element::U32,
            &cluster_start,
            Encoding::Delta4Shuffle4Zstd,
        ),
        SectionInput::new(
            names::CLUSTER_BASE,
            Element::U32,
            &cluster_base,
            Encoding::Delta4Shuffle4Zstd,
        ),
        SectionInput::new(
            names::CLUSTER_NEIGHBOURS,
            Element::U32,
            &cluster_words,
            Encoding::Shuffle4Zstd,
        )
        .raw_within_budget(raw_rank::CLUSTER_NEIGHBOURS),
        SectionInput::new(
            names::SPHERES,
            Element::Sphere,
            &spheres,
            by_element(Element::Sphere),
        ),
    ];
    if let Some(words) = &per_point_h {
        sections.push(SectionInput::new(
            names::BALL_H,
            Element::U32,
            words,
            Encoding::Shuffle4Zstd,
        ));
    }
    // A cubic's other four coefficients, where the bake fits cubics.
    if params.mls.degree == 3 {
        sections.push(SectionInput::new(
            names::BALL_CUBIC,
            Element::U32,
            bytemuck::cast_slice::<CubicWords, u32>(&cubic),
            Encoding::Shuffle4Zstd,
        ));
    }
    if let Some(ns) = &surface.normals {
        let normals: Vec<u32> = ns
            .par_iter()
            .map(|v| octahedral::encode([v.x, v.y, v.z]))
            .collect();
        sections.insert(
            1,
            SectionInput::new(
                names::NORMALS,
                Element::Octahedral,
                &normals,
                Encoding::Shuffle4Zstd,
            )
            .raw_within_budget(raw_rank::NORMALS),
        );
    }
    let mut fields = Vec::with_capacity(params.fields.len());
    for name in &params.fields {
        let values = input
            .fields
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v)
            .ok_or_else(|| input_err(format!("field '{name}' was not read")))?;
        let section = format!("{}{name}", names::FIELD_PREFIX);
        fields.push(match values {
            FieldValues::Scalar(v) => SectionInput::new(
                &section,
                Element::F32,
                &permute(v, source_index),
                Encoding::Shuffle4Zstd,
            ),
            FieldValues::Vector(v) => {
                let vec4: Vec<[f32; 4]> = source_index
                    .par_iter()
                    .map(|&i| {
                        let x = v[i as usize];
                        [x[0], x[1], x[2], 0.0]
                    })
                    .collect();
                SectionInput::new(&section, Element::Vec4, &vec4, by_element(Element::Vec4))
            }
        });
    }
    let kinds = bits.iter().map(|b| b.kind()).collect();
    parts.lap("sections: arrays");
    Ok((sections, fields, kinds, parts.laps))
}

fn permute<T: Copy + Send + Sync>(values: &[T], order: &[u32]) -> Vec<T> {
    order.par_iter().map(|&i| values[i as usize]).collect()
}

pub fn bake_step(input: &StepInput, params: &BakeParams) -> Result<BakedStep, BakeError> {
    bake_step_with(input, params, &Stages::cpu())
}

/// [`bake_step`], its parallel stages run by `stages` (the GPU's, say).
pub fn bake_step_with(
    input: &StepInput,
    params: &BakeParams,
    stages: &Stages,
) -> Result<BakedStep, BakeError> {
    bake_step_parts_with(input, params, stages).map(|(baked, _)| baked)
}

/// [`bake_step`] with the parts the bake computed, in f64, before the cache's layout stored
/// them (in the cache's point order and local coordinates): what `slosh bench precision`
/// compares the stored step with.
pub fn bake_step_parts(
    input: &StepInput,
    params: &BakeParams,
) -> Result<(BakedStep, SurfaceParts<f64>), BakeError> {
    bake_step_parts_with(input, params, &Stages::cpu())
}

/// [`bake_step_parts`], its parallel stages run by `stages`.
pub fn bake_step_parts_with(
    input: &StepInput,
    params: &BakeParams,
    stages: &Stages,
) -> Result<(BakedStep, SurfaceParts<f64>), BakeError> {
    bake_parts(
        input,
        params,
        stages,
        &|| false,
        TurnOrder::waited(input.index),
    )
}

/// [`bake_step_with`], given up with [`BakeError::Withdrawn`] once `withdrawn` says so: it
/// is asked between stages and before each neighbour search. Where the stages share a
/// device, the step's passes wait for their turns there at `order`.
pub fn bake_step_unless_withdrawn(
    input: &StepInput,
    params: &BakeParams,
    stages: &Stages,
    withdrawn: Withdrawn<'_>,
    order: TurnOrder,
) -> Result<BakedStep, BakeError> {
    bake_parts(input, params, stages, withdrawn, order).map(|(baked, _)| baked)
}

fn bake_parts(
    input: &StepInput,
    params: &BakeParams,
    stages: &Stages,
    withdrawn: Withdrawn<'_>,
    order: TurnOrder,
) -> Result<(BakedStep, SurfaceParts<f64>), BakeError> {
    let search = Withdrawable {
        inner: stages.search.as_ref(),
        withdrawn,
        turns: stages.turns.as_ref(),
        order,
    };
    // The tree's passes take the step's turns on the device as the searches do.
    let build_tree = |leaves: &[slosh_cache::BvhNode]| {
        on_device(stages.turns.as_ref(), order, || stages.tree.build(leaves))
    };
    let mut clock = StageClock::start();
    let step = input.index;
    let input_err = |problem: String| BakeError::Input { step, problem };
    let n_in = input.positions.len();
    for (name, values) in &input.fields {
        let len = match values {
            FieldValues::Scalar(v) => v.len(),
            FieldValues::Vector(v) => v.len(),
        };
        if len != n_in {
            return Err(input_err(format!(
                "field '{name}' has {len} values for {n_in} particles"
            )));
        }
    }

    if n_in == 0 {
        return Ok((
            empty_step(input, params, StepStats::default())?,
            SurfaceParts::empty(&params.mls),
        ));
    }

    // 1. Select: finite positions not far beyond the rest, then the surface.
    // In parallel: at 4M points a serial pass is tens of milliseconds that every other
    // thread waits for.
    let finite: Vec<u32> = (0..n_in as u32)
        .into_par_iter()
        .filter(|&i| input.positions[i as usize].iter().all(|c| c.is_finite()))
        .collect();
    let dropped_non_finite = n_in - finite.len();
    if finite.is_empty() {
        return Err(input_err(format!(
            "none of the {n_in} particles has finite coordinates: nothing to bake"
        )));
    }
    // Before the estimate too, whose own frame a sentinel would set as well.
    let finite_count = finite.len();
    // From here on, `finite` means finite and not far beyond the rest.
    let finite = crate::far::without_far(&input.positions, finite);
    let dropped_far = finite_count - finite.len();
    // The surface estimate and its normals, from all finite particles not far beyond the rest,
    // where the selection or the normals ask for it (else empty).
    let estimated: Vec<(bool, [f64; 3])> = if matches!(params.surface, SurfaceSelect::Estimate)
        || matches!(params.normals, crate::params::NormalSource::Estimate)
    {
        estimate_surface_normals_with(&permute(&input.positions, &finite), &search)
            .map_err(|source| BakeError::Surface { step, source })?
    } else {
        Vec::new()
    };
    let surface_of_finite: Vec<bool> = match &params.surface {
        SurfaceSelect::All => vec![true; finite.len()],
        SurfaceSelect::Variable(name) => {
            let flags = input
                .surface_flags
                .as_ref()
                .ok_or_else(|| input_err(format!("no surface flags read from '{name}'")))?;
            if flags.len() != n_in {
                return Err(input_err(format!(
                    "surface variable '{name}' has {} values for {n_in} particles",
                    flags.len()
                )));
            }
            finite.par_iter().map(|&i| flags[i as usize]).collect()
        }
        SurfaceSelect::Estimate => estimated.iter().map(|e| e.0).collect(),
    };
    let kept: Vec<u32> = finite
        .par_iter()
        .zip(&surface_of_finite)
        .filter_map(|(&i, &s)| s.then_some(i))
        .collect();
    let dropped_interior = finite.len() - kept.len();
    if kept.len() < 2 {
        // One particle (an injection's first, or the only one the selection keeps) has no
        // spacing to size a sphere or a surface by: an empty step that says what it dropped.
        let stats = StepStats {
            input_points: n_in as u64,
            dropped_non_finite: dropped_non_finite as u64,
            dropped_far: dropped_far as u64,
            dropped_interior: dropped_interior as u64,
            dropped_too_few: kept.len() as u64,
            ..StepStats::default()
        };
        return Ok((
            empty_step(input, params, stats)?,
            SurfaceParts::empty(&params.mls),
        ));
    }
    clock.lap("select");

    // 2. Recentre and scale: local = (world − origin) / scale, coordinates within [−1, 1].
    let world = permute(&input.positions, &kept);
    let (lo, hi) = slosh_mls::bounds_in_parallel(&world);
    let origin: [f64; 3] = std::array::from_fn(|a| 0.5 * (lo[a] + hi[a]));
    let half = (0..3).map(|a| 0.5 * (hi[a] - lo[a])).fold(0.0, f64::max);
    if half == 0.0 {
        return Err(input_err(format!(
            "all {} particles left after selection coincide, at ({}, {}, {}): coincident \
             points define no surface",
            world.len(),
            lo[0],
            lo[1],
            lo[2]
        )));
    }
    let scale = half;
    let transform = Transform { origin, scale };
    let local: Vec<[f64; 3]> = world.par_iter().map(|p| transform.to_local(*p)).collect();
    clock.lap("recentre");

    // 3. Spatial order, carried through every per-point array below.
    let order = slosh_mls::morton_order(&local);
    let local = permute(&local, &order);
    let source_index: Vec<u32> = order.par_iter().map(|&o| kept[o as usize]).collect();
    let normals: Option<Vec<[f64; 3]>> = match &params.normals {
        crate::params::NormalSource::Pca => None,
        crate::params::NormalSource::Estimate => {
            // From all finite particles (the interior shapes the surface's normals), then
            // the kept ones, in the spatial order.
            let all = &estimated;
            // `finite` is ascending, so a source index finds its estimate by search.
            Some(
                source_index
                    .par_iter()
                    .map(|i| finite.binary_search(i).map_or([0.0; 3], |k| all[k].1))
                    .collect(),
            )
        }
        crate::params::NormalSource::Variable(name) => {
            let ns = input
                .normals
                .as_ref()
                .ok_or_else(|| input_err(format!("no normals read from '{name}'")))?;
            if ns.len() != n_in {
                return Err(input_err(format!(
                    "normal variable '{name}' has {} values for {n_in} particles",
                    ns.len()
                )));
            }
            Some(permute(ns, &source_index))
        }
    };
    clock.lap("morton order");

    // Which way is up, from the selected points and their data normals (local coordinates
    // keep directions).
    let up = normals
        .as_deref()
        .and_then(|ns| slosh_mls::guess_up(&local, ns));

    // 4–8. kNN, radii, neighbour lists, initial fits, droplets, and the BVH over fitted balls
    // and droplet spheres, started as soon as the spray is known and left to run beside the
    // fits and the sections' arrays: obvhs leaves cores idle that they take. It is built
    // before the fits are known, on the guess that every ball outside the spray gets one; the
    // rare step where some ball has none builds it again.
    type Built = (Result<slosh_cache::Bvh, String>, f64);
    let speculative: std::sync::Mutex<Option<Built>> = Default::default();
    let built = rayon::scope(|scope| {
        let start_bvh = |beside: BesideFits<'_, f64>| {
            let start = std::time::Instant::now();
            let mut spray = vec![false; beside.points.len()];
            for &(i, _) in beside.droplet_of {
                spray[i as usize] = true;
            }
            let items = bvh_items(
                |i| !spray[i],
                |i| beside.points[i],
                beside.radii,
                beside.spheres,
            );
            let (slot, build_tree) = (&speculative, &build_tree);
            scope.spawn(move |_| {
                let bvh = build_tree(&crate::bvh::leaves(&items));
                if let Ok(mut slot) = slot.lock() {
                    *slot = Some((bvh, start.elapsed().as_secs_f64()));
                }
            });
        };
        let (surface, build_laps) = SurfaceParts::<f64>::build_with(
            &local,
            normals.as_deref(),
            &params.mls,
            &search,
            Some(crate::reach::NEAR_REACH_BAND),
            start_bvh,
        )
        .map_err(|source| BakeError::Surface { step, source })?;
        if withdrawn() {
            return Err(BakeError::Withdrawn { step });
        }
        // Sections, in the GPU layouts (the BVH's are added once it is built).
        let sections_start = std::time::Instant::now();
        let (sections, fields, kinds, section_parts) =
            gpu_sections(&surface, input, &source_index, params)?;
        let sections_seconds = sections_start.elapsed().as_secs_f64();
        Ok((
            surface,
            build_laps,
            sections,
            fields,
            kinds,
            (sections_seconds, section_parts),
        ))
    });
    let (surface, build_laps, mut sections, fields, kinds, (sections_seconds, section_parts)) =
        built?;
    let candidate = |i: usize| matches!(kinds[i], BallState::Full | BallState::Degraded);
    clock.extend(&build_laps);
    let n = surface.len();
    let (bvh, bvh_seconds) = match speculative.into_inner().ok().flatten() {
        Some(built) if !kinds.par_iter().any(|k| *k == BallState::Unfitted) => built,
        _ => {
            let start = std::time::Instant::now();
            let items = bvh_items(
                candidate,
                |i| {
                    let c = surface.points[i];
                    [c.x, c.y, c.z]
                },
                &surface.radii,
                &surface.spheres,
            );
            (
                build_tree(&crate::bvh::leaves(&items)),
                start.elapsed().as_secs_f64(),
            )
        }
    };
    let bvh = bvh.map_err(|problem| BakeError::Tree { step, problem })?;
    // Boxes the grid cannot hold come from coordinates beyond f32's range, which the
    // recentring rules out; refused rather than stored wrong.
    let (bvh_grid, stored_nodes) = bvh.stored().ok_or_else(|| {
        input_err("the BVH's boxes do not fit the grid of its root's box".to_string())
    })?;
    // After the spheres, before the fields: the order every cache has had.
    sections.extend(bvh_sections(&stored_nodes));
    let field_ranges = field_ranges(&fields);
    sections.extend(fields);

    let mut stats = StepStats {
        input_points: n_in as u64,
        dropped_non_finite: dropped_non_finite as u64,
        dropped_far: dropped_far as u64,
        dropped_interior: dropped_interior as u64,
        capped: surface.capped as u64,
        orientation_flipped: surface.orientation.flipped_points as u64,
        orientation_patches: surface.orientation.flipped_patches as u64,
        orientation_patch_points: surface.orientation.patch_points as u64,
        droplets: surface.spheres.len() as u64,
        bvh_nodes: bvh.nodes.len() as u64,
        bvh_depth: bvh.depth().unwrap_or(0) as u64,
        ..StepStats::default()
    };
    // As stored: a fit the layout could not hold counts as none.
    for kind in &kinds {
        match kind {
            BallState::Full => stats.fit_full += 1,
            BallState::Degraded => stats.fit_degraded += 1,
            BallState::Unfitted => stats.fit_none += 1,
            BallState::Droplet => stats.droplet_points += 1,
        }
    }
    // The BVH's own wall time: it ran beside the fits.
    clock.extend(&[("bvh", bvh_seconds), ("sections", sections_seconds)]);
    clock.extend(&section_parts);
    stats.stage_seconds = clock
        .laps
        .iter()
        .map(|(name, s)| (name.to_string(), *s))
        .collect();

    let header = Header {
        points: n as u64,
        transform,
        bounds: [lo, hi],
        smoothing_length: surface.h,
        spacing: surface.spacing,
        surface_offset: surface.offset,
        bvh_grid,
        stats,
        up,
        field_ranges,
        ..step_header(input, params)
    };
    Ok((BakedStep { header, sections }, surface))
}

/// The header fields every step of `input` shares, whatever it holds.
fn step_header(input: &StepInput, params: &BakeParams) -> Header {
    Header {
        source: Source {
            path: input.source.clone(),
            step: input.index,
            time: input.time,
            identity: input.identity.clone(),
        },
        points: 0,
        transform: Transform {
            origin: [0.0; 3],
            scale: 1.0,
        },
        bounds: [[0.0; 3]; 2],
        smoothing_length: 0.0,
        spacing: 0.0,
        surface_offset: 0.0,
        bvh_grid: slosh_cache::BvhGrid::default(),
        neighbour_cluster: NEIGHBOUR_CLUSTER,
        mls: MlsSettings::from_params(&params.mls),
        bake: params.record(),
        params_hash: params.hash(),
        series: None,
        stats: StepStats::default(),
        sections: Vec::new(),
        up: None,
        field_ranges: Default::default(),
    }
}

/// Each field view's range, from the field sections as they will be stored
/// (`slosh_cache::field_view_ranges`).
fn field_ranges(fields: &[SectionInput]) -> std::collections::BTreeMap<String, FieldRange> {
    fields
        .iter()
        .flat_map(|s| {
            let name = s.name.strip_prefix(names::FIELD_PREFIX).unwrap_or(&s.name);
            slosh_cache::field_view_ranges(name, s.element, &s.bytes)
        })
        .collect()
}

/// The BVH's section: its nodes on the header's grid (a leaf names its items as a range).
fn bvh_sections(nodes: &[slosh_cache::GpuBvhNode]) -> [SectionInput; 1] {
    [SectionInput::new(
        names::BVH_NODES,
        Element::BvhNode,
        nodes,
        by_element(Element::BvhNode),
    )
    .raw_within_budget(raw_rank::BVH_NODES)]
}

/// A step without particles (a Lagrangian or DEM run before its first injection), or with
/// too few left after selection to size a surface (`stats` says which): a valid step with
/// every section empty, shown as empty and counted as such, not a failure.
fn empty_step(
    input: &StepInput,
    params: &BakeParams,
    stats: StepStats,
) -> Result<BakedStep, BakeError> {
    let surface = SurfaceParts::<f64>::empty(&params.mls);
    let (mut sections, fields, _, _) = gpu_sections(&surface, input, &[], params)?;
    sections.extend(bvh_sections(&[]));
    sections.extend(fields);
    Ok(BakedStep {
        header: Header {
            stats,
            ..step_header(input, params)
        },
        sections,
    })
}
