#![no_main]
//! Fuzz target: see `svetlo::fuzzing::pbrt`.

libfuzzer_sys::fuzz_target!(|data: &[u8]| svetlo::fuzzing::pbrt(data));
