//! File bytes: memory-mapped where the OS allows, read into memory otherwise.

use std::fs::File;
use std::ops::Deref;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

/// The whole content of one file, mapped or owned.
#[derive(Debug)]
pub struct FileBytes {
    path: PathBuf,
    data: Data,
}

#[derive(Debug)]
enum Data {
    Mapped(memmap2::Mmap),
    Owned(Vec<u8>),
}

impl FileBytes {
    /// Maps `path` read-only; falls back to reading it (pipes, some network file systems).
    pub fn open(path: &Path) -> Result<Self> {
        let file = File::open(path).map_err(|e| Error::io(path, e))?;
        let len = file.metadata().map_err(|e| Error::io(path, e))?.len();
        // An empty file cannot be mapped on every OS; it has nothing to map anyway.
        if len > 0 {
            // SAFETY: the map is read-only. Another process truncating the file while it is
            // mapped would raise SIGBUS; solver output is written before it is read, and the
            // read fallback below exists for file systems where that promise does not hold.
            let mapped = unsafe { memmap2::MmapOptions::new().populate().map(&file) };
            if let Ok(map) = mapped {
                return Ok(FileBytes {
                    path: path.to_path_buf(),
                    data: Data::Mapped(map),
                });
            }
        }
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        Ok(FileBytes {
            path: path.to_path_buf(),
            data: Data::Owned(bytes),
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Deref for FileBytes {
    type Target = [u8];
    fn deref(&self) -> &[u8] {
        match &self.data {
            Data::Mapped(m) => m,
            Data::Owned(v) => v,
        }
    }
}
