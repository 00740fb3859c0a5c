//! Every point's nearest points on the GPU (`shaders/nearest.wgsl`), on a grid whose occupied
//! cells hold a few points each.

use rayon::prelude::*;
use slosh_mls::SurfaceError;

use crate::dispatch::{gpu_error, output, read_back, storage};
use crate::index::{Dispatch, GpuIndex};
use crate::layout::NEAREST_MAX;

/// Points per occupied cell the nearest-points grid aims at.
const POINTS_PER_CELL: f64 = 4.0;

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
    let level = sorted.level_for_occupancy(POINTS_PER_CELL, sorted.max_level(gpu.max_binding()));
    let starts = storage(gpu, "cell starts", &sorted.cell_starts(level));
    let per_point = (count * 4) as u64;
    let per_batch = (index.search.output_limit() / per_point).max(1) as usize;
    let mut sorted_ids: Vec<u32> = Vec::with_capacity(n * count);
    for first in (0..n).step_by(per_batch) {
        let len = per_batch.min(n - first);
        let bytes = len as u64 * per_point;
        let out = output(gpu, "nearest points", bytes);
        index.submit(Dispatch {
            pipeline: &index.search.nearest,
            layout: &index.search.nearest_layout,
            level,
            cell_starts: &starts,
            first,
            count: len,
            wanted: count,
            flags: 0,
            out_base: 0,
            buffers: &[(4, &out)],
        })?;
        sorted_ids.extend(read_back::<u32>(gpu, &out, bytes)?);
    }
    if sorted.identity {
        return Ok(sorted_ids);
    }
    // Point i's at [i·count, (i + 1)·count): sorted position t holds point order[t]'s.
    let mut rank = vec![0u32; n];
    for (t, &i) in sorted.order.iter().enumerate() {
        rank[i as usize] = t as u32;
    }
    Ok(rank
        .par_iter()
        .flat_map_iter(|&t| sorted_ids[t as usize * count..][..count].iter().copied())
        .collect())
}
