//! slosh's measurement harness: each benchmark takes its validated `Settings` (the binary maps
//! flags to them), measures, and returns a [`report::Report`]: typed measurements with a
//! markdown renderer, which the binary writes.
//! Speed figures always stand next to the error of the same setting. Never part of what a
//! user's bake, render or play runs; the library crates never depend on it.
//!
//! Errors are `anyhow`'s: a benchmark's failure only ever reaches the binary's top level,
//! with the context of which case failed, and no caller matches on its kind.

pub mod accuracy;
pub mod bake;
pub mod gpu;
mod plot;
pub mod precision;
pub mod report;
pub mod scrub;
mod sph;
pub mod stats;
