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
    /// GLSL `BvhNode.a_min`: lower corner of child `a`'s box, world space.
    pub a_min: [f32; 3],
    /// GLSL `a_child`: node index of child `a`, or [`LEAF_BIT`] | its first triangle.
    pub a_child: u32,
    /// GLSL `a_max`: upper corner of child `a`'s box, world space.
    pub a_max: [f32; 3],
    /// GLSL `a_count`: triangles of leaf `a`; 0 for an inner node or an absent child.
    pub a_count: u32,
    /// GLSL `b_min`: lower corner of child `b`'s box, world space.
    pub b_min: [f32; 3],
    /// GLSL `b_child`: node index of child `b`, or [`LEAF_BIT`] | its first triangle.
    pub b_child: u32,
    /// GLSL `b_max`: upper corner of child `b`'s box, world space.
    pub b_max: [f32; 3],
    /// GLSL `b_count`: triangles of leaf `b`; 0 for an inner node or an absent child.
    pub b_count: u32,
}
const _: () = assert!(std::mem::size_of::<GpuNode>() == 64);

/// One child as the builder sees it, before packing.
#[derive(Clone, Copy, Debug)]
pub struct ChildRef {
    /// World-space box of the child's subtree (or leaf triangles).
    pub bounds: Aabb,
    /// Node index of an inner child, or [`LEAF_BIT`] | first triangle of a leaf.
    pub child: u32,
    /// Triangles of a leaf; 0 for an inner node or an absent child.
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

    /// Whether `child` carries [`LEAF_BIT`] (a leaf, possibly the empty [`ChildRef::ABSENT`]).
    pub fn is_leaf(&self) -> bool {
        self.child & LEAF_BIT != 0
    }
}

impl GpuNode {
    /// Packs two children, `a` and `b`, into one node; the inverse of [`GpuNode::children`].
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
    /// GLSL `BvhTriangle.v0`: first vertex, world space.
    pub v0: [f32; 3],
    /// GLSL `prim`: the triangle's index in the scene, returned as the hit `id`.
    pub prim: u32,
    /// GLSL `v1`: second vertex, world space.
    pub v1: [f32; 3],
    /// GLSL `pad1`: padding to 16 bytes; always 0.
    pub pad1: u32,
    /// GLSL `v2`: third vertex, world space; winding `v0, v1, v2` gives [`GpuTriangle::normal`].
    pub v2: [f32; 3],
    /// GLSL `pad2`: padding to 16 bytes; always 0.
    pub pad2: u32,
}
const _: () = assert!(std::mem::size_of::<GpuTriangle>() == 48);

impl GpuTriangle {
    /// Packs the vertices `[v0, v1, v2]` (winding kept) of scene triangle `prim`, padding zeroed.
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

    /// The vertices `[v0, v1, v2]`, world space.
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
