//! The search passes, compiled once for a device and shared by every step in flight.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, OnceLock};

use slosh_render::Gpu;

use crate::dispatch::{PassMemory, gpu_error, layout, record};
use crate::layout::{
    UNION_SPAN_WORDS, components_source, fits_source, lists_source, nearest_source,
    orient_votes_source, tree_source, unions_source,
};
use crate::pass_clock::PassClock;

/// The bytes one dispatch's output may take, at most (with the adapter's binding limit):
/// larger outputs go in several dispatches, so that a 4M-point step's lists (about 2 GB)
/// never sit on the GPU whole.
pub(crate) const OUTPUT_BATCH_BYTES: u64 = 256 << 20;

/// Steps with work queued on the device at once ([`slosh_bake::DeviceTurns`]). A 64 × 1M
/// series on an H100 host had its first step 0.3-1.8 s sooner with 2, 4 or 8 than with no
/// limit, and baked soonest with 4 (`docs/results-bake.md`, stop 68).
const STEPS_ON_DEVICE: usize = 4;

/// The bake's stages on a GPU: a [`slosh_mls::NeighbourSearch`] (with the initial fits) and a
/// [`slosh_bake::TreeBuild`], their passes built once and shared by every step in flight.
#[derive(Debug)]
pub struct GpuStages {
    pub(crate) gpu: Arc<Gpu>,
    pub(crate) nearest_layout: wgpu::BindGroupLayout,
    pub(crate) nearest: wgpu::ComputePipeline,
    /// `shaders/orient_votes.wgsl`'s layout and pass.
    pub(crate) orient_layout: wgpu::BindGroupLayout,
    pub(crate) orient_votes: wgpu::ComputePipeline,
    pub(crate) lists_layout: wgpu::BindGroupLayout,
    pub(crate) cut: wgpu::ComputePipeline,
    pub(crate) write: wgpu::ComputePipeline,
    pub(crate) fits_layout: wgpu::BindGroupLayout,
    fits_pipeline_layout: wgpu::PipelineLayout,
    /// The initial fits' pipeline per degree (1–3), built on first use.
    fits: [OnceLock<wgpu::ComputePipeline>; 3],
    pub(crate) tree_layout: wgpu::BindGroupLayout,
    /// `shaders/bvh_build.wgsl`'s entry points, in the order a build runs them.
    pub(crate) link_nodes: wgpu::ComputePipeline,
    pub(crate) measure_depths: wgpu::ComputePipeline,
    pub(crate) place_nodes: wgpu::ComputePipeline,
    pub(crate) fit_boxes: wgpu::ComputePipeline,
    pub(crate) next_depth: wgpu::ComputePipeline,
    /// `shaders/spray_components.wgsl`'s layout and entry points.
    pub(crate) components_layout: wgpu::BindGroupLayout,
    pub(crate) join_links: wgpu::ComputePipeline,
    pub(crate) flatten: wgpu::ComputePipeline,
    /// `shaders/cluster_unions.wgsl`'s layout and pass.
    pub(crate) unions_layout: wgpu::BindGroupLayout,
    unions_pipeline_layout: wgpu::PipelineLayout,
    pub(crate) cluster_unions: wgpu::ComputePipeline,
    /// GPU time of every pass run so far, where the device has timestamps.
    clock: PassClock,
    /// Buffers the large read-backs (lists, nearest points, fits, nodes) reuse.
    pub(crate) readback: slosh_render::ReadbackPool,
    /// The passes' inputs and outputs, kept from step to step (`dispatch::Pooled`), and the
    /// staging memory their inputs arrive through.
    pub(crate) memory: PassMemory,
    /// The steps' turns on this device: one queue for every bake that shares it.
    pub(crate) turns: Arc<slosh_bake::DeviceTurns>,
}

/// What [`GpuStages`] keeps between steps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct KeptBuffers {
    /// Bytes of the passes' inputs and outputs.
    pub pass_bytes: u64,
    /// Staging buffers ready for uploads.
    pub staging: usize,
    /// Buffers for read-backs.
    pub readback: usize,
}

