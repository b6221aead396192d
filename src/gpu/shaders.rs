//! The SPIR-V of every `glsl/*.comp`, compiled by `build.rs` (never stored in the repository).

include!(concat!(env!("OUT_DIR"), "/shaders.rs"));

/// SPIR-V bytes as the 32-bit words Vulkan takes. Fails only if `bytes` is not SPIR-V.
pub fn words(bytes: &[u8]) -> std::io::Result<Vec<u32>> {
    ash::util::read_spv(&mut std::io::Cursor::new(bytes))
}

/// The GLSL headers an engine includes in its own shaders (docs/embedding.md, "In the engine's own shaders"), by
/// the name `#include` gives them: `rbvh.glsl` (the RBVH's march and leaf hook), `bvh.glsl` (the
/// exact BVH), `traverse.glsl` (the one traversal they instantiate), `grid.glsl` (grid stepping
/// for both marches), `lod.glsl` (level of detail, on top of `rbvh.glsl`) and what they include. An
/// engine that compiles its shaders resolves its includes from this table and needs no files of
/// this crate.
pub const GLSL_HEADERS: [(&str, &str); 8] = [
    ("common.glsl", include_str!("../../glsl/common.glsl")),
    ("intersect.glsl", include_str!("../../glsl/intersect.glsl")),
    ("traverse.glsl", include_str!("../../glsl/traverse.glsl")),
    ("grid.glsl", include_str!("../../glsl/grid.glsl")),
    ("bvh.glsl", include_str!("../../glsl/bvh.glsl")),
    ("atlas.glsl", include_str!("../../glsl/atlas.glsl")),
    ("rbvh.glsl", include_str!("../../glsl/rbvh.glsl")),
    ("lod.glsl", include_str!("../../glsl/lod.glsl")),
];

/// The header `name` of [`GLSL_HEADERS`], for an include callback.
pub fn glsl_header(name: &str) -> Option<&'static str> {
    GLSL_HEADERS
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, text)| *text)
}
