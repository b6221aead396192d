//! `glsl/rbvh.glsl` is a header an engine can include in its own shaders: a foreign compute shader
//! that picks non-default descriptor set and bindings through the documented macros compiles, and
//! the compiled SPIR-V puts every RBVH buffer exactly where the includer asked. Includes resolve
//! from `rbvh::gpu::shaders::GLSL_HEADERS` only, as in an engine that has none of this crate's
//! files.

use rbvh::gpu::spirv;

const FOREIGN: &str = r#"
#version 460
#extension GL_GOOGLE_include_directive : require
layout(local_size_x = 32) in;

#define RBVH_BVH_SET 2
#define RBVH_BVH_NODES_BINDING 5
#define RBVH_BVH_TRIS_BINDING 6
#define RBVH_LEAVES_BINDING 7
#define RBVH_ATLAS_BINDING 8
#include "rbvh.glsl"

layout(std430, set = 0, binding = 0) writeonly buffer EngineDepth { float depth[]; };
layout(push_constant) uniform EnginePush { RbvhSizes sizes; uint width; } push;

void main() {
    uvec2 px = uvec2(gl_GlobalInvocationID.x % push.width, gl_GlobalInvocationID.x / push.width);
    Ray ray = Ray(vec3(px, -10.0), 0.0, vec3(0.0, 0.0, 1.0), 1e30);
    uint steps;
    bool overflow;
    Hit hit = rbvh_trace_rbvh(ray, false, push.sizes, steps, overflow);
    depth[gl_GlobalInvocationID.x] = overflow ? -1.0 : hit.t;
}
"#;

fn compile(source: &str) -> Result<Vec<u32>, String> {
    let compiler = shaderc::Compiler::new().expect("shaderc");
    let mut options = shaderc::CompileOptions::new().expect("options");
    options.set_target_env(
        shaderc::TargetEnv::Vulkan,
        shaderc::EnvVersion::Vulkan1_1 as u32,
    );
    // Includes resolved from the crate's constants alone, as an engine without this crate's
    // files would: a header missing from them fails the compile.
    options.set_include_callback(move |name, _, _, _| {
        rbvh::gpu::shaders::glsl_header(name)
            .map(|content| shaderc::ResolvedInclude {
                resolved_name: name.to_string(),
                content: content.to_string(),
            })
            .ok_or_else(|| format!("{name}: not in rbvh::gpu::shaders::GLSL_HEADERS"))
    });
    compiler
        .compile_into_spirv(
            source,
            shaderc::ShaderKind::Compute,
            "engine.comp",
            "main",
            Some(&options),
        )
        .map(|a| a.as_binary().to_vec())
        .map_err(|e| e.to_string())
}

#[test]
fn header_compiles_in_a_foreign_shader_with_its_own_bindings() {
    let words = compile(FOREIGN).unwrap();
    let r = spirv::reflect(&words);
    for (block, binding) in [
        ("RbvhBvhNodes", 5),
        ("RbvhBvhTriangles", 6),
        ("RbvhLeaves", 7),
        ("RbvhAtlas", 8),
    ] {
        assert_eq!(
            r.bindings.get(block),
            Some(&(2, binding)),
            "{block}: {:?}",
            r.bindings
        );
    }
    assert_eq!(r.bindings.get("EngineDepth"), Some(&(0, 0)));
}

/// The same engine shader tracing with level of detail, LOD buffers at its own bindings.
const FOREIGN_LOD: &str = r#"
#version 460
#extension GL_GOOGLE_include_directive : require
layout(local_size_x = 32) in;

#define RBVH_BVH_SET 1
#define RBVH_LOD 1
#define RBVH_LODS_BINDING 11
#define RBVH_LOD_TEXELS_BINDING 12
#include "rbvh.glsl"

layout(std430, set = 0, binding = 0) writeonly buffer EngineDepth { float depth[]; };
layout(push_constant) uniform EnginePush { RbvhSizes sizes; RbvhLodSizes lod_sizes; float spread; } push;

