//! One bake holds a cache directory for its whole run. The shards of one bake (the same input,
//! settings and steps, given to each task of a job array) hold it together; any other bake is
//! refused while they do, before it writes anything. The hold is an OS file lock, which the
//! kernel releases when its holder exits, however it exits: a SIGKILLed bake never blocks the
//! next one.

use std::fs::{File, OpenOptions, TryLockError};
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::Path;

use slosh_cache::SeriesKey;
use slosh_fileio::IoError;

/// The lock every bake of the directory holds (shared) for its run; it names their series.
pub const BAKE_LOCK_NAME: &str = ".bake.lock";
/// One byte per step index, locked while a bake of the directory bakes that step
/// ([`slosh_fileio::RangeLocks`]): two runs of one bake (a job array's shards, a requeued job,
/// the same command twice, players of one case) never bake one step twice at once.
pub const STEP_LOCKS_NAME: &str = ".bake.steps.lock";
/// Taken (exclusive) only while a bake joins or starts the hold, so that the check of who
/// holds the directory and the taking of it are one step.
const JOIN_LOCK_NAME: &str = ".bake.join.lock";

/// The directory held; released on drop.
#[derive(Debug)]
pub struct Claim {
    _lock: File,
}

fn open_rw(path: &Path) -> Result<File, slosh_cache::Error> {
    OpenOptions::new()
        .create(true)
        .truncate(false)
        .read(true)
        .write(true)
        .open(path)
        .map_err(|e| IoError::new(path, e).into())
}

/// Holds `dir` for a bake of `key`, with the bakes of the same key already holding it.
pub fn claim(dir: &Path, key: &SeriesKey) -> Result<Claim, slosh_cache::Error> {
    let join_path = dir.join(JOIN_LOCK_NAME);
    let join = open_rw(&join_path)?;
    join.lock().map_err(|e| IoError::new(&join_path, e))?;
    let path = dir.join(BAKE_LOCK_NAME);
    let mut lock = open_rw(&path)?;
    let io = |e: std::io::Error| -> slosh_cache::Error { IoError::new(&path, e).into() };
    let ours = serde_json::to_string(key).map_err(|e| io(std::io::Error::other(e)))?;
    match lock.try_lock() {
        Ok(()) => {
            // Nobody holds it: this bake starts the hold and names its series for the bakes
            // that come to join (converting to shared is safe under the join lock).
            lock.set_len(0).map_err(io)?;
            lock.seek(SeekFrom::Start(0)).map_err(io)?;
            lock.write_all(ours.as_bytes()).map_err(io)?;
            lock.sync_data().map_err(io)?;
            lock.lock_shared().map_err(io)?;
        }
        Err(TryLockError::WouldBlock) => {
            let mut theirs = String::new();
            lock.seek(SeekFrom::Start(0)).map_err(io)?;
            lock.read_to_string(&mut theirs).map_err(io)?;
            if theirs != ours {
                let what = serde_json::from_str::<SeriesKey>(&theirs)
                    .map_or_else(|_| "another bake".to_string(), |k| describe(&k));
                return Err(slosh_cache::Error::Invalid {
                    path: dir.to_path_buf(),
                    problem: format!(
                        "{what} is writing this directory now, and this run is {}; one directory \
                         holds one bake, so nothing was written: wait for it to finish, or bake \
                         into another directory",
                        describe(key)
                    ),
                });
            }
            // A shard of the same bake: hold it beside the others.
            lock.try_lock_shared().map_err(|e| match e {
                TryLockError::Error(e) => io(e),
                TryLockError::WouldBlock => io(std::io::Error::other("the lock is held")),
            })?;
        }
        Err(TryLockError::Error(e)) => return Err(io(e)),
    }
    drop(join);
    Ok(Claim { _lock: lock })
}

/// "a bake of steps 0..=9 (10 steps) of /runs/tank.case (parameter hash …)".
pub fn describe(key: &SeriesKey) -> String {
    format!(
        "a bake of {}of {} (parameter hash {})",
        key.series.map_or(String::new(), |s| format!("{s} ")),
        key.source,
        key.params_hash
    )
}
