#![no_main]
//! Fuzz target: see `svetlo::fuzzing::mitsuba_xml`.

libfuzzer_sys::fuzz_target!(|data: &[u8]| svetlo::fuzzing::mitsuba_xml(data));
