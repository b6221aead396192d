//! Fuzz target `strokes`: see `rbvh_fuzz::strokes` (fuzz/src/lib.rs).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| rbvh_fuzz::strokes(data));
