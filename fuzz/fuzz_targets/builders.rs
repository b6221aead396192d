//! Fuzz target `builders`: see `rbvh_fuzz::builders` (fuzz/src/lib.rs).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| rbvh_fuzz::builders(data));