void main() {
    Ray ray = Ray(vec3(gl_GlobalInvocationID.x, 0.0, -10.0), 0.0, vec3(0.0, 0.0, 1.0), 1e30);
    uint steps;
    bool overflow;
    Hit hit = rbvh_trace_rbvh_lod(ray, vec2(0.0, push.spread), false, push.sizes, push.lod_sizes,
                                  steps, overflow);
    depth[gl_GlobalInvocationID.x] = overflow ? -1.0 : hit.t;
}
"#;

#[test]
fn lod_header_compiles_in_a_foreign_shader_with_its_own_bindings() {
    let r = spirv::reflect(&compile(FOREIGN_LOD).unwrap());
    for (block, binding) in [
        ("RbvhBvhNodes", 0),
        ("RbvhAtlas", 3),
        ("RbvhLods", 11),
        ("RbvhLodTexels", 12),
    ] {
        assert_eq!(
            r.bindings.get(block),
            Some(&(1, binding)),
            "{block}: {:?}",
            r.bindings
        );
    }
}

/// The engine shader reading the RBVH and its LOD through buffer device addresses it passes in its
/// own push constants: no RBVH binding is left in the SPIR-V.
const FOREIGN_ADDRESSED: &str = r#"
#version 460
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_buffer_reference_uvec2 : require
layout(local_size_x = 32) in;

layout(push_constant) uniform EnginePush {
    uvec2 rbvh_arrays[6];
    uint node_count, tri_count, leaf_count, atlas_pitch, atlas_len, lod_nodes, lod_texels;
    float spread;
} push;

#define RBVH_DEVICE_ADDRESS 1
#define RBVH_LOD 1
#define RBVH_BVH_NODES_ADDRESS push.rbvh_arrays[0]
#define RBVH_BVH_TRIS_ADDRESS push.rbvh_arrays[1]
#define RBVH_LEAVES_ADDRESS push.rbvh_arrays[2]
#define RBVH_ATLAS_ADDRESS push.rbvh_arrays[3]
#define RBVH_LODS_ADDRESS push.rbvh_arrays[4]
#define RBVH_LOD_TEXELS_ADDRESS push.rbvh_arrays[5]
#include "rbvh.glsl"

layout(std430, set = 0, binding = 0) writeonly buffer EngineDepth { float depth[]; };

void main() {
    Ray ray = Ray(vec3(gl_GlobalInvocationID.x, 0.0, -10.0), 0.0, vec3(0.0, 0.0, 1.0), 1e30);
    RbvhSizes sz = RbvhSizes(push.node_count, push.tri_count, push.leaf_count, push.atlas_pitch,
                             push.atlas_len);
    uint steps;
    bool overflow;
    Hit hit = rbvh_trace_rbvh_lod(ray, vec2(0.0, push.spread), false, sz,
                                  RbvhLodSizes(push.lod_nodes, push.lod_texels), steps, overflow);
    depth[gl_GlobalInvocationID.x] = overflow ? -1.0 : hit.t;
}
"#;

#[test]
fn header_reads_through_device_addresses_the_includer_passes() {
    let r = spirv::reflect(&compile(FOREIGN_ADDRESSED).unwrap());
    assert_eq!(
        r.bindings.len(),
        1,
        "only the engine's own buffer is bound: {:?}",
        r.bindings
    );
    assert_eq!(r.bindings.get("EngineDepth"), Some(&(0, 0)));
}

#[test]
fn each_header_compiles_on_its_own() {
    // lod.glsl is the RBVH_LOD part of rbvh.glsl, compiled above through it.
    for (header, _) in rbvh::gpu::shaders::GLSL_HEADERS
        .iter()
        .filter(|(name, _)| *name != "lod.glsl")
    {
        let source = format!(
            "#version 460\n#extension GL_GOOGLE_include_directive : require\nlayout(local_size_x = 1) in;\n#include \"{header}\"\nvoid main() {{}}\n"
        );
        compile(&source).unwrap_or_else(|e| panic!("{header}: {e}"));
    }
}
