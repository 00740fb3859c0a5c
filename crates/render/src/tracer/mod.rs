//! The trace and shade compute passes: pipelines, bind groups, a frame's buffers, readback and
//! GPU timestamps.
//!
//! `shaders/trace.wgsl`'s entry points share one BVH walk to the next candidate in the order
//! of initial hits: `trace_initial` (one iteration, no refinement code, a small kernel) and
//! `trace_refined` (Adamson & Alexa: refine that candidate, hand over to the next when the
//! hit leaves its ball). The walk descends the 4-wide tree the tracer widens
//! (four boxes per 128-byte read over half the levels), keeps the node in hand in registers
//! and descends to a leaf before testing it (while-while, after Aila & Laine), stacking the
//! other entered slots, farthest first, as packed (first, count) links, so a pop reads no
//! node. The module is built without wgpu's loop guards: the upload checks that every BVH
//! child follows its parent, so every walk ends. Hits are stored as whole words; a miss
//! writes its status word alone.
//!
//! Pipelines are built on first use per traversal stack size (32, 64 or 96 entries, by the
//! step's BVH depth: WGSL sizes private arrays by constants only) and per fit degree (a
//! pipeline override, so the fit's loops have constant bounds). The fit accumulates its
//! normal equations in register blocks: dynamically indexed private arrays live in slow
//! per-thread memory on GPUs.
//!
//! [`Tracer::targets`] makes one image size's buffers (hits, packed pixels, the uniforms in
//! group 1, and an `Rgba8Unorm` texture that `shaders/present.wgsl` fills, for egui-wgpu's
//! `register_native_texture`); [`Tracer::record`] records trace, shade (or water) and present
//! into the caller's encoder; [`Tracer::run`] and [`Tracer::render`] submit, wait and read
//! back. The tracer holds the neighbour masks of the step it last refined (`masks.rs`,
//! group 2; a frame of one iteration binds an empty group there) and the 4-wide tree of the
//! step it last drew (`widen.rs`, group 3).

use std::sync::{Mutex, OnceLock, PoisonError};

use slosh_mls::Camera;

use crate::bindings::{bind_entries, capacity, layout_entries, needs_split};
use crate::context::Gpu;
use crate::error::{Error, Result};
use crate::layout::{GpuHit, GpuSettings};
use crate::masks::{MaskProgress, NeighbourMasks, candidate_buffer, cluster_count, mask_buffer};
use crate::shaders::{
    FRAME_ARRAYS, PRESENT_ARRAYS, TEXTURE_BINDING, TRACE_STACK_SIZES, present_wgsl, shade_wgsl,
    trace_wgsl,
};

use crate::upload::GpuStep;
use crate::widen::Widening;

/// The format of a frame's texture: the shaded pixels' bytes as they are (sRGB-encoded).
pub const FRAME_TEXTURE_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;

mod params;
mod readback;
mod rows;

pub use params::{ShadeMode, TraceParams, settings};
pub use readback::{PendingHit, ReadbackPool, read_buffer, read_storage};
pub use rows::RowSet;

/// A rendered frame read back from the GPU.
#[derive(Debug, Clone)]
pub struct Frame {
    pub width: u32,
    pub height: u32,
    /// Row-major, y down, in the cache's local coordinates.
    pub hits: Vec<GpuHit>,
    /// Row-major RGBA8 (sRGB), as little-endian u32s.
    pub rgba: Vec<u32>,
}

/// GPU times of one frame's passes, in milliseconds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PassTimes {
    pub trace_ms: f64,
    pub shade_ms: f64,
}

/// The trace pass built for one traversal stack size; pipelines are built when first asked
/// for.
#[derive(Debug)]
struct TraceVariant {
    module: wgpu::ShaderModule,
    /// One iteration: the nearest initial hit, a lean kernel; by [`BallKnowledge`].
    initial: BallSlots,
    /// More: candidates refined in the order of their initial hits, one pipeline per fit
    /// degree (1–3, the `FIT_DEGREE` override), by [`BallKnowledge`].
    refined: [BallSlots; 3],
    /// The water pass (secondary rays), in place of the shade pass; by [`BallKnowledge`].
    water: BallSlots,
}

