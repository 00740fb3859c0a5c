//! `slosh info`: what a case holds, for people (a table) and programs (`--json`).

use anyhow::{Result, bail};
use slosh_ensight::Case;
use slosh_ensight::info::{gather, render_human};

pub fn run(case: &Case, json: bool) -> Result<()> {
    let info = gather(case);
    let text = if json {
        serde_json::to_string_pretty(&info)? + "\n"
    } else {
        render_human(&info)
    };
    slosh_fileio::stdout::print(&text)?;
    let failed: Vec<String> = info
        .steps
        .iter()
        .filter_map(|s| s.error.as_ref().map(|e| format!("step {}: {e}", s.index)))
        .collect();
    if !failed.is_empty() {
        bail!(
            "{} of {} steps could not be read:\n{}",
            failed.len(),
            info.steps.len(),
            failed.join("\n")
        );
    }
    Ok(())
}
