//! The `.slc` step cache: one memory-mappable file per time step holding everything the
//! tracer needs (points, radii, neighbour lists, initial fits, droplets, BVH) in the exact
//! layout of the WGSL storage buffers, plus a manifest per series. The one contract between
//! `slosh bake` and the renderers; `docs/cache-format.md` specifies it byte by byte.

mod ball_state;
mod bvh;
mod bvh_grid;
pub mod candidates;
mod codec;
mod error;
mod field_view;
mod format;
#[doc(hidden)]
pub mod fuzzing;
mod layout;
mod manifest;
pub mod names;
mod nearest_point;
pub mod octahedral;
mod probe;
mod reader;
mod statistics;
mod step;
mod verify;
mod writer;

pub use ball_state::{BALLS_PER_STATE_WORD, BallBits, StoredBall, exact_half, h_of, pack_h};
pub use bvh::{Bvh, BvhNode, MAX_BVH_DEPTH, MAX_LEAF_RANGE};
pub use bvh_grid::{BvhGrid, GpuBvhNode, LINK_FIRST_BITS};
/// The section codecs by themselves (for measuring encodings); readers use
/// [`CacheFile::decode_into`].
pub use codec::{
    DecodeError, decode_into as decode_bytes, encode as encode_bytes, shuffle, shuffle4,
};
pub use error::{Error, Result};
pub use field_view::{
    FieldRange, FieldView, VectorPart, component_view, field_view_ranges, field_views,
    find_field_view, vector_values, views_of,
};
pub use format::{
    ALIGN, CHUNK_ALIGN, CHUNK_RAW, CHUNK_RAW_MIN, CHUNKS_PER_SECTION, ChunkEntry, Encoding,
    FOOTER_LEN, Header, MAJOR, MINOR, MlsSettings, PREAMBLE_LEN, SectionEntry, SeriesRecord,
    Source, StepStats, Transform, hex64,
};
pub use layout::{
    BallState, CubicWords, Element, FIELD_MISSING, GpuBall, GpuPoint, GpuSphere, MAX_SPHERES,
    field_missing, stored_radius,
};
pub use manifest::{
    MANIFEST_LOCK_NAME, MANIFEST_NAME, Manifest, ManifestStep, SeriesKey, parse_step_file_name,
    step_file_name,
};
pub use nearest_point::NearestPoints;
pub use probe::{ProbeReading, SurfaceProbe};
pub use reader::CacheFile;
pub use statistics::{Statistics, Summary};
pub use step::LoadedStep;
pub use verify::VerifyReport;
pub use writer::{Compression, RAW_BUDGET_BYTES_PER_POINT, SectionInput, encode_step, write_step};