/// The most bytes of pass buffers kept between steps, where the device's memory is not
/// known; else a quarter of it ([`kept_buffer_bytes`]).
const KEPT_BUFFER_BYTES: u64 = 2 << 30;

/// Pass buffers kept between steps: a quarter of the device's memory. The jobs are sized
/// to half of it, and the shelf holds only buffers they made and gave back, so it keeps
/// about what they use at once. A series of 64 steps of 1M points, 24 jobs on an H100 host
/// (80 GB), made 1544-1574 pass buffers afresh (26-28 GB) with 2 GB kept, and 1406-1413
/// (18-19 GB, the first steps' own) with 32 GB, and baked 3-8 % faster in two alternated
/// pairs and at 128 steps; with a quarter kept, 1-3 % faster at 64 steps and 4-7 % at 128
/// in five alternated pairs on another host.
fn kept_buffer_bytes(gpu: &Gpu) -> u64 {
    gpu.device_memory().map_or(KEPT_BUFFER_BYTES, |m| m / 4)
}

/// Staging buffers kept for the passes' inputs: enough for the uploads of many jobs in
/// flight at once (a series of 64 steps of 1M points, 24 jobs on an H100 host: 75-89 buffers
/// made afresh with 8 kept, each zeroed by wgpu and faulted in, 14-29 with 64).
const STAGING_BUFFERS_KEPT: usize = 64;

/// Staging buffers the pool's warm-up makes for each step in flight: a step's uploads
/// between two waits for the GPU, each holding its buffer until the GPU has read it. One
/// job's 1M-point steps on lavapipe kept 5 in all with 3 a step, and 8 with 6: the
/// uploads larger than the first make buffers of their own either way. 24 jobs still fill
/// the pool ([`STAGING_BUFFERS_KEPT`]).
const STAGING_BUFFERS_PER_STEP: usize = 3;

/// Reads from this size on reuse pooled buffers; smaller ones are cheap to make.
const POOLED_READ_BYTES: u64 = 1 << 20;

/// Read-back buffers kept for reuse: as many as steps commonly read back at once, each up to
/// [`OUTPUT_BATCH_BYTES`] (the series above: 174-232 made afresh with 3 kept, 19-27 with 24).
const READBACK_BUFFERS_KEPT: usize = 24;

/// The most host memory the kept staging buffers, and again the kept read-back buffers, hold:
/// a thirty-second of the memory available (where known), at most this.
const KEPT_HOST_BYTES: u64 = 2 << 30;

/// What [`KEPT_HOST_BYTES`] allows on this machine now.
fn kept_host_bytes() -> u64 {
    slosh_bake::available_memory().map_or(KEPT_HOST_BYTES, |m| (m / 32).min(KEPT_HOST_BYTES))
}

/// `cluster_unions` over a bitset of `span_words` words.
fn union_pipeline(
    gpu: &Gpu,
    layout: &wgpu::PipelineLayout,
    span_words: u32,
) -> Result<wgpu::ComputePipeline, slosh_render::Error> {
    let [pipeline] = entry_points(gpu, layout, &unions_source(span_words), ["cluster_unions"])?;
    Ok(pipeline)
}

/// The pipelines of a module's `entries`, each labelled by its name.
fn entry_points<const N: usize>(
    gpu: &Gpu,
    layout: &wgpu::PipelineLayout,
    source: &str,
    entries: [&str; N],
) -> Result<[wgpu::ComputePipeline; N], slosh_render::Error> {
    let mut pipelines = Vec::with_capacity(N);
    for entry in entries {
        pipelines.push(slosh_render::checked_pipeline(
            gpu,
            layout,
            entry,
            source.to_string(),
            entry,
            &[],
        )?);
    }
    pipelines
        .try_into()
        .map_err(|_| unreachable!("one pipeline per entry"))
}

/// Bindings every pass reads: positions, original indices, cell starts, residuals.
const GRID_BINDINGS: [(u32, bool); 4] = [(1, false), (2, false), (3, false), (10, false)];

