//! The initial fits on the GPU (`shaders/bake_fit.wgsl`): each batch of lists fitted where the
//! lists pass wrote it, before the lists are read back, and the fits read back beside them.

use rayon::prelude::*;
use slosh_mls::{FitRequest, InitialFit, NormalsMode, Poly, SurfaceError};

use crate::dispatch::{Pooled, bind, gpu_error, groups, output, storage, uniform};
use crate::index::GpuIndex;
use crate::layout::FitSettings;

/// vec4s a point's fit takes in `fits_out`.
const VEC4_PER_FIT: usize = 4;

/// What every batch's fits share: the pipeline for the degree, each point's h and the
/// sorted position of each caller's index.
pub(crate) struct FitInputs<'a> {
    pipeline: &'a wgpu::ComputePipeline,
    smoothing: Pooled,
    rank: Pooled,
    has_normals: bool,
    normals_mode: u32,
}

pub(crate) fn prepare<'a>(
    index: &'a GpuIndex<'_>,
    request: FitRequest<'_>,
    has_normals: bool,
) -> Result<FitInputs<'a>, SurfaceError> {
    let order = &index.sorted.order;
    let smoothing: Vec<f32> = order
        .par_iter()
        .map(|&i| (request.h)(i as usize) as f32)
        .collect();
    Ok(FitInputs {
        pipeline: index
            .search
            .fits_pipeline(request.degree)
            .map_err(gpu_error)?,
        smoothing: storage(&index.search.memory, "smoothing lengths", &smoothing)?,
        rank: storage(&index.search.memory, "ranks", &index.sorted.rank())?,
        has_normals,
        normals_mode: match request.normals {
            NormalsMode::Mean => 0,
            NormalsMode::Covariance => 1,
        },
    })
}

/// The buffers a batch's fits read.
pub(crate) struct BatchLists<'b> {
    pub normals: &'b wgpu::Buffer,
    pub list_start: &'b wgpu::Buffer,
    pub lists: &'b wgpu::Buffer,
    /// The batch's first sorted point, its points, and its first list slot.
    pub first: usize,
    pub count: usize,
    pub list_base: u32,
}

/// Where a batch's fits spent their wall time: waiting for the GPU (the batch's lists, then
/// its fits) and their read-back, and unpacking them into [`InitialFit`]s.
#[derive(Debug, Default, Clone, Copy)]
pub(crate) struct FitSeconds {
    pub gpu: f64,
    pub unpack: f64,
}

/// The fits of a batch's points, in sorted order (waits for the GPU), and where the time
/// went (added to `seconds`).
pub(crate) fn fit_batch(
    index: &GpuIndex<'_>,
    inputs: &FitInputs<'_>,
    batch: BatchLists<'_>,
    seconds: &mut FitSeconds,
) -> Result<Vec<Option<InitialFit>>, SurfaceError> {
    let start = std::time::Instant::now();
    let gpu = index.search.gpu();
    let bytes = (batch.count * VEC4_PER_FIT * 16) as u64;
    let out = output(&index.search.memory, "initial fits", bytes);
    let (x, y, row_threads) = groups(gpu, batch.count as u32);
    let settings = uniform(
        gpu,
        &FitSettings {
            count: batch.count as u32,
            first: batch.first as u32,
            row_threads,
            list_base: batch.list_base,
            has_normals: u32::from(inputs.has_normals),
            normals_mode: inputs.normals_mode,
            _pad0: 0,
            _pad1: 0,
        },
    );
    let group = bind(
        gpu,
        &index.search.fits_layout,
        &[
            (0, &settings),
            (1, &index.positions),
            (2, &index.residuals),
            (3, batch.normals),
            (4, batch.list_start),
            (5, &inputs.smoothing),
            (6, batch.lists),
            (7, &inputs.rank),
            (8, &out),
        ],
    );
    index
        .search
        .run("initial fits", &[(inputs.pipeline, (x, y))], &group);
    // No wait for the pass alone: each wait is a round trip through the queue the jobs share.
    let raw: Vec<[f32; 4]> = index.search.read_back(&out, bytes)?;
    let unpacking = std::time::Instant::now();
    seconds.gpu += (unpacking - start).as_secs_f64();
    let fits = raw
        .par_chunks(VEC4_PER_FIT)
        .map(|v| {
            let status = v[0][3];
            (status != 0.0).then(|| {
                let mut c = [0.0f32; 10];
                c[..4].copy_from_slice(&v[1]);
                c[4..8].copy_from_slice(&v[2]);
                c[8..].copy_from_slice(&v[3][..2]);
                InitialFit {
                    normal: [v[0][0], v[0][1], v[0][2]],
                    poly: Poly {
                        degree: v[3][2] as u8,
                        c,
                    },
                    degraded: status == 2.0,
                }
            })
        })
        .collect();
    seconds.unpack += unpacking.elapsed().as_secs_f64();
    Ok(fits)
}