/// Pipelines of one entry point, one per way of knowing a ball's degree (`BALL_DEGREE`: the
/// step's one degree 0–3, or 4: each ball's state) and h (`BALL_H`: 0 the step's, 1 each
/// ball's), so that the common step (no degraded fit, one h) traces with neither fallback
/// compiled in (mls.wgsl).
type BallSlots = [[OnceLock<wgpu::ComputePipeline>; 2]; 5];

/// What a step's frames compile in about its balls: the `BALL_DEGREE` and `BALL_H`
/// overrides of mls.wgsl.
#[derive(Debug, Clone, Copy)]
struct BallKnowledge {
    degree: u8,
    per_point_h: bool,
}

impl BallKnowledge {
    fn of(step: &GpuStep) -> BallKnowledge {
        BallKnowledge {
            degree: step.info.ball_degree.map_or(4, |d| d.min(3)),
            per_point_h: step.info.per_point_h,
        }
    }

    fn slot<'a>(&self, slots: &'a BallSlots) -> &'a OnceLock<wgpu::ComputePipeline> {
        &slots[usize::from(self.degree)][usize::from(self.per_point_h)]
    }

    fn constants(&self) -> [(&'static str, f64); 2] {
        [
            ("BALL_DEGREE", f64::from(self.degree)),
            ("BALL_H", f64::from(u8::from(self.per_point_h))),
        ]
    }
}

/// The compiled passes. Trace pipelines are built on first use, for the smallest stack in
/// `TRACE_STACK_SIZES` that holds the step's BVH, and with arrays read from one binding or,
/// where one spans several, from `RANGES` (`split`).
#[derive(Debug)]
pub struct Tracer {
    traces: [[OnceLock<TraceVariant>; 2]; TRACE_STACK_SIZES.len()],
    layout: wgpu::PipelineLayout,
    /// The shade pass, by split.
    shade: [OnceLock<wgpu::ComputePipeline>; 2],
    /// The present pass (image into the frame's texture), by split.
    present: [OnceLock<wgpu::ComputePipeline>; 2],
    present_layout: wgpu::BindGroupLayout,
    present_pipeline_layout: wgpu::PipelineLayout,
    frame_layout: wgpu::BindGroupLayout,
    masks: NeighbourMasks,
    widening: Widening,
    /// Held from a frame's recording to its submission in [`Tracer::run`]: which step's tree
    /// and masks are held changes when a frame is recorded, and what the held buffers hold
    /// changes when it is submitted, so another thread's frame between the two would find
    /// its step held and draw with what this frame wrote.
    frames: Mutex<()>,
    /// The binding limit the modules and bind groups are made for (`Gpu::max_binding` when
    /// the tracer was built).
    limit: u64,
}

/// One frame size's GPU buffers, texture and bind groups; any step can be traced into them.
#[derive(Debug)]
pub struct FrameTargets {
    width: u32,
    height: u32,
    settings: wgpu::Buffer,
    hits: wgpu::Buffer,
    image: wgpu::Buffer,
    /// The shaded image as an `Rgba8Unorm` texture (sRGB-encoded bytes, as in `image`), for
    /// a window toolkit to draw.
    texture: wgpu::Texture,
    /// Whether an array of the frame spans several bindings.
    split: bool,
    frame_group: wgpu::BindGroup,
    present_group: wgpu::BindGroup,
    queries: Option<(wgpu::QuerySet, wgpu::Buffer, wgpu::Buffer)>,
}

impl FrameTargets {
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// The shaded image of the last frame recorded into these targets: `Rgba8Unorm`, usable
    /// as a texture binding, a storage binding and a copy source.
    pub fn texture(&self) -> &wgpu::Texture {
        &self.texture
    }

    /// The per-pixel hits buffer (three 16-byte words per pixel, `GpuHit`'s layout).
    pub fn hits(&self) -> &wgpu::Buffer {
        &self.hits
    }

    /// The shaded image as packed RGBA8 words, row-major.
    pub fn image(&self) -> &wgpu::Buffer {
        &self.image
    }
}

