//! The descriptor bindings (set 0) of the library's own pipelines, as `glsl/bindings.glsl`, the
//! one table of them that the shaders include, gives them: `build.rs` makes each of its
//! `#define RBVH_<NAME>_BINDING <n>` lines a constant `<NAME>` here. The tracer and the painter
//! bind their buffers by these (`trace`, `paint`), so a binding is numbered once, and a
//! pipeline's list is checked against its SPIR-V below. An engine that traces in its own shaders
//! picks its own bindings (docs/embedding.md, "In the engine's own shaders"); the headers' defaults are these
//! (`tests/glsl_header.rs` checks).

use super::Reach;
use crate::structure::Kind;

include!(concat!(env!("OUT_DIR"), "/bindings.rs"));

/// The bindings of `kind`'s trace shader for arrays reached by `reach`, in the order the tracer
/// gives its buffers (ascending but for the instances'): the structure's arrays where bound, rays,
/// hits, status and the counters' first record, then with levels of detail the LOD's arrays where
/// bound and the cones, then the counters' second record.
pub(crate) fn trace(kind: Kind, reach: Reach) -> Vec<u32> {
    let structure: &[u32] = match kind {
        Kind::Exact => &[BVH_NODES, BVH_TRIS],
        Kind::ExactInstanced => &[BVH_NODES, BVH_TRIS, BVH_INSTANCES],
        Kind::Rbvh | Kind::RbvhLod => &[BVH_NODES, BVH_TRIS, HEIGHTFIELDS, ATLAS],
        Kind::RbvhInstanced => &[BVH_NODES, BVH_TRIS, HEIGHTFIELDS, ATLAS, BVH_INSTANCES],
    };
    let lod: &[u32] = match kind {
        Kind::Exact | Kind::ExactInstanced | Kind::Rbvh | Kind::RbvhInstanced => &[],
        Kind::RbvhLod => &[LODS, LOD_TEXELS],
    };
    let bound = reach == Reach::Bindings;
    let mut bindings = Vec::new();
    if bound {
        bindings.extend(structure);
    }
    bindings.extend([RAYS, HITS, STATUS, COUNTERS]);
    if bound {
        bindings.extend(lod);
    }
    if kind == Kind::RbvhLod {
        bindings.push(CONES);
    }
    bindings.push(COUNTERS_TAIL);
    bindings
}

/// The bindings of the paint shader for an atlas and colours reached by `reach`, in the order the
/// painter gives its buffers: the atlas, the brushes and the colours, or the brushes alone where
/// the other two are reached through their device addresses.
pub(crate) fn paint(reach: Reach) -> &'static [u32] {
    match reach {
        Reach::Bindings => &[PAINT_ATLAS, PAINT_BRUSHES, PAINT_COLOURS],
        Reach::DeviceAddresses => &[PAINT_BRUSHES],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::tracer::shader_spirv;
    use crate::gpu::{shaders, spirv};

    /// The bindings `spirv` declares (set 0 only), sorted.
    fn declared(spirv: &[u8]) -> Vec<u32> {
        let reflected = spirv::reflect(&shaders::words(spirv).unwrap());
        let mut bindings: Vec<u32> = reflected
            .bindings
            .values()
            .map(|&(set, binding)| {
                assert_eq!(set, 0, "{:?}", reflected.bindings);
                binding
            })
            .collect();
        bindings.sort_unstable();
        bindings
    }

    /// Every pipeline the library makes binds exactly what its shader declares, each binding once
    /// and in ascending order but for the instances' (each specialization of a shader shares its
    /// SPIR-V, and so its bindings).
    #[test]
    fn every_pipeline_binds_what_its_shader_declares() {
        for reach in [Reach::Bindings, Reach::DeviceAddresses] {
            for kind in Kind::ALL {
                let rust = trace(kind, reach);
                let mut sorted = rust.clone();
                sorted.sort_unstable();
                sorted.dedup();
                assert_eq!(sorted.len(), rust.len(), "{kind:?} {reach:?}: {rust:?}");
                if !matches!(kind, Kind::ExactInstanced | Kind::RbvhInstanced) {
                    assert_eq!(sorted, rust, "{kind:?} {reach:?}");
                }
                assert_eq!(
                    declared(shader_spirv(kind, reach)),
                    sorted,
                    "{kind:?} {reach:?}"
                );
            }
            let paint_spirv = crate::gpu::painter::shader_spirv(reach);
            assert_eq!(declared(paint_spirv), paint(reach), "paint {reach:?}");
        }
    }
}
