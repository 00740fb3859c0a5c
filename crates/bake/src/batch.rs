//! The batch driver: bakes a series step by step with a bounded number of steps in memory,
//! skips steps whose cache already verifies with the same parameters (resume), splits work
//! into disjoint shards, goes on past bad steps and reports them, and rebuilds the manifest.

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use slosh_cache::{CacheFile, Manifest, StepStats, encode_step, step_file_name};
use slosh_fileio::FileBytes;

use crate::params::BakeParams;
use crate::select::StepInput;
use crate::step::bake_step;

/// Where steps come from: an EnSight case, or a single point-cloud file.
pub trait StepSource: Sync {
    /// (step index, time) of every step, in order.
    fn steps(&self) -> Vec<(usize, f64)>;
    /// Reads one step with everything `BakeParams` asks for.
    fn read(&self, index: usize) -> Result<StepInput, String>;
    /// What step `index` is read from (its files' paths, sizes and modification times,
    /// hashed), cheaply: a kept cache must have been baked from the same input. `None`
    /// where the source cannot tell (then only the settings decide).
    fn identity(&self, index: usize) -> Option<String> {
        let _ = index;
        None
    }
}

/// The identity of a set of input files: their paths, sizes and modification times, hashed.
/// A file that cannot be read gives `None` (nothing can be kept against it).
pub fn files_identity<'a>(paths: impl IntoIterator<Item = &'a Path>) -> Option<String> {
    let mut text = String::new();
    for path in paths {
        let meta = std::fs::metadata(path).ok()?;
        let modified = meta
            .modified()
            .ok()
            .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
            .map_or(0, |d| d.as_nanos());
        text += &format!("{}\u{0}{}\u{0}{modified}\n", path.display(), meta.len());
    }
    Some(slosh_cache::hex64(xxhash_rust::xxh3::xxh3_64(
        text.as_bytes(),
    )))
}

/// Which of the series' steps this process bakes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    /// 0-based.
    pub index: usize,
    pub count: usize,
}

impl Shard {
    pub const WHOLE: Shard = Shard { index: 0, count: 1 };

    /// Step at position `pos` of the selected steps belongs to shard `pos % count`: disjoint,
    /// covering, and balanced when step sizes drift over a run.
    pub fn owns(self, pos: usize) -> bool {
        pos % self.count == self.index
    }
}

#[derive(Debug, Clone)]
pub struct BatchOptions {
    pub out: PathBuf,
    /// Step indices to bake (inclusive range of EnSight step indices); all when `None`.
    pub steps: Option<(usize, usize)>,
    /// Steps in flight at once (each is parallel inside).
    pub jobs: usize,
    /// Threads of the whole bake. Each job bakes its steps on a pool of its own, an equal
    /// share of them (at least one), so that steps in flight do not compete inside one pool.
    pub threads: usize,
    pub shard: Shard,
    pub params: BakeParams,
}

#[derive(Debug, Clone)]
pub enum Outcome {
    Baked {
        bytes: u64,
        points: u64,
        seconds: f64,
        stats: Box<StepStats>,
    },
    /// A cache with the same parameter hash was already there and verified.
    Kept,
    Failed(String),
}

/// Progress events, for a progress bar.
#[derive(Debug, Clone)]
pub enum Event {
    Planned { steps: usize },
    Done { index: usize, outcome: Outcome },
}

#[derive(Debug, Default)]
pub struct BatchReport {
    pub baked: usize,
    pub kept: usize,
    pub failed: Vec<(usize, String)>,
    pub points: u64,
    pub bytes: u64,
    /// Summed seconds per stage over baked steps, pipeline order; plus "write".
    pub stages: Vec<(String, f64)>,
    pub wall_seconds: f64,
    /// Step files that failed when the manifest was rebuilt.
    pub manifest_problems: Vec<(PathBuf, String)>,
    /// Why the manifest could not be rebuilt or written, if it could not.
    pub manifest_error: Option<String>,
}

/// The steps this process is responsible for.
pub fn plan(source: &dyn StepSource, opts: &BatchOptions) -> Vec<(usize, f64)> {
    source
        .steps()
        .into_iter()
        .filter(|(i, _)| opts.steps.is_none_or(|(a, b)| (a..=b).contains(i)))
        .enumerate()
        .filter(|(pos, _)| opts.shard.owns(*pos))
        .map(|(_, s)| s)
        .collect()
}

