//! The `slosh` binary end to end, as a user runs it: one test binary, split by feature as
//! ripgrep's tests are, over the helpers in `tests/util` that the window tests share.

#![allow(clippy::unwrap_used)] // helpers of tests, where a failed unwrap is a failed test

#[path = "../util/mod.rs"]
mod util;

mod bake;
mod bench;
mod field_colours;
mod hard_inputs;
mod movie;
mod read;
mod refusals;
mod sequence_framing;
mod series_integrity;
