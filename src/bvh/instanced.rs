//! The exact BVH of a scene with instances, in two levels (issue "Instances"): one tree per mesh,
//! built once in the mesh's own space, and a top-level tree over the instances' world boxes
//! whose leaves enter a mesh's tree with the ray taken into its space, the split of Vulkan's
//! top and bottom acceleration structures, of Embree's instances and of tinybvh's TLAS.
//!
//! One node array and one traversal serve both levels ([`traverse`] with the instance hook of
//! `top_level.rs`, which the two-level RBVH shares): the top level's nodes come first (node 0 its
//! root), then each mesh's tree, its child references offset to where it lies; a top-level leaf
//! is `LEAF_BIT | instance` with the count [`INSTANCE_LEAF`](super::INSTANCE_LEAF), but for the
//! first instance placed where it is, whose mesh's root is the top level's child
//! ([`GRAFTED`](super::GRAFTED)). Moving instances rebuilds the top level only
//! ([`InstancedBvh::set_transforms`]): its node count depends only on how many instances there
//! are, so the meshes' trees stay where they are.

use std::time::Instant;

use glam::Mat4;
use rayon::prelude::*;

use super::layout::{GpuInstance, GpuNode, GpuTriangle, LEAF_BIT};
use super::top_level::{
    check_transforms, index, place, top_node_count, Aim, BottomLevel, InstanceHook,
};
use super::traverse::{traverse, BvhLeafHook, TriangleSlots};
use super::{BuildParams, Bvh};
use crate::geom::{Aabb, Hit, Ray};
use crate::probe::{Probe, TraceStats};
use crate::scene::InstancedScene;
use crate::Result;

/// A two-level exact BVH in its GPU layout.
#[derive(Clone, Debug, PartialEq)]
pub struct InstancedBvh {
    /// The top level's nodes (node 0 its root), then each mesh's tree.
    pub nodes: Vec<GpuNode>,
    /// Each mesh's triangles in its leaf order, one mesh after another; a triangle's `prim` is
    /// its index in its mesh.
    pub triangles: Vec<GpuTriangle>,
    /// Per instance of the scene, its record.
    pub instances: Vec<GpuInstance>,
    /// Per mesh of the scene, where its tree lies.
    pub meshes: Vec<BottomLevel>,
    /// Nodes of the top level: `nodes[..top_nodes]`.
    pub top_nodes: u32,
    /// Inner nodes on the top level's longest root-to-leaf path.
    pub top_depth: u32,
    /// Bounds of every instance, world space.
    pub bounds: Aabb,
    /// Wall time of the build in milliseconds (the last top-level rebuild's alone after
    /// [`InstancedBvh::set_transforms`]).
    pub build_ms: f64,
}

impl InstancedBvh {
    /// Builds with [`BuildParams::DEFAULT`].
    pub fn build(scene: &InstancedScene) -> Result<InstancedBvh> {
        Self::build_with(scene, &BuildParams::DEFAULT)
    }

    /// Builds each mesh's tree with `params` ([`Bvh::build_with`], whose errors it returns) and
    /// the top level over the instances. Fails with [`crate::Error::InvalidGeometry`] from
    /// [`InstancedScene::validate`], and with [`crate::Error::InvalidParameter`] where the arrays
    /// outgrow 31-bit indices or the two levels together are deeper than the traversal stack.
    pub fn build_with(scene: &InstancedScene, params: &BuildParams) -> Result<InstancedBvh> {
        let start = Instant::now();
        scene.validate()?;
        let trees = scene
            .meshes
            .iter()
            .map(|mesh| Bvh::build_with(mesh, params))
            .collect::<Result<Vec<Bvh>>>()?;
        let transforms: Vec<Mat4> = scene.instances.iter().map(|i| i.transform).collect();
        let mesh_of: Vec<u32> = scene.instances.iter().map(|i| i.mesh).collect();
        let mut nodes = Vec::new();
        let mut triangles = Vec::new();
        let mut meshes = Vec::with_capacity(trees.len());
        let bottoms: Vec<BottomLevel> = trees.iter().map(|t| bottom(t, 0, 0)).collect();
        let top_nodes = top_node_count(&bottoms, &mesh_of);
        nodes.resize(top_nodes as usize, GpuNode::default());
        for tree in trees {
            let node_base = index(nodes.len(), "nodes")?;
            let triangle_base = index(triangles.len(), "triangles")?;
            nodes.extend(
                tree.nodes
                    .iter()
                    .map(|n| relocated(n, node_base, triangle_base)),
            );
            triangles.extend_from_slice(&tree.triangles);
            meshes.push(bottom(&tree, node_base, triangle_base));
        }
        index(nodes.len(), "nodes")?;
        index(triangles.len(), "triangles")?;
        let mut bvh = InstancedBvh {
            nodes,
            triangles,
            instances: Vec::new(),
            meshes,
            top_nodes,
            top_depth: 0,
            bounds: Aabb::EMPTY,
            build_ms: 0.0,
        };
        bvh.place(&transforms, &mesh_of)?;
        bvh.build_ms = start.elapsed().as_secs_f64() * 1e3;
        Ok(bvh)
    }

