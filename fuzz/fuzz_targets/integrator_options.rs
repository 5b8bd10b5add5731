#![no_main]
//! Fuzz target: see `svetlo::fuzzing::integrator_options`.

libfuzzer_sys::fuzz_target!(|data: &[u8]| svetlo::fuzzing::integrator_options(data));
