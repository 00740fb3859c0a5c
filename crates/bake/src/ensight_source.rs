//! EnSight cases as a step source for the batch driver.

use std::path::Path;

use slosh_ensight::{Case, PointSource, StepRequest};

use crate::batch::StepSource;
use crate::params::{BakeParams, NormalSource, SurfaceSelect};
use crate::select::StepInput;

#[derive(Debug)]
pub struct EnsightSource {
    case: Case,
    request: StepRequest,
    label: String,
}

impl EnsightSource {
    /// A source reading what `params` needs (surface flags, normals, fields) from `case`.
    pub fn new(case: Case, path: &Path, points: PointSource, params: &BakeParams) -> EnsightSource {
        let request = StepRequest {
            points,
            parts: None,
            normals: match &params.normals {
                NormalSource::Variable(v) => Some(v.clone()),
                NormalSource::Pca | NormalSource::Estimate => None,
            },
            fields: params.fields.clone(),
            surface: match &params.surface {
                SurfaceSelect::Variable(v) => Some(v.clone()),
                _ => None,
            },
            // The bake drops and counts non-finite particles itself.
            allow_non_finite: true,
        };
        EnsightSource {
            case,
            request,
            label: canonical_label(path),
        }
    }
}

/// A path as every step file records its input: canonical (absolute, links resolved) where
/// it can be made so, so that runs given one input by different paths agree.
pub fn canonical_label(path: &Path) -> String {
    std::fs::canonicalize(path)
        .unwrap_or_else(|_| path.to_path_buf())
        .display()
        .to_string()
}

impl StepSource for EnsightSource {
    fn source_path(&self) -> String {
        self.label.clone()
    }

    fn steps(&self) -> Vec<(usize, f64)> {
        let times = self.case.times();
        (0..self.case.step_count())
            .map(|i| (i, times.get(i).copied().unwrap_or(0.0)))
            .collect()
    }

    fn read(&self, index: usize) -> Result<StepInput, String> {
        let step = self
            .case
            .read_step(index, &self.request)
            .map_err(|e| e.to_string())?;
        let widen =
            |v: &[[f32; 3]]| -> Vec<[f64; 3]> { v.iter().map(|p| p.map(f64::from)).collect() };
        Ok(StepInput {
            index,
            time: step.time,
            source: self.label.clone(),
            positions: widen(&step.positions),
            normals: step.normals.as_deref().map(widen),
            surface_flags: step.surface,
            fields: step
                .fields
                .into_iter()
                .map(|f| (f.name, f.values))
                .collect(),
            identity: None,
        })
    }

    /// The measured file where the case has one (particles there), else the geometry.
    fn particle_file(&self, index: usize) -> Option<std::path::PathBuf> {
        match self.case.measured_file(index).ok()? {
            Some(measured) => Some(measured.path),
            None => Some(self.case.model_file(index).ok()??.path),
        }
    }

    /// The case file, the step's geometry or measured file and its variable files.
    fn identity(&self, index: usize) -> Option<String> {
        let mut files = vec![self.case.path().to_path_buf()];
        files.extend(self.case.model_file(index).ok()?.map(|f| f.path));
        files.extend(self.case.measured_file(index).ok()?.map(|f| f.path));
        for v in self.case.variables() {
            if let Some(fref) = &v.file {
                files.push(self.case.resolve(fref, index).ok()?.path);
            }
        }
        crate::batch::files_identity(files.iter().map(|p| p.as_path()))
    }
}
