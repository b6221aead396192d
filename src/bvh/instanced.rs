//! The exact BVH of a scene with instances, in two levels (issue "Instances"): one tree per mesh,
//! built once in the mesh's own space, and a top-level tree over the instances' world boxes
//! whose leaves enter a mesh's tree with the ray taken into its space, the split of Vulkan's
//! top and bottom acceleration structures, of Embree's instances and of tinybvh's TLAS.
//!
//! One node array and one traversal serve both levels ([`traverse`]'s instance hook): the top
//! level's nodes come first (node 0 its root), then each mesh's tree, its child references
//! offset to where it lies; a top-level leaf is `LEAF_BIT | instance` with the count
//! [`INSTANCE_LEAF`]. Moving instances rebuilds the top level only
//! ([`InstancedBvh::set_transforms`]): its node count depends only on how many instances there
//! are, so the meshes' trees stay where they are.

use std::time::Instant;

use glam::Mat4;
use rayon::prelude::*;

use super::build::{tree_over, Placed};
use super::layout::{ChildRef, GpuInstance, GpuNode, GpuTriangle, INSTANCE_LEAF, LEAF_BIT};
use super::traverse::{traverse, BvhLeafHook, Leaves};
use super::{BuildParams, Bvh, STACK_SIZE};
use crate::geom::{Aabb, Hit, Ray};
use crate::probe::{element, Array, Probe, TraceStats};
use crate::scene::{transform_fault, transformed_box, InstancedScene};
use crate::{Error, Result};

/// Where one mesh's tree lies in the two-level arrays.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BottomLevel {
    /// Its root: the first of its nodes.
    pub root: u32,
    /// Its nodes.
    pub nodes: u32,
    /// Its first triangle.
    pub first_triangle: u32,
    /// Its triangles.
    pub triangles: u32,
    /// Inner nodes on its longest root-to-leaf path.
    pub depth: u32,
    /// Its box, in the mesh's space.
    pub bounds: Aabb,
}

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
    /// the top level over the instances. Fails with [`Error::InvalidGeometry`] from
    /// [`InstancedScene::validate`], and with [`Error::InvalidParameter`] where the arrays
    /// outgrow 32-bit indices or the two levels together are deeper than the traversal stack.
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
        let top_nodes = top_node_count(&trees, &mesh_of);
        let mut nodes = vec![GpuNode::default(); top_nodes as usize];
        let mut triangles = Vec::new();
        let mut meshes = Vec::with_capacity(trees.len());
        for tree in trees {
            let node_base = index(nodes.len(), "nodes")?;
            let triangle_base = index(triangles.len(), "triangles")?;
            nodes.extend(
                tree.nodes
                    .iter()
                    .map(|n| relocated(n, node_base, triangle_base)),
            );
            triangles.extend_from_slice(&tree.triangles);
            meshes.push(BottomLevel {
                root: node_base,
                nodes: tree.nodes.len() as u32,
                first_triangle: triangle_base,
                triangles: tree.triangles.len() as u32,
                depth: tree.depth,
                bounds: tree.bounds,
            });
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
    /// affine, finite and invertible ([`transform_fault`]), a count that is not the instances',
    /// or a top level that no longer fits the stack beside the meshes' trees is an
    /// [`Error::InvalidParameter`], and the structure is left as it was.
    pub fn set_transforms(&mut self, transforms: &[Mat4]) -> Result<()> {
        let start = Instant::now();
        if transforms.len() != self.instances.len() {
            return Err(Error::param(
                "transforms",
                format!(
                    "{} transforms for {} instances",
                    transforms.len(),
                    self.instances.len()
                ),
            ));
        }
        for (k, m) in transforms.iter().enumerate() {
            if let Some(fault) = transform_fault(m) {
                return Err(Error::param("transforms", format!("instance {k}: {fault}")));
            }
        }
        let mesh_of: Vec<u32> = self.instances.iter().map(|i| i.mesh).collect();
        self.place(transforms, &mesh_of)?;
        self.build_ms = start.elapsed().as_secs_f64() * 1e3;
        Ok(())
    }

    /// Builds the top level over instances of meshes `mesh_of` at `transforms` (checked), into
    /// `nodes[..top_nodes]`, and the instance records; on an error nothing changes.
    fn place(&mut self, transforms: &[Mat4], mesh_of: &[u32]) -> Result<()> {
        let items: Vec<Placed> = transforms
            .par_iter()
            .zip(mesh_of)
            .enumerate()
            .map(|(k, (&m, &mesh))| {
                let bounds = transformed_box(self.meshes[mesh as usize].bounds, m);
                match bounds.is_empty() {
                    // A mesh without triangles: nothing to enter.
                    true => Placed::Leaf(ChildRef::ABSENT),
                    false => Placed::Leaf(ChildRef {
                        bounds,
                        child: LEAF_BIT | k as u32,
                        count: INSTANCE_LEAF,
                    }),
                }
            })
            .collect();
        let (top, top_depth, _) = tree_over(&items, 1, 0)?;
        if top.len() != self.top_nodes as usize {
            return Err(Error::param(
                "transforms",
                format!(
                    "the top level has {} nodes where {} were set aside",
                    top.len(),
                    self.top_nodes
                ),
            ));
        }
        let deepest = mesh_of
            .iter()
            .map(|&m| self.meshes[m as usize].depth)
            .max()
            .unwrap_or(0);
        // The top level's entries, the instance's end, the mesh's entries.
        if top_depth + 1 + deepest > STACK_SIZE {
            return Err(Error::param(
                "scene",
                format!(
                    "the top level (depth {top_depth}) and the deepest mesh's tree (depth \
                     {deepest}) together exceed the {STACK_SIZE}-entry traversal stack"
                ),
            ));
        }
        self.nodes[..top.len()].copy_from_slice(&top);
        self.top_depth = top_depth;
        self.instances = transforms
            .iter()
            .zip(mesh_of)
            .map(|(&m, &mesh)| GpuInstance::new(m, self.meshes[mesh as usize].root, mesh))
            .collect();
        self.bounds = items
            .iter()
            .filter_map(|item| match item {
                Placed::Leaf(leaf) if !leaf.is_absent() => Some(leaf.bounds),
                _ => None,
            })
            .fold(Aabb::EMPTY, Aabb::union);
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
        let mut leaves = InstanceHook {
            triangles: BvhLeafHook::new(self.triangles.as_slice(), ray, any_hit),
            instances: &self.instances,
            world: *ray,
            entered: None,
            best: None,
        };
        let stats = traverse(&self.nodes, ray, any_hit, &mut leaves, probe);
        (leaves.hit(probe).unwrap_or(Hit::MISS), stats)
    }
}

