//! Every point's nearest points on the GPU (`shaders/nearest.wgsl`), on a grid whose occupied
//! cells hold a few points each.

use rayon::prelude::*;
use slosh_mls::SurfaceError;

use crate::dispatch::{gpu_error, output, storage};
use crate::index::{Dispatch, GpuIndex, KeptNearest};
use crate::layout::{FLAG_TODO, NEAREST_MAX, UNFINISHED};

/// Points per occupied cell the nearest-points grid aims at.
const POINTS_PER_CELL: f64 = 4.0;

/// Shells of cells a point searches on one grid: its nearest 17 lie within one or two where
/// occupied cells hold a few points; an outlier goes on to a coarser grid.
const SHELLS: u32 = 3;

pub(crate) fn nearest(index: &GpuIndex<'_>, count: usize) -> Result<Vec<u32>, SurfaceError> {
    if count > NEAREST_MAX {
        return Err(gpu_error(format!(
            "{count} nearest points asked for, where the GPU search finds at most \
             {NEAREST_MAX}; lower k or bake with --device cpu"
        )));
    }
    let sorted = &index.sorted;
    let gpu = index.search.gpu();
    let n = sorted.len();
    let per_point = (count * 4) as u64;
    let per_batch = (index.search.output_limit() / per_point).max(1) as usize;
    let mut level =
        sorted.level_for_occupancy(POINTS_PER_CELL, sorted.max_level(gpu.max_binding()));
    // Filled batch by batch in order by the first pass (no fill beforehand: 28 MB of fresh
    // pages at 1M points cost the H200's host more than the search's own read-back).
    let mut sorted_ids: Vec<u32> = Vec::new();
    // Every point first; then those the shells did not satisfy (outliers far from the rest),
    // on grids of cells four times wider, until a grid of two cells a side visits them all.
    let mut todo: Option<Vec<u32>> = None;
    // The first round's buffers, every point's ids in sorted order, kept for the orientation
    // votes where the sorted order is the caller's (a bake's always is).
    let mut kept = Vec::new();
    drop(index.take_kept_nearest());
    loop {
        let starts = storage(
            &index.search.memory,
            "cell starts",
            &sorted.cell_starts(level),
        )?;
        let points = todo.as_ref().map_or(n, Vec::len);
        let mut unfinished: Vec<u32> = Vec::new();
        for first in (0..points).step_by(per_batch) {
            let len = per_batch.min(points - first);
            let bytes = len as u64 * per_point;
            let out = output(&index.search.memory, "nearest points", bytes);
            let todo_buffer = match &todo {
                Some(t) => storage(&index.search.memory, "nearest todo", &t[first..first + len])?,
                None => output(&index.search.memory, "no todo", 16),
            };
            index.submit(Dispatch {
                pass: "nearest points",
                pipeline: &index.search.nearest,
                layout: &index.search.nearest_layout,
                level,
                cell_starts: &starts,
                first: if todo.is_some() { 0 } else { first },
                count: len,
                wanted: count,
                flags: if todo.is_some() { FLAG_TODO } else { 0 },
                out_base: 0,
                shells: SHELLS,
                band: 0.0,
                buffers: &[(4, &out), (5, &todo_buffer)],
            });
            match &todo {
                // Consecutive points: copied out by every thread straight into place (one
                // thread's copy of a 1M step's 68 MB took tens of milliseconds), and the few
                // unfinished found in parallel (a loop over every point took 19 ms of a 1M
                // step on the H200's host).
                None => {
                    let at = sorted_ids.len();
                    index.search.read_into(&out, bytes, &mut sorted_ids)?;
                    let found = &sorted_ids[at..];
                    let more: Vec<u32> = (0..len)
                        .into_par_iter()
                        .filter(|k| found[k * count] == UNFINISHED)
                        .map(|k| (first + k) as u32)
                        .collect();
                    unfinished.extend(more);
                    if sorted.identity {
                        kept.push((first, len, out));
                    }
                }
                Some(t) => {
                    let found: Vec<u32> = index.search.read_back(&out, bytes)?;
                    for (k, ids) in found.chunks(count).enumerate() {
                        let t = t[first + k] as usize;
                        if ids[0] == UNFINISHED {
                            unfinished.push(t as u32);
                        } else {
                            sorted_ids[t * count..][..count].copy_from_slice(ids);
                        }
                    }
                }
            }
        }
        if unfinished.is_empty() {
            break;
        }
        if level == 1 {
            return Err(gpu_error(format!(
                "{} points found fewer than {count} nearest points on a grid of two cells a side",
                unfinished.len()
            )));
        }
        level = level.saturating_sub(2).max(1);
        todo = Some(unfinished);
    }
    if sorted.identity {
        *index.kept_nearest.lock().unwrap_or_else(|p| p.into_inner()) = Some(KeptNearest {
            wanted: count,
            batches: kept,
        });
        return Ok(sorted_ids);
    }
    // Point i's at [i·count, (i + 1)·count): sorted position t holds point order[t]'s.
    Ok(sorted
        .rank()
        .par_iter()
        .flat_map_iter(|&t| sorted_ids[t as usize * count..][..count].iter().copied())
        .collect())
}
