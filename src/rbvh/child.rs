//! What a child of an RBVH node is: the one place the CPU tells an inner node, an absent child, a
//! triangle leaf and a height-field leaf apart ([`Child`]), so that adding a kind of leaf starts
//! here, with the match arms the compiler then asks for, and at `rbvh_is_heightfield` in
//! `glsl/rbvh.glsl`, the device's one test of the same encoding.
//!
//! A node ([`GpuNode`](crate::bvh::GpuNode)) names each child by two words, `child` and `count`,
//! with [`LEAF_BIT`] = bit 31 of `child`:
//! * inner node: `child` = node index, `count` = 0 (level of detail's annotated copy of the
//!   nodes puts a column width there: [`crate::lod::Lod::annotated_nodes`]);
//! * absent child: `child` = [`LEAF_BIT`], `count` = 0 (a leaf of no triangles);
//! * triangle leaf: `child` = `LEAF_BIT | first triangle`, `count` = triangles;
//! * height-field leaf: `child` = `LEAF_BIT | height-field index`, `count` = [`HEIGHTFIELD_COUNT`].
//!
//! The exact BVH's nodes have the first three alone (`crate::bvh::layout`). The encoding is the
//! file format's and the device's: it does not change, only how it is read.

use crate::bvh::ChildRef;
use crate::geom::Aabb;

pub use crate::bvh::LEAF_BIT;

/// `count` of a child reference that is a height-field leaf: a count no triangle leaf reaches
/// (its triangles' indices stay below [`LEAF_BIT`]).
pub const HEIGHTFIELD_COUNT: u32 = u32::MAX;

/// A child of an RBVH node, decoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Child {
    /// An inner node: its index in the node array.
    Inner(u32),
    /// No child: a leaf with nothing in it, whose box means nothing (`ChildRef::ABSENT`).
    Absent,
    /// A triangle leaf: `count` (at least 1) triangles from `first` in the triangle array.
    Triangles {
        /// Index of its first triangle.
        first: u32,
        /// Its triangles, at least 1 (0 is an absent child) and below [`HEIGHTFIELD_COUNT`].
        count: u32,
    },
    /// A height-field leaf: its index in the height-field records (and the id of its hits, with
    /// [`LEAF_BIT`]).
    Heightfield(u32),
}

impl Child {
    /// The child a node's `child` and `count` words name. Every pair names one: an inner child's
    /// count is not read (level of detail keeps a width there).
    pub const fn decode(child: u32, count: u32) -> Child {
        let index = child & !LEAF_BIT;
        if child & LEAF_BIT == 0 {
            Child::Inner(child)
        } else if count == HEIGHTFIELD_COUNT {
            Child::Heightfield(index)
        } else if count == 0 {
            Child::Absent
        } else {
            Child::Triangles {
                first: index,
                count,
            }
        }
    }

    /// The `child` and `count` words that name this child; [`Child::decode`] gives it back, for
    /// indices below [`LEAF_BIT`] and a triangle count in its range.
    pub const fn encode(self) -> (u32, u32) {
        match self {
            Child::Inner(node) => (node, 0),
            Child::Absent => (LEAF_BIT, 0),
            Child::Triangles { first, count } => (LEAF_BIT | first, count),
            Child::Heightfield(index) => (LEAF_BIT | index, HEIGHTFIELD_COUNT),
        }
    }

    /// A reference to this child whose subtree (or leaf) lies in `bounds`.
    pub const fn with_bounds(self, bounds: Aabb) -> ChildRef {
        let (child, count) = self.encode();
        ChildRef {
            bounds,
            child,
            count,
        }
    }
}

impl ChildRef {
    /// What this reference names in an RBVH ([`Child::decode`]).
    pub const fn kind(&self) -> Child {
        Child::decode(self.child, self.count)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_kind_decodes_from_its_encoding() {
        for kind in [
            Child::Inner(0),
            Child::Inner(LEAF_BIT - 1),
            Child::Absent,
            Child::Triangles { first: 0, count: 1 },
            Child::Triangles {
                first: 7,
                count: HEIGHTFIELD_COUNT - 1,
            },
            Child::Heightfield(0),
            Child::Heightfield(LEAF_BIT - 1),
        ] {
            let (child, count) = kind.encode();
            assert_eq!(Child::decode(child, count), kind);
            assert_eq!(kind.with_bounds(Aabb::EMPTY).kind(), kind);
        }
        assert_eq!(ChildRef::ABSENT.kind(), Child::Absent);
    }

    #[test]
    fn an_inner_child_keeps_whatever_count_level_of_detail_gives_it() {
        let width = 0.25f32.to_bits();
        assert_eq!(Child::decode(5, width), Child::Inner(5));
        assert_eq!(Child::decode(5, HEIGHTFIELD_COUNT), Child::Inner(5));
    }
}
