//! Fuzz target `textures`: see `rbvh_fuzz::textures` (fuzz/src/lib.rs).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| rbvh_fuzz::textures(data));
