use std::path::PathBuf;

pub type Result<T, E = Error> = std::result::Result<T, E>;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error(transparent)]
    Io(#[from] slosh_fileio::IoError),
    /// The bytes at `offset` are not what the format requires there.
    #[error("{}: at byte {offset}: expected {expected}, found {found}", path.display())]
    Format {
        path: PathBuf,
        offset: u64,
        expected: String,
        found: String,
    },
    #[error(
        "{}: cache format version {found_major}.{found_minor} is newer than this slosh reads \
         (major version {supported}); upgrade slosh or re-bake",
        path.display()
    )]
    NewerVersion {
        path: PathBuf,
        found_major: u16,
        found_minor: u16,
        supported: u16,
    },
    #[error(
        "{}: cache format version {found_major}.{found_minor} is older than this slosh reads \
         ({supported_major}.{supported_minor}: steps stored in the compact GPU layout); \
         re-bake it: slosh bake {case} --out {}",
        path.display(),
        path.parent().map_or_else(|| ".".into(), |d| d.display().to_string())
    )]
    OlderVersion {
        path: PathBuf,
        found_major: u16,
        found_minor: u16,
        supported_major: u16,
        supported_minor: u16,
        /// The case the file was baked from, as its header names it.
        case: String,
    },
    /// A section failed its checksum, its decoding or a structural check.
    #[error("{}: section '{section}' (at byte {offset}): {problem}", path.display())]
    Section {
        path: PathBuf,
        section: String,
        offset: u64,
        problem: String,
    },
    #[error("{}: {problem}", path.display())]
    Invalid { path: PathBuf, problem: String },
}
