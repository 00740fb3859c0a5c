//! The 4-wide tree the trace walk descends, widened from a step's baked BVH2 by
//! `shaders/widen.wgsl`.
//!
//! A step holds only its BVH2 (as the cache stores it, so loading it is a copy and the
//! host half does no widening): the tracer keeps one wide tree, for the step it last drew,
//! and widens it again, in the same submission as the frame, when a frame draws another
//! step. The pass is one thread per node, so a new step costs microseconds of GPU time
//! where the host half's serial widening cost milliseconds of every load.

use std::sync::{Mutex, PoisonError};

use crate::bindings::bind_entries;
use crate::context::Gpu;
use crate::error::{Error, Result};
use crate::layout::WidenSettings;
use crate::pass::{PassLayouts, StepPass, held_storage, uniform_buffer};
use crate::shaders::{TREE_ARRAYS, WIDEN_ARRAYS, WIDEN_GROUP, widen_wgsl};
use crate::upload::{GpuStep, NO_STEP};

/// The wide tree the tracer holds: whose, and the trace passes' group over it.
#[derive(Debug)]
struct HeldTree {
    step: u64,
    buffer: wgpu::Buffer,
    group: wgpu::BindGroup,
}

/// The widening pass, and the one wide tree held.
#[derive(Debug)]
pub(crate) struct Widening {
    pass: StepPass,
    held: Mutex<Option<HeldTree>>,
}

impl Widening {
    pub(crate) fn new(gpu: &Gpu, limit: u64) -> Widening {
        let layouts = PassLayouts::new(gpu, "widen", &WIDEN_ARRAYS, "wide tree", &TREE_ARRAYS);
        Widening {
            pass: StepPass::new(layouts, "widen", widen_wgsl, limit),
            held: Mutex::new(None),
        }
    }

    /// The layout of the trace passes' group 3.
    pub(crate) fn layout(&self) -> &wgpu::BindGroupLayout {
        &self.pass.layouts.output
    }

    /// The trace passes' group 3 for a frame of `step`: the held tree, widened first
    /// (recorded into `encoder`) where it is another step's.
    pub(crate) fn group_for(
        &self,
        gpu: &Gpu,
        step: &GpuStep,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<wgpu::BindGroup> {
        let mut held = self
            .held
            .lock()
            .map_err(|_| Error::Validation("the wide tree's lock was poisoned".into()))?;
        if let Some(h) = held.as_ref().filter(|h| h.step == step.id()) {
            return Ok(h.group.clone());
        }
        // The pass writes every entry the walk can reach.
        let held_buffer = held.take().map(|h| h.buffer);
        let buffer = held_storage(gpu, "wide tree", held_buffer, step.info.wide_bytes());
        self.record(gpu, step, &buffer, encoder)?;
        let group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("wide tree"),
            layout: self.layout(),
            entries: &bind_entries(&TREE_ARRAYS, &[&buffer], None, self.pass.limit),
        });
        *held = Some(HeldTree {
            step: step.id(),
            buffer,
            group: group.clone(),
        });
        Ok(group)
    }

    /// Forgets whose tree the held buffer holds, keeping the buffer: the next frame widens
    /// its step's again.
    pub(crate) fn forget(&self) {
        let mut held = self.held.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(h) = held.as_mut() {
            h.step = NO_STEP;
        }
    }

    /// Bytes of the wide tree held now (0 before the first frame).
    pub(crate) fn held_bytes(&self) -> u64 {
        self.held
            .lock()
            .map_or(0, |h| h.as_ref().map_or(0, |h| h.buffer.size()))
    }

    /// Records the pass that widens `step`'s BVH2 into `tree`.
    pub(crate) fn record(
        &self,
        gpu: &Gpu,
        step: &GpuStep,
        tree: &wgpu::Buffer,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<()> {
        let nodes = step.info.node_count;
        if nodes == 0 {
            return Ok(());
        }
        let device = &gpu.device;
        let groups = nodes.div_ceil(WIDEN_GROUP);
        let max_groups = device.limits().max_compute_workgroups_per_dimension;
        let row_groups = groups.min(max_groups);
        let grid = &step.info.bvh_grid;
        let settings = WidenSettings {
            origin: grid.origin,
            node_count: nodes,
            step: grid.step,
            row_threads: row_groups * WIDEN_GROUP,
        };
        let uniform = uniform_buffer(gpu, "widen settings", &settings)?;
        let buffers = [&step.buffers.bvh_nodes, tree];
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("widen"),
            layout: &self.pass.layouts.pass,
            entries: &bind_entries(&WIDEN_ARRAYS, &buffers, Some(&uniform), self.pass.limit),
        });
        let pipeline = self.pass.pipeline(gpu, step.split)?;
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("widen"),
            timestamp_writes: None,
        });
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, &group, &[]);
        pass.dispatch_workgroups(row_groups, groups.div_ceil(row_groups), 1);
        Ok(())
    }
}
