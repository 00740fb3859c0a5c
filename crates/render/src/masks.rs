//! The neighbour masks of `shaders/expand.wgsl`: a bit per cluster candidate saying whether
//! it is in the point's neighbour list, so the refinement loops visit the list itself instead
//! of filtering every candidate each time.
//!
//! Only refinement reads them, and they are the largest thing a step would hold (about a
//! third of its bytes), so no step holds them: the tracer keeps one set, for the step it
//! last refined, and derives it again, in the same submission as the frame, when a refined
//! frame asks for another step. One-iteration frames (scrubbing) never run the pass.

use std::sync::{Mutex, PoisonError};

use crate::bindings::bind_entries;
use crate::context::Gpu;
use crate::error::{Error, Result};
use crate::layout::ExpandSettings;
use crate::pass::{PassLayouts, StepPass, held_storage, storage_buffer, uniform_buffer};
use crate::shaders::{EXPAND_ARRAYS, MASK_ARRAYS, expand_wgsl};
use crate::upload::{EMPTY_BINDING, GpuStep, NO_STEP};

/// The masks the tracer holds: whose, how many of its clusters are derived, and the trace
/// passes' group over them.
#[derive(Debug)]
struct HeldMasks {
    step: u64,
    derived: u32,
    buffer: wgpu::Buffer,
    /// The step's candidates, one per slot, expanded from its runs with the masks.
    candidates: wgpu::Buffer,
    group: wgpu::BindGroup,
}

/// How far the derivation of a step's neighbour masks has got, in clusters.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MaskProgress {
    pub derived: u32,
    pub total: u32,
}

impl MaskProgress {
    pub fn finished(&self) -> bool {
        self.derived >= self.total
    }
}

/// The clusters of `step`, one mask-pass workgroup each.
pub(crate) fn cluster_count(step: &GpuStep) -> u32 {
    step.info
        .point_count
        .div_ceil(step.info.cluster_size.max(1))
}

/// The mask pass, the trace passes' empty group 2, and the one set of masks held.
#[derive(Debug)]
pub(crate) struct NeighbourMasks {
    pass: StepPass,
    /// Group 2 over an empty buffer, for frames that do not refine.
    none: wgpu::BindGroup,
    held: Mutex<Option<HeldMasks>>,
}

/// A storage buffer of `size` bytes the mask pass writes (readable back for tests).
pub(crate) fn mask_buffer(gpu: &Gpu, size: u64) -> wgpu::Buffer {
    storage_buffer(gpu, MASKS_LABEL, size)
}

/// A buffer for the candidates the mask pass expands, one per slot.
pub(crate) fn candidate_buffer(gpu: &Gpu, size: u64) -> wgpu::Buffer {
    storage_buffer(gpu, CANDIDATES_LABEL, size)
}

const MASKS_LABEL: &str = "neighbour masks";
const CANDIDATES_LABEL: &str = "candidates";

impl NeighbourMasks {
    pub(crate) fn new(gpu: &Gpu, limit: u64) -> NeighbourMasks {
        let layouts = PassLayouts::new(gpu, "expand", &EXPAND_ARRAYS, "masks", &MASK_ARRAYS);
        let none = Self::group(
            gpu,
            &layouts.output,
            &mask_buffer(gpu, EMPTY_BINDING),
            &candidate_buffer(gpu, EMPTY_BINDING),
            limit,
        );
        NeighbourMasks {
            pass: StepPass::new(layouts, "expand", expand_wgsl, limit),
            none,
            held: Mutex::new(None),
        }
    }

    /// The layout of the trace and shade passes' group 2.
    pub(crate) fn layout(&self) -> &wgpu::BindGroupLayout {
        &self.pass.layouts.output
    }

