//! Fuzz target `points`: see `rbvh_fuzz::points` (fuzz/src/lib.rs).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| rbvh_fuzz::points(data));
