//! Rust and GLSL agree on every shared layout: offsets and strides are read back from the SPIR-V
//! that build.rs compiled, and compared with `offset_of!`/`size_of` of the `#[repr(C)]` mirrors.
//! The shared constants are checked on the device, as the compiled shader sees them
//! (`tests/glsl_header.rs`).

use std::mem::{offset_of, size_of};

use rbvh::bvh::{GpuInstance, GpuNode, GpuTriangle};
use rbvh::geom::{Hit, Ray};
use rbvh::gpu::{shaders, spirv};
use rbvh::probe::RayCounters;

mod common;
use common::{check_struct_layout as check, ray_counter_fields};

fn reflect_trace_exact() -> spirv::Reflection {
    spirv::reflect(&shaders::words(shaders::TRACE_EXACT).unwrap())
}

#[test]
fn bvh_node_layout_matches() {
    let r = reflect_trace_exact();
    check(
        &r,
        "BvhNode",
        size_of::<GpuNode>(),
        &[
            ("origin", offset_of!(GpuNode, origin)),
            ("exponents", offset_of!(GpuNode, exponents)),
            ("planes", offset_of!(GpuNode, planes)),
            ("a_child", offset_of!(GpuNode, a_child)),
            ("a_count", offset_of!(GpuNode, a_count)),
            ("b_child", offset_of!(GpuNode, b_child)),
            ("b_count", offset_of!(GpuNode, b_count)),
            ("pad", offset_of!(GpuNode, pad)),
        ],
    );
}

#[test]
fn bvh_instance_layout_matches() {
    for spv in [
        shaders::TRACE_EXACT_INSTANCES,
        shaders::TRACE_EXACT_INSTANCES_BDA,
    ] {
        let r = spirv::reflect(&shaders::words(spv).unwrap());
        check(
            &r,
            "BvhInstance",
            size_of::<GpuInstance>(),
            &[
                ("world_to_mesh", offset_of!(GpuInstance, world_to_mesh)),
                ("root", offset_of!(GpuInstance, root)),
                ("mesh", offset_of!(GpuInstance, mesh)),
                ("pad0", offset_of!(GpuInstance, pad)),
                ("pad1", offset_of!(GpuInstance, pad) + 4),
            ],
        );
    }
}

#[test]
fn bvh_triangle_layout_matches() {
    let r = reflect_trace_exact();
    check(
        &r,
        "BvhTriangle",
        size_of::<GpuTriangle>(),
        &[
            ("v0", offset_of!(GpuTriangle, v0)),
            ("prim", offset_of!(GpuTriangle, prim)),
            ("v1", offset_of!(GpuTriangle, v1)),
            ("flags", offset_of!(GpuTriangle, flags)),
            ("v2", offset_of!(GpuTriangle, v2)),
            ("pad2", offset_of!(GpuTriangle, pad2)),
        ],
    );
}

#[test]
fn counter_layout_matches_in_every_trace_shader() {
    // The trace shaders count in two 32-byte records a ray (glsl/trace_io.glsl): RayCounters'
    // first eight words, then its last two and six reserved.
    let fields = ray_counter_fields();
    let (head, tail) = fields.split_at(8);
    let mut tail: Vec<(&str, usize)> = tail.iter().map(|&(name, at)| (name, at - 32)).collect();
    tail.push(("reserved", 8));
    assert_eq!(size_of::<RayCounters>(), 40);
    for spirv_bytes in [
        shaders::TRACE_EXACT,
        shaders::TRACE_EXACT_BDA,
        shaders::TRACE_EXACT_INSTANCES,
        shaders::TRACE_EXACT_INSTANCES_BDA,
        shaders::TRACE_RBVH,
        shaders::TRACE_RBVH_BDA,
        shaders::TRACE_RBVH_LOD,
        shaders::TRACE_RBVH_LOD_BDA,
        shaders::TRACE_RBVH_INSTANCES,
        shaders::TRACE_RBVH_INSTANCES_BDA,
    ] {
        let r = spirv::reflect(&shaders::words(spirv_bytes).unwrap());
        check(&r, "RbvhCountersHead", 32, head);
        check(&r, "RbvhCountersTail", 32, &tail);
    }
}

