#![no_main]
//! Fuzz target: see `svetlo::fuzzing::ply`.

libfuzzer_sys::fuzz_target!(|data: &[u8]| svetlo::fuzzing::ply(data));
