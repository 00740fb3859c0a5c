//! Every point's neighbour list on the GPU (`shaders/lists.wgsl`): where the cap cuts each
//! list and how many it keeps (one pass over all points), the lists' offsets (a prefix sum
//! here), then the lists themselves, written and read back in batches of bounded size.

use rayon::prelude::*;
use slosh_mls::{
    InitialFit, KeptLists, ListRequest, NeighbourLists, Neighbours, SurfaceError, csr_pieces,
    distance2,
};

use crate::components::Components;
use crate::dispatch::{Pooled, gpu_error, output, storage};
use crate::index::{Dispatch, GpuIndex};
use crate::layout::{
    DEFERRED, FAR_BIT, FLAG_LINKS, FLAG_NORMALS, FLAG_PAIRS, FLAG_SORTED, FLAG_TODO, ID_MASK,
    LINK_BIT,
};
use crate::unions::{CLUSTER, UnionBatch, Unions};

/// (point, neighbour) within the link distance.
type Link = (u32, u32);

/// Reaches sampled for the median that sizes the grid's cells.
const MEDIAN_SAMPLE: usize = 1 << 16;

/// List words are allocated in multiples of this many (16 MB).
const WORDS_GRANULE: usize = 4 << 20;

/// The most points of one dispatch over a list of points.
const MAX_TODO: usize = 1 << 20;

/// Room for pairs (`FLAG_PAIRS`) per point of a batch: a list has some 0.1 members near its
/// reach on a surface; a cut list, the point the cut fell on (most of a surface's lists at the
/// default cap) and rarely another. Where more come (lattices, whose distances tie), the
/// batch's lists are read back instead.
const PAIRS_PER_POINT: usize = 2;

/// Room for pairs of a batch, at least.
const PAIRS_LEAST: usize = 1 << 12;

/// Points per piece of the lists' assembly (a task, and a piece of the links): the CPU lists
/// stage's blocks, whose links the spray joins piece by piece in parallel.
const POINTS_PER_PIECE: usize = slosh_mls::LIST_BLOCK;

