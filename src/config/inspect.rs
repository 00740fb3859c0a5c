//! `slosh inspect` flags turned into one validated [`InspectConfig`].

use std::path::PathBuf;

use anyhow::{Result, bail};

use crate::cli::InspectArgs;

/// What `slosh inspect` looks at and how.
#[derive(Debug, Clone)]
pub struct InspectConfig {
    /// A cache directory or one step file.
    pub path: PathBuf,
    pub json: bool,
    pub verify: bool,
    /// One point of a step file to show in full.
    pub point: Option<usize>,
}

impl InspectConfig {
    pub fn from_args(args: &InspectArgs) -> Result<InspectConfig> {
        if args.point.is_some() && args.path.is_dir() {
            bail!("--point needs a step file, not a directory");
        }
        Ok(InspectConfig {
            path: args.path.clone(),
            json: args.json,
            verify: args.verify,
            point: args.point,
        })
    }
}