fn compute_pipeline(
    device: &wgpu::Device,
    layout: &wgpu::PipelineLayout,
    module: &wgpu::ShaderModule,
    entry: &str,
    constants: &[(&str, f64)],
) -> wgpu::ComputePipeline {
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(entry),
        layout: Some(layout),
        module,
        entry_point: Some(entry),
        compilation_options: wgpu::PipelineCompilationOptions {
            constants,
            ..Default::default()
        },
        cache: None,
    })
}

/// A WGSL module, validation errors caught. `trusted_loops` drops wgpu's loop guards (a
/// 64-bit counter checked on every iteration of every loop, 4 % of a 1-iteration frame on an
/// H100): only for the trace module, whose loops all end: the walk's because the upload
/// checks that children follow their parents (`check_tree`), the rest by constant or
/// uniform bounds. Bounds checks stay on.
fn shader_module(
    gpu: &Gpu,
    label: &str,
    source: String,
    trusted_loops: bool,
) -> Result<wgpu::ShaderModule> {
    let scope = gpu.device.push_error_scope(wgpu::ErrorFilter::Validation);
    let desc = wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    };
    let module = if trusted_loops {
        let checks = wgpu::ShaderRuntimeChecks {
            force_loop_bounding: false,
            ..wgpu::ShaderRuntimeChecks::checked()
        };
        // SAFETY: every loop of the trace module terminates (above); bounds checks are kept.
        unsafe { gpu.device.create_shader_module_trusted(desc, checks) }
    } else {
        gpu.device.create_shader_module(desc)
    };
    match pollster::block_on(scope.pop()) {
        Some(e) => Err(Error::Validation(e.to_string())),
        None => Ok(module),
    }
}

