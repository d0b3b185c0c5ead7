#![no_main]
//! `cargo fuzz run color_model_json`: the entry point is shared with tests/fuzz_smoke.rs.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = tarn_sim::fuzzing::color_model_json(data);
});
