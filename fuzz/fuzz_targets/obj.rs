//! Fuzz target `obj`: see `rbvh_fuzz::obj` (fuzz/src/lib.rs).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| rbvh_fuzz::obj(data));
