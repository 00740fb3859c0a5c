#![no_main]
//! Any bytes as a geometry file: an error or a result, never a panic.

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| slosh_ensight::fuzzing::geometry(data));
