//! The batch driver: bakes a series step by step with a bounded number of steps in memory,
//! skips steps whose cache already verifies with the same parameters (resume), splits work
//! into disjoint shards, goes on past bad steps and reports them, and rebuilds the manifest.

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use slosh_cache::{
    CacheFile, Manifest, SeriesKey, SeriesRecord, StepStats, encode_step, step_file_name,
};
use slosh_fileio::FileBytes;

use crate::claim::STEP_LOCKS_NAME;
use crate::device_turns::TurnOrder;
use crate::params::BakeParams;
use crate::select::StepInput;
use crate::step::{BakeError, bake_step_unless_withdrawn};
use crate::withdrawable::Withdrawn;

/// Where steps come from: an EnSight case, or a single point-cloud file.
pub trait StepSource: Sync {
    /// What the steps are read from, as every step file records it: the input's canonical
    /// path, so that two runs given one input by different paths agree.
    fn source_path(&self) -> String;
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
    /// The file step `index`'s particles are read from, for messages about them (a case's
    /// step numbers need not be its files'); `None` where there is no one file to name.
    fn particle_file(&self, index: usize) -> Option<PathBuf> {
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
        // One file given by different paths (relative, absolute, through a link) is one
        // input.
        let path = std::fs::canonicalize(path).ok()?;
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
    /// Where each step's neighbours and tree are found: the CPU ([`crate::Stages::cpu`]) or
    /// a GPU.
    pub stages: crate::Stages,
}

#[derive(Debug, Clone)]
pub enum StepOutcome {
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
    Done { index: usize, outcome: StepOutcome },
}

/// How reports name the particles a step drops for a non-finite coordinate
/// (`StepStats::dropped_non_finite`).
pub const NON_FINITE_PARTICLES: &str = "with a non-finite coordinate";
/// How reports name the particles a step drops far beyond the rest (`StepStats::dropped_far`).
pub const FAR_PARTICLES: &str = "far beyond the rest";

/// The particles a step dropped as damaged input, as reports name them ("10 with a
/// non-finite coordinate and 2 far beyond the rest"); `None` where it dropped none.
pub fn dropped_input(non_finite: u64, far: u64) -> Option<String> {
    let parts: Vec<String> = [(non_finite, NON_FINITE_PARTICLES), (far, FAR_PARTICLES)]
        .into_iter()
        .filter(|(n, _)| *n > 0)
        .map(|(n, what)| format!("{n} {what}"))
        .collect();
    (!parts.is_empty()).then(|| parts.join(" and "))
}

/// A step's particles dropped for a non-finite coordinate, or as far beyond the rest.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Dropped {
    pub step: usize,
    pub dropped: u64,
    pub read: u64,
}

#[derive(Debug, Default)]
pub struct BatchReport {
    pub baked: usize,
    pub kept: usize,
    pub failed: Vec<(usize, String)>,
    /// Steps baked without particles (valid steps, not failures), in order.
    pub empty: Vec<usize>,
    /// Steps with particles baked empty, fewer than two being left after selection (one
    /// cannot be sized), in order.
    pub too_few: Vec<usize>,
    /// Steps that dropped particles with a non-finite coordinate: the step, how many it
    /// dropped and how many it read, in order.
    pub non_finite: Vec<Dropped>,
    /// Steps that dropped particles far beyond the rest (`docs/bake.md`, "Select"), so.
    pub far: Vec<Dropped>,
    pub points: u64,
    pub bytes: u64,
    /// Summed seconds per stage over baked steps, pipeline order; plus "write".
    pub stages: Vec<(String, f64)>,
    pub wall_seconds: f64,
    /// Step files that failed when the manifest was rebuilt.
    pub manifest_problems: Vec<(PathBuf, String)>,
    /// Why the manifest could not be rebuilt or written, if it could not.
    pub manifest_error: Option<String>,
    /// Steps this run baked or found current that the rebuilt manifest does not hold, in
    /// order: their files were deleted, moved or damaged while the run went on.
    pub gone: Vec<usize>,
    /// Steps this run baked or found current, in order.
    done: Vec<usize>,
}

/// The steps of the series, every shard's: the source's steps that `--steps` selects.
fn selection(source: &dyn StepSource, opts: &BatchOptions) -> Vec<(usize, f64)> {
    source
        .steps()
        .into_iter()
        .filter(|(i, _)| opts.steps.is_none_or(|(a, b)| (a..=b).contains(i)))
        .collect()
}

