//! What every benchmark returns: its measurements, typed, with a markdown renderer over
//! them. Measuring and writing are apart, so a table's values can be checked, compared
//! across runs or rendered again without measuring again; the binary writes the markdown.

use std::path::Path;

use anyhow::{Context, Result};

/// A benchmark's measurements, renderable as the markdown report it writes.
pub trait Report {
    /// The whole report: prose saying what was measured and how, then the tables.
    fn markdown(&self) -> String;
}

/// Writes `report`'s markdown to `path` atomically, creating its folder.
pub fn write(path: &Path, report: &impl Report) -> Result<()> {
    write_bytes(path, report.markdown().as_bytes())
}

/// Writes `bytes` to `path` atomically, creating its folder.
pub fn write_bytes(path: &Path, bytes: &[u8]) -> Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    slosh_fileio::atomic_write(path, bytes).with_context(|| format!("writing {}", path.display()))
}
