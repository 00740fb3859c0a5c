use std::path::PathBuf;

/// What can go wrong on the GPU side; every message names what was asked and what was found.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("no GPU adapter: {0}")]
    NoAdapter(String),
    #[error("GPU adapter '{adapter}': {problem}")]
    Limits { adapter: String, problem: String },
    #[error("GPU device request on '{adapter}' failed: {source}")]
    Device {
        adapter: String,
        #[source]
        source: wgpu::RequestDeviceError,
    },
    #[error("{path}: {problem}")]
    Step { path: PathBuf, problem: String },
    #[error(transparent)]
    Cache(#[from] slosh_cache::Error),
    #[error("GPU readback failed: {0}")]
    Readback(String),
    #[error("GPU validation: {0}")]
    Validation(String),
    /// The caller withdrew the upload ([`crate::UploadOptions::cancelled`]).
    #[error("upload cancelled")]
    Cancelled,
    #[error("writing {path}: {problem}")]
    Output { path: PathBuf, problem: String },
}

pub type Result<T> = std::result::Result<T, Error>;
