//! GPU layout of the exact BVH, read by `glsl/bvh.glsl`. `tests/layout.rs` checks every offset
//! against the compiled SPIR-V.

use bytemuck::{Pod, Zeroable};
use glam::Vec3;

use crate::geom::Aabb;

/// Entries of the traversal stack, in GLSL and in the CPU reference. Nearest-first traversal
/// pushes at most one entry per level, so a tree of depth ≤ `STACK_SIZE` cannot overflow it; the
/// builder enforces that (see [`crate::bvh::BuildParams::median_below_depth`]) and the GPU still
/// counts overflows, so a violation is reported, never silent.
pub const STACK_SIZE: u32 = 64;

/// Marks a child reference as a leaf: `child = LEAF_BIT | first_triangle`, `count` triangles.
pub const LEAF_BIT: u32 = 0x8000_0000;

/// An inner node holding both children's boxes (Aila & Laine 2009). 64 bytes:
///
/// | bytes | field |
/// |---|---|
/// | 0..12, 12..16 | `a_min`, `a_child` |
/// | 16..28, 28..32 | `a_max`, `a_count` |
/// | 32..44, 44..48 | `b_min`, `b_child` |
/// | 48..60, 60..64 | `b_max`, `b_count` |
///
/// A child is an inner node (`child` = node index, `count` = 0) or a leaf (`child` =
/// [`LEAF_BIT`] | first triangle, `count` triangles; 0 for an absent child).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuNode {
    pub a_min: [f32; 3],
    pub a_child: u32,
    pub a_max: [f32; 3],
    pub a_count: u32,
    pub b_min: [f32; 3],
    pub b_child: u32,
    pub b_max: [f32; 3],
    pub b_count: u32,
}
const _: () = assert!(std::mem::size_of::<GpuNode>() == 64);

/// One child as the builder sees it, before packing.
#[derive(Clone, Copy, Debug)]
pub struct ChildRef {
    pub bounds: Aabb,
    pub child: u32,
    pub count: u32,
}

impl ChildRef {
    /// A child that no ray can reach usefully: a leaf with no triangles and a point box.
    pub const ABSENT: ChildRef = ChildRef {
        bounds: Aabb {
            min: Vec3::ZERO,
            max: Vec3::ZERO,
        },
        child: LEAF_BIT,
        count: 0,
    };

    pub fn is_leaf(&self) -> bool {
        self.child & LEAF_BIT != 0
    }
}

impl GpuNode {
    pub fn new(a: ChildRef, b: ChildRef) -> Self {
        GpuNode {
            a_min: a.bounds.min.to_array(),
            a_child: a.child,
            a_max: a.bounds.max.to_array(),
            a_count: a.count,
            b_min: b.bounds.min.to_array(),
            b_child: b.child,
            b_max: b.bounds.max.to_array(),
            b_count: b.count,
        }
    }

    /// The two children, `a` then `b`.
    pub fn children(&self) -> [ChildRef; 2] {
        [
            ChildRef {
                bounds: Aabb {
                    min: self.a_min.into(),
                    max: self.a_max.into(),
                },
                child: self.a_child,
                count: self.a_count,
            },
            ChildRef {
                bounds: Aabb {
                    min: self.b_min.into(),
                    max: self.b_max.into(),
                },
                child: self.b_child,
                count: self.b_count,
            },
        ]
    }
}

/// A triangle in BVH order, vertices gathered so that a leaf is one contiguous read. 48 bytes:
/// `v0` + `prim` (the triangle's index in the scene, reported as the hit `id`), `v1` + pad,
/// `v2` + pad.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuTriangle {
    pub v0: [f32; 3],
    pub prim: u32,
    pub v1: [f32; 3],
    pub pad1: u32,
    pub v2: [f32; 3],
    pub pad2: u32,
}
const _: () = assert!(std::mem::size_of::<GpuTriangle>() == 48);

impl GpuTriangle {
    pub fn new([a, b, c]: [Vec3; 3], prim: u32) -> Self {
        GpuTriangle {
            v0: a.to_array(),
            prim,
            v1: b.to_array(),
            pad1: 0,
            v2: c.to_array(),
            pad2: 0,
        }
    }

    pub fn vertices(&self) -> [Vec3; 3] {
        [self.v0.into(), self.v1.into(), self.v2.into()]
    }

    /// The unit geometric normal as wound, `normalize((v1 − v0) × (v2 − v0))`; zero for a
    /// degenerate triangle (which the watertight test never reports as hit).
    pub fn normal(&self) -> Vec3 {
        let [a, b, c] = self.vertices();
        (b - a).cross(c - a).normalize_or_zero()
    }
}
