//! File bytes: memory-mapped where the OS allows, read into memory otherwise.

use std::path::Path;

use crate::error::{Error, Result};

pub use slosh_fileio::FileBytes;

/// Opens `path` (mapped or read) with this crate's error.
pub(crate) fn open(path: &Path) -> Result<FileBytes> {
    FileBytes::open(path).map_err(|e| Error::io(&e.path, e.source))
}