/// Nodes of the top level over instances of meshes `mesh_of`: one leaf per instance whose mesh
/// has triangles, so a binary tree of that many leaves (one node, with one or no leaf, for fewer
/// than two). The same for every placement, which is what lets the top level be rebuilt in place.
fn top_node_count(trees: &[Bvh], mesh_of: &[u32]) -> u32 {
    let leaves = mesh_of
        .iter()
        .filter(|&&m| !trees[m as usize].triangles.is_empty())
        .count();
    leaves.saturating_sub(1).max(1) as u32
}

/// `n` as a 32-bit index of the two-level arrays, or an error naming `what` outgrew them.
fn index(n: usize, what: &str) -> Result<u32> {
    u32::try_from(n)
        .ok()
        .filter(|&i| i < LEAF_BIT)
        .ok_or_else(|| {
            Error::param(
                "scene",
                format!("the meshes' {what} ({n}) outgrow the 31-bit indices of a two-level BVH"),
            )
        })
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

/// The exact two-level hook: the top level's leaves enter instances, the meshes' leaves are
/// triangle leaves ([`BvhLeafHook`]) tested in the mesh's space.
struct InstanceHook<'a> {
    triangles: BvhLeafHook<'a, [GpuTriangle]>,
    instances: &'a [GpuInstance],
    world: Ray,
    /// The instance the ray is in, if any.
    entered: Option<u32>,
    /// The instance of the nearest hit kept.
    best: Option<u32>,
}

impl InstanceHook<'_> {
    /// The nearest hit kept: its triangle read once more as the device does, its normal taken to
    /// world space by its instance.
    fn hit<P: Probe>(&self, probe: &mut P) -> Option<Hit> {
        let mut hit = self.triangles.hit(probe)?;
        let instance = self.best?;
        probe.read(element::<GpuInstance>(Array::Instances, instance as usize));
        let n = self.instances[instance as usize].normal_out(hit.normal());
        hit.normal = n.to_array();
        hit.instance = instance;
        Some(hit)
    }
}

impl<P: Probe> Leaves<P> for InstanceHook<'_> {
    fn enter_instance(&mut self, reference: u32, count: u32, probe: &mut P) -> Option<(Ray, u32)> {
        if count != INSTANCE_LEAF {
            return None;
        }
        let k = reference & !LEAF_BIT;
        let instance = self.instances.get(k as usize)?;
        probe.read(element::<GpuInstance>(Array::Instances, k as usize));
        let ray = instance.ray_into(&self.world);
        self.triangles.aim(&ray);
        self.entered = Some(k);
        Some((ray, instance.root))
    }

    fn exit_instance(&mut self) {
        self.triangles.aim(&self.world);
        self.entered = None;
    }

    fn has_instances(&self) -> bool {
        true
    }

    fn test(
        &mut self,
        reference: u32,
        count: u32,
        t_closest: &mut f32,
        stats: &mut TraceStats,
        probe: &mut P,
    ) -> bool {
        // Triangles are the meshes': tested inside an instance only (an instance leaf met inside
        // one, or one naming no instance, holds nothing).
        let Some(k) = self.entered else { return false };
        if count == INSTANCE_LEAF {
            return false;
        }
        let found = self
            .triangles
            .test(reference, count, t_closest, stats, probe);
        if found {
            self.best = Some(k);
        }
        found
    }
}