/// The steps this process is responsible for.
pub fn plan(source: &dyn StepSource, opts: &BatchOptions) -> Vec<(usize, f64)> {
    selection(source, opts)
        .into_iter()
        .enumerate()
        .filter(|(pos, _)| opts.shard.owns(*pos))
        .map(|(_, s)| s)
        .collect()
}

/// What every step file of this bake records: its input, settings and steps (the source's
/// steps are numbered consecutively, so the selection is a range).
pub fn series_key(source: &dyn StepSource, opts: &BatchOptions) -> SeriesKey {
    let selected = selection(source, opts);
    SeriesKey {
        source: source.source_path(),
        params_hash: opts.params.hash(),
        series: match (selected.first(), selected.last()) {
            (Some(&(first, _)), Some(&(last, _))) => Some(SeriesRecord { first, last }),
            _ => None,
        },
    }
}

/// True when `path` holds a complete cache of step `index` of the series `key`, from the
/// input `identity` (where the source gives one), whose bytes are intact.
pub fn is_current(path: &Path, key: &SeriesKey, index: usize, identity: Option<&str>) -> bool {
    CacheFile::open(path).is_ok_and(|f| {
        let source = &f.header().source;
        key.differences(index, f.header()).is_empty()
            && identity.is_none_or(|id| source.identity.as_deref() == Some(id))
            && f.body_intact()
            // Deeper trees were written before the bake kept within the tracer's stack.
            && f.header().stats.bvh_depth <= slosh_cache::MAX_BVH_DEPTH
    })
}

/// Bakes step `index` of `source` into `opts.out` unless a current cache of it is there:
/// read, bake, encode, verify in memory, then write atomically.
pub(crate) fn bake_one(
    source: &dyn StepSource,
    index: usize,
    opts: &BatchOptions,
    key: &SeriesKey,
    withdrawn: Withdrawn<'_>,
    order: TurnOrder,
) -> StepOutcome {
    let path = opts.out.join(step_file_name(index));
    let identity = source.identity(index);
    if is_current(&path, key, index, identity.as_deref()) {
        return StepOutcome::Kept;
    }
    let withdrawn_now =
        || withdrawn().then(|| StepOutcome::Failed(BakeError::Withdrawn { step: index }.problem()));
    if let Some(outcome) = withdrawn_now() {
        return outcome;
    }
    let start = Instant::now();
    let input = match source.read(index) {
        Ok(i) => i,
        Err(e) => return StepOutcome::Failed(e),
    };
    let read_seconds = start.elapsed().as_secs_f64();
    let mut input = input;
    input.identity = identity;
    let baked =
        match bake_step_unless_withdrawn(&input, &opts.params, &opts.stages, withdrawn, order) {
            Ok(b) => b,
            // The report names the step; the error's own "step N:" would say it twice. The
            // particles' file, as a read error names its file.
            Err(e) => {
                return StepOutcome::Failed(match source.particle_file(index) {
                    Some(file) => format!("{}: {}", file.display(), e.problem()),
                    None => e.problem(),
                });
            }
        };
    drop(input);
    if let Some(outcome) = withdrawn_now() {
        return outcome;
    }
    let mut header = baked.header;
    header.series = key.series;
    header.source.path.clone_from(&key.source);
    header
        .stats
        .stage_seconds
        .insert(0, ("read".into(), read_seconds));
    let points = header.points;
    let mut stats = header.stats.clone();
    let write_start = Instant::now();
    // What is put in place is what the verifier accepts: the encoded file is verified in
    // memory while it is written under a temporary name beside its place, and renamed into
    // place only if it passed; a step that fails is reported, and its temporary file removed.
    // (One after the other, they took a 1M step's verification and its write 43-50 and 27-31
    // ms on this machine's two cores.)
    let written = encode_step(header, &baked.sections, opts.params.compression)
        .map_err(|e| format!("{}: encoding: {e}", path.display()))
        .and_then(|bytes| {
            CacheFile::from_bytes(FileBytes::from_vec(&path, bytes))
                .map_err(|e| format!("{e} (the step was not written)"))
        })
        .and_then(|file| {
            let (verified, staged) = rayon::join(
                || file.verify(),
                || slosh_fileio::StagedFile::write(&path, file.bytes()),
            );
            verified.map_err(|e| format!("{e} (the step was not written)"))?;
            staged
                .and_then(slosh_fileio::StagedFile::publish)
                .map(|()| file.file_len())
                .map_err(|e| e.to_string())
        });
    match written {
        Ok(bytes) => {
            stats.stage_seconds.push((
                "compress, verify and write".into(),
                write_start.elapsed().as_secs_f64(),
            ));
            StepOutcome::Baked {
                bytes,
                points,
                seconds: start.elapsed().as_secs_f64(),
                stats: Box::new(stats),
            }
        }
        Err(e) => StepOutcome::Failed(e),
    }
}

