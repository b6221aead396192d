//! Fuzz target `gltf`: see `rbvh_fuzz::gltf` (fuzz/src/lib.rs).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| rbvh_fuzz::gltf(data));
