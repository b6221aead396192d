//! Fuzz target `environment`: see `rbvh_fuzz::environment` (fuzz/src/lib.rs).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| rbvh_fuzz::environment(data));
