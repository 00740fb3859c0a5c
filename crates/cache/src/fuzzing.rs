//! Entry points for `cargo fuzz` (see fuzz/): arbitrary bytes through the reader, with
//! checksum comparisons off so that mutations reach the header parser, the section decoders,
//! the invariant checks and the CPU tracer. Never used by slosh itself.

use std::path::Path;

use slosh_fileio::FileBytes;

use crate::reader::CacheFile;

/// Opens, verifies, loads and traces a few rays through `data`: errors are fine, panics,
/// hangs and huge allocations are bugs.
pub fn open_verify_trace(data: &[u8]) {
    let opened = CacheFile::parse(
        FileBytes::from_vec(Path::new("fuzz.slc"), data.to_vec()),
        true,
    );
    let Ok(file) = opened else {
        return;
    };
    exercise(&file);
}

/// The bytes after the first two as a file that another program truncates while it is mapped
/// (to the fraction of its length the first byte says), then, where the second byte is odd,
/// rewrites in place to its old length with other bytes: the reads that follow meet pages past
/// the file's end, or bytes that changed under them. Errors are fine; a SIGBUS, a panic or a
/// verification that passes on bytes that went to zeros are bugs. Returns whether the file was
/// seen to change.
pub fn changed_while_mapped(data: &[u8]) -> bool {
    use std::io::Write;
    let [cut, rewrite, body @ ..] = data else {
        return false;
    };
    static SERIAL: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let serial = SERIAL.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let path = std::env::temp_dir().join(format!("slosh-fuzz-{}-{serial}.slc", std::process::id()));
    let changed = (|| {
        std::fs::write(&path, body).ok()?;
        let file = CacheFile::parse(FileBytes::open(&path).ok()?, true).ok()?;
        let handle = std::fs::OpenOptions::new().write(true).open(&path).ok()?;
        handle
            .set_len((body.len() * usize::from(*cut) / 255) as u64)
            .ok()?;
        if rewrite % 2 == 1 {
            let other: Vec<u8> = body.iter().map(|b| b ^ rewrite).collect();
            (&handle).write_all(&other).ok()?;
        }
        drop(handle);
        // Every page read once, as a verifier or a loader would.
        std::hint::black_box(xxhash_rust::xxh3::xxh3_64(file.bytes()));
        let verified = file.verify().is_ok();
        let changed = file.unchanged().is_err();
        assert!(
            !(verified && changed),
            "verification passed on a file that changed under its map"
        );
        exercise(&file);
        Some(changed)
    })();
    let _ = std::fs::remove_file(&path);
    changed.unwrap_or(false)
}

/// Verifies, loads and traces a few rays through an opened file.
fn exercise(file: &CacheFile) {
    if file.verify().is_err() {
        return;
    }
    let Ok(step) = crate::LoadedStep::load(file) else {
        return;
    };
    let camera = slosh_mls::Camera {
        eye: [0.3, -3.0, 0.4],
        target: [0.0, 0.0, 0.0],
        up: [0.0, 0.0, 1.0],
        fov_y: 60.0,
        width: 4,
        height: 4,
    };
    let params = slosh_mls::Params::<f32> {
        iterations: 3,
        ..slosh_mls::Params::new()
    };
    for hit in step
        .surface
        .render_in(&step.bvh, &camera, &params)
        .into_iter()
        .flatten()
    {
        assert!(hit.t.is_finite(), "non-finite hit {hit:?}");
    }
}
