//! The exact triangle BVH: the referee that every RBVH approximation is measured against.
//!
//! * [`build`](Bvh::build): binned SAH (Wald, "On fast construction of SAH-based bounding volume
//!   hierarchies", 2007), parallel with `rayon`, deterministic whatever the thread count.
//! * [`layout`]: the GPU node in the style of Aila & Laine, "Understanding the efficiency of ray
//!   traversal on GPUs" (HPG 2009): one node holds both children's boxes, so one fetch answers
//!   "which children does the ray enter, and in which order"; the boxes are quantized to 8 bits
//!   per plane against the node's own box (Ylitie, Karras & Laine, HPG 2017), 48 bytes a node.
//! * `morton`: a linear BVH (Morton order), built in a fraction of the time, for the RBVH
//!   builder's short rays around each leaf, where a tree is needed fast rather than good.
//! * `traverse`: the one CPU traversal of the node array, generic over what a leaf is (its
//!   `Leaves` hook: the exact BVH's triangles here, an RBVH's height fields and levels of detail
//!   in `crate::rbvh`), operation for operation the same as `glsl/traverse.glsl` (whose hooks
//!   `glsl/bvh.glsl`, `glsl/rbvh.glsl` and `glsl/lod.glsl` define), on the same packed data;
//!   with it the exact BVH's CPU reference tracer.
//! * `instanced`: the exact BVH of a scene with instances, in two levels (a tree per mesh, a
//!   top level over the instances) traced by the same traversal.

mod build;
mod instanced;
pub mod layout;
mod morton;
mod top_level;
mod traverse;
mod validate;

pub(crate) use build::{check_node_count, join_halves, partition, sah_cost, tree_over, Placed};
pub use build::{BuildParams, Bvh};
pub use instanced::InstancedBvh;
pub use layout::{
    ChildRef, GpuInstance, GpuNode, GpuTriangle, INSTANCE_LEAF, LEAF_BIT, MAX_NODES, STACK_SIZE,
};
pub(crate) use morton::LinearBvh;
pub(crate) use top_level::{check_transforms, index, place, top_node_count, Aim, InstanceHook};
pub use top_level::{BottomLevel, GRAFTED};
pub(crate) use traverse::{traverse, BvhLeafHook, Leaves, TriangleSlots};
