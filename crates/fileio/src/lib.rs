//! Whole files in and out: bytes memory-mapped where the OS allows (read into memory
//! otherwise), guarded against the file shrinking under the map, writes that either land
//! completely or not at all, and stdout that a closed pipe or a full disk never panics.

mod range_lock;
mod sigbus;
pub mod stdout;

pub use range_lock::{RangeLock, RangeLocks};

use std::fs::{File, OpenOptions};
use std::io::Write;
use std::ops::Deref;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// An I/O failure and the file it concerns.
#[derive(Debug, thiserror::Error)]
#[error("{}: {source}", path.display())]
pub struct IoError {
    pub path: PathBuf,
    #[source]
    pub source: std::io::Error,
}

impl IoError {
    pub fn new(path: &Path, source: std::io::Error) -> IoError {
        IoError {
            path: path.to_path_buf(),
            source,
        }
    }
}

/// The whole content of one file, mapped or owned.
#[derive(Debug)]
pub struct FileBytes {
    path: PathBuf,
    data: Data,
}

#[derive(Debug)]
enum Data {
    /// The guard is dropped (unregistered) before the map is unmapped: fields drop in order.
    Mapped {
        guard: sigbus::Guard,
        map: memmap2::Mmap,
    },
    Owned(Vec<u8>),
}

impl FileBytes {
    /// Maps `path` read-only; falls back to reading it (some network file systems). Only
    /// regular files are taken: a FIFO would block forever and a device (`/dev/zero`) never
    /// ends, so both are refused before they are opened.
    pub fn open(path: &Path) -> Result<FileBytes, IoError> {
        let meta = std::fs::metadata(path).map_err(|e| IoError::new(path, e))?;
        if !meta.is_file() {
            return Err(IoError::new(
                path,
                std::io::Error::new(
                    std::io::ErrorKind::InvalidInput,
                    "not a regular file (a directory, FIFO or device); give a file",
                ),
            ));
        }
        let file = File::open(path).map_err(|e| IoError::new(path, e))?;
        let len = file.metadata().map_err(|e| IoError::new(path, e))?.len();
        // An empty file cannot be mapped on every OS; it has nothing to map anyway.
        if len > 0 {
            // SAFETY: the map is read-only. slosh replaces files by rename (`atomic_write`),
            // which leaves a mapped old inode intact, but another program may truncate or
            // rewrite the file in place: a read past its new end then raises SIGBUS, which
            // the guard turns into a page of zeros and a mark (`changed`). Without a guard
            // the file is read instead.
            let mapped = unsafe { memmap2::MmapOptions::new().populate().map(&file) };
            if let Ok(map) = mapped
                && let Some(guard) = sigbus::register(map.as_ptr(), map.len())
            {
                return Ok(FileBytes {
                    path: path.to_path_buf(),
                    data: Data::Mapped { guard, map },
                });
            }
        }
        let bytes = std::fs::read(path).map_err(|e| IoError::new(path, e))?;
        Ok(FileBytes::from_vec(path, bytes))
    }

    /// Bytes already in memory, labelled with the path they stand for.
    pub fn from_vec(path: &Path, bytes: Vec<u8>) -> FileBytes {
        FileBytes {
            path: path.to_path_buf(),
            data: Data::Owned(bytes),
        }
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn is_mapped(&self) -> bool {
        matches!(self.data, Data::Mapped { .. })
    }

    /// Whether the file shrank under its map since it was opened and a read past its new end
    /// got zeros instead of its bytes: nothing read from it can be trusted. Checked after
    /// reading, since it can happen at any moment.
    pub fn changed(&self) -> bool {
        match &self.data {
            Data::Mapped { guard, .. } => guard.faulted(),
            Data::Owned(_) => false,
        }
    }
}

impl Deref for FileBytes {
    type Target = [u8];
    fn deref(&self) -> &[u8] {
        match &self.data {
            Data::Mapped { map, .. } => map,
            Data::Owned(v) => v,
        }
    }
}

static TEMP_SERIAL: AtomicU64 = AtomicU64::new(0);

/// Writes to a temporary name in the same directory, flushes it to disk, then renames it over
/// the target: a reader sees the old file or the whole new one, even after a crash or kill.
pub fn atomic_write(path: &Path, bytes: &[u8]) -> Result<(), IoError> {
    StagedFile::write(path, bytes)?.publish()
}

/// A file written and flushed to disk under a temporary name beside its target, not yet in
/// place: [`StagedFile::publish`] renames it over the target, and dropped unpublished it is
/// removed. A caller can so write a file while it still checks what it writes, and put it in
/// place only if the check passes.
#[derive(Debug)]
pub struct StagedFile {
    path: PathBuf,
    tmp: PathBuf,
    published: bool,
}

impl StagedFile {
    /// Writes `bytes` under a fresh temporary name beside `path` and flushes them to disk.
    pub fn write(path: &Path, bytes: &[u8]) -> Result<StagedFile, IoError> {
        let file_name = path
            .file_name()
            .map(|f| f.to_string_lossy().into_owned())
            .unwrap_or_default();
        // The temporary file is created exclusively (O_EXCL: never an existing file, never
        // through a link someone planted under its name); a name that is taken gets the next
        // serial. Errors name the file asked for, not the temporary one.
        let (tmp, mut file) = loop {
            let serial = TEMP_SERIAL.fetch_add(1, Ordering::Relaxed);
            let tmp =
                path.with_file_name(format!(".{file_name}.tmp-{}-{serial}", std::process::id()));
            match OpenOptions::new().write(true).create_new(true).open(&tmp) {
                Ok(file) => break (tmp, file),
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists && serial < 1 << 20 => {
                    continue;
                }
                Err(e) => return Err(IoError::new(path, e)),
            }
        };
        let staged = StagedFile {
            path: path.to_path_buf(),
            tmp,
            published: false,
        };
        // On an error the staged file is dropped, and so removed.
        file.write_all(bytes)
            .and_then(|()| file.sync_data())
            .map_err(|e| IoError::new(path, e))?;
        Ok(staged)
    }