/// True when `path` holds a complete cache made with `hash`, from the input `identity`
/// (where the source gives one) of step `index`, whose bytes are intact.
pub fn is_current(path: &Path, hash: &str, index: usize, identity: Option<&str>) -> bool {
    CacheFile::open(path).is_ok_and(|f| {
        let source = &f.header().source;
        f.header().params_hash == hash
            && source.step == index
            && identity.is_none_or(|id| source.identity.as_deref() == Some(id))
            && f.body_intact()
    })
}

fn bake_one(source: &dyn StepSource, index: usize, opts: &BatchOptions, hash: &str) -> Outcome {
    let path = opts.out.join(step_file_name(index));
    let identity = source.identity(index);
    if is_current(&path, hash, index, identity.as_deref()) {
        return Outcome::Kept;
    }
    let start = Instant::now();
    let input = match source.read(index) {
        Ok(i) => i,
        Err(e) => return Outcome::Failed(e),
    };
    let read_seconds = start.elapsed().as_secs_f64();
    let mut input = input;
    input.identity = identity;
    let baked = match bake_step(&input, &opts.params) {
        Ok(b) => b,
        // The report names the step; the error's own "step N:" would say it twice.
        Err(e) => return Outcome::Failed(e.problem()),
    };
    drop(input);
    let mut header = baked.header;
    header
        .stats
        .stage_seconds
        .insert(0, ("read".into(), read_seconds));
    let points = header.points;
    let mut stats = header.stats.clone();
    let write_start = Instant::now();
    // What is written is what the verifier accepts: the encoded file is opened and verified
    // in memory first, and a step that fails is reported, never written.
    let written = encode_step(header, &baked.sections, opts.params.compression)
        .map_err(|e| format!("{}: encoding: {e}", path.display()))
        .and_then(|bytes| {
            CacheFile::from_bytes(FileBytes::from_vec(&path, bytes))
                .and_then(|file| file.verify().map(|_| file))
                .map_err(|e| format!("{e} (the step was not written)"))
        })
        .and_then(|file| {
            slosh_fileio::atomic_write(&path, file.bytes())
                .map(|()| file.file_len())
                .map_err(|e| e.to_string())
        });
    match written {
        Ok(bytes) => {
            stats.stage_seconds.push((
                "compress, verify and write".into(),
                write_start.elapsed().as_secs_f64(),
            ));
            Outcome::Baked {
                bytes,
                points,
                seconds: start.elapsed().as_secs_f64(),
                stats: Box::new(stats),
            }
        }
        Err(e) => Outcome::Failed(e),
    }
}

/// One directory holds one bake: a step file this run will not rewrite, made with other
/// settings, stops the run before anything is written (otherwise the steps it bakes would
/// replace good ones and the manifest would then refuse the mixture).
fn refuse_mixing(
    dir: &Path,
    planned: &[(usize, f64)],
    hash: &str,
) -> Result<(), slosh_cache::Error> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Ok(());
    };
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        let Some(index) = slosh_cache::parse_step_file_name(&name) else {
            continue;
        };
        if planned.iter().any(|(i, _)| *i == index) {
            continue;
        }
        let Ok(file) = CacheFile::open(&e.path()) else {
            continue;
        };
        let theirs = &file.header().params_hash;
        if theirs != hash {
            return Err(slosh_cache::Error::Invalid {
                path: e.path(),
                problem: format!(
                    "this step was baked with other settings (parameter hash {theirs}, this run's {hash}), and this run does not rebake it; one directory holds one bake, so nothing was written: bake every step with the new settings, or into another directory"
                ),
            });
        }
    }
    Ok(())
}

/// Removes temporary files that a killed bake left behind (their writer is gone).
fn remove_stale_temps(dir: &Path) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        // Step files and the manifest are the only files a bake writes.
        let ours = name.starts_with(".step-")
            || name.starts_with(&format!(".{}.", slosh_cache::MANIFEST_NAME));
        if !(slosh_fileio::is_atomic_temp(&name) && ours) {
            continue;
        }
        let pid = name
            .rsplit_once(".tmp-")
            .and_then(|(_, rest)| rest.split('-').next())
            .and_then(|p| p.parse::<u32>().ok());
        let alive = pid.is_none_or(|p| {
            cfg!(not(target_os = "linux")) || Path::new(&format!("/proc/{p}")).exists()
        });
        if !alive {
            let _ = std::fs::remove_file(e.path());
        }
    }
}

