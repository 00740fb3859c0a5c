//! A cache step streamed into GPU storage buffers, in two halves. The host half
//! ([`HostStep`], `host.rs`) opens and checks the file, checksums its raw sections in place,
//! decodes the sections it reads (BVH nodes, cluster offsets) where they are compressed, and
//! checks the tree and the mask layout (`checks.rs`); it needs no device and runs on any
//! thread. The BVH2 goes to the GPU as baked: the tracer widens the one it draws into the
//! 4-wide tree its walk descends (`widen.rs`). The GPU half
//! ([`GpuStep::create`], `gpu_step.rs`) creates the buffers and fills one staging buffer
//! (`fill.rs`; from a [`StagingPool`](crate::StagingPool), so its pages are already faulted
//! in) on rayon's threads: raw sections copied from the map, compressed ones decoded run by
//! run into a cache-sized buffer and copied on while hot (staging memory may be
//! write-combined, and a decoder reads its own output), so a section never makes a round trip
//! through main memory. It records the copies into the caller's encoder without waiting; no
//! pass runs per upload (the neighbour masks are the tracer's, `masks.rs`). A step owns its bind group (group 0); the colour
//! field has its own buffer, so switching fields uploads only the field.

mod checks;
mod fill;
mod gpu_step;
mod host;

use slosh_cache::{CacheFile, names};

use crate::error::Error;

pub use checks::{MAX_BVH_DEPTH, MAX_LEAF_LINK_COUNT, MAX_LINK_FIRST, mask_row};
pub(crate) use gpu_step::NO_STEP;
pub use gpu_step::{GpuStep, StepBuffers, UploadOptions, UploadStats};
pub use host::{HostField, HostStep, StepInfo};

const SECTIONS: [&str; 11] = [
    names::POINTS,
    names::NORMALS,
    names::CLUSTER_START,
    names::CLUSTER_BASE,
    names::CLUSTER_NEIGHBOURS,
    names::BALLS,
    names::BALL_CUBIC,
    names::BALL_STATES,
    names::BALL_H,
    names::SPHERES,
    names::BVH_NODES,
];

/// The sections the host half reads (the tree check, the mask and candidate layouts), so
/// decodes itself.
const HOST_READS: [&str; 3] = [names::BVH_NODES, names::CLUSTER_START, names::CLUSTER_BASE];

fn slot_of(name: &str) -> usize {
    SECTIONS.iter().position(|n| *n == name).unwrap_or_default()
}

/// Bytes of an entry of the 4-wide tree (`struct Wide` in step.wgsl).
const WIDE_NODE_BYTES: u64 = 128;

/// wgpu refuses zero-sized bindings, and a binding must hold one element of its array:
/// absent or empty sections (a step without particles) bind this many zero bytes, the
/// largest element any binding holds (the wide node).
pub(crate) const EMPTY_BINDING: u64 = WIDE_NODE_BYTES;

fn field_buffer_size(bytes: &[u8]) -> u64 {
    (bytes.len() as u64).max(EMPTY_BINDING).next_multiple_of(4)
}

fn invalid(file: &CacheFile, problem: String) -> Error {
    Error::Step {
        path: file.path().to_path_buf(),
        problem,
    }
}
