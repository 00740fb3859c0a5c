/// What can go wrong in the engine; every message names the file or directory.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("{path}: {problem}")]
    Series {
        path: std::path::PathBuf,
        problem: String,
    },
    /// A step driven to the screen without a window that did not get there.
    #[error("step {position}: {why}")]
    NotShown { position: usize, why: String },
    #[error(transparent)]
    Render(#[from] slosh_render::Error),
    #[error(transparent)]
    Cache(#[from] slosh_cache::Error),
}

pub type Result<T> = std::result::Result<T, Error>;
