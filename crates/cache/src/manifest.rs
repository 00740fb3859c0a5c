//! The series manifest: one JSON file per cache directory listing the step files, their
//! times, bounds and checksums, and the bake parameters they share. It is derived data: it can
//! always be rebuilt from the step files (`slosh bake --manifest-only DIR`).

use std::path::{Path, PathBuf};

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::format::{Header, SeriesRecord, hex64};
use crate::reader::CacheFile;

pub const MANIFEST_NAME: &str = "manifest.json";
/// The file whose lock serialises manifest rebuilds in one directory.
pub const MANIFEST_LOCK_NAME: &str = ".manifest.lock";
pub const MANIFEST_FORMAT: &str = "slosh-cache-series";

/// The file name of step `index`.
pub fn step_file_name(index: usize) -> String {
    format!("step-{index:05}.slc")
}

/// The step index a file name stands for, if it is a step file name.
pub fn parse_step_file_name(name: &str) -> Option<usize> {
    let digits = name.strip_prefix("step-")?.strip_suffix(".slc")?;
    (digits.len() >= 5 && digits.bytes().all(|b| b.is_ascii_digit()))
        .then(|| digits.parse().ok())
        .flatten()
}

/// What every step file of one bake shares: the input (its canonical path), the settings and
/// the steps asked for. Two step files that differ in it belong to different bakes.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct SeriesKey {
    pub source: String,
    pub params_hash: String,
    pub series: Option<SeriesRecord>,
}

impl SeriesKey {
    pub fn of(header: &Header) -> SeriesKey {
        SeriesKey {
            source: header.source.path.clone(),
            params_hash: header.params_hash.clone(),
            series: header.series,
        }
    }

    /// Why step file `index` with `header` is not of this series (empty when it is).
    pub fn differences(&self, index: usize, header: &Header) -> Vec<String> {
        let mut problems = Vec::new();
        if header.source.step != index {
            problems.push(format!(
                "holds step {} of its source, not step {index} as its name says",
                header.source.step
            ));
        }
        if header.params_hash != self.params_hash {
            problems.push(format!(
                "baked with parameter hash {}, the series with {}",
                header.params_hash, self.params_hash
            ));
        }
        if header.source.path != self.source {
            problems.push(format!(
                "baked from {}, the series from {}",
                header.source.path, self.source
            ));
        }
        if header.series != self.series {
            let say = |s: &Option<SeriesRecord>| {
                s.map_or("steps not recorded".to_string(), |s| s.to_string())
            };
            problems.push(format!(
                "baked as part of {}, the series is {}",
                say(&header.series),
                say(&self.series)
            ));
        }
        if let Some(series) = self.series
            && !series.contains(index)
        {
            problems.push(format!("is outside the series ({series})"));
        }
        problems
    }

    /// The steps of the series that `present` lacks (none where the series is not recorded).
    pub fn missing(&self, present: &[usize]) -> Vec<usize> {
        self.series.map_or_else(Vec::new, |s| {
            (s.first..=s.last)
                .filter(|i| present.binary_search(i).is_err())
                .collect()
        })
    }

