#![no_main]
//! Any bytes as a .slc step file, in memory and as a mapped file that is truncated or
//! rewritten under its map: an error or a result, never a panic or a SIGBUS.

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    slosh_cache::fuzzing::open_verify_trace(data);
    slosh_cache::fuzzing::changed_while_mapped(data);
});
