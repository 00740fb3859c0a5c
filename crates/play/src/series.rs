//! A cache directory as a series of steps: the manifest's steps, and the step files a bake
//! is still adding (bake renames each finished file into place, so a file that is there is
//! whole).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use slosh_cache::{CacheFile, Manifest, parse_step_file_name};

use crate::error::{Error, Result};

/// One step of a series.
#[derive(Debug, Clone, PartialEq)]
pub struct SeriesStep {
    /// The bake's step index (the file's number).
    pub index: usize,
    pub time: f64,
    pub path: PathBuf,
}

/// The steps of a cache directory, in the bake's order.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    dir: PathBuf,
    steps: Vec<SeriesStep>,
    /// Files that are there but could not be read, with why.
    unreadable: Vec<(PathBuf, String)>,
}

impl Series {
    /// Reads `dir`: the manifest where there is one, and every step file beside it. A
    /// directory without steps yet is a series of none (a bake may be about to fill it).
    pub fn open(dir: &Path) -> Result<Series> {
        let mut series = Series {
            dir: dir.to_path_buf(),
            steps: Vec::new(),
            unreadable: Vec::new(),
        };
        series.refresh()?;
        Ok(series)
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

    pub fn unreadable(&self) -> &[(PathBuf, String)] {
        &self.unreadable
    }

    /// Looks again for step files (a bake still filling the directory); returns whether
    /// steps were added. Known steps keep their positions only if no new step sorts before
    /// them, so callers re-map by [`SeriesStep::index`].
    pub fn refresh(&mut self) -> Result<bool> {
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
        let mut known: BTreeMap<usize, SeriesStep> =
            self.steps.drain(..).map(|s| (s.index, s)).collect();
        if known.is_empty()
            && let Ok(manifest) = Manifest::read(&self.dir)
        {
            for s in manifest.steps {
                if files.contains_key(&s.index) {
                    let path = self.dir.join(&s.file);
                    known.insert(
                        s.index,
                        SeriesStep {
                            index: s.index,
                            time: s.time,
                            path,
                        },
                    );
                }
            }
        }
        let before = known.len();
        self.unreadable.clear();
        for (index, path) in files {
            if known.contains_key(&index) {
                continue;
            }
            // A step the manifest does not list yet: its time from its own header.
            match CacheFile::open(&path) {
                Ok(file) => {
                    let time = file.header().source.time;
                    known.insert(index, SeriesStep { index, time, path });
                }
                Err(e) => self.unreadable.push((path, e.to_string())),
            }
        }
        known.retain(|_, s| s.path.exists());
        let added = known.len() > before;
        self.steps = known.into_values().collect();
        Ok(added)
    }
}
