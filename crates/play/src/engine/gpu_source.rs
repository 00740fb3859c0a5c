//! The loaders' side of the engine: a step's host half and GPU half prepared off the frame
//! thread, checked against the series it must belong to.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::{Arc, Mutex, PoisonError};

use slosh_render::{BufferShelf, Gpu, GpuStep, HostStep, StagingPool, UploadOptions};

use crate::prefetch::StepLoader;

/// A step a loader prepared: its buffers on the GPU, and the commands (copies) that fill
/// them, to be submitted before any frame that reads it.
#[derive(Debug)]
pub struct Prepared {
    pub step: GpuStep,
    pub commands: wgpu::CommandBuffer,
    /// The field the step was loaded with.
    pub field: Option<String>,
}

/// The loaders' view of the series: paths by bake index, and the field to load.
#[derive(Debug)]
pub struct GpuSource {
    pub(super) gpu: Arc<Gpu>,
    /// What a step must be to belong to the series: the manifest's entries where it has one
    /// (a bake in progress may not yet), and the series' key (the manifest's, else the first
    /// readable step's).
    pub(super) belongs: Mutex<(
        Option<slosh_cache::Manifest>,
        Option<slosh_cache::SeriesKey>,
    )>,
    pub(super) staging: StagingPool,
    /// Section buffers of steps dropped from the pool, for the next uploads.
    pub(super) shelf: BufferShelf,
    pub(super) delay: Option<std::time::Duration>,
    pub(super) paths: Mutex<HashMap<usize, PathBuf>>,
    pub(super) field: Mutex<Option<String>>,
    /// A raw case's bake: a step is baked into its file (unless a current one is there)
    /// before it loads.
    pub(super) bake: Option<Arc<slosh_bake::OnDemand>>,
}

impl GpuSource {
    pub(super) fn path(&self, index: usize) -> Option<PathBuf> {
        let paths = self.paths.lock().unwrap_or_else(PoisonError::into_inner);
        paths.get(&index).cloned()
    }

    pub(super) fn field(&self) -> Option<String> {
        self.field
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }
}

impl StepLoader for GpuSource {
    type Step = Prepared;

    fn load(
        &self,
        index: usize,
        waited: bool,
        withdrawn: &(dyn Fn() -> bool + Sync),
    ) -> Result<Prepared, String> {
        let path = self
            .path(index)
            .ok_or_else(|| format!("step {index} is not in the series"))?;
        if let Some(delay) = self.delay {
            std::thread::sleep(delay);
        }
        if let Some(bake) = &self.bake {
            if withdrawn() {
                return Err("withdrawn".into());
            }
            let urgency = if waited {
                slosh_bake::Urgency::Waited
            } else {
                slosh_bake::Urgency::Ahead
            };
            if let slosh_bake::StepOutcome::Failed(why) = bake.bake_as(index, urgency, withdrawn) {
                return Err(format!("step {index} did not bake: {why}"));
            }
        }
        let field = self.field();
        let host = HostStep::open(&path, field.as_deref()).map_err(|e| e.to_string())?;
        // A file must hold the step its name says, be of the series (its input, settings
        // and steps), and, where the manifest lists the step, be the file it describes.
        let (manifest, key) = self
            .belongs
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone();
        let header = host.file().header();
        let problems = match (&manifest, &key) {
            (Some(m), _) if m.steps.iter().any(|s| s.index == index) => {
                m.step_problems(index, host.file())
            }
            (_, Some(key)) => key.differences(index, header),
            _ if header.source.step != index => vec![format!(
                "holds step {} of its source, not step {index} as its name says",
                header.source.step
            )],
            _ => Vec::new(),
        };
        if !problems.is_empty() {
            return Err(format!(
                "{}: not step {index} of this series: {}",
                path.display(),
                problems.join("; ")
            ));
        }
        let mut encoder = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("step upload"),
            });
        if withdrawn() {
            return Err("withdrawn".into());
        }
        let options = UploadOptions {
            staging: Some(&self.staging),
            shelf: Some(&self.shelf),
            cancelled: Some(withdrawn),
        };
        let step = GpuStep::create_in(&self.gpu, &host, &mut encoder, options)
            .map_err(|e| e.to_string())?;
        Ok(Prepared {
            step,
            commands: encoder.finish(),
            field,
        })
    }
}
