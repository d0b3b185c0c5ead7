#![no_main]
//! `cargo fuzz run cdr`: the entry point is shared with tests/fuzz_smoke.rs.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = tarn_sim::fuzzing::cdr(data);
});
