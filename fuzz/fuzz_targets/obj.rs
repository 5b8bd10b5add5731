#![no_main]
//! Fuzz target: see `svetlo::fuzzing::obj`.

libfuzzer_sys::fuzz_target!(|data: &[u8]| svetlo::fuzzing::obj(data));