impl slosh_bake::StepsInFlight for GpuStages {
    /// The staging pool's warm-up makes buffers for `steps` steps' uploads, not for as many
    /// as it keeps (64, for a series' 24 jobs at once): the buffers may live in the device's
    /// memory.
    fn steps_at_once(&self, steps: usize) {
        // Stages that baked a batch before have shrunk their shelf as its jobs ended.
        self.memory.planned.store(steps, Ordering::Relaxed);
        self.memory.buffers.set_limit(self.memory.kept_bytes);
        self.memory.staging.keep_at_most(STAGING_BUFFERS_KEPT);
        self.readback.keep_at_most(READBACK_BUFFERS_KEPT);
        self.memory
            .staging
            .warm_at_most(steps.saturating_mul(STAGING_BUFFERS_PER_STEP));
    }

    /// The kept pass, staging and read-back buffers shrink to the share of the steps still in
    /// flight, as each job finds no step left: freed while the others finish, on cores the
    /// series' tail leaves idle, where the stages' drop after the last step freed them all
    /// at once (0.42-0.63 s of a 9.5 s series of 64 steps of 1M points, 24 jobs, on an H100
    /// host in stop 61; with the pass buffers alone shrinking, the time after the last step
    /// was 0.33-0.54 s against 0.53-0.60 s in three alternated pairs in stop 65).
    fn steps_left(&self, steps: usize) {
        let planned = self.memory.planned.load(Ordering::Relaxed).max(1);
        let steps = steps.min(planned);
        let share = self.memory.kept_bytes / planned as u64 * steps as u64;
        self.memory.buffers.set_limit(share);
        // The host's pools too: a series' staging buffers may be mapped device memory.
        let of = |kept: usize| (kept * steps).div_ceil(planned);
        self.memory.staging.keep_at_most(of(STAGING_BUFFERS_KEPT));
        self.readback.keep_at_most(of(READBACK_BUFFERS_KEPT));
    }
}

impl GpuStages {
    /// The buffers kept between steps now.
    pub fn kept(&self) -> KeptBuffers {
        KeptBuffers {
            pass_bytes: self.memory.buffers.bytes(),
            staging: self.memory.staging.ready(),
            readback: self.readback.kept(),
        }
    }