    fn group(
        gpu: &Gpu,
        layout: &wgpu::BindGroupLayout,
        masks: &wgpu::Buffer,
        candidates: &wgpu::Buffer,
        limit: u64,
    ) -> wgpu::BindGroup {
        gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("masks"),
            layout,
            entries: &bind_entries(&MASK_ARRAYS, &[masks, candidates], None, limit),
        })
    }

    /// The trace passes' group 2 for a frame of `step`: the empty one where the frame does
    /// not refine, else the held masks, derived first (recorded into `encoder`) as far as
    /// they are not yet.
    pub(crate) fn group_for(
        &self,
        gpu: &Gpu,
        step: &GpuStep,
        refines: bool,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<wgpu::BindGroup> {
        if !refines {
            return Ok(self.none.clone());
        }
        self.derive(gpu, step, u32::MAX, encoder)?;
        let held = self.lock()?;
        held.as_ref()
            .map(|h| h.group.clone())
            .ok_or_else(|| Error::Validation("the neighbour masks were not derived".into()))
    }

    /// Derives up to `clusters` more clusters of `step`'s masks (recorded into `encoder`),
    /// starting them where the held masks are another step's.
    pub(crate) fn derive(
        &self,
        gpu: &Gpu,
        step: &GpuStep,
        clusters: u32,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<MaskProgress> {
        let total = cluster_count(step);
        let mut held = self.lock()?;
        let current = held.as_ref().is_some_and(|h| h.step == step.id());
        if !current {
            let (needed, candidates_needed) = (step.info.mask_bytes(), step.info.candidate_bytes());
            // The pass writes every word the step's clusters read.
            let (buffer, candidates) = match held.take() {
                Some(h) => (Some(h.buffer), Some(h.candidates)),
                None => (None, None),
            };
            let buffer = held_storage(gpu, MASKS_LABEL, buffer, needed);
            let candidates = held_storage(gpu, CANDIDATES_LABEL, candidates, candidates_needed);
            let group = Self::group(gpu, self.layout(), &buffer, &candidates, self.pass.limit);
            *held = Some(HeldMasks {
                step: step.id(),
                derived: 0,
                buffer,
                candidates,
                group,
            });
        }
        let h = held
            .as_mut()
            .ok_or_else(|| Error::Validation("the neighbour masks were not made".into()))?;
        if h.derived < total {
            let end = h.derived.saturating_add(clusters.max(1)).min(total);
            let held = (&h.buffer, &h.candidates);
            self.record(gpu, step, held, h.derived..end, encoder, None)?;
            h.derived = end;
        }
        Ok(MaskProgress {
            derived: h.derived,
            total,
        })
    }

    /// How far `step`'s masks are derived (none where the held ones are another's).
    pub(crate) fn progress(&self, step: &GpuStep) -> MaskProgress {
        let derived = self.held.lock().map_or(0, |h| {
            h.as_ref()
                .filter(|h| h.step == step.id())
                .map_or(0, |h| h.derived)
        });
        MaskProgress {
            derived,
            total: cluster_count(step),
        }
    }

    fn lock(&self) -> Result<std::sync::MutexGuard<'_, Option<HeldMasks>>> {
        self.held
            .lock()
            .map_err(|_| Error::Validation("the neighbour masks' lock was poisoned".into()))
    }

    /// Forgets whose masks the held buffers hold, keeping the buffers: the next refined
    /// frame derives its step's again.
    pub(crate) fn forget(&self) {
        let mut held = self.held.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(h) = held.as_mut() {
            h.step = NO_STEP;
            h.derived = 0;
        }
    }

    /// Bytes of the masks held now (0 before the first refined frame).
    pub(crate) fn held_bytes(&self) -> u64 {
        self.held.lock().map_or(0, |h| {
            h.as_ref()
                .map_or(0, |h| h.buffer.size() + h.candidates.size())
        })
    }

    /// Records the pass that fills `masks` for `step`'s clusters `clusters` (rows of words,
    /// `mask_row`), timed into `timestamps` (2 queries) where given.
    pub(crate) fn record(
        &self,
        gpu: &Gpu,
        step: &GpuStep,
        (masks, candidates): (&wgpu::Buffer, &wgpu::Buffer),
        clusters: std::ops::Range<u32>,
        encoder: &mut wgpu::CommandEncoder,
        timestamps: Option<&wgpu::QuerySet>,
    ) -> Result<()> {
        let device = &gpu.device;
        let info = &step.info;
        let settings = ExpandSettings {
            point_count: info.point_count,
            cluster_size: info.cluster_size,
            mask_words: info.mask_words,
            has_normals: u32::from(info.has_normals),
            run_words: info.run_words,
            first_cluster: clusters.start,
            end_cluster: clusters.end,
            candidate_count: info.cluster_id_count,
        };
        let uniform = uniform_buffer(gpu, "expand settings", &settings)?;
        let b = &step.buffers;
        let buffers = [
            &b.points,
            &b.normals,
            &b.cluster_start,
            &b.cluster_ids,
            masks,
            &b.cluster_base,
            candidates,
        ];
        let entries = bind_entries(&EXPAND_ARRAYS, &buffers, Some(&uniform), self.pass.limit);
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("expand"),
            layout: &self.pass.layouts.pass,
            entries: &entries,
        });
        let pipeline = self.pass.pipeline(gpu, step.split)?;
        let max_groups = device.limits().max_compute_workgroups_per_dimension;
        // One workgroup per cluster.
        let groups = if info.mask_words == 0 {
            0
        } else {
            clusters.len() as u32
        };
        let timestamp_writes = timestamps.map(|set| wgpu::ComputePassTimestampWrites {
            query_set: set,
            beginning_of_pass_write_index: Some(0),
            end_of_pass_write_index: Some(1),
        });
        // A timed pass runs even with nothing to do, so that its stamps are written.
        if groups == 0 && timestamp_writes.is_none() {
            return Ok(());
        }
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("neighbour masks"),
            timestamp_writes,
        });
        if groups > 0 {
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, &group, &[]);
            pass.dispatch_workgroups(groups.min(max_groups), groups.div_ceil(max_groups), 1);
        }
        Ok(())
    }
}
