#![no_main]
//! Any bytes as a .slc step file: an error or a result, never a panic.

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| slosh_cache::fuzzing::open_verify_trace(data));
