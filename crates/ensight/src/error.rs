//! Errors that say which file, where in it, and what was expected.

use std::fmt;
use std::path::{Path, PathBuf};

/// Where in a file an error was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Location {
    /// 1-based line of an ASCII file.
    Line(usize),
    /// Byte offset into a binary file.
    Byte(u64),
    /// The file as a whole (missing, unreadable, wrong size).
    File,
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Location::Line(l) => write!(f, "line {l}"),
            Location::Byte(b) => write!(f, "byte offset {b}"),
            Location::File => Ok(()),
        }
    }
}

/// Every failure of this crate.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The file could not be opened or read at all.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The content does not follow the format.
    #[error("{}", format_parse(path, *location, expected, found))]
    Parse {
        path: PathBuf,
        location: Location,
        expected: String,
        found: String,
    },
    /// A valid file that uses something slosh does not read (and says so rather than guessing).
    #[error("{path}: {what} is not supported")]
    Unsupported { path: PathBuf, what: String },
    /// A request names a step, variable or part that the case does not have.
    #[error("{0}")]
    Request(String),
}

fn format_parse(path: &Path, location: Location, expected: &str, found: &str) -> String {
    match location {
        Location::File => format!("{}: expected {expected}, found {found}", path.display()),
        _ => format!(
            "{}: {location}: expected {expected}, found {found}",
            path.display()
        ),
    }
}

impl Error {
    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        Error::Io {
            path: path.to_path_buf(),
            source,
        }
    }

    pub(crate) fn parse(
        path: &Path,
        location: Location,
        expected: impl Into<String>,
        found: impl Into<String>,
    ) -> Self {
        Error::Parse {
            path: path.to_path_buf(),
            location,
            expected: expected.into(),
            found: found.into(),
        }
    }

    pub(crate) fn unsupported(path: &Path, what: impl Into<String>) -> Self {
        Error::Unsupported {
            path: path.to_path_buf(),
            what: what.into(),
        }
    }
}

pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Quotes a piece of input for an error message, shortened so that binary garbage stays readable.
pub(crate) fn quote(bytes: &[u8]) -> String {
    const MAX: usize = 60;
    let text = String::from_utf8_lossy(&bytes[..bytes.len().min(MAX)]);
    let text = text.trim_end_matches('\0').trim_end();
    if bytes.len() > MAX {
        format!("{text:?}…")
    } else {
        format!("{text:?}")
    }
}