pub(crate) fn lists(
    index: &GpuIndex<'_>,
    request: ListRequest<'_>,
) -> Result<NeighbourLists, SurfaceError> {
    // Where the time goes, part by part (`NeighbourLists::parts`).
    let mut parts = slosh_mls::StageClock::start();
    let sorted = &index.sorted;
    let search = index.search;
    let gpu = search.gpu();
    let n = sorted.len();
    let order = &sorted.order;
    let cap = request.cap.max(1);
    if n as u64 > u64::from(ID_MASK) + 1 {
        return Err(gpu_error(format!(
            "{n} points; the lists' words hold indices below {}",
            u64::from(ID_MASK) + 1
        )));
    }
    if request.reach.len() != n {
        return Err(gpu_error(format!(
            "{} reaches for {n} points",
            request.reach.len()
        )));
    }
    let reach: Vec<f32> = order
        .par_iter()
        .map(|&i| request.reach[i as usize] as f32)
        .collect();
    let mut flags = if sorted.identity { FLAG_SORTED } else { 0 };
    let normals: Vec<[f32; 4]> = match request.normals {
        Some(ns) => {
            flags |= FLAG_NORMALS;
            order
                .par_iter()
                .map(|&i| {
                    let n = ns[i as usize].unwrap_or([0.0; 3]);
                    [n[0] as f32, n[1] as f32, n[2] as f32, 0.0]
                })
                .collect()
        }
        None => Vec::new(),
    };
    let link2: Vec<f32> = match request.link_distance2 {
        Some(f) => {
            flags |= FLAG_LINKS;
            order.par_iter().map(|&i| f(i as usize) as f32).collect()
        }
        None => Vec::new(),
    };
    // Cells about half the typical reach wide: a query visits some 5³ cells.
    // (Of an evenly strided sample: the grid only decides how fast the passes run, and a
    // million-point selection took milliseconds of one thread.)
    let median = {
        let mut r: Vec<f32> = reach
            .iter()
            .step_by(n.div_ceil(MEDIAN_SAMPLE).max(1))
            .copied()
            .collect();
        let mid = r.len() / 2;
        *r.select_nth_unstable_by(mid, f32::total_cmp).1
    };
    let level = sorted.level_for_size(0.5 * f64::from(median), sorted.max_level(gpu.max_binding()));
    let starts = storage(&search.memory, "cell starts", &sorted.cell_starts(level))?;
    let reach_buffer = storage(&search.memory, "reach", &reach)?;
    let normals_buffer = storage(&search.memory, "normals", &normals)?;
    let link_buffer = storage(&search.memory, "link distances", &link2)?;
    let cut_bytes = n as u64 * 16;
    if cut_bytes > gpu.max_binding() {
        return Err(gpu_error(format!(
            "{n} points' cuts take {cut_bytes} bytes, more than one binding holds"
        )));
    }
    let cut = output(&search.memory, "list cuts", cut_bytes);
    let (no_pairs, no_pair_count) = (
        output(&search.memory, "no pairs", 16),
        output(&search.memory, "no pair count", 16),
    );
    parts.lap("neighbour lists: inputs");
    // One dispatch of the cut or the write pass: points first.. (or `todo`'s) on the grid of
    // `level`.
    struct Pass<'p> {
        pass: &'static str,
        pipeline: &'p wgpu::ComputePipeline,
        level: u32,
        starts: &'p wgpu::Buffer,
        first: usize,
        count: usize,
        todo: Option<&'p [u32]>,
        out_base: u32,
        list_start: &'p wgpu::Buffer,
        lists_out: &'p wgpu::Buffer,
        /// With FLAG_PAIRS: the pairs and their count.
        pairs: Option<(&'p wgpu::Buffer, &'p wgpu::Buffer, f32)>,
    }
    let pass = |p: Pass<'_>| -> Result<wgpu::SubmissionIndex, SurfaceError> {
        let todo = match p.todo {
            Some(t) => storage(&search.memory, "lists todo", t)?,
            None => output(&search.memory, "no todo", 16),
        };
        let (pairs, pair_count, band) = match p.pairs {
            Some((pairs, count, band)) => (pairs, count, band),
            None => (&*no_pairs, &*no_pair_count, 0.0),
        };
        Ok(index.submit(Dispatch {
            pass: p.pass,
            pipeline: p.pipeline,
            layout: &search.lists_layout,
            level: p.level,
            cell_starts: p.starts,
            first: p.first,
            count: p.count,
            wanted: cap,
            flags: flags
                | if p.todo.is_some() { FLAG_TODO } else { 0 }
                | if p.pairs.is_some() { FLAG_PAIRS } else { 0 },
            out_base: p.out_base,
            shells: 0,
            band,
            buffers: &[
                (4, &reach_buffer),
                (5, &normals_buffer),
                (6, &link_buffer),
                (7, &cut),
                (8, p.list_start),
                (9, p.lists_out),
                (11, &todo),
                (12, pairs),
                (13, pair_count),
            ],
        }))
    };
    // The cut pass reads no offsets and writes no lists: two buffers of their own, since one
    // buffer may not be bound read-only and writable at once.
    let (no_starts, no_lists) = (
        output(&search.memory, "no offsets", 16),
        output(&search.memory, "no lists", 16),
    );
    let cut_pass = |level: u32, starts: &wgpu::Buffer, todo: Option<&[u32]>| {
        pass(Pass {
            pass: "lists: cut",
            pipeline: &search.cut,
            level,
            starts,
            first: 0,
            count: todo.map_or(n, <[u32]>::len),
            todo,
            out_base: 0,
            list_start: &no_starts,
            lists_out: &no_lists,
            pairs: None,
        })
    };
    cut_pass(level, &starts, None)?;
    let mut cuts: Vec<[u32; 4]> = search.read_back(&cut, cut_bytes)?;
    // Points whose reach spans too many cells (DEFERRED), cut again on grids four times
    // coarser until none is left: each grid's level, cell table and points.
    let mut coarser: Vec<(u32, Pooled, Vec<u32>)> = Vec::new();
    let mut deferred: Vec<u32> = (0..n as u32)
        .into_par_iter()
        .filter(|&t| cuts[t as usize][3] == DEFERRED)
        .collect();
    let mut coarse_level = level;
    while !deferred.is_empty() {
        coarse_level = coarse_level.saturating_sub(2).max(1);
        let coarse_starts = storage(
            &search.memory,
            "cell starts",
            &sorted.cell_starts(coarse_level),
        )?;
        for todo in deferred.chunks(MAX_TODO) {
            cut_pass(coarse_level, &coarse_starts, Some(todo))?;
        }
        cuts = search.read_back(&cut, cut_bytes)?;
        let (still, done): (Vec<u32>, Vec<u32>) = deferred
            .iter()
            .partition(|&&t| cuts[t as usize][3] == DEFERRED);
        coarser.push((coarse_level, coarse_starts, done));
        deferred = still;
    }

    // Offsets in sorted order.
    let total: u64 = cuts.par_iter().map(|c| u64::from(c[2])).sum();
    if total > u64::from(u32::MAX) {
        return Err(gpu_error(format!(
            "{total} neighbours in all; lists hold at most {} (32-bit offsets)",
            u32::MAX
        )));
    }
    let mut start = Vec::with_capacity(n + 1);
    start.push(0u32);
    for c in &cuts {
        start.push(start[start.len() - 1] + c[2]);
    }
    let start_buffer = storage(&search.memory, "list starts", &start)?;
    parts.lap("neighbour lists: cut and offsets");
    let fit_inputs = request
        .fits
        .map(|f| crate::fits::prepare(index, f, request.normals.is_some()))
        .transpose()?;
    parts.lap("neighbour lists: fit inputs");
    let (mut write_seconds, mut read_seconds) = (0.0, 0.0);
    let mut sorted_fits: Vec<Option<InitialFit>> = Vec::new();
    let mut fit_seconds = 0.0;
    let mut fit_parts = crate::fits::FitSeconds::default();
    // Batches of consecutive points whose lists fit one output, and of whole clusters where
    // every batch can be.
    let limit_ids = (search.output_limit() / 4).max(cap as u64);
    // A batch's fits take 64 bytes a point.
    let limit_points = (search.output_limit() / 64).max(1) as usize;
    let mut batches: Vec<(usize, usize)> = Vec::new();
    let mut whole_clusters = true;
    let mut first = 0;
    while first < n {
        let mut last = first + 1;
        while last < n
            && last - first < limit_points
            && u64::from(start[last + 1] - start[first]) <= limit_ids
        {
            last += 1;
        }
        if last < n {
            match last - last % CLUSTER {
                whole if whole > first => last = whole,
                _ => whole_clusters = false,
            }
        }
        batches.push((first, last));
        first = last;
    }
    // The bake's cluster unions, made where the points came in spatial order (each cluster
    // is consecutive points here too) and every batch holds whole clusters.
    let mut unions = (sorted.identity && whole_clusters).then(|| Unions::new(n));
    // The spray's components joined on the GPU where the lists are, but for points in
    // another order (whose roots would be named by sorted positions): then the host joins the
    // links it reads.
    let components = if sorted.identity && flags & FLAG_LINKS != 0 {
        Some(Components::new(index)?)
    } else {
        None
    };
    let host_links = components.is_none() && flags & FLAG_LINKS != 0;
    // Where the unions, fits and links are all made here, the lists themselves need not come
    // back: only each list's members near its reach, which the caller measures, and those
    // the cut's reach is measured on (`ListRequest::near_reach_band`).
    let band = request
        .near_reach_band
        .filter(|_| unions.is_some() && fit_inputs.is_some() && !host_links);
    // (caller's index, word) of each member near its list's reach, where `band` is set.
    let mut near: Vec<[u32; 2]> = Vec::new();
    // In whole 16 MB steps, so that the next step's lists (of a slightly other length) find
    // this one's memory free rather than fault in fresh pages.
    let mut words: Vec<u32> = Vec::new();
    if band.is_none() {
        words.reserve_exact((total as usize).next_multiple_of(WORDS_GRANULE));
        crate::host_memory::advise_huge_pages(&mut words);
    }
    let (mut union_seconds, mut component_seconds) = (0.0, 0.0);
    for &(first, last) in &batches {
        let writing = std::time::Instant::now();
        let count = u64::from(start[last] - start[first]);
        let lists_out = output(&search.memory, "lists", count * 4);
        let room = (last - first)
            .saturating_mul(PAIRS_PER_POINT)
            .max(PAIRS_LEAST);
        let pair_buffers = band.map(|b| {
            (
                output(&search.memory, "near pairs", room as u64 * 8),
                output(&search.memory, "near pair count", 16),
                b as f32,
            )
        });
        if count > 0 {
            let out_base = start[first];
            let write = |level, starts, first, count, todo| {
                pass(Pass {
                    pass: "lists: write",
                    pipeline: &search.write,
                    level,
                    starts,
                    first,
                    count,
                    todo,
                    out_base,
                    list_start: &start_buffer,
                    lists_out: &lists_out,
                    pairs: pair_buffers.as_ref().map(|(p, c, b)| (&**p, &**c, *b)),
                })
            };
            write(level, &starts, first, last - first, None)?;
            // The batch's points cut on coarser grids, each on its own.
            for (coarse_level, coarse_starts, points) in &coarser {
                let lo = points.partition_point(|&t| (t as usize) < first);
                let hi = points.partition_point(|&t| (t as usize) < last);
                for todo in points[lo..hi].chunks(MAX_TODO) {
                    write(*coarse_level, coarse_starts, 0, todo.len(), Some(todo))?;
                }
            }
        }
        // Fitted where the lists are, before they are read back.
        if let Some(inputs) = &fit_inputs {
            let fitting = std::time::Instant::now();
            sorted_fits.extend(crate::fits::fit_batch(
                index,
                inputs,
                crate::fits::BatchLists {
                    normals: &normals_buffer,
                    list_start: &start_buffer,
                    lists: &lists_out,
                    first,
                    count: last - first,
                    list_base: start[first],
                },
                &mut fit_parts,
            )?);
            fit_seconds += fitting.elapsed().as_secs_f64();
        }
        let reading = std::time::Instant::now();
        write_seconds += (reading - writing).as_secs_f64();
        match &pair_buffers {
            None => search.read_into(&lists_out, count * 4, &mut words)?,
            Some((pairs, pair_count, _)) => {
                let found = search.read_back::<u32>(pair_count, 4)?[0] as usize;
                if found <= room {
                    near.extend(search.read_back::<[u32; 2]>(pairs, found as u64 * 8)?);
                } else {
                    // More than the room: every member of the batch's lists, which holds
                    // those near the reach.
                    let batch: Vec<u32> = search.read_back(&lists_out, count * 4)?;
                    let base = start[first];
                    for t in first..last {
                        let i = order[t];
                        let list =
                            &batch[(start[t] - base) as usize..(start[t + 1] - base) as usize];
                        near.extend(list.iter().map(|&w| [i, w]));
                    }
                }
            }
        }
        read_seconds += reading.elapsed().as_secs_f64();
        if let Some(c) = &components {
            let joining = std::time::Instant::now();
            c.join(
                index,
                &start_buffer,
                &lists_out,
                start[first],
                (first, last),
            )?;
            component_seconds += joining.elapsed().as_secs_f64();
        }
        if let Some(u) = &mut unions {
            let merging = std::time::Instant::now();
            u.add(
                index,
                UnionBatch {
                    start: &start,
                    list_start: &start_buffer,
                    lists: &lists_out,
                    list_base: start[first],
                    first,
                    last,
                },
            )?;
            union_seconds += merging.elapsed().as_secs_f64();
        }
    }
    let joining = std::time::Instant::now();
    let components = components
        .map(|c| c.finish(index, &start_buffer, &no_lists))
        .transpose()?;
    component_seconds += joining.elapsed().as_secs_f64();
    parts.extend(&[
        (
            "neighbour lists: write",
            (write_seconds - fit_seconds).max(0.0),
        ),
        ("neighbour lists: read back", read_seconds),
        ("neighbour lists: cluster unions", union_seconds),
        ("neighbour lists: spray components", component_seconds),
    ]);
    if fit_inputs.is_some() {
        parts.extend(&[
            ("initial fits: waiting for the GPU", fit_parts.gpu),
            ("initial fits: unpacked", fit_parts.unpack),
        ]);
    }
    let points = index.points;
    // A list's reach: as asked, or where the cap cut it, as far as its farthest point in f64
    // (`lists.rs` in slosh-mls): the point the cut fell on, which the list keeps unless its
    // normal opposes, or a member marked near the cut (only those could lie farther, where
    // two distances tie within f32; `NEAR_CUT`). `members` holds those marked, and may hold
    // more.
    let reach_of = |t: usize, members: &[u32]| -> f64 {
        let (c, i) = (cuts[t], order[t] as usize);
        if c[3] & 1 == 0 {
            return request.reach[i];
        }
        let far = members
            .iter()
            .filter(|&&w| w & FAR_BIT != 0)
            .map(|&w| distance2(points[i], points[(w & ID_MASK) as usize]))
            .fold(distance2(points[i], points[c[1] as usize]), f64::max);
        far.sqrt().next_up().next_up()
    };
    let capped = cuts.par_iter().filter(|c| c[3] & 1 != 0).count();
    let (lists, reach_out, links) = match band {
        Some(band) => {
            // Each point's near members (CSR in the caller's order, each point's in index
            // order: they came in the order the GPU's threads appended them); reaches in
            // sorted order.
            let (near_start, mut ids) = crate::csr::grouped(&near, n, |w| w & ID_MASK)
                .ok_or_else(|| gpu_error("a member near its list's reach names no point"))?;
            drop(near);
            let of = |i: usize| &ids[near_start[i] as usize..near_start[i + 1] as usize];
            let by_sorted: Vec<f64> = (0..n)
                .into_par_iter()
                .map(|t| reach_of(t, of(order[t] as usize)))
                .collect();
            ids.par_iter_mut().for_each(|w| *w &= ID_MASK);
            let members = Neighbours::from_csr(near_start, ids)
                .ok_or_else(|| gpu_error("the near members do not match their counts"))?;
            (
                KeptLists::NearReach { band, members },
                sorted.unsort(by_sorted),
                Vec::new(),
            )
        }
        None => {
            // Links out, the marks cleared in place, and each list's reach, piece by piece
            // (in sorted order).
            let pieces: Vec<(Vec<Link>, Vec<f64>)> =
                csr_pieces(&start, &mut words, POINTS_PER_PIECE)
                    .into_par_iter()
                    .map(|(range, piece)| {
                        let base = start[range.start] as usize;
                        let mut links = Vec::new();
                        let mut reach = Vec::with_capacity(range.len());
                        for t in range {
                            let list =
                                &mut piece[start[t] as usize - base..start[t + 1] as usize - base];
                            reach.push(reach_of(t, list));
                            for w in list {
                                // Most words carry no mark: they are read, not written.
                                if *w & !ID_MASK == 0 {
                                    continue;
                                }
                                let j = *w & ID_MASK;
                                if host_links && *w & LINK_BIT != 0 {
                                    links.push((order[t], j));
                                }
                                *w = j;
                            }
                        }
                        (links, reach)
                    })
                    .collect();
            let (links, by_sorted): (Vec<Vec<Link>>, Vec<Vec<f64>>) = pieces.into_iter().unzip();
            let lists = if sorted.identity {
                Neighbours::from_csr(start, words)
            } else {
                // Back to the caller's order.
                let sorted_ids = words;
                let mut by_point = vec![0u32; n + 1];
                for (t, &i) in order.iter().enumerate() {
                    by_point[i as usize + 1] = start[t + 1] - start[t];
                }
                for i in 0..n {
                    by_point[i + 1] += by_point[i];
                }
                let mut ids = vec![0u32; sorted_ids.len()];
                for (t, &i) in order.iter().enumerate() {
                    let from = &sorted_ids[start[t] as usize..start[t + 1] as usize];
                    let at = by_point[i as usize] as usize;
                    ids[at..at + from.len()].copy_from_slice(from);
                }
                Neighbours::from_csr(by_point, ids)
            }
            .ok_or_else(|| gpu_error("the lists read back do not match their counts"))?;
            (
                KeptLists::Whole(lists),
                sorted.unsort(by_sorted.concat()),
                links,
            )
        }
    };
    parts.lap("neighbour lists: links and reach");
    // (Made only where the lists are in the caller's order.)
    let run_unions = unions.and_then(|u| u.finish(n));
    if matches!(lists, KeptLists::NearReach { .. }) && run_unions.is_none() {
        return Err(gpu_error(
            "the cluster unions do not cover the points, and the lists were not read back",
        ));
    }
    // Fits in the caller's order.
    let fits = fit_inputs.map(|_| sorted.unsort(sorted_fits));
    parts.lap("neighbour lists: order");
    Ok(NeighbourLists {
        lists,
        reach: reach_out,
        capped,
        run_unions,
        links,
        components,
        fits,
        fit_seconds,
        parts: parts.laps,
    })
}
