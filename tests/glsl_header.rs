//! `glsl/rbvh.glsl` is a header an engine can include in its own shaders: a foreign compute shader
//! that picks non-default descriptor set and bindings through the documented macros compiles, and
//! the compiled SPIR-V puts every RBVH buffer exactly where the includer asked. Includes resolve
//! from `rbvh::gpu::shaders::GLSL_HEADERS` only, as in an engine that has none of this crate's
//! files.

mod common;

use rbvh::gpu::spirv;

const FOREIGN: &str = r#"
#version 460
#extension GL_GOOGLE_include_directive : require
layout(local_size_x = 32) in;

#define RBVH_BVH_SET 2
#define RBVH_BVH_NODES_BINDING 5
#define RBVH_BVH_TRIS_BINDING 6
#define RBVH_HEIGHTFIELDS_BINDING 7
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
        ("RbvhExactQuads", 6),
        ("RbvhHeightfields", 7),
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

/// An engine shader tracing with level of detail: `defines` pick where the headers' buffers live
/// (none: their defaults), and its own depth buffer is at set `depth_set`, binding 0.
fn lod_engine_shader(defines: &str, depth_set: u32) -> String {
    format!(
        r#"
#version 460
#extension GL_GOOGLE_include_directive : require
layout(local_size_x = 32) in;

{defines}
#include "lod.glsl"

layout(std430, set = {depth_set}, binding = 0) writeonly buffer EngineDepth {{ float depth[]; }};
layout(push_constant) uniform EnginePush {{ RbvhSizes sizes; RbvhLodSizes lod_sizes; float spread; }} push;

void main() {{
    Ray ray = Ray(vec3(gl_GlobalInvocationID.x, 0.0, -10.0), 0.0, vec3(0.0, 0.0, 1.0), 1e30);
    uint steps;
    bool overflow;
    Hit hit = rbvh_trace_rbvh_lod(ray, vec2(0.0, push.spread), false, push.sizes, push.lod_sizes,
                                  steps, overflow);
    depth[gl_GlobalInvocationID.x] = overflow ? -1.0 : hit.t;
}}
"#
    )
}

