//! The orientation check's first-pass votes on the GPU (`shaders/orient_votes.wgsl`): every
//! point's tangent weights and agreements with its nearest in f32, each point whose outcome
//! rounding could have decided marked for the host to cast again in f64
//! (`slosh_mls::vote_word`), so that the repair comes out as the CPU's.

use rayon::prelude::*;
use slosh_mls::{NearestIds, ORIENT_NEIGHBOURS, SurfaceError};

use crate::dispatch::{bind, groups, output, storage, uniform};
use crate::index::GpuIndex;
use crate::layout::SearchParams;

/// The votes of every point of `index`, given its nearest and unit normals, read from the
/// ids its nearest-points pass left on the GPU; `None` where there are none to read (the
/// caller's order is not the GPU's Morton order, which a bake's always is, or `nearest` is
/// not the pass's last query) or where the check takes fewer neighbours than the shader
/// does (all others of a point, up to [`ORIENT_NEIGHBOURS`]). Uploading the ids again was
/// 64 bytes a point from host memory made for it.
pub(crate) fn orientation_votes(
    index: &GpuIndex<'_>,
    nearest: NearestIds<'_>,
    normals: &[Option<[f64; 3]>],
) -> Result<Option<Vec<u32>>, SurfaceError> {
    let n = nearest.len();
    let search = index.search;
    let gpu = search.gpu();
    let unit_bytes = n as u64 * 16;
    let Some(kept) = index
        .take_kept_nearest()
        .filter(|k| k.wanted == nearest.stride())
    else {
        return Ok(None);
    };
    let takes_all = nearest.take() == ORIENT_NEIGHBOURS || nearest.take() + 1 >= kept.wanted;
    if !takes_all
        || normals.len() != n
        || index.points.len() != n
        || n == 0
        || unit_bytes > gpu.max_binding()
    {
        return Ok(None);
    }
    // w 1 for a normal, all zero for none (`shaders/orient_votes.wgsl`).
    let as_f32: Vec<[f32; 4]> = normals
        .par_iter()
        .map(|v| v.map_or([0.0; 4], |v| [v[0] as f32, v[1] as f32, v[2] as f32, 1.0]))
        .collect();
    let normals_on_gpu = storage(&search.memory, "orientation normals", &as_f32)?;
    let mut votes: Vec<u32> = Vec::with_capacity(n);
    for (first, len, ids) in &kept.batches {
        let (first, len) = (*first, *len);
        let out = output(&search.memory, "orientation votes", len as u64 * 4);
        let (x, y, row_threads) = groups(gpu, len as u32);
        let params = uniform(
            gpu,
            // The pass reads no grid: its other fields stay zero.
            &SearchParams {
                count: len as u32,
                first: first as u32,
                wanted: kept.wanted as u32,
                row_threads,
                ..bytemuck::Zeroable::zeroed()
            },
        );
        let group = bind(
            gpu,
            &search.orient_layout,
            &[
                (0, &params),
                (1, &index.positions),
                (10, &index.residuals),
                (4, &out),
                (5, ids),
                (6, &normals_on_gpu),
            ],
        );
        search.run(
            "orientation votes",
            &[(&search.orient_votes, (x, y))],
            &group,
        );
        votes.extend(search.read_back::<u32>(&out, len as u64 * 4)?);
    }
    if votes.len() != n {
        return Ok(None);
    }
    Ok(Some(votes))
}
