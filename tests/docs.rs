//! docs/architecture.md names files and folders in backticks; each must exist, so that the
//! code map never sends a reader to a file that moved. A name is looked for from the
//! repository root, then under the folders its section's heading names (and their `src/`),
//! and a bare file name anywhere under those folders.

use std::path::{Path, PathBuf};

const FILE_ENDINGS: [&str; 6] = [".rs", ".wgsl", ".md", ".py", ".sh", ".toml"];

/// The backticked spans of `line`.
fn spans(line: &str) -> Vec<&str> {
    line.split('`').skip(1).step_by(2).collect()
}

/// Whether a span names a path: path characters only, with a folder or a source file ending.
fn is_path(span: &str) -> bool {
    let path_chars = span
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || "_./-".contains(c));
    path_chars
        && !span.starts_with(['-', '.'])
        && (span.contains('/') || FILE_ENDINGS.iter().any(|e| span.ends_with(e)))
}

/// Whether a file or folder named `name` lies anywhere under `dir` (targets left out).
fn found_under(dir: &Path, name: &str) -> bool {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return false;
    };
    entries.flatten().any(|e| {
        let path = e.path();
        if path
            .file_name()
            .is_some_and(|n| n == "target" || n == ".git")
        {
            return false;
        }
        path.ends_with(name) || (path.is_dir() && found_under(&path, name))
    })
}

/// Every path span of `text` that exists nowhere it could mean, and how many were checked.
fn missing_paths(root: &Path, text: &str) -> (Vec<String>, usize) {
    let mut bases = vec![root.to_path_buf()];
    let (mut missing, mut checked) = (Vec::new(), 0);
    for line in text.lines() {
        if line.starts_with('#') {
            let named: Vec<PathBuf> = spans(line)
                .into_iter()
                .map(|s| root.join(s.trim_end_matches('/')))
                .filter(|p| p.is_dir())
                .collect();
            bases = if named.is_empty() {
                vec![root.to_path_buf()]
            } else {
                named
            };
            continue;
        }
        for span in spans(line).into_iter().filter(|s| is_path(s)) {
            checked += 1;
            let name = span.trim_end_matches('/');
            let exists = root.join(name).exists()
                || bases
                    .iter()
                    .any(|b| b.join(name).exists() || b.join("src").join(name).exists())
                || bases.iter().any(|b| found_under(b, name));
            if !exists {
                missing.push(span.to_string());
            }
        }
    }
    (missing, checked)
}

#[test]
fn every_path_the_architecture_names_exists() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(root.join("docs/architecture.md"))
        .unwrap_or_else(|e| panic!("docs/architecture.md: {e}"));
    let (missing, checked) = missing_paths(root, &text);
    // The code map names well over a hundred paths: fewer means the spans were misread.
    assert!(checked > 100, "only {checked} paths found in the document");
    assert!(missing.is_empty(), "named but absent: {missing:?}");
    // And the check sees a moved file.
    let (moved, _) = missing_paths(root, "### `crates/render`\n`upload.rs` and `tracer/`\n");
    assert_eq!(moved, vec!["upload.rs".to_string()]);
}
