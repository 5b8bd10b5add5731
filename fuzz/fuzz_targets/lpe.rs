#![no_main]
//! Fuzz target: see `svetlo::fuzzing::lpe`.

libfuzzer_sys::fuzz_target!(|data: &[u8]| svetlo::fuzzing::lpe(data));
