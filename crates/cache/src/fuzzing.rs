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
    if file.verify().is_err() {
        return;
    }
    let Ok(step) = crate::LoadedStep::load(&file) else {
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