    /// Renames the file over its target.
    pub fn publish(mut self) -> Result<(), IoError> {
        std::fs::rename(&self.tmp, &self.path).map_err(|e| IoError::new(&self.path, e))?;
        self.published = true;
        Ok(())
    }
}

impl Drop for StagedFile {
    fn drop(&mut self) {
        if !self.published {
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

/// True for the temporary files `atomic_write` leaves behind when it is killed mid-write.
pub fn is_atomic_temp(file_name: &str) -> bool {
    file_name.starts_with('.') && file_name.contains(".tmp-")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A link planted under the next temporary name is never written through.
    #[cfg(unix)]
    #[test]
    fn a_planted_link_is_not_followed() {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let outside = dir.path().join("outside.txt");
        std::fs::write(&outside, b"precious").unwrap_or_else(|e| panic!("{e}"));
        let target = dir.path().join("out.bin");
        // Plant links under the next few temporary names.
        let next = TEMP_SERIAL.load(Ordering::Relaxed);
        for serial in next..next + 4 {
            let name = format!(".out.bin.tmp-{}-{serial}", std::process::id());
            std::os::unix::fs::symlink(&outside, dir.path().join(name))
                .unwrap_or_else(|e| panic!("{e}"));
        }
        atomic_write(&target, b"new").unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            std::fs::read(&outside).ok().as_deref(),
            Some(&b"precious"[..])
        );
        assert_eq!(std::fs::read(&target).ok().as_deref(), Some(&b"new"[..]));
    }

    /// A mapped file truncated under its map: reading past the new end neither kills the
    /// process nor returns the old bytes unmarked.
    #[cfg(unix)]
    #[test]
    fn a_file_truncated_under_its_map_is_marked_changed() {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let path = dir.path().join("big.bin");
        let len = 64 * 4096;
        std::fs::write(&path, vec![7u8; len]).unwrap_or_else(|e| panic!("{e}"));
        let bytes = FileBytes::open(&path).unwrap_or_else(|e| panic!("{e}"));
        assert!(bytes.is_mapped());
        assert!(!bytes.changed());
        let file = OpenOptions::new()
            .write(true)
            .open(&path)
            .unwrap_or_else(|e| panic!("{e}"));
        file.set_len(4096).unwrap_or_else(|e| panic!("{e}"));
        // Past the new end: zeros (the page was dropped), and the map is marked.
        let sum: u64 = bytes.iter().map(|&b| u64::from(b)).sum();
        assert!(bytes.changed());
        assert_eq!(
            sum,
            7 * 4096,
            "only the first page still holds the file's bytes"
        );
        // Another map is unaffected, and a dropped map frees its slot.
        let other = dir.path().join("other.bin");
        std::fs::write(&other, vec![1u8; 8192]).unwrap_or_else(|e| panic!("{e}"));
        let second = FileBytes::open(&other).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(second.iter().map(|&b| u64::from(b)).sum::<u64>(), 8192);
        assert!(!second.changed());
    }

    /// A staged file is in place only once published: dropped unpublished, it is removed
    /// and the target keeps its old bytes.
    #[test]
    fn a_staged_file_replaces_its_target_only_when_published() {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let target = dir.path().join("step.slc");
        std::fs::write(&target, b"old").unwrap_or_else(|e| panic!("{e}"));
        let names = || -> Vec<String> {
            let mut names: Vec<String> = std::fs::read_dir(dir.path())
                .unwrap_or_else(|e| panic!("{e}"))
                .map(|e| {
                    e.unwrap_or_else(|e| panic!("{e}"))
                        .file_name()
                        .to_string_lossy()
                        .into_owned()
                })
                .collect();
            names.sort();
            names
        };
        let staged = StagedFile::write(&target, b"rejected").unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(names().len(), 2, "the staged file lies beside its target");
        assert!(names().iter().any(|n| is_atomic_temp(n)));
        drop(staged);
        assert_eq!(names(), ["step.slc"]);
        assert_eq!(std::fs::read(&target).ok().as_deref(), Some(&b"old"[..]));
        StagedFile::write(&target, b"new")
            .and_then(StagedFile::publish)
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(names(), ["step.slc"]);
        assert_eq!(std::fs::read(&target).ok().as_deref(), Some(&b"new"[..]));
    }

    #[test]
    fn errors_name_the_file_asked_for() {
        let missing = Path::new("/nonexistent-slosh-dir/out.png");
        let err = atomic_write(missing, b"x")
            .map(|_| ())
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("/nonexistent-slosh-dir/out.png:"), "{err}");
        assert!(!err.contains(".tmp-"), "{err}");
    }

    /// A FIFO (which would block) and a device (which never ends) are refused at once.
    #[cfg(unix)]
    #[test]
    fn only_regular_files_are_read() {
        let err = FileBytes::open(Path::new("/dev/zero"))
            .map(|_| ())
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("/dev/zero") && err.contains("not a regular file"),
            "{err}"
        );
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let fifo = dir.path().join("pipe");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        if made.is_ok_and(|s| s.success()) {
            let err = FileBytes::open(&fifo).map(|_| ()).unwrap_err().to_string();
            assert!(err.contains("not a regular file"), "{err}");
        }
    }
}