#[test]
fn ray_and_hit_layouts_match() {
    let r = reflect_trace_exact();
    check(
        &r,
        "Ray",
        size_of::<Ray>(),
        &[
            ("origin", offset_of!(Ray, origin)),
            ("tmin", offset_of!(Ray, tmin)),
            ("dir", offset_of!(Ray, dir)),
            ("tmax", offset_of!(Ray, tmax)),
        ],
    );
    check(
        &r,
        "Hit",
        size_of::<Hit>(),
        &[
            ("t", offset_of!(Hit, t)),
            ("nx", offset_of!(Hit, normal)),
            ("ny", offset_of!(Hit, normal) + 4),
            ("nz", offset_of!(Hit, normal) + 8),
            ("id", offset_of!(Hit, id)),
            ("instance_id", offset_of!(Hit, instance)),
            ("reserved1", offset_of!(Hit, reserved)),
            ("reserved2", offset_of!(Hit, reserved) + 4),
        ],
    );
}

#[test]
fn workgroup_size_is_reflected() {
    let r = reflect_trace_exact();
    let size = r.local_size.expect("LocalSize");
    assert!(size[0] >= 1 && size[1] == 1 && size[2] == 1, "{size:?}");
}

#[test]
fn rbvh_leaf_layout_matches() {
    use rbvh::rbvh::GpuHeightfield as L;
    let r = spirv::reflect(&shaders::words(shaders::TRACE_RBVH).unwrap());
    check(
        &r,
        "RbvhHeightfield",
        size_of::<L>(),
        &[
            ("origin", offset_of!(L, origin)),
            ("atlas_base", offset_of!(L, atlas_base)),
            ("axis_u", offset_of!(L, axis_u)),
            ("res_u", offset_of!(L, res_u)),
            ("axis_v", offset_of!(L, axis_v)),
            ("res_v", offset_of!(L, res_v)),
            ("axis_w", offset_of!(L, axis_w)),
            ("h_scale", offset_of!(L, h_scale)),
        ],
    );
    // The RBVH shader shares the BVH node layout. Its triangles are words, not BvhTriangle
    // records: a GpuIndexedTriangle's four words a slot, then the vertices
    // (src/rbvh/triangles.rs), which rbvh_bvh_triangle reads by offset; the device's hits on
    // them, bit for bit the CPU twin's (tests/rbvh_agreement.rs), check that the two agree.
    assert_eq!(
        r.array_strides.get("BvhNode"),
        Some(&(size_of::<GpuNode>() as u32))
    );
    assert_eq!(r.array_strides.get("BvhTriangle"), None);
    assert_eq!(size_of::<rbvh::rbvh::GpuIndexedTriangle>(), 16);
}

#[test]
fn push_constants_match_in_every_trace_shader() {
    use rbvh::gpu::TraceParams as P;
    let expected = [
        ("ray_offset", offset_of!(P, ray_offset)),
        ("ray_count", offset_of!(P, ray_count)),
        ("flags", offset_of!(P, flags)),
        ("node_count", offset_of!(P, node_count)),
        ("tri_count", offset_of!(P, tri_count)),
        ("heightfield_count", offset_of!(P, heightfield_count)),
        ("atlas_pitch", offset_of!(P, atlas_pitch)),
        ("atlas_len", offset_of!(P, atlas_len)),
        ("atlas_wide_len", offset_of!(P, atlas_wide_len)),
        ("atlas_end12", offset_of!(P, atlas_end12)),
        ("atlas_end10", offset_of!(P, atlas_end10)),
        ("lod_node_count", offset_of!(P, lod_node_count)),
        ("lod_texel_len", offset_of!(P, lod_texel_len)),
        ("instance_count", offset_of!(P, instance_count)),
        ("addresses", offset_of!(P, addresses)),
    ];
    assert_eq!(size_of::<P>(), offset_of!(P, addresses) + 7 * 8);
    for spv in [
        shaders::TRACE_EXACT,
        shaders::TRACE_EXACT_INSTANCES,
        shaders::TRACE_EXACT_INSTANCES_BDA,
        shaders::TRACE_RBVH,
        shaders::TRACE_RBVH_LOD,
        shaders::TRACE_EXACT_BDA,
        shaders::TRACE_RBVH_BDA,
        shaders::TRACE_RBVH_LOD_BDA,
    ] {
        let r = spirv::reflect(&shaders::words(spv).unwrap());
        let glsl = r.structs.get("Params").expect("push constant block Params");
        let glsl: Vec<(&str, usize)> = glsl
            .iter()
            .map(|(m, o)| (m.as_str(), *o as usize))
            .collect();
        assert_eq!(glsl, expected);
    }
}

