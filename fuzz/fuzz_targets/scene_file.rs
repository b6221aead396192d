//! Fuzz target `scene_file`: see `rbvh_fuzz::scene_file` (fuzz/src/lib.rs).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| rbvh_fuzz::scene_file(data));
