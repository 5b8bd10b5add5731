#![no_main]
//! Fuzz target: see `svetlo::fuzzing::image`.

libfuzzer_sys::fuzz_target!(|data: &[u8]| svetlo::fuzzing::image(data));