    /// Moves every instance to its new transform (one per instance, in the scene's order) and
    /// rebuilds the top level alone: the meshes' trees are not touched. A transform that is not
    /// affine, finite and invertible ([`crate::scene::transform_fault`]), a count that is not the instances',
    /// or a top level that no longer fits the stack beside the meshes' trees is an
    /// [`crate::Error::InvalidParameter`], and the structure is left as it was.
    pub fn set_transforms(&mut self, transforms: &[Mat4]) -> Result<()> {
        let start = Instant::now();
        check_transforms(transforms, self.instances.len())?;
        let mesh_of: Vec<u32> = self.instances.iter().map(|i| i.mesh).collect();
        self.place(transforms, &mesh_of)?;
        self.build_ms = start.elapsed().as_secs_f64() * 1e3;
        Ok(())
    }

    /// Builds the top level over instances of meshes `mesh_of` at `transforms` (checked), into
    /// `nodes[..top_nodes]`, and the instance records; on an error nothing changes.
    fn place(&mut self, transforms: &[Mat4], mesh_of: &[u32]) -> Result<()> {
        let top = place(
            &self.meshes,
            &self.nodes,
            transforms,
            mesh_of,
            self.top_nodes,
        )?;
        self.nodes[..top.nodes.len()].copy_from_slice(&top.nodes);
        self.top_depth = top.depth;
        self.instances = top.instances;
        self.bounds = top.bounds;
        Ok(())
    }

    /// Bytes of the node array (both levels).
    pub fn tree_bytes(&self) -> u64 {
        std::mem::size_of_val(self.nodes.as_slice()) as u64
    }

    /// Bytes of the triangle array.
    pub fn triangle_bytes(&self) -> u64 {
        std::mem::size_of_val(self.triangles.as_slice()) as u64
    }

    /// Bytes of the instance records.
    pub fn instance_bytes(&self) -> u64 {
        std::mem::size_of_val(self.instances.as_slice()) as u64
    }

    /// Closest hit of one ray, or [`Hit::MISS`]: the hit names its instance and its mesh's
    /// triangle, with the normal in world space. Invalid rays ([`Ray::is_valid`]) miss.
    pub fn closest_hit(&self, ray: &Ray) -> (Hit, TraceStats) {
        self.traverse(ray, false, &mut ())
    }

    /// Whether anything is hit in `[tmin, tmax)`: the hit returned is *some* hit, not the closest.
    pub fn any_hit(&self, ray: &Ray) -> (Hit, TraceStats) {
        self.traverse(ray, true, &mut ())
    }

    /// One ray as [`InstancedBvh::closest_hit`] or [`InstancedBvh::any_hit`] traces it,
    /// reporting every read of the node, triangle and instance arrays to `probe`.
    pub fn trace_probed<P: Probe>(
        &self,
        ray: &Ray,
        any_hit: bool,
        probe: &mut P,
    ) -> (Hit, TraceStats) {
        self.traverse(ray, any_hit, probe)
    }

    /// Traces many rays in parallel with `rayon`.
    pub fn trace_cpu(&self, rays: &[Ray], any_hit: bool) -> Vec<Hit> {
        rays.par_iter()
            .map(|r| self.traverse(r, any_hit, &mut ()).0)
            .collect()
    }

    fn traverse<P: Probe>(&self, ray: &Ray, any_hit: bool, probe: &mut P) -> (Hit, TraceStats) {
        let triangles = BvhLeafHook::new(self.triangles.as_slice(), ray, any_hit);
        let mut leaves = InstanceHook::new(triangles, &self.instances, ray);
        let stats = traverse(&self.nodes, ray, any_hit, &mut leaves, probe);
        let hit = leaves.finish(probe, |t, p| t.hit(p).unwrap_or(Hit::MISS));
        (hit, stats)
    }
}

/// Where `tree` lies placed at `node_base` among the nodes and `triangle_base` among the
/// triangles.
fn bottom(tree: &Bvh, node_base: u32, triangle_base: u32) -> BottomLevel {
    BottomLevel {
        root: node_base,
        nodes: tree.nodes.len() as u32,
        first_triangle: triangle_base,
        triangles: tree.triangles.len() as u32,
        depth: tree.depth,
        bounds: match tree.triangles.is_empty() {
            true => Aabb::EMPTY,
            false => tree.bounds,
        },
    }
}

/// `node` of a mesh's tree placed at `node_base` among the nodes and `triangle_base` among the
/// triangles: inner children and leaves offset, absent children kept.
fn relocated(node: &GpuNode, node_base: u32, triangle_base: u32) -> GpuNode {
    let shift = |child: u32, count: u32| match (child & LEAF_BIT != 0, count) {
        (true, 0) => child,
        (true, _) => child + triangle_base,
        (false, _) => child + node_base,
    };
    GpuNode {
        a_child: shift(node.a_child, node.a_count),
        b_child: shift(node.b_child, node.b_count),
        ..*node
    }
}

impl<T: TriangleSlots + ?Sized> Aim for BvhLeafHook<'_, T> {
    fn aim(&mut self, ray: &Ray) {
        BvhLeafHook::aim(self, ray);
    }
}
