//! Rust and GLSL agree on every shared layout: offsets and strides are read back from the SPIR-V
//! that build.rs compiled, and compared with `offset_of!`/`size_of` of the `#[repr(C)]` mirrors.

use std::mem::{offset_of, size_of};

use rbvh::bvh::{GpuNode, GpuTriangle, STACK_SIZE};
use rbvh::geom::{Hit, Ray};
use rbvh::gpu::{shaders, spirv};

fn reflect_trace_exact() -> spirv::Reflection {
    spirv::reflect(&shaders::words(shaders::TRACE_EXACT).unwrap())
}

fn check(r: &spirv::Reflection, name: &str, size: usize, rust: &[(&str, usize)]) {
    let glsl = r
        .structs
        .get(name)
        .unwrap_or_else(|| panic!("struct {name} not in SPIR-V: {:?}", r.structs.keys()));
    let glsl: Vec<(&str, usize)> = glsl
        .iter()
        .map(|(m, o)| (m.as_str(), *o as usize))
        .collect();
    assert_eq!(glsl, rust, "{name}: GLSL member offsets differ from Rust");
    assert_eq!(
        r.array_strides.get(name).copied(),
        Some(size as u32),
        "{name}: array stride"
    );
}

#[test]
fn bvh_node_layout_matches() {
    let r = reflect_trace_exact();
    check(
        &r,
        "BvhNode",
        size_of::<GpuNode>(),
        &[
            ("a_min", offset_of!(GpuNode, a_min)),
            ("a_child", offset_of!(GpuNode, a_child)),
            ("a_max", offset_of!(GpuNode, a_max)),
            ("a_count", offset_of!(GpuNode, a_count)),
            ("b_min", offset_of!(GpuNode, b_min)),
            ("b_child", offset_of!(GpuNode, b_child)),
            ("b_max", offset_of!(GpuNode, b_max)),
            ("b_count", offset_of!(GpuNode, b_count)),
        ],
    );
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
            ("pad1", offset_of!(GpuTriangle, pad1)),
            ("v2", offset_of!(GpuTriangle, v2)),
            ("pad2", offset_of!(GpuTriangle, pad2)),
        ],
    );
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
            ("reserved0", offset_of!(Hit, reserved)),
            ("reserved1", offset_of!(Hit, reserved) + 4),
            ("reserved2", offset_of!(Hit, reserved) + 8),
        ],
    );
}

#[test]
fn stack_size_matches() {
    let header = include_str!("../glsl/bvh.glsl");
    let define = format!("#define RBVH_STACK_SIZE {STACK_SIZE}\n");
    assert!(
        header.contains(&define),
        "glsl/bvh.glsl must contain {define:?}"
    );
}

#[test]
fn workgroup_size_is_reflected() {
    let r = reflect_trace_exact();
    let size = r.local_size.expect("LocalSize");
    assert!(size[0] >= 1 && size[1] == 1 && size[2] == 1, "{size:?}");
}
