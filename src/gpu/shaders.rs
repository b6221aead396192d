//! The SPIR-V of every `glsl/*.comp`, compiled by `build.rs` (never stored in the repository).

include!(concat!(env!("OUT_DIR"), "/shaders.rs"));

/// SPIR-V bytes as the 32-bit words Vulkan takes. Fails only if `bytes` is not SPIR-V.
pub fn words(bytes: &[u8]) -> std::io::Result<Vec<u32>> {
    ash::util::read_spv(&mut std::io::Cursor::new(bytes))
}
