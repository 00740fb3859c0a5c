//! Locks on single bytes of one file, each held by whoever took it (an open file description:
//! another process, or another opening in this one, is refused) and released by the kernel
//! when its holder exits however it exits. Linux's open file description locks; elsewhere,
//! and on file systems without them, every lock is granted, which only loses the exclusion.

use std::fs::File;
use std::path::Path;

use crate::IoError;

/// One file whose bytes are locked one at a time.
#[derive(Debug)]
pub struct RangeLocks {
    file: File,
    path: std::path::PathBuf,
}

/// Byte `offset` of a [`RangeLocks`] file, held until dropped.
#[derive(Debug)]
pub struct RangeLock<'a> {
    locks: &'a RangeLocks,
    offset: u64,
}

impl RangeLocks {
    /// Opens (creating) the file at `path`.
    pub fn open(path: &Path) -> Result<RangeLocks, IoError> {
        let file = std::fs::OpenOptions::new()
            .create(true)
            .truncate(false)
            .read(true)
            .write(true)
            .open(path)
            .map_err(|e| IoError::new(path, e))?;
        Ok(RangeLocks {
            file,
            path: path.to_path_buf(),
        })
    }

    /// Byte `offset`, or `None` where another holder has it.
    pub fn try_lock(&self, offset: u64) -> Result<Option<RangeLock<'_>>, IoError> {
        self.set(offset, Mode::TryLock).map(|taken| {
            taken.then_some(RangeLock {
                locks: self,
                offset,
            })
        })
    }

    /// Byte `offset`, once its holder lets it go (waits).
    pub fn lock(&self, offset: u64) -> Result<RangeLock<'_>, IoError> {
        self.set(offset, Mode::Wait)?;
        Ok(RangeLock {
            locks: self,
            offset,
        })
    }

    #[cfg(target_os = "linux")]
    fn set(&self, offset: u64, mode: Mode) -> Result<bool, IoError> {
        use std::os::fd::AsRawFd;
        let start = libc::off_t::try_from(offset)
            .map_err(|_| IoError::new(&self.path, std::io::Error::other("offset too large")))?;
        // SAFETY: a zeroed `flock` is a valid value of a plain C struct; the fields the call
        // reads are set below.
        let mut lock: libc::flock = unsafe { std::mem::zeroed() };
        lock.l_type = match mode {
            Mode::Unlock => libc::F_UNLCK,
            _ => libc::F_WRLCK,
        } as libc::c_short;
        lock.l_whence = libc::SEEK_SET as libc::c_short;
        lock.l_start = start;
        lock.l_len = 1;
        let command = match mode {
            Mode::Wait => libc::F_OFD_SETLKW,
            _ => libc::F_OFD_SETLK,
        };
        loop {
            // SAFETY: `fcntl` with an OFD lock command reads the `flock` it is given, which
            // lives for the call; the descriptor is this struct's open file.
            let r = unsafe { libc::fcntl(self.file.as_raw_fd(), command, &mut lock) };
            if r == 0 {
                return Ok(true);
            }
            let e = std::io::Error::last_os_error();
            match e.raw_os_error() {
                Some(libc::EINTR) => continue,
                Some(libc::EAGAIN | libc::EACCES) if mode == Mode::TryLock => return Ok(false),
                // A file system without these locks (some network mounts): granted, as on
                // other systems; only the exclusion is lost, never the work.
                Some(libc::ENOLCK | libc::EOPNOTSUPP | libc::ENOSYS | libc::EINVAL) => {
                    return Ok(true);
                }
                _ => return Err(IoError::new(&self.path, e)),
            }
        }
    }

    #[cfg(not(target_os = "linux"))]
    fn set(&self, _offset: u64, _mode: Mode) -> Result<bool, IoError> {
        Ok(true)
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mode {
    TryLock,
    Wait,
    Unlock,
}

impl Drop for RangeLock<'_> {
    fn drop(&mut self) {
        // Closing the file releases it too; an unlock that fails leaves it to that.
        let _ = self.locks.set(self.offset, Mode::Unlock);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_byte_is_held_by_one_opening_at_a_time() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("locks");
        let (a, b) = (
            RangeLocks::open(&path).unwrap(),
            RangeLocks::open(&path).unwrap(),
        );
        let held = a.try_lock(5).unwrap().expect("free");
        if cfg!(target_os = "linux") {
            assert!(b.try_lock(5).unwrap().is_none(), "byte 5 is held");
        }
        // Other bytes are free.
        let other = b.try_lock(6).unwrap().expect("byte 6 is free");
        drop(held);
        assert!(b.try_lock(5).unwrap().is_some(), "released on drop");
        drop(other);
        // A waiter gets it once the holder lets go, from another thread.
        let held = a.lock(7).unwrap();
        std::thread::scope(|s| {
            let waiter = s.spawn(|| b.lock(7).map(|_| ()));
            std::thread::sleep(std::time::Duration::from_millis(50));
            assert!(!waiter.is_finished() || !cfg!(target_os = "linux"));
            drop(held);
            waiter.join().unwrap().unwrap();
        });
    }
}