    /// "steps 3, 5 and 7 of steps 0..=9 (10 steps) are missing", at most `shown` listed.
    pub fn describe_missing(&self, missing: &[usize]) -> Option<String> {
        const SHOWN: usize = 12;
        let series = self.series?;
        if missing.is_empty() {
            return None;
        }
        let mut list: Vec<String> = missing.iter().take(SHOWN).map(|i| i.to_string()).collect();
        if missing.len() > SHOWN {
            list.push(format!("… ({} in all)", missing.len()));
        }
        Some(format!(
            "{} of the series' {series} {} missing: {}",
            missing.len(),
            if missing.len() == 1 { "is" } else { "are" },
            list.join(", ")
        ))
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ManifestStep {
    pub index: usize,
    pub time: f64,
    pub file: String,
    pub points: u64,
    pub bytes: u64,
    /// The footer's xxh3 over the file body.
    pub xxh3: String,
    pub bounds: [[f64; 3]; 2],
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    pub format: String,
    pub version: u32,
    pub source: String,
    pub params_hash: String,
    /// The steps the series holds (absent in manifests of earlier bakes).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub series: Option<SeriesRecord>,
    pub bake: serde_json::Value,
    /// World bounds over all steps.
    pub bounds: [[f64; 3]; 2],
    /// Each field view's range over all steps whose headers record one (format 9.1): what
    /// a colour map spans over the series from its first frame.
    #[serde(default, skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub field_ranges: std::collections::BTreeMap<String, crate::FieldRange>,
    pub steps: Vec<ManifestStep>,
}

/// Step files a manifest's rebuild checks at once.
const CHECKED_AT_ONCE: usize = 256;

/// What the manifest takes from a step file whose footer checksum matches its bytes.
struct CheckedStep {
    header: Header,
    bytes: u64,
    checksum: u64,
}

impl CheckedStep {
    fn read(path: &Path) -> Result<CheckedStep> {
        let file = CacheFile::open(path)?;
        if !file.body_intact() {
            return Err(Error::Invalid {
                path: path.to_path_buf(),
                problem: "the footer checksum does not match the file's bytes".into(),
            });
        }
        Ok(CheckedStep {
            header: file.header().clone(),
            bytes: file.file_len(),
            checksum: file.footer_checksum(),
        })
    }
}

impl Manifest {
    /// Rebuilds the manifest from the step files in `dir`, checking each one's footer checksum.
    /// Files that fail are returned beside it, not listed in it.
    pub fn rebuild(dir: &Path) -> Result<(Manifest, Vec<(PathBuf, Error)>)> {
        let mut files: Vec<(usize, PathBuf)> = std::fs::read_dir(dir)
            .map_err(|e| slosh_fileio::IoError::new(dir, e))?
            .filter_map(|e| e.ok())
            .filter_map(|e| {
                let name = e.file_name().to_string_lossy().into_owned();
                parse_step_file_name(&name).map(|i| (i, e.path()))
            })
            .collect();
        files.sort();
        let mut steps = Vec::new();
        let mut failed = Vec::new();
        let mut first: Option<(SeriesKey, serde_json::Value)> = None;
        let mut bounds = [[f64::INFINITY; 3], [f64::NEG_INFINITY; 3]];
        let mut field_ranges: std::collections::BTreeMap<String, crate::FieldRange> =
            Default::default();
        // The files are opened and their checksums read in parallel, a chunk at a time (the
        // checksums read every byte: the manifest of 64 steps of 1M points, 2.8 GB, took
        // 0.43-0.48 s at the end of a bake on one thread of an H100 host), and gone through in
        // index order; a chunk bounds the headers held at once in a series of thousands.
        let checked = files.chunks(CHECKED_AT_ONCE).flat_map(|chunk| {
            let checked: Vec<Result<CheckedStep>> = chunk
                .par_iter()
                .map(|(_, path)| CheckedStep::read(path))
                .collect();
            chunk.iter().cloned().zip(checked)
        });
        for ((index, path), checked) in checked {
            let CheckedStep {
                header,
                bytes,
                checksum: foot,
            } = match checked {
                Ok(c) => c,
                Err(e) => {
                    failed.push((path, e));
                    continue;
                }
            };
            let h = &header;
            match &first {
                None => first = Some((SeriesKey::of(h), h.bake.clone())),
                Some((key, _)) => {
                    let differences = key.differences(index, h);
                    if !differences.is_empty() {
                        return Err(Error::Invalid {
                            path: path.clone(),
                            problem: format!(
                                "{}, unlike the other steps in {}: one directory holds one bake",
                                differences.join("; "),
                                dir.display()
                            ),
                        });
                    }
                }
            }
            // A step without particles has no extent to add.
            if h.points > 0 {
                bounds = [
                    std::array::from_fn(|a| bounds[0][a].min(h.bounds[0][a])),
                    std::array::from_fn(|a| bounds[1][a].max(h.bounds[1][a])),
                ];
            }
            for (view, &[lo, hi]) in &h.field_ranges {
                let range = field_ranges.entry(view.clone()).or_insert([lo, hi]);
                *range = [range[0].min(lo), range[1].max(hi)];
            }
            steps.push(ManifestStep {
                index,
                time: h.source.time,
                file: step_file_name(index),
                points: h.points,
                bytes,
                xxh3: hex64(foot),
                bounds: h.bounds,
            });
        }
        let (key, bake) = first.unwrap_or_else(|| {
            (
                SeriesKey {
                    source: String::new(),
                    params_hash: String::new(),
                    series: None,
                },
                serde_json::Value::Null,
            )
        });
        // A series of no steps has no extent: zero bounds, not infinities (JSON has none,
        // and the manifest would not read back).
        if steps.iter().all(|s| s.points == 0) {
            bounds = [[0.0; 3]; 2];
        }
        Ok((
            Manifest {
                format: MANIFEST_FORMAT.into(),
                version: 1,
                source: key.source,
                params_hash: key.params_hash,
                series: key.series,
                bake,
                bounds,
                field_ranges,
                steps,
            },
            failed,
        ))
    }

    /// Rebuilds the manifest from the step files and writes it, holding the directory's
    /// manifest lock throughout: of bakes finishing side by side (shards of a job array), the
    /// last to write also scanned last, so the manifest never misses a step file that was
    /// renamed into place before it. Returns the manifest and the files left out.
    pub fn refresh(dir: &Path) -> Result<(Manifest, Vec<(PathBuf, Error)>)> {
        // Where the lock cannot even be created (read-only storage) nobody writes here, and
        // the scan needs no lock.
        let lock = std::fs::OpenOptions::new()
            .create(true)
            .truncate(false)
            .write(true)
            .open(dir.join(MANIFEST_LOCK_NAME))
            .ok();
        if let Some(lock) = &lock {
            let lock_path = dir.join(MANIFEST_LOCK_NAME);
            lock.lock()
                .map_err(|e| slosh_fileio::IoError::new(&lock_path, e))?;
        }
        let (manifest, problems) = Manifest::rebuild(dir)?;
        // A manifest that already says this is left alone (and read-only storage is fine).
        if Manifest::read(dir).ok().as_ref() != Some(&manifest) {
            manifest.write(dir)?;
        }
        drop(lock);
        Ok((manifest, problems))
    }

    /// What is wrong with `file` as step `index` of the series this manifest describes (empty
    /// when it belongs): its header's step index, settings and source against the file name
    /// and the manifest; its bytes, checksum, points and time against the manifest's entry.
    pub fn step_problems(&self, index: usize, file: &CacheFile) -> Vec<String> {
        let h = file.header();
        let mut problems = self.key().differences(index, h);
        match self.steps.iter().find(|s| s.index == index) {
            None => problems.push("is not in the manifest".into()),
            Some(entry) => {
                let checksum = hex64(file.footer_checksum());
                if entry.bytes != file.file_len() || entry.xxh3 != checksum {
                    problems.push(format!(
                        "has {} bytes with checksum {checksum}; the manifest lists {} bytes with {}",
                        file.file_len(),
                        entry.bytes,
                        entry.xxh3
                    ));
                }
                if entry.points != h.points || entry.time != h.source.time {
                    problems.push(format!(
                        "has {} points at t = {}; the manifest lists {} at t = {}",
                        h.points, h.source.time, entry.points, entry.time
                    ));
                }
            }
        }
        problems
    }

    /// What every step of the series shares.
    pub fn key(&self) -> SeriesKey {
        SeriesKey {
            source: self.source.clone(),
            params_hash: self.params_hash.clone(),
            series: self.series,
        }
    }

    /// The steps of the series that are not listed (a shard not yet done, a file deleted).
    pub fn missing(&self) -> Vec<usize> {
        let present: Vec<usize> = self.steps.iter().map(|s| s.index).collect();
        self.key().missing(&present)
    }

    pub fn write(&self, dir: &Path) -> Result<()> {
        let path = dir.join(MANIFEST_NAME);
        let json = serde_json::to_vec_pretty(self)
            .map_err(|e| slosh_fileio::IoError::new(&path, std::io::Error::other(e)))?;
        slosh_fileio::atomic_write(&path, &json)?;
        Ok(())
    }

    pub fn read(dir: &Path) -> Result<Manifest> {
        let path = dir.join(MANIFEST_NAME);
        let bytes = std::fs::read(&path).map_err(|e| slosh_fileio::IoError::new(&path, e))?;
        let m: Manifest = serde_json::from_slice(&bytes).map_err(|e| Error::Invalid {
            path: path.clone(),
            problem: format!("not a manifest: {e}"),
        })?;
        if m.format != MANIFEST_FORMAT {
            return Err(Error::Invalid {
                path,
                problem: format!("format '{}', expected '{MANIFEST_FORMAT}'", m.format),
            });
        }
        Ok(m)
    }
}
