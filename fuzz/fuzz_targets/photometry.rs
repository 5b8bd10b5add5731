#![no_main]
//! Fuzz target: see `svetlo::fuzzing::photometry`.

libfuzzer_sys::fuzz_target!(|data: &[u8]| svetlo::fuzzing::photometry(data));