impl Tracer {
    pub fn new(gpu: &Gpu) -> Result<Tracer> {
        let device = &gpu.device;
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let step_layout = gpu.step_layout();
        let frame_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("frame"),
            entries: &layout_entries(&FRAME_ARRAYS, true),
        });
        let masks = NeighbourMasks::new(gpu, gpu.max_binding());
        let widening = Widening::new(gpu, gpu.max_binding());
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("slosh"),
            bind_group_layouts: &[
                Some(step_layout),
                Some(&frame_layout),
                Some(masks.layout()),
                Some(widening.layout()),
            ],
            immediate_size: 0,
        });
        let mut present_entries = layout_entries(&PRESENT_ARRAYS, false);
        present_entries.push(wgpu::BindGroupLayoutEntry {
            binding: TEXTURE_BINDING,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::StorageTexture {
                access: wgpu::StorageTextureAccess::WriteOnly,
                format: FRAME_TEXTURE_FORMAT,
                view_dimension: wgpu::TextureViewDimension::D2,
            },
            count: None,
        });
        let present_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("present"),
            entries: &present_entries,
        });
        let present_pipeline_layout =
            device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("present"),
                bind_group_layouts: &[Some(&present_layout)],
                immediate_size: 0,
            });
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(Error::Validation(e.to_string()));
        }
        let tracer = Tracer {
            traces: Default::default(),
            layout,
            shade: Default::default(),
            present: Default::default(),
            present_layout,
            present_pipeline_layout,
            frame_layout,
            masks,
            widening,
            frames: Mutex::new(()),
            limit: gpu.max_binding(),
        };
        // The shade pass is built now: a device that cannot take the layout fails here.
        tracer.shade_pipeline(gpu, false)?;
        tracer.present_pipeline(gpu, false)?;
        Ok(tracer)
    }

    fn present_pipeline(&self, gpu: &Gpu, split: bool) -> Result<&wgpu::ComputePipeline> {
        let slot = &self.present[usize::from(split)];
        if let Some(pipeline) = slot.get() {
            return Ok(pipeline);
        }
        let module = shader_module(gpu, "present", present_wgsl(self.limit, split), false)?;
        let scope = gpu.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let pipeline = compute_pipeline(
            &gpu.device,
            &self.present_pipeline_layout,
            &module,
            "present",
            &[],
        );
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(Error::Validation(e.to_string()));
        }
        Ok(slot.get_or_init(|| pipeline))
    }

    fn shade_pipeline(&self, gpu: &Gpu, split: bool) -> Result<&wgpu::ComputePipeline> {
        let slot = &self.shade[usize::from(split)];
        if let Some(pipeline) = slot.get() {
            return Ok(pipeline);
        }
        let module = shader_module(gpu, "shade", shade_wgsl(self.limit, split), false)?;
        let pipeline = self.build(gpu, &module, "shade", &[])?;
        Ok(slot.get_or_init(|| pipeline))
    }

    /// Buffers, texture and bind groups for `width` × `height` frames of any step; an error
    /// where the frame's hits exceed `RANGES` bindings.
    /// The most pixels a frame can have on `gpu`: its hits and its image must each bind
    /// (a larger view is traced smaller and stretched, as the player does).
    pub fn max_frame_pixels(&self, gpu: &Gpu) -> u64 {
        let hits = capacity(&gpu.device, self.limit, &FRAME_ARRAYS[0]) / size_of::<GpuHit>() as u64;
        let image = capacity(&gpu.device, self.limit, &FRAME_ARRAYS[1]) / 4;
        hits.min(image)
    }

    pub fn targets(&self, gpu: &Gpu, width: u32, height: u32) -> Result<FrameTargets> {
        let device = &gpu.device;
        let (width, height) = (width.max(1), height.max(1));
        let pixels = u64::from(width) * u64::from(height);
        let hit_bytes = pixels * size_of::<GpuHit>() as u64;
        let hits_what = format!("hits of a {width}×{height} frame");
        let hits_split = needs_split(
            &gpu.device,
            &gpu.describe(),
            self.limit,
            &FRAME_ARRAYS[0],
            &hits_what,
            hit_bytes,
        );
        let image_split = needs_split(
            &gpu.device,
            &gpu.describe(),
            self.limit,
            &FRAME_ARRAYS[1],
            "image",
            pixels * 4,
        );
        let split =
            hits_split.map_err(Error::Validation)? || image_split.map_err(Error::Validation)?;
        let max_side = device.limits().max_texture_dimension_2d;
        if width > max_side || height > max_side {
            return Err(Error::Validation(format!(
                "a {width}×{height} frame exceeds {}'s largest texture ({max_side} pixels a side)",
                gpu.describe()
            )));
        }
        let buffer = |label, size: u64, usage| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage,
                mapped_at_creation: false,
            })
        };
        use wgpu::BufferUsages as U;
        let settings = buffer(
            "settings",
            size_of::<GpuSettings>() as u64,
            U::UNIFORM | U::COPY_DST,
        );
        let hits = buffer("hits", hit_bytes, U::STORAGE | U::COPY_SRC);
        let image = buffer("image", pixels * 4, U::STORAGE | U::COPY_SRC);
        let frame_buffers = [&hits, &image];
        let frame_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("frame"),
            layout: &self.frame_layout,
            entries: &bind_entries(&FRAME_ARRAYS, &frame_buffers, Some(&settings), self.limit),
        });
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("frame texture"),
            size: wgpu::Extent3d {
                width,
                height,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: FRAME_TEXTURE_FORMAT,
            usage: wgpu::TextureUsages::STORAGE_BINDING
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
        let mut present_entries = bind_entries(&PRESENT_ARRAYS, &[&image], None, self.limit);
        present_entries.push(wgpu::BindGroupEntry {
            binding: TEXTURE_BINDING,
            resource: wgpu::BindingResource::TextureView(&view),
        });
        let present_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("present"),
            layout: &self.present_layout,
            entries: &present_entries,
        });
        let queries = gpu.timestamps.then(|| {
            let set = device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("pass times"),
                ty: wgpu::QueryType::Timestamp,
                count: 4,
            });
            (
                set,
                buffer("timestamps", 32, U::QUERY_RESOLVE | U::COPY_SRC),
                buffer("timestamps readback", 32, U::MAP_READ | U::COPY_DST),
            )
        });
        Ok(FrameTargets {
            width,
            height,
            settings,
            hits,
            image,
            texture,
            split,
            frame_group,
            present_group,
            queries,
        })
    }

    /// A pipeline of the trace module's `entry` with `constants`, validation errors caught.
    fn build(
        &self,
        gpu: &Gpu,
        module: &wgpu::ShaderModule,
        entry: &str,
        constants: &[(&str, f64)],
    ) -> Result<wgpu::ComputePipeline> {
        let scope = gpu.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let pipeline = compute_pipeline(&gpu.device, &self.layout, module, entry, constants);
        match pollster::block_on(scope.pop()) {
            Some(e) => Err(Error::Validation(e.to_string())),
            None => Ok(pipeline),
        }
    }

    /// The trace module for `step`'s BVH: the smallest stack that holds it.
    fn variant(&self, gpu: &Gpu, step: &GpuStep, split: bool) -> Result<&TraceVariant> {
        // The wide tree has half the levels, each stacking up to three slots.
        let needed = u32::try_from(3 * step.info.bvh_depth.div_ceil(2) + 2).unwrap_or(u32::MAX);
        let slot = TRACE_STACK_SIZES
            .iter()
            .position(|&size| size >= needed)
            .ok_or_else(|| {
                Error::Validation(format!(
                    "BVH depth {} exceeds the trace stack",
                    step.info.bvh_depth
                ))
            })?;
        let cell = &self.traces[slot][usize::from(split)];
        if let Some(variant) = cell.get() {
            return Ok(variant);
        }
        let source = trace_wgsl(TRACE_STACK_SIZES[slot], self.limit, split);
        let module = shader_module(gpu, "trace", source, true)?;
        Ok(cell.get_or_init(|| TraceVariant {
            module,
            initial: Default::default(),
            refined: Default::default(),
            water: Default::default(),
        }))
    }

    /// `slot`'s pipeline of the variant's `entry` with `constants`, built on first use.
    fn cached<'a>(
        &self,
        gpu: &Gpu,
        variant: &TraceVariant,
        slot: &'a OnceLock<wgpu::ComputePipeline>,
        entry: &str,
        constants: &[(&str, f64)],
    ) -> Result<&'a wgpu::ComputePipeline> {
        if let Some(pipeline) = slot.get() {
            return Ok(pipeline);
        }
        let pipeline = self.build(gpu, &variant.module, entry, constants)?;
        Ok(slot.get_or_init(|| pipeline))
    }

    /// The trace pipeline: one iteration, or refinement with fits of `degree` (1–3), for
    /// steps whose balls are known as `balls` says.
    fn trace_pipeline<'a>(
        &self,
        gpu: &Gpu,
        variant: &'a TraceVariant,
        iterations: u32,
        degree: u8,
        balls: BallKnowledge,
    ) -> Result<&'a wgpu::ComputePipeline> {
        let [d, h] = balls.constants();
        if iterations <= 1 {
            let slot = balls.slot(&variant.initial);
            return self.cached(gpu, variant, slot, "trace_initial", &[d, h]);
        }
        let degree = degree.clamp(1, 3);
        let slot = balls.slot(&variant.refined[usize::from(degree) - 1]);
        let fit = ("FIT_DEGREE", f64::from(degree));
        self.cached(gpu, variant, slot, "trace_refined", &[fit, d, h])
    }

    /// Records the trace, shade and present passes (trace and shade timed where the targets
    /// have timestamp queries).
    #[allow(clippy::too_many_arguments)]
    fn encode(
        &self,
        step: &GpuStep,
        targets: &FrameTargets,
        [masks, tree]: [&wgpu::BindGroup; 2],
        passes: [&wgpu::ComputePipeline; 3],
        rows: RowSet,
        present_frame: bool,
        encoder: &mut wgpu::CommandEncoder,
    ) {
        let groups = (
            targets.width.div_ceil(8),
            rows.count(targets.height).div_ceil(8),
        );
        let [trace, shade, present] = passes;
        for (i, pipeline) in [trace, shade].into_iter().enumerate() {
            let timestamp_writes =
                targets
                    .queries
                    .as_ref()
                    .map(|(set, _, _)| wgpu::ComputePassTimestampWrites {
                        query_set: set,
                        beginning_of_pass_write_index: Some(2 * i as u32),
                        end_of_pass_write_index: Some(2 * i as u32 + 1),
                    });
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some(if i == 0 { "trace" } else { "shade" }),
                timestamp_writes,
            });
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, step.bind_group(), &[]);
            pass.set_bind_group(1, &targets.frame_group, &[]);
            pass.set_bind_group(2, masks, &[]);
            pass.set_bind_group(3, tree, &[]);
            pass.dispatch_workgroups(groups.0, groups.1, 1);
        }
        // The texture takes the image once its last rows are in, so it never shows a frame
        // half drawn.
        if present_frame {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("present"),
                timestamp_writes: None,
            });
            pass.set_pipeline(present);
            pass.set_bind_group(0, &targets.present_group, &[]);
            pass.dispatch_workgroups(groups.0, targets.height.div_ceil(8), 1);
        }
        if let Some((set, resolve, readback)) = &targets.queries {
            encoder.resolve_query_set(set, 0..4, resolve, 0);
            encoder.copy_buffer_to_buffer(resolve, 0, readback, 0, 32);
        }
    }

    /// Records one frame of `step` into `encoder` (trace, shade, and the image into the
    /// targets' texture) without submitting or waiting: the way an app embeds the tracer.
    /// A refined frame of a step other than the last one refined first records the step's
    /// neighbour-mask pass.
    /// The frame's uniforms go through `queue.write_buffer`, so they are in place for the
    /// next submission; one frame per targets per submission.
    ///
    /// The held tree and masks are written in the encoders of the frames that found them
    /// another step's, and read by later frames as held: submit every encoder recorded into,
    /// in the order recorded, before another thread records with this tracer (as
    /// [`Tracer::run`] does under the tracer's lock). An encoder dropped unsubmitted after
    /// a record (its frame failed further on) calls for [`Tracer::forget_held`].
    pub fn record(
        &self,
        gpu: &Gpu,
        step: &GpuStep,
        targets: &FrameTargets,
        camera: &Camera,
        params: &TraceParams,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<()> {
        self.record_rows(
            gpu,
            step,
            targets,
            camera,
            params,
            RowSet::WHOLE,
            true,
            encoder,
        )
    }

    /// [`Tracer::record`] for a set of the frame's rows: the trace and shade passes cover
    /// only `rows`, and the texture takes the image where `present_frame` (the set that
    /// completes the frame). A frame recorded set by set, one set per submission with the
    /// same camera and parameters, holds the pixels of one recorded whole: every pass is per
    /// pixel.
    #[allow(clippy::too_many_arguments)]
    pub fn record_rows(
        &self,
        gpu: &Gpu,
        step: &GpuStep,
        targets: &FrameTargets,
        camera: &Camera,
        params: &TraceParams,
        rows: RowSet,
        present_frame: bool,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<()> {
        self.check_limit(step)?;
        if rows.count(targets.height) == 0 {
            return Err(Error::Validation(format!(
                "rows {rows:?} hold none of a frame {} rows high (a stride of at least 1 and a first row inside the frame)",
                targets.height
            )));
        }
        let mut camera = *camera;
        camera.width = targets.width;
        camera.height = targets.height;
        let mut uniforms = settings(step, &camera, params);
        uniforms.first_row = rows.first;
        uniforms.row_stride = rows.stride;
        gpu.queue
            .write_buffer(&targets.settings, 0, bytemuck::bytes_of(&uniforms));
        let split = step.split || targets.split;
        let variant = self.variant(gpu, step, split)?;
        let balls = BallKnowledge::of(step);
        let trace = self.trace_pipeline(gpu, variant, params.iterations, params.degree, balls)?;
        let shade = if params.mode == ShadeMode::Water {
            let slot = balls.slot(&variant.water);
            self.cached(gpu, variant, slot, "water", &balls.constants())?
        } else {
            self.shade_pipeline(gpu, split)?
        };
        let present = self.present_pipeline(gpu, targets.split)?;
        let masks = self
            .masks
            .group_for(gpu, step, params.iterations > 1, encoder)?;
        let tree = self.widening.group_for(gpu, step, encoder)?;
        self.encode(
            step,
            targets,
            [&masks, &tree],
            [trace, shade, present],
            rows,
            present_frame,
            encoder,
        );
        Ok(())
    }

    /// Forgets whose tree and masks the held buffers hold, keeping the buffers, so that the
    /// next frame writes its step's again: for a caller that dropped an encoder it had
    /// recorded into, whose writes never ran.
    pub fn forget_held(&self) {
        self.masks.forget();
        self.widening.forget();
    }

    /// Bytes of the neighbour masks the tracer holds (one step's, once a frame refined).
    pub fn mask_bytes(&self) -> u64 {
        self.masks.held_bytes()
    }

    /// Bytes of the 4-wide tree the tracer holds (the last drawn step's).
    pub fn tree_bytes(&self) -> u64 {
        self.widening.held_bytes()
    }

    /// `step`'s neighbour masks and expanded candidates in new buffers, their pass recorded
    /// into `encoder` and timed into `timestamps` (a set of 2) where given: what a step's
    /// first refined frame records, for tests that check them and benches that time the
    /// pass.
    pub fn neighbour_masks(
        &self,
        gpu: &Gpu,
        step: &GpuStep,
        encoder: &mut wgpu::CommandEncoder,
        timestamps: Option<&wgpu::QuerySet>,
    ) -> Result<(wgpu::Buffer, wgpu::Buffer)> {
        self.check_limit(step)?;
        let masks = mask_buffer(gpu, step.info.mask_bytes());
        let candidates = candidate_buffer(gpu, step.info.candidate_bytes());
        let clusters = 0..cluster_count(step);
        self.masks.record(
            gpu,
            step,
            (&masks, &candidates),
            clusters,
            encoder,
            timestamps,
        )?;
        Ok((masks, candidates))
    }

    /// Derives up to `clusters` more clusters of the neighbour masks of `step` into
    /// `encoder`, ahead of its first refined frame: a slow adapter spreads the pass over
    /// several submissions, where a refined frame would derive all that is missing at once.
    /// Submit `encoder` as [`Tracer::record`] says.
    pub fn derive_masks(
        &self,
        gpu: &Gpu,
        step: &GpuStep,
        clusters: u32,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<MaskProgress> {
        self.check_limit(step)?;
        self.masks.derive(gpu, step, clusters, encoder)
    }

    /// How far the neighbour masks of `step` are derived.
    pub fn mask_progress(&self, step: &GpuStep) -> MaskProgress {
        self.masks.progress(step)
    }

    fn check_limit(&self, step: &GpuStep) -> Result<()> {
        if step.binding_limit() != self.limit {
            return Err(Error::Validation(format!(
                "the step was uploaded for bindings of {} bytes, the tracer built for {}",
                step.binding_limit(),
                self.limit
            )));
        }
        Ok(())
    }

    /// Traces and shades one frame on the GPU and waits for it; the pass times when the
    /// adapter has timestamp queries.
    pub fn run(
        &self,
        gpu: &Gpu,
        step: &GpuStep,
        targets: &FrameTargets,
        camera: &Camera,
        params: &TraceParams,
    ) -> Result<Option<PassTimes>> {
        let scope = gpu.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let mut encoder = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("frame"),
            });
        let frames = self.frames.lock().unwrap_or_else(PoisonError::into_inner);
        if let Err(e) = self.record(gpu, step, targets, camera, params, &mut encoder) {
            // The encoder is dropped with what the frame recorded before it failed.
            self.forget_held();
            return Err(e);
        }
        let submitted = gpu.queue.submit([encoder.finish()]);
        drop(frames);
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(Error::Validation(e.to_string()));
        }
        if targets.queries.is_none() {
            gpu.wait_for(submitted)?;
        }
        self.pass_times(gpu, targets)
    }

    /// Renders one frame and reads its hits and pixels back.
    pub fn render(
        &self,
        gpu: &Gpu,
        step: &GpuStep,
        camera: &Camera,
        params: &TraceParams,
    ) -> Result<Frame> {
        let targets = self.targets(gpu, camera.width, camera.height)?;
        self.run(gpu, step, &targets, camera, params)?;
        self.read_frame(gpu, &targets)
    }
}