#[test]
fn lod_layout_matches() {
    use rbvh::lod::{GpuLod, RayCone, LOD_BIT};
    let r = spirv::reflect(&shaders::words(shaders::TRACE_RBVH_LOD).unwrap());
    check(
        &r,
        "RbvhLod",
        size_of::<GpuLod>(),
        &[
            ("origin", offset_of!(GpuLod, origin)),
            ("texel_size", offset_of!(GpuLod, texel_size)),
            ("axis", offset_of!(GpuLod, axis)),
            ("res_u", offset_of!(GpuLod, res_u)),
            ("res_v", offset_of!(GpuLod, res_v)),
            ("base", offset_of!(GpuLod, base)),
            ("h_scale", offset_of!(GpuLod, h_scale)),
            ("inv_texel", offset_of!(GpuLod, inv_texel)),
            ("pad0", offset_of!(GpuLod, pad)),
            ("pad1", offset_of!(GpuLod, pad) + 4),
        ],
    );
    // The cone buffer is an array of vec2: (width, spread).
    assert_eq!(size_of::<RayCone>(), 8);
    assert_eq!(offset_of!(RayCone, spread), 4);
    let header = include_str!("../glsl/lod.glsl");
    assert!(
        header.contains(&format!("const uint RBVH_LOD_BIT = 0x{LOD_BIT:08X}u;")),
        "glsl/lod.glsl's RBVH_LOD_BIT differs from LOD_BIT"
    );
}

#[test]
fn paint_brush_and_push_constants_match() {
    use rbvh::gpu::PaintParams as P;
    use rbvh::surface::Brush as B;
    let r = spirv::reflect(&shaders::words(shaders::PAINT).unwrap());
    check(
        &r,
        "PaintBrush",
        size_of::<B>(),
        &[
            ("centre", offset_of!(B, centre)),
            ("radius", offset_of!(B, radius)),
            ("colour", offset_of!(B, colour)),
            ("pad0", offset_of!(B, pad)),
            ("pad1", offset_of!(B, pad) + 4),
            ("pad2", offset_of!(B, pad) + 8),
        ],
    );
    assert_eq!(size_of::<P>(), offset_of!(P, colours_address) + 8);
    for spv in [shaders::PAINT, shaders::PAINT_BDA] {
        let r = spirv::reflect(&shaders::words(spv).unwrap());
        let glsl = r
            .structs
            .get("PaintParams")
            .expect("push constant block PaintParams");
        let glsl: Vec<(&str, usize)> = glsl
            .iter()
            .map(|(m, o)| (m.as_str(), *o as usize))
            .collect();
        assert_eq!(
            glsl,
            [
                ("origin", offset_of!(P, origin)),
                ("atlas_base", offset_of!(P, atlas_base)),
                ("step_u", offset_of!(P, step_u)),
                ("res_u", offset_of!(P, res_u)),
                ("step_v", offset_of!(P, step_v)),
                ("res_v", offset_of!(P, res_v)),
                ("axis_w", offset_of!(P, axis_w)),
                ("h_scale", offset_of!(P, h_scale)),
                ("texel_offset", offset_of!(P, texel_offset)),
                ("brush_count", offset_of!(P, brush_count)),
                ("atlas_pitch", offset_of!(P, atlas_pitch)),
                ("atlas_len", offset_of!(P, atlas_len)),
                ("atlas_wide_len", offset_of!(P, atlas_wide_len)),
                ("atlas_end12", offset_of!(P, atlas_end12)),
                ("atlas_end10", offset_of!(P, atlas_end10)),
                ("reserved", offset_of!(P, reserved)),
                ("atlas_address", offset_of!(P, atlas_address)),
                ("colours_address", offset_of!(P, colours_address)),
            ]
        );
    }
}