/// One directory holds one bake. A step file of another input stops the run before anything
/// is written, whether this run would rewrite it or not (it would replace another series'
/// steps); so does a step file this run will not rewrite that belongs to another bake of this
/// input (other settings or other steps: the directory would end up holding a mixture).
fn refuse_mixing(
    dir: &Path,
    planned: &[(usize, f64)],
    key: &SeriesKey,
) -> Result<(), slosh_cache::Error> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Ok(());
    };
    let mut files: Vec<(usize, PathBuf)> = entries
        .flatten()
        .filter_map(|e| {
            slosh_cache::parse_step_file_name(&e.file_name().to_string_lossy())
                .map(|i| (i, e.path()))
        })
        .collect();
    files.sort();
    for (index, path) in files {
        let Ok(file) = CacheFile::open(&path) else {
            continue;
        };
        let theirs = SeriesKey::of(file.header());
        let rewritten = planned.iter().any(|(i, _)| *i == index);
        let problem = if theirs.source != key.source {
            format!(
                "this step is of another series, {}; this run is {}",
                crate::claim::describe(&theirs),
                crate::claim::describe(key)
            )
        } else if !rewritten && theirs != *key {
            format!(
                "this step was {} and this run, {}, does not rebake it",
                crate::claim::describe(&theirs).replacen("a bake", "baked by a bake", 1),
                crate::claim::describe(key)
            )
        } else {
            continue;
        };
        return Err(slosh_cache::Error::Invalid {
            path,
            problem: format!(
                "{problem}; one directory holds one bake, so nothing was written: bake into \
                 another directory, or remove the old steps first"
            ),
        });
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

/// Holds `dir` for a bake of `key` that writes the `planned` steps: claimed, cleared of the
/// temporary files of killed bakes, and checked to hold no other series' steps.
pub(crate) fn prepare_dir(
    dir: &Path,
    planned: &[(usize, f64)],
    key: &SeriesKey,
) -> Result<crate::claim::Claim, slosh_cache::Error> {
    if dir.exists() && !dir.is_dir() {
        return Err(slosh_fileio::IoError::new(
            dir,
            std::io::Error::other(
                "is there and is not a directory (a bake writes its steps into one)",
            ),
        )
        .into());
    }
    std::fs::create_dir_all(dir).map_err(|e| slosh_fileio::IoError::new(dir, e))?;
    let claim = crate::claim::claim(dir, key)?;
    remove_stale_temps(dir);
    refuse_mixing(dir, planned, key)?;
    Ok(claim)
}

/// Bakes the planned steps of `source` into `opts.out`, then rebuilds the manifest.
pub fn run_batch(
    source: &dyn StepSource,
    opts: &BatchOptions,
    progress: &(dyn Fn(Event) + Sync),
) -> Result<BatchReport, slosh_cache::Error> {
    let start = Instant::now();
    let key = series_key(source, opts);
    let planned = plan(source, opts);
    // Held to the end of the run, manifest included.
    let _claim = prepare_dir(&opts.out, &planned, &key)?;
    progress(Event::Planned {
        steps: planned.len(),
    });
    let next = AtomicUsize::new(0);
    let report = Mutex::new(BatchReport::default());
    // A step another run of this bake is baking now is left to it, and waited for at the end
    // (then found current, or baked here if that run died).
    let step_locks = slosh_fileio::RangeLocks::open(&opts.out.join(STEP_LOCKS_NAME))?;
    let deferred: Mutex<Vec<usize>> = Mutex::new(Vec::new());
    // Plain threads pull steps; each runs its steps on a rayon pool of its own. A rayon thread
    // waiting inside one step could otherwise start another step, and memory would grow with
    // the series; and steps sharing one pool spread every stage over all cores, paying for its
    // splitting and stealing, where a pool per job keeps each step on its share (16 steps of
    // 1M points on the 16-core H200 host, 8 jobs: 23.1 and 21.2 s shared, 19.5 and 16.8 s).
    // So too where the stages run on a device, with steps on their own threads and their
    // parallel parts on rayon's global pool (64 steps of 1M on an H100 host, 24 jobs: 10.70 to
    // 12.46 s, against 7.25 to 7.66 s with a pool per job).
    let jobs = opts.jobs.clamp(1, planned.len().max(1));
    opts.stages.plan_steps_at_once(jobs);
    // Jobs still pulling steps; each that finds none left says how many go on.
    let running = AtomicUsize::new(jobs);
    std::thread::scope(|scope| {
        for job in 0..jobs {
            // At least one thread each.
            let threads = crate::jobs::thread_share(opts.threads, jobs, job);
            // A pool that cannot be made leaves the job on the global pool.
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .thread_name(move |t| format!("bake-{job}-{t}"))
                .build()
                .ok();
            let (next, report, planned, key) = (&next, &report, &planned, &key);
            let (step_locks, deferred, running) = (&step_locks, &deferred, &running);
            scope.spawn(move || {
                loop {
                    let k = next.fetch_add(1, Ordering::Relaxed);
                    let (index, wait) = match planned.get(k) {
                        Some(&(index, _)) => (index, false),
                        None => {
                            let left = deferred.lock().unwrap_or_else(|p| p.into_inner()).pop();
                            match left {
                                Some(index) => (index, true),
                                None => {
                                    // Memory kept for more steps goes while the others
                                    // finish, not all at the end.
                                    let on = running.fetch_sub(1, Ordering::AcqRel) - 1;
                                    opts.stages.plan_steps_left(on);
                                    break;
                                }
                            }
                        }
                    };
                    let held = if wait {
                        step_locks.lock(index as u64).map(Some)
                    } else {
                        step_locks.try_lock(index as u64)
                    };
                    let bake =
                        || bake_one(source, index, opts, key, &|| false, TurnOrder::ahead(index));
                    let outcome = match held {
                        Ok(None) => {
                            deferred
                                .lock()
                                .unwrap_or_else(|p| p.into_inner())
                                .push(index);
                            continue;
                        }
                        Err(e) => StepOutcome::Failed(e.to_string()),
                        Ok(Some(lock)) => {
                            let outcome = match &pool {
                                Some(pool) => pool.install(bake),
                                None => bake(),
                            };
                            drop(lock);
                            outcome
                        }
                    };
                    {
                        let mut r = report.lock().unwrap_or_else(|p| p.into_inner());
                        match &outcome {
                            StepOutcome::Baked {
                                bytes,
                                points,
                                stats,
                                ..
                            } => {
                                r.baked += 1;
                                if *points == 0 && stats.input_points == 0 {
                                    r.empty.push(index);
                                } else if *points == 0 {
                                    r.too_few.push(index);
                                }
                                let dropped = |dropped| Dropped {
                                    step: index,
                                    dropped,
                                    read: stats.input_points,
                                };
                                if stats.dropped_non_finite > 0 {
                                    r.non_finite.push(dropped(stats.dropped_non_finite));
                                }
                                if stats.dropped_far > 0 {
                                    r.far.push(dropped(stats.dropped_far));
                                }
                                r.bytes += bytes;
                                r.points += points;
                                for (name, s) in &stats.stage_seconds {
                                    match r.stages.iter_mut().find(|(n, _)| n == name) {
                                        Some(entry) => entry.1 += s,
                                        None => r.stages.push((name.clone(), *s)),
                                    }
                                }
                            }
                            StepOutcome::Kept => r.kept += 1,
                            StepOutcome::Failed(e) => r.failed.push((index, e.clone())),
                        }
                        if !matches!(outcome, StepOutcome::Failed(_)) {
                            r.done.push(index);
                        }
                    }
                    progress(Event::Done { index, outcome });
                }
            });
        }
    });
    let mut report = report.into_inner().unwrap_or_else(|p| p.into_inner());
    report.failed.sort_by_key(|(i, _)| *i);
    report.empty.sort_unstable();
    report.too_few.sort_unstable();
    report.non_finite.sort_unstable_by_key(|s| s.step);
    report.far.sort_unstable_by_key(|s| s.step);
    // A manifest that cannot be written is reported beside the steps' own outcomes, which
    // must not be lost behind it.
    match Manifest::refresh(&opts.out) {
        Ok((manifest, problems)) => {
            report.manifest_problems = problems
                .into_iter()
                .map(|(p, e)| (p, e.to_string()))
                .collect();
            // A step file gone between its write and the manifest would otherwise leave a
            // run that says it baked every step and a manifest without them.
            let held: std::collections::HashSet<usize> =
                manifest.steps.iter().map(|s| s.index).collect();
            report.done.sort_unstable();
            report.gone = report
                .done
                .iter()
                .copied()
                .filter(|i| !held.contains(i))
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
