//! A cache directory as a series of steps: the manifest's steps, and the step files a bake
//! is still adding (bake renames each finished file into place, so a file that is there is
//! whole); or a raw case's planned steps, each baked into the directory when first loaded. Positions are stable for the life of the series: a step whose file disappears
//! stays in place, marked, so that every later step keeps its place on the timeline; a step
//! file that cannot be read is a step too, marked with why.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::SystemTime;

use slosh_cache::{CacheFile, Manifest, SeriesKey, parse_step_file_name, step_file_name};

use crate::error::{Error, Result};

/// What a file was when it was last looked at: a file copied over, restored or rewritten has
/// another stamp.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FileStamp {
    len: u64,
    modified: Option<SystemTime>,
    inode: u64,
}

impl FileStamp {
    pub fn of(path: &Path) -> Option<FileStamp> {
        let meta = std::fs::metadata(path).ok()?;
        #[cfg(unix)]
        let inode = std::os::unix::fs::MetadataExt::ino(&meta);
        #[cfg(not(unix))]
        let inode = 0;
        Some(FileStamp {
            len: meta.len(),
            modified: meta.modified().ok(),
            inode,
        })
    }
}

/// One step of a series.
#[derive(Debug, Clone, PartialEq)]
pub struct SeriesStep {
    /// The bake's step index (the file's number): what the step is called everywhere.
    pub index: usize,
    pub time: f64,
    pub path: PathBuf,
    /// The file as last seen; `None` while it is missing.
    pub stamp: Option<FileStamp>,
    /// Why the step cannot be shown, where it cannot be: its file is gone or unreadable.
    pub problem: Option<String>,
}

/// What a refresh found.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SeriesChange {
    /// Steps new to the series.
    pub added: usize,
    /// Bake indices of known steps whose file changed, vanished or came back: whatever was
    /// loaded or concluded from them is stale.
    pub changed: Vec<usize>,
    /// Planned steps whose file has appeared (baked since the last look).
    pub baked: usize,
    /// The manifest appeared, changed or went away.
    pub manifest: bool,
}

impl SeriesChange {
    pub fn any(&self) -> bool {
        self.added > 0 || !self.changed.is_empty() || self.manifest || self.baked > 0
    }
}

/// The steps of a cache directory, in the bake's order.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    dir: PathBuf,
    steps: Vec<SeriesStep>,
    manifest: Option<Manifest>,
    manifest_stamp: Option<FileStamp>,
    /// What every step must share: the manifest's, else the first readable step's; a
    /// planned series' own.
    key: Option<SeriesKey>,
    /// A raw case's steps (bake index, time), each baked on demand: every one is a position
    /// from the start, baked or not, and the directory's manifest is not read.
    plan: Option<BTreeMap<usize, f64>>,
}

impl Series {
    /// Reads `dir`: the manifest where there is one, and every step file beside it. A
    /// directory without steps yet is a series of none (a bake may be about to fill it).
    pub fn open(dir: &Path) -> Result<Series> {
        let mut series = Series {
            dir: dir.to_path_buf(),
            steps: Vec::new(),
            manifest: None,
            manifest_stamp: None,
            key: None,
            plan: None,
        };
        series.refresh()?;
        Ok(series)
    }

    /// The planned `steps` (bake index, time) of the series `key`, cached in `dir` once
    /// baked: a step without its file is a position still to bake, not a problem.
    pub fn planned(dir: &Path, steps: &[(usize, f64)], key: SeriesKey) -> Result<Series> {
        let mut series = Series {
            dir: dir.to_path_buf(),
            steps: Vec::new(),
            manifest: None,
            manifest_stamp: None,
            key: Some(key),
            plan: Some(steps.iter().copied().collect()),
        };
        series.refresh()?;
        Ok(series)
    }