#[test]
fn lod_header_compiles_in_a_foreign_shader_with_its_own_bindings() {
    // The same engine shader as above, the LOD buffers at its own bindings too.
    let defines =
        "#define RBVH_BVH_SET 1\n#define RBVH_LODS_BINDING 11\n#define RBVH_LOD_TEXELS_BINDING 12";
    let r = spirv::reflect(&compile(&lod_engine_shader(defines, 0)).unwrap());
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

/// The defaults of `bvh.glsl`, `rbvh.glsl` and `lod.glsl` are the bindings of the library's own
/// trace shaders (`glsl/bindings.glsl`, which those include first): the headers keep their own, so
/// that an engine needs no other file, and this keeps the two one table.
#[test]
fn header_defaults_are_the_library_bindings() {
    use rbvh::gpu::bindings;
    // An engine shader that picks no bindings: every buffer of the headers at its default.
    let r = spirv::reflect(&compile(&lod_engine_shader("", 1)).unwrap());
    for (block, binding) in [
        ("RbvhBvhNodes", bindings::BVH_NODES),
        ("RbvhExactQuads", bindings::BVH_TRIS),
        ("RbvhHeightfields", bindings::HEIGHTFIELDS),
        ("RbvhAtlas", bindings::ATLAS),
        ("RbvhLods", bindings::LODS),
        ("RbvhLodTexels", bindings::LOD_TEXELS),
    ] {
        assert_eq!(
            r.bindings.get(block),
            Some(&(0, binding)),
            "{block}: {:?}",
            r.bindings
        );
    }
}

/// An engine shader tracing a two-level structure (`RBVH_INSTANCES`): the exact BVH's
/// (`bvh.glsl`) or, with `rbvh`, the RBVH's (`rbvh.glsl`); `defines` pick where its buffers live
/// (none: their defaults).
fn instanced_engine_shader(defines: &str, rbvh: bool) -> String {
    let (header, push, call) = match rbvh {
        false => (
            "bvh.glsl",
            "BvhInstanceSizes sizes;",
            "rbvh_trace_instances(ray, false, push.sizes, steps, overflow)",
        ),
        true => (
            "rbvh.glsl",
            "RbvhSizes sizes; uint instance_count;",
            "rbvh_trace_rbvh_instances(ray, false, push.sizes, push.instance_count, steps, overflow)",
        ),
    };
    format!(
        r#"
#version 460
#extension GL_GOOGLE_include_directive : require
layout(local_size_x = 32) in;

#define RBVH_INSTANCES 1
{defines}
#include "{header}"

layout(std430, set = 3, binding = 0) writeonly buffer EngineHits {{ Hit engine_hits[]; }};
layout(push_constant) uniform EnginePush {{ {push} }} push;

void main() {{
    Ray ray = Ray(vec3(gl_GlobalInvocationID.x, 0.0, -10.0), 0.0, vec3(0.0, 0.0, 1.0), 1e30);
    uint steps;
    bool overflow;
    engine_hits[gl_GlobalInvocationID.x] = {call};
}}
"#
    )
}

#[test]
fn instanced_headers_compile_in_a_foreign_shader_with_its_own_bindings_or_the_defaults() {
    use rbvh::gpu::bindings;
    let defines = "#define RBVH_BVH_SET 1\n#define RBVH_BVH_NODES_BINDING 4\n\
                   #define RBVH_BVH_TRIS_BINDING 5\n#define RBVH_BVH_INSTANCES_BINDING 6\n\
                   #define RBVH_HEIGHTFIELDS_BINDING 7\n#define RBVH_ATLAS_BINDING 8";
    for rbvh in [false, true] {
        let own = spirv::reflect(&compile(&instanced_engine_shader(defines, rbvh)).unwrap());
        let defaults = spirv::reflect(&compile(&instanced_engine_shader("", rbvh)).unwrap());
        let mut blocks = vec![
            ("RbvhBvhNodes", 4, bindings::BVH_NODES),
            ("RbvhBvhInstances", 6, bindings::BVH_INSTANCES),
        ];
        match rbvh {
            false => blocks.push(("RbvhBvhTriangles", 5, bindings::BVH_TRIS)),
            true => blocks.extend([
                ("RbvhExactQuads", 5, bindings::BVH_TRIS),
                ("RbvhHeightfields", 7, bindings::HEIGHTFIELDS),
                ("RbvhAtlas", 8, bindings::ATLAS),
            ]),
        }
        for (block, binding, default) in blocks {
            assert_eq!(
                own.bindings.get(block),
                Some(&(1, binding)),
                "{block}: {:?}",
                own.bindings
            );
            assert_eq!(
                defaults.bindings.get(block),
                Some(&(0, default)),
                "{block}: {:?}",
                defaults.bindings
            );
        }
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
    uint node_count, tri_count, heightfield_count, atlas_pitch, atlas_len, atlas_wide_len, atlas_end12,
        atlas_end10, lod_nodes, lod_texels;
    float spread;
} push;

#define RBVH_DEVICE_ADDRESS 1
#define RBVH_BVH_NODES_ADDRESS push.rbvh_arrays[0]
#define RBVH_BVH_TRIS_ADDRESS push.rbvh_arrays[1]
#define RBVH_HEIGHTFIELDS_ADDRESS push.rbvh_arrays[2]
#define RBVH_ATLAS_ADDRESS push.rbvh_arrays[3]
#define RBVH_LODS_ADDRESS push.rbvh_arrays[4]
#define RBVH_LOD_TEXELS_ADDRESS push.rbvh_arrays[5]
#include "lod.glsl"

layout(std430, set = 0, binding = 0) writeonly buffer EngineDepth { float depth[]; };

void main() {
    Ray ray = Ray(vec3(gl_GlobalInvocationID.x, 0.0, -10.0), 0.0, vec3(0.0, 0.0, 1.0), 1e30);
    RbvhSizes sz = RbvhSizes(push.node_count, push.tri_count, push.heightfield_count, push.atlas_pitch,
                             push.atlas_len, push.atlas_wide_len, push.atlas_end12, push.atlas_end10);
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

/// An engine that counts its rays' work (`RBVH_COUNT` true) reads the counters from the private
/// `rbvh_counters` (`glsl/common.glsl`), a `RbvhCounters` in [`RayCounters`]' order, so that it
/// can copy them into a buffer the crate's type reads.
///
/// [`RayCounters`]: rbvh::probe::RayCounters
#[test]
fn an_engine_counts_in_ray_counters_order() {
    use rbvh::probe::RayCounters;
    use std::mem::size_of;
    let source = FOREIGN
        .replace(
            "#include \"rbvh.glsl\"",
            "#define RBVH_COUNT true\n#include \"rbvh.glsl\"\n\
             layout(std430, set = 0, binding = 1) writeonly buffer EngineCounters { RbvhCounters counters[]; };",
        )
        .replace(
            "depth[gl_GlobalInvocationID.x] =",
            "counters[gl_GlobalInvocationID.x] = rbvh_counters;\n    depth[gl_GlobalInvocationID.x] =",
        );
    let r = spirv::reflect(&compile(&source).unwrap());
    common::check_struct_layout(
        &r,
        "RbvhCounters",
        size_of::<RayCounters>(),
        &common::ray_counter_fields(),
    );
}

#[test]
fn each_header_compiles_on_its_own() {
    // traverse.glsl is a template that bvh.glsl, rbvh.glsl and lod.glsl instantiate, and
    // atlas.glsl one that rbvh.glsl and the paint shader instantiate, compiled through them.
    for (header, _) in rbvh::gpu::shaders::GLSL_HEADERS
        .iter()
        .filter(|(name, _)| !["traverse.glsl", "atlas.glsl"].contains(name))
    {
        let source = format!(
            "#version 460\n#extension GL_GOOGLE_include_directive : require\nlayout(local_size_x = 1) in;\n#include \"{header}\"\nvoid main() {{}}\n"
        );
        compile(&source).unwrap_or_else(|e| panic!("{header}: {e}"));
    }
}

/// Every constant the shaders share with Rust, as the compiled shader sees it: a probe including
/// the headers writes each one's bits into a buffer on the device, and each must equal the Rust
/// constant it mirrors bit for bit. This reads what the compiler made of each `#define` and
/// `const` (folding included), rather than the header's text.
const CONSTANTS_PROBE: &str = r#"
#version 460
#extension GL_GOOGLE_include_directive : require
layout(local_size_x = 1) in;
#define RBVH_INSTANCES 1
#include "lod.glsl"

layout(std430, set = 0, binding = 0) writeonly buffer Out { uint words[]; };

void main() {
    words[0] = RBVH_LEAF_BIT;
    words[1] = RBVH_LOD_BIT;
    words[2] = RBVH_HEIGHTFIELD_COUNT;
    words[3] = RBVH_INVALID;
    words[4] = uint(RBVH_STACK_SIZE);
    words[5] = RBVH_MAX_CODE;
    words[6] = RBVH_HOLE_CODE;
    words[7] = floatBitsToUint(float(RBVH_MARCH_SLACK));
    words[8] = floatBitsToUint(float(RBVH_MARCH_EDGE_PAD));
    words[9] = floatBitsToUint(RBVH_FAR_SCALE);
    words[10] = floatBitsToUint(float(RBVH_FLT_MAX));
    words[11] = floatBitsToUint(float(RBVH_FLT_MIN));
    words[12] = floatBitsToUint(float(RBVH_MARCH_SKIRT_TEXELS));
    words[13] = floatBitsToUint(float(RBVH_MARCH_DIAGONAL_SKIRT_TEXELS));
    words[14] = RBVH_INSTANCE_LEAF;
}
"#;

#[test]
fn shared_constants_are_the_rust_ones_in_the_compiled_shader() {
    use rbvh::bvh::{INSTANCE_LEAF, LEAF_BIT, STACK_SIZE};
    use rbvh::geom::ROBUST_FAR_SCALE;
    use rbvh::gpu::ComputePipeline;
    use rbvh::lod::LOD_BIT;
    use rbvh::rbvh::layout::{
        MARCH_DIAGONAL_SKIRT_TEXELS, MARCH_EDGE_PAD, MARCH_SKIRT_TEXELS, MARCH_SLACK,
    };
    use rbvh::rbvh::{Texel, HEIGHTFIELD_COUNT};

    let expected: [(&str, u32); 15] = [
        ("RBVH_LEAF_BIT", LEAF_BIT),
        ("RBVH_LOD_BIT", LOD_BIT),
        ("RBVH_HEIGHTFIELD_COUNT", HEIGHTFIELD_COUNT),
        ("RBVH_INVALID (Hit::MISS id)", rbvh::geom::Hit::MISS.id),
        ("RBVH_STACK_SIZE", STACK_SIZE),
        ("RBVH_MAX_CODE", u32::from(Texel::MAX_CODE)),
        ("RBVH_HOLE_CODE", u32::from(Texel::HOLE_CODE)),
        ("RBVH_MARCH_SLACK", MARCH_SLACK.to_bits()),
        ("RBVH_MARCH_EDGE_PAD", MARCH_EDGE_PAD.to_bits()),
        ("RBVH_FAR_SCALE", ROBUST_FAR_SCALE.to_bits()),
        ("RBVH_FLT_MAX", f32::MAX.to_bits()),
        ("RBVH_FLT_MIN", f32::MIN_POSITIVE.to_bits()),
        ("RBVH_MARCH_SKIRT_TEXELS", MARCH_SKIRT_TEXELS.to_bits()),
        (
            "RBVH_MARCH_DIAGONAL_SKIRT_TEXELS",
            MARCH_DIAGONAL_SKIRT_TEXELS.to_bits(),
        ),
        ("RBVH_INSTANCE_LEAF", INSTANCE_LEAF),
    ];
    let words = compile(CONSTANTS_PROBE).unwrap();
    let ctx = common::context();
    let pipeline = ComputePipeline::new(
        &ctx,
        "constants probe",
        bytemuck::cast_slice(&words),
        &[0],
        0,
    )
    .unwrap();
    let mut out = ctx
        .zeroed_storage("constants", 4 * expected.len() as u64)
        .unwrap();
    pipeline.run(&[(out.raw(), 0)], 1, |_| Vec::new()).unwrap();
    let got: Vec<u32> = ctx.read(&mut out).unwrap();
    let wrong: Vec<String> = expected
        .iter()
        .zip(&got)
        .filter(|((_, rust), glsl)| rust != *glsl)
        .map(|((name, rust), glsl)| format!("{name}: GLSL {glsl:#x}, Rust {rust:#x}"))
        .collect();
    assert!(wrong.is_empty(), "constants differ: {wrong:#?}");
}

/// An engine's shader that traces two rays one after another in one invocation: a closest hit of
/// its own ray, then an any hit of another invocation's. The headers keep a ray's words beside
/// the traversal stack in one private global array (`rbvh_stack`: the world ray, where a height
/// field's hit takes its normal from), so the second trace must not see the first one's.
const TWO_RAYS: &str = r#"
#version 460
#extension GL_GOOGLE_include_directive : require
layout(local_size_x = 64) in;
#include "rbvh.glsl"

layout(std430, set = 0, binding = 4) readonly buffer EngineRays { Ray rays[]; };
layout(std430, set = 0, binding = 5) writeonly buffer EngineHits { Hit hits[]; };
layout(push_constant) uniform EnginePush { RbvhSizes sizes; uint count; uint other; } push;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= push.count) {
        return;
    }
    uint steps;
    bool overflow;
    Hit first = rbvh_trace_rbvh(rays[i], false, push.sizes, steps, overflow);
    Hit second = rbvh_trace_rbvh(rays[(i + push.other) % push.count], true, push.sizes, steps, overflow);
    hits[2u * i] = first;
    hits[2u * i + 1u] = second;
}
"#;

#[test]
fn one_invocation_traces_rays_one_after_another_as_each_alone() {
    use rbvh::geom::{Hit, Ray};
    use rbvh::gpu::{ComputePipeline, Query, Tracer};
    use rbvh::rbvh::{Rbvh, RbvhParams};
    use rbvh::scene::Scene;
    use rbvh::structure::Structure;
    use std::sync::Arc;

    let ctx = common::context();
    let scene = Scene::builtin("default").unwrap();
    let r = Arc::new(Rbvh::build(&scene, &RbvhParams::quality(2).unwrap()).unwrap());
    assert!(
        !r.heightfields.is_empty() && !r.triangles.is_empty(),
        "height fields and exact triangles both traced"
    );
    let mut rays: Vec<Ray> = scene.camera_or_framed(1.0).primary_rays(48, 48);
    rays.extend(common::random_rays(&scene, 2000, &mut common::Rng::new(7)));
    let count = rays.len() as u32;
    let other = count / 2 + 1;

    let tracer = Tracer::new(&ctx, &Structure::from(r.clone())).unwrap();
    let closest = tracer.trace(&rays, Query::Closest).unwrap().hits;
    let any = tracer.trace(&rays, Query::Any).unwrap().hits;

    let words = compile(TWO_RAYS).unwrap();
    let pipeline = ComputePipeline::new(
        &ctx,
        "two rays an invocation",
        bytemuck::cast_slice(&words),
        &[0, 1, 2, 3, 4, 5],
        40,
    )
    .unwrap();
    let nodes = ctx.upload_storage("nodes", &r.nodes).unwrap();
    let tris = ctx
        .upload_storage("triangles", r.triangles.device_words())
        .unwrap();
    let heightfields = ctx
        .upload_storage("height fields", &r.heightfields)
        .unwrap();
    let atlas = ctx.upload_storage("atlas", &r.atlas_words()).unwrap();
    let ray_buffer = ctx.upload_storage("rays", &rays).unwrap();
    let mut hit_buffer = ctx
        .zeroed_storage(
            "hits",
            2 * std::mem::size_of::<Hit>() as u64 * u64::from(count),
        )
        .unwrap();
    let [wide_len, end12, end10] = r.atlas.band_ends().map(|end| end as u32);
    let push: [u32; 10] = [
        r.nodes.len() as u32,
        r.triangles.len() as u32,
        r.heightfields.len() as u32,
        r.atlas.pitch,
        r.atlas.texels.len() as u32,
        wide_len,
        end12,
        end10,
        count,
        other,
    ];
    pipeline
        .run(
            &[
                (nodes.raw(), 0),
                (tris.raw(), 0),
                (heightfields.raw(), 0),
                (atlas.raw(), 0),
                (ray_buffer.raw(), 0),
                (hit_buffer.raw(), 0),
            ],
            count,
            |_| bytemuck::cast_slice(&push).to_vec(),
        )
        .unwrap();
    let got: Vec<Hit> = ctx.read(&mut hit_buffer).unwrap();
    let heightfield_hits = closest
        .iter()
        .filter(|h| h.id != u32::MAX && h.id & rbvh::bvh::LEAF_BIT != 0)
        .count();
    assert!(
        heightfield_hits > 100,
        "{heightfield_hits} height-field hits"
    );
    for i in 0..count as usize {
        let j = (i + other as usize) % count as usize;
        assert_eq!(
            got[2 * i],
            closest[i],
            "closest hit of ray {i}, traced first"
        );
        assert_eq!(
            got[2 * i + 1],
            any[j],
            "any hit of ray {j}, traced second by {i}"
        );
    }
}