    /// The passes, compiled for `gpu`; an error where the adapter refuses them.
    pub fn new(gpu: Arc<Gpu>) -> Result<GpuStages, slosh_render::Error> {
        let nearest_layout = layout(
            &gpu,
            "nearest points",
            &[GRID_BINDINGS.as_slice(), &[(4, true), (5, false)]].concat(),
        );
        let lists_layout = layout(
            &gpu,
            "neighbour lists",
            &[
                GRID_BINDINGS.as_slice(),
                &[
                    (4, false),
                    (5, false),
                    (6, false),
                    (7, true),
                    (8, false),
                    (9, true),
                    (11, false),
                    (12, true),
                    (13, true),
                ],
            ]
            .concat(),
        );
        let pipeline_layout = |layout: &wgpu::BindGroupLayout| {
            gpu.device
                .create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                    label: Some("neighbour search"),
                    bind_group_layouts: &[Some(layout)],
                    immediate_size: 0,
                })
        };
        let fits_layout = layout(
            &gpu,
            "initial fits",
            &[
                (1, false),
                (2, false),
                (3, false),
                (4, false),
                (5, false),
                (6, false),
                (7, false),
                (8, true),
            ],
        );
        let fits_pipeline_layout = pipeline_layout(&fits_layout);
        let nearest_pipeline_layout = pipeline_layout(&nearest_layout);
        let lists_pipeline_layout = pipeline_layout(&lists_layout);
        let nearest = slosh_render::checked_pipeline(
            &gpu,
            &nearest_pipeline_layout,
            "nearest",
            nearest_source(),
            "nearest",
            &[],
        )?;
        let cut = slosh_render::checked_pipeline(
            &gpu,
            &lists_pipeline_layout,
            "cut_lists",
            lists_source(),
            "cut_lists",
            &[],
        )?;
        let write = slosh_render::checked_pipeline(
            &gpu,
            &lists_pipeline_layout,
            "write_lists",
            lists_source(),
            "write_lists",
            &[],
        )?;
        // The points (binding 1 and 10), the votes (4), each point's nearest (5), the normals.
        let orient_layout = layout(
            &gpu,
            "orientation votes",
            &[(1, false), (10, false), (4, true), (5, false), (6, false)],
        );
        let orient_votes = slosh_render::checked_pipeline(
            &gpu,
            &pipeline_layout(&orient_layout),
            "orient_votes",
            orient_votes_source(),
            "orient_votes",
            &[],
        )?;
        let tree_layout = layout(
            &gpu,
            "bvh build",
            &[
                (1, false),
                (2, false),
                (3, true),
                (4, true),
                (5, true),
                (6, true),
                (7, true),
            ],
        );
        let tree_pipeline_layout = pipeline_layout(&tree_layout);
        let [
            link_nodes,
            measure_depths,
            place_nodes,
            fit_boxes,
            next_depth,
        ] = entry_points(
            &gpu,
            &tree_pipeline_layout,
            &tree_source(),
            [
                "link_nodes",
                "measure_depths",
                "place_nodes",
                "fit_boxes",
                "next_depth",
            ],
        )?;
        let components_layout = layout(
            &gpu,
            "spray components",
            &[(1, false), (2, false), (3, true)],
        );
        let [join_links, flatten] = entry_points(
            &gpu,
            &pipeline_layout(&components_layout),
            &components_source(),
            ["join_links", "flatten"],
        )?;
        let unions_layout = layout(
            &gpu,
            "cluster unions",
            &[(1, false), (2, false), (3, true), (4, false), (5, true)],
        );
        let unions_pipeline_layout = pipeline_layout(&unions_layout);
        let cluster_unions = union_pipeline(&gpu, &unions_pipeline_layout, UNION_SPAN_WORDS)?;
        let buffers = slosh_render::BufferShelf::of(crate::dispatch::PASS_BUFFER_USAGE, true);
        let kept_bytes = kept_buffer_bytes(&gpu);
        buffers.set_limit(kept_bytes);
        // Read once (from /proc/meminfo) for both pools.
        let kept_host = kept_host_bytes();
        Ok(GpuStages {
            nearest_layout,
            nearest,
            orient_layout,
            orient_votes,
            lists_layout,
            cut,
            write,
            fits_layout,
            fits_pipeline_layout,
            fits: Default::default(),
            tree_layout,
            link_nodes,
            measure_depths,
            place_nodes,
            fit_boxes,
            next_depth,
            components_layout,
            join_links,
            flatten,
            unions_layout,
            unions_pipeline_layout,
            cluster_unions,
            clock: PassClock::new(&gpu),
            readback: slosh_render::ReadbackPool::new(READBACK_BUFFERS_KEPT).within(kept_host),
            memory: PassMemory {
                gpu: gpu.clone(),
                buffers,
                kept_bytes,
                planned: AtomicUsize::new(1),
                staging: slosh_render::StagingPool::new(STAGING_BUFFERS_KEPT).within(kept_host),
            },
            turns: Arc::new(slosh_bake::DeviceTurns::new(STEPS_ON_DEVICE)),
            gpu,
        })
    }

    /// The cluster unions' pass rebuilt with a bitset of `words` words, rounded down to an
    /// even number of at least 2 (the shader's is [`UNION_SPAN_WORDS`]), so that a test's
    /// small set has clusters wider than it.
    pub fn narrow_union_span(&mut self, words: u32) -> Result<(), slosh_render::Error> {
        self.cluster_unions =
            union_pipeline(&self.gpu, &self.unions_pipeline_layout, words.max(2) & !1)?;
        Ok(())
    }

    /// GPU seconds of every pass this search has run (timestamp queries, not wall time:
    /// transfers and the host's work are not in it), or `None` where the device has no
    /// timestamps. Read before and after a bake for that bake's GPU time.
    pub fn gpu_seconds(&self) -> Option<f64> {
        self.gpu.timestamps.then(|| {
            self.clock.settle(&self.gpu);
            self.clock.seconds()
        })
    }

    /// [`GpuStages::gpu_seconds`] by pass, in the order the passes first ran: read before
    /// and after a bake for where its GPU time went. Empty where the device has no
    /// timestamps.
    pub fn gpu_seconds_by_pass(&self) -> Vec<(&'static str, f64)> {
        self.clock.settle(&self.gpu);
        self.clock.seconds_by_pass()
    }

    /// Records `dispatches` over `group` in one pass and submits them, timed (where the device
    /// has timestamps) into [`GpuStages::gpu_seconds`] under `pass` without waiting. Returns
    /// the submission, for a caller that waits for it.
    pub(crate) fn run(
        &self,
        pass: &'static str,
        dispatches: &[(&wgpu::ComputePipeline, (u32, u32))],
        group: &wgpu::BindGroup,
    ) -> wgpu::SubmissionIndex {
        let gpu = &self.gpu;
        let mut encoder = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("bake pass"),
            });
        let stamps = self.clock.stamps(gpu);
        record(&mut encoder, dispatches, group, stamps.as_ref());
        slosh_bake::device_busy();
        let submitted = gpu.queue.submit([encoder.finish()]);
        if let Some(stamps) = stamps {
            self.clock.submitted(pass, stamps, submitted.clone());
        }
        submitted
    }

    /// Compiles the initial fits for `degree` now rather than in the first step's bake (a
    /// software adapter takes a second).
    pub fn compile_fits(&self, degree: u8) -> Result<(), slosh_render::Error> {
        self.fits_pipeline(degree).map(|_| ())
    }

    /// The initial fits' pipeline for `degree` (1–3).
    pub(crate) fn fits_pipeline(
        &self,
        degree: u8,
    ) -> Result<&wgpu::ComputePipeline, slosh_render::Error> {
        let degree = degree.clamp(1, 3);
        let slot = &self.fits[usize::from(degree) - 1];
        if let Some(pipeline) = slot.get() {
            return Ok(pipeline);
        }
        let pipeline = slosh_render::checked_pipeline(
            &self.gpu,
            &self.fits_pipeline_layout,
            "initial_fits",
            fits_source(),
            "initial_fits",
            &[("FIT_DEGREE", f64::from(degree))],
        )?;
        Ok(slot.get_or_init(|| pipeline))
    }

    /// `bytes` of `source` copied out, once the work submitted before has run. Reads of a
    /// megabyte or more go through the pool of read-back buffers, copied out by every thread
    /// (one thread's copy of a 1M step's fits, 64 MB, took tens of milliseconds).
    pub(crate) fn read_back<T: bytemuck::Pod + Send + Sync>(
        &self,
        source: &wgpu::Buffer,
        bytes: u64,
    ) -> Result<Vec<T>, slosh_mls::SurfaceError> {
        if bytes == 0 {
            return Ok(Vec::new());
        }
        if bytes >= POOLED_READ_BYTES {
            let mut out = Vec::new();
            self.read_into(source, bytes, &mut out).map(|()| out)
        } else {
            slosh_bake::device_busy();
            let read = slosh_render::read_storage(&self.gpu, source, bytes);
            slosh_bake::device_idle();
            read.map_err(gpu_error)
        }
    }

    /// `bytes` of `source` appended to `out` through the pool of read-back buffers, once the
    /// work submitted before has run; the step's turn on the device is given back after.
    pub(crate) fn read_into<T: bytemuck::Pod + Send + Sync>(
        &self,
        source: &wgpu::Buffer,
        bytes: u64,
        out: &mut Vec<T>,
    ) -> Result<(), slosh_mls::SurfaceError> {
        slosh_bake::device_busy();
        let read = self.readback.read_into(&self.gpu, source, bytes, out);
        slosh_bake::device_idle();
        read.map_err(gpu_error)
    }

    pub fn gpu(&self) -> &Gpu {
        &self.gpu
    }

    /// The most bytes one output of a dispatch takes.
    pub(crate) fn output_limit(&self) -> u64 {
        OUTPUT_BATCH_BYTES.min(self.gpu.max_binding())
    }
}