    /// Whether the series is a raw case's, baked on demand.
    pub fn is_planned(&self) -> bool {
        self.plan.is_some()
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    pub fn steps(&self) -> &[SeriesStep] {
        &self.steps
    }

    pub fn len(&self) -> usize {
        self.steps.len()
    }

    pub fn is_empty(&self) -> bool {
        self.steps.is_empty()
    }

    pub fn times(&self) -> Vec<f64> {
        self.steps.iter().map(|s| s.time).collect()
    }

    pub fn manifest(&self) -> Option<&Manifest> {
        self.manifest.as_ref()
    }

    /// The range of field view `view` over the series, where its manifest records one
    /// (format 9.1): what a colour map spans from the first frame on.
    pub fn field_range(&self, view: &str) -> Option<(f32, f32)> {
        let [lo, hi] = *self.manifest.as_ref()?.field_ranges.get(view)?;
        Some((lo, hi))
    }

    /// What every step of the series shares, where it is known yet.
    pub fn key(&self) -> Option<&SeriesKey> {
        self.key.as_ref()
    }

    /// The series' world bounds: the manifest's, or while a bake runs the first step's with
    /// particles (a Lagrangian run's first steps may have none); `None` before any.
    pub fn bounds(&self) -> Option<[[f64; 3]; 2]> {
        if let Some(m) = &self.manifest {
            return Some(m.bounds);
        }
        self.steps
            .iter()
            .filter_map(|s| CacheFile::open(&s.path).ok())
            .find(|f| f.header().points > 0)
            .map(|f| f.header().bounds)
    }

    /// The fields the series can be coloured by (its first step's): each scalar field, and
    /// each vector field's magnitude and components (`slosh_cache::field_views`).
    pub fn fields(&self) -> Vec<String> {
        self.first_file()
            .map(|f| slosh_cache::field_views(f.header()))
            .unwrap_or_default()
    }

    /// The data's up direction, where the bake recorded one (its first step's).
    pub fn up(&self) -> Option<[f64; 3]> {
        self.first_file().and_then(|f| f.header().up)
    }

    fn first_file(&self) -> Option<CacheFile> {
        self.steps
            .first()
            .and_then(|s| CacheFile::open(&s.path).ok())
    }

    /// Steps that cannot be shown (a file gone or unreadable), by bake index, with why.
    pub fn problems(&self) -> impl Iterator<Item = (usize, &str)> {
        self.steps
            .iter()
            .filter_map(|s| s.problem.as_deref().map(|p| (s.index, p)))
    }

    /// Looks again at the directory (a bake still filling it, files copied over or deleted).
    /// Known steps keep their positions unless a new step sorts before them, so callers
    /// re-map by [`SeriesStep::index`].
    pub fn refresh(&mut self) -> Result<SeriesChange> {
        let entries = std::fs::read_dir(&self.dir).map_err(|e| Error::Series {
            path: self.dir.clone(),
            problem: format!("cannot list the directory: {e}"),
        })?;
        let mut files: BTreeMap<usize, PathBuf> = BTreeMap::new();
        for entry in entries.flatten() {
            let name = entry.file_name();
            if let Some(index) = name.to_str().and_then(parse_step_file_name) {
                files.insert(index, entry.path());
            }
        }
        let mut change = SeriesChange::default();
        if let Some(plan) = &self.plan {
            // Only the planned steps, whatever else the directory holds.
            files.retain(|index, _| plan.contains_key(index));
        }
        let manifest_path = self.dir.join(slosh_cache::MANIFEST_NAME);
        let manifest_stamp = FileStamp::of(&manifest_path);
        if self.plan.is_some() {
            // The plan and its key say what the series is.
        } else if manifest_stamp != self.manifest_stamp
            || (self.steps.is_empty() && !files.is_empty())
        {
            let manifest = Manifest::read(&self.dir).ok();
            change.manifest = manifest != self.manifest;
            self.manifest = manifest;
            self.manifest_stamp = manifest_stamp;
        }
        let mut known: BTreeMap<usize, SeriesStep> =
            self.steps.drain(..).map(|s| (s.index, s)).collect();
        // Known steps: still there, changed, gone or back.
        for step in known.values_mut() {
            let stamp = files.get(&step.index).and_then(|p| FileStamp::of(p));
            if stamp == step.stamp {
                continue;
            }
            if self.plan.is_some() {
                // A planned step's file appearing is its bake; one removed is baked again
                // when next loaded; one replaced is stale.
                if step.stamp.is_none() {
                    change.baked += 1;
                } else {
                    change.changed.push(step.index);
                }
                step.stamp = stamp;
                continue;
            }
            change.changed.push(step.index);
            step.stamp = stamp;
            step.problem = match stamp {
                None => Some(format!(
                    "{} was removed while the series was open",
                    step.path.display()
                )),
                Some(_) => match CacheFile::open(&step.path) {
                    Ok(file) => {
                        step.time = file.header().source.time;
                        None
                    }
                    Err(e) => Some(e.to_string()),
                },
            };
        }
        // New steps: their times from the manifest where it lists them, else their headers.
        let listed: BTreeMap<usize, f64> = self
            .manifest
            .iter()
            .flat_map(|m| m.steps.iter().map(|s| (s.index, s.time)))
            .collect();
        for (index, path) in files {
            if known.contains_key(&index) {
                continue;
            }
            let stamp = FileStamp::of(&path);
            // A planned step's time is the case's; its file is judged when loaded (and
            // baked again where it is not of the series).
            let planned = self.plan.as_ref().and_then(|p| p.get(&index));
            let (time, problem) = match planned.or(listed.get(&index)) {
                Some(&time) => (time, None),
                None => match CacheFile::open(&path) {
                    Ok(file) => {
                        if self.key.is_none() && self.manifest.is_none() {
                            self.key = Some(SeriesKey::of(file.header()));
                        }
                        (file.header().source.time, None)
                    }
                    Err(e) => (f64::NAN, Some(e.to_string())),
                },
            };
            change.added += 1;
            known.insert(
                index,
                SeriesStep {
                    index,
                    time,
                    path,
                    stamp,
                    problem,
                },
            );
        }
        // Planned steps not baked yet.
        for (&index, &time) in self.plan.iter().flatten() {
            known.entry(index).or_insert_with(|| {
                change.added += 1;
                SeriesStep {
                    index,
                    time,
                    path: self.dir.join(step_file_name(index)),
                    stamp: None,
                    problem: None,
                }
            });
        }
        if let Some(m) = &self.manifest {
            self.key = Some(m.key());
        }
        self.steps = known.into_values().collect();
        // A step whose time is unknown (its file unreadable) takes its predecessor's, so the
        // timeline stays ordered.
        let mut last = 0.0;
        for step in &mut self.steps {
            if step.time.is_finite() {
                last = step.time;
            } else {
                step.time = last;
            }
        }
        Ok(change)
    }
}