/// Bakes the planned steps of `source` into `opts.out`, then rebuilds the manifest.
pub fn run_batch(
    source: &dyn StepSource,
    opts: &BatchOptions,
    progress: &(dyn Fn(Event) + Sync),
) -> Result<BatchReport, slosh_cache::Error> {
    let start = Instant::now();
    std::fs::create_dir_all(&opts.out).map_err(|e| slosh_fileio::IoError::new(&opts.out, e))?;
    remove_stale_temps(&opts.out);
    let planned = plan(source, opts);
    progress(Event::Planned {
        steps: planned.len(),
    });
    let hash = opts.params.hash();
    refuse_mixing(&opts.out, &planned, &hash)?;
    let next = AtomicUsize::new(0);
    let report = Mutex::new(BatchReport::default());
    // Plain threads pull steps; each runs its steps on a rayon pool of its own. A rayon thread
    // waiting inside one step could otherwise start another step, and memory would grow with
    // the series; and steps sharing one pool spread every stage over all cores, paying for its
    // splitting and stealing, where a pool per job keeps each step on its share (16 steps of
    // 1M points on the 16-core H200 host, 8 jobs: 23.1 and 21.2 s shared, 19.5 and 16.8 s).
    let jobs = opts.jobs.clamp(1, planned.len().max(1));
    std::thread::scope(|scope| {
        for job in 0..jobs {
            let threads = opts.threads / jobs + usize::from(job < opts.threads % jobs);
            // A pool that cannot be made leaves the job on the global pool.
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads.max(1))
                .thread_name(move |t| format!("bake-{job}-{t}"))
                .build()
                .ok();
            let (next, report, planned, hash) = (&next, &report, &planned, &hash);
            scope.spawn(move || {
                loop {
                    let k = next.fetch_add(1, Ordering::Relaxed);
                    let Some(&(index, _)) = planned.get(k) else {
                        break;
                    };
                    let bake = || bake_one(source, index, opts, hash);
                    let outcome = match &pool {
                        Some(pool) => pool.install(bake),
                        None => bake(),
                    };
                    {
                        let mut r = report.lock().unwrap_or_else(|p| p.into_inner());
                        match &outcome {
                            Outcome::Baked {
                                bytes,
                                points,
                                stats,
                                ..
                            } => {
                                r.baked += 1;
                                r.bytes += bytes;
                                r.points += points;
                                for (name, s) in &stats.stage_seconds {
                                    match r.stages.iter_mut().find(|(n, _)| n == name) {
                                        Some(entry) => entry.1 += s,
                                        None => r.stages.push((name.clone(), *s)),
                                    }
                                }
                            }
                            Outcome::Kept => r.kept += 1,
                            Outcome::Failed(e) => r.failed.push((index, e.clone())),
                        }
                    }
                    progress(Event::Done { index, outcome });
                }
            });
        }
    });
    let mut report = report.into_inner().unwrap_or_else(|p| p.into_inner());
    report.failed.sort_by_key(|(i, _)| *i);
    // A manifest that cannot be written is reported beside the steps' own outcomes, which
    // must not be lost behind it.
    match Manifest::refresh(&opts.out) {
        Ok((_, problems)) => {
            report.manifest_problems = problems
                .into_iter()
                .map(|(p, e)| (p, e.to_string()))
                .collect();
        }
        Err(e) => report.manifest_error = Some(e.to_string()),
    }
    report.wall_seconds = start.elapsed().as_secs_f64();
    Ok(report)
}

#[cfg(test)]
mod tests {
    use crate::step::BakeError;

    /// A failed step is reported as "step N: problem", once (issue 14, item 12).
    #[test]
    fn failures_do_not_repeat_the_step() {
        let e = BakeError::Input {
            step: 3,
            problem: "no normals read from 'normal'".into(),
        };
        assert_eq!(e.to_string(), "step 3: no normals read from 'normal'");
        assert_eq!(e.problem(), "no normals read from 'normal'");
    }
}
