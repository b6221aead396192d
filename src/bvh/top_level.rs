//! The top level of a two-level structure (issue "Instances"), the same for every bottom level
//! (the exact BVH's trees, [`super::InstancedBvh`]; an RBVH's, `crate::rbvh::InstancedRbvh`):
//! where each mesh's tree lies ([`BottomLevel`]), the tree over the instances' world boxes
//! ([`place`]), and the traversal's hook that enters an instance by taking the ray into its
//! mesh's space ([`InstanceHook`], around the bottom level's own leaves).
//!
//! A top-level leaf is `LEAF_BIT | instance` with the count [`INSTANCE_LEAF`], which no mesh's
//! leaf has. The first instance, where it places its mesh where it is (the identity: a scene
//! file's `[[mesh]]` entries, [`InstancedScene`](crate::scene::InstancedScene)'s convention), is
//! *grafted* ([`GRAFTED`]): its top-level child is its mesh's root, so a ray walks that tree in
//! the top level with the world ray, entering no instance. Entering and leaving an instance take
//! a round of the traversal each, which the rays of a scene placed around its own geometry paid
//! for nearly every ray (docs/paper-scale.md, "The scene's own geometry in the top level").

use glam::Mat4;
use rayon::prelude::*;

use super::build::{tree_over, Placed};
use super::layout::{ChildRef, GpuInstance, GpuNode, INSTANCE_LEAF, LEAF_BIT};
use super::traverse::Leaves;
use super::STACK_SIZE;
use crate::geom::{Aabb, Hit, Ray};
use crate::probe::{element, Array, Probe, TraceStats};
use crate::scene::{transform_fault, transformed_box};
use crate::{Error, Result};

/// Where one mesh's tree lies in the two-level arrays.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BottomLevel {
    /// Its root: the first of its nodes.
    pub root: u32,
    /// Its nodes.
    pub nodes: u32,
    /// Its first triangle (for an RBVH, its first exact triangle's slot).
    pub first_triangle: u32,
    /// Its triangles (for an RBVH, those traced exactly).
    pub triangles: u32,
    /// Inner nodes on its longest root-to-leaf path.
    pub depth: u32,
    /// Its box, in the mesh's space; empty for a mesh with nothing to enter.
    pub bounds: Aabb,
}

/// A top level built by [`place`]: its nodes (node 0 its root) and what they place.
pub(crate) struct TopLevel {
    pub(crate) nodes: Vec<GpuNode>,
    /// Inner nodes on its longest root-to-leaf path.
    pub(crate) depth: u32,
    /// Per instance, its record.
    pub(crate) instances: Vec<GpuInstance>,
    /// The box of every instance, world space.
    pub(crate) bounds: Aabb,
}

/// Nodes of the top level over instances of meshes `mesh_of`: one leaf per instance whose mesh
/// has something to enter, so a binary tree of that many leaves (one node, with one or no leaf,
/// for fewer than two). The same for every placement, which is what lets the top level be
/// rebuilt in place.
pub(crate) fn top_node_count(meshes: &[BottomLevel], mesh_of: &[u32]) -> u32 {
    let leaves = mesh_of
        .iter()
        .filter(|&&m| !meshes[m as usize].bounds.is_empty())
        .count();
    leaves.saturating_sub(1).max(1) as u32
}

/// Checks new transforms for `instances` instances: one each, each affine, finite and
/// invertible ([`transform_fault`]); the error names the instance.
pub(crate) fn check_transforms(transforms: &[Mat4], instances: usize) -> Result<()> {
    if transforms.len() != instances {
        return Err(Error::param(
            "transforms",
            format!("{} transforms for {instances} instances", transforms.len()),
        ));
    }
    for (k, m) in transforms.iter().enumerate() {
        if let Some(fault) = transform_fault(m) {
            return Err(Error::param("transforms", format!("instance {k}: {fault}")));
        }
    }
    Ok(())
}

/// The instance whose mesh the top level holds in place of a leaf, where it places it where it is
/// (the identity transform, exactly): its tree's root is the top level's child, walked with the
/// world ray. A leaf met in the top level is then that mesh's, and its hit is named by this
/// instance, which is why one instance only, and always the first, is grafted: the device names
/// such a hit without a record saying which. Moved elsewhere ([`InstancedBvh::set_transforms`]),
/// it is an instance like the others.
///
/// [`InstancedBvh::set_transforms`]: super::InstancedBvh::set_transforms
pub const GRAFTED: u32 = 0;

/// Most boxes of a mesh's tree that an instance's world box is made from ([`cut`]): 16 turned
/// dragons' top-level boxes enclose less empty space than their root boxes turned would, so
/// that fewer rays enter an instance they miss, for up to 136 corners transformed per instance when
/// the top level is rebuilt.
const CUT_BOXES: usize = 16;

/// Up to [`CUT_BOXES`] boxes of `mesh`'s tree in `nodes` that hold everything a ray can reach
/// in it: starting from its root's children, the inner child of largest surface area is
/// replaced by its own children while there is room. An instance's world box is then the union
/// of these boxes transformed, rather than the root's box transformed, which for a turned mesh
/// encloses the corners of a box that itself encloses empty corners (the box of a box twice).
/// A child reference outside the mesh's nodes is kept as a box, not followed, and the
/// expansions are bounded: corrupt data (a loaded file's cycle) neither reads out of range nor
/// loops. Empty for a mesh with no tree.
fn cut(nodes: &[GpuNode], mesh: &BottomLevel) -> Vec<Aabb> {
    let inside = |child: u32| {
        child >= mesh.root && child - mesh.root < mesh.nodes && (child as usize) < nodes.len()
    };
    if mesh.bounds.is_empty() || !inside(mesh.root) {
        return Vec::new();
    }
    let children = |node: u32| {
        nodes[node as usize]
            .children()
            .into_iter()
            .filter(|c| !c.is_absent())
    };
    let mut boxes: Vec<ChildRef> = children(mesh.root).collect();
    // A tree reaches CUT_BOXES boxes in fewer expansions than this; a corrupt one whose nodes
    // lead back to themselves (which no file check looks for) stops here instead of looping.
    for _ in 0..2 * CUT_BOXES {
        if boxes.len() >= CUT_BOXES {
            break;
        }
        let widest = boxes
            .iter()
            .enumerate()
            .filter(|(_, c)| !c.is_leaf() && inside(c.child))
            .max_by(|(_, a), (_, b)| a.bounds.area().total_cmp(&b.bounds.area()));
        let Some((k, _)) = widest else { break };
        let node = boxes.swap_remove(k).child;
        boxes.extend(children(node));
    }
    boxes.into_iter().map(|c| c.bounds).collect()
}

/// The world box of `mesh` placed by `m`: its [`cut`]'s boxes transformed, within its whole
/// box transformed (a node's decoded boxes are rounded outward to its grid).
fn placed_box(mesh: &BottomLevel, cut: &[Aabb], m: Mat4) -> Aabb {
    let whole = transformed_box(mesh.bounds, m);
    if cut.is_empty() {
        return whole;
    }
    let parts = cut
        .iter()
        .fold(Aabb::EMPTY, |acc, &b| acc.union(transformed_box(b, m)));
    Aabb {
        min: parts.min.max(whole.min),
        max: parts.max.min(whole.max),
    }
}

/// The top level over instances of meshes `mesh_of` (lying as `meshes` say in `nodes`) at
/// `transforms`, the [`GRAFTED`] instance's mesh in place of its leaf where it lies where it is:
/// `top_nodes` nodes ([`top_node_count`]), or an [`Error::InvalidParameter`]
/// where the tree came out otherwise or the two levels together are deeper than the traversal
/// stack.
pub(crate) fn place(
    meshes: &[BottomLevel],
    nodes: &[GpuNode],
    transforms: &[Mat4],
    mesh_of: &[u32],
    top_nodes: u32,
) -> Result<TopLevel> {
    let cuts: Vec<Vec<Aabb>> = meshes.iter().map(|mesh| cut(nodes, mesh)).collect();
    let items: Vec<Placed> = transforms
        .par_iter()
        .zip(mesh_of)
        .enumerate()
        .map(|(k, (&m, &mesh))| {
            let bottom = &meshes[mesh as usize];
            let bounds = placed_box(bottom, &cuts[mesh as usize], m);
            match bounds.is_empty() {
                // A mesh with nothing in it: nothing to enter.
                true => Placed::Leaf(ChildRef::ABSENT),
                false if k as u32 == GRAFTED && m == Mat4::IDENTITY => Placed::Leaf(ChildRef {
                    bounds,
                    child: bottom.root,
                    count: 0,
                }),
                false => Placed::Leaf(ChildRef {
                    bounds,
                    child: LEAF_BIT | k as u32,
                    count: INSTANCE_LEAF,
                }),
            }
        })
        .collect();
    let (nodes, depth, _) = tree_over(&items, 1, 0)?;
    if nodes.len() != top_nodes as usize {
        return Err(Error::param(
            "transforms",
            format!(
                "the top level has {} nodes where {top_nodes} were set aside",
                nodes.len()
            ),
        ));
    }
    let deepest = mesh_of
        .iter()
        .map(|&m| meshes[m as usize].depth)
        .max()
        .unwrap_or(0);
    // The top level's entries, the instance's end, the mesh's entries (a grafted mesh's without
    // the end).
    if depth + 1 + deepest > STACK_SIZE {
        return Err(Error::param(
            "scene",
            format!(
                "the top level (depth {depth}) and the deepest mesh's tree (depth {deepest}) \
                 together exceed the {STACK_SIZE}-entry traversal stack"
            ),
        ));
    }
    let instances = transforms
        .iter()
        .zip(mesh_of)
        .map(|(&m, &mesh)| GpuInstance::new(m, meshes[mesh as usize].root, mesh))
        .collect();
    let bounds = items
        .iter()
        .filter_map(|item| match item {
            Placed::Leaf(leaf) if !leaf.is_absent() => Some(leaf.bounds),
            _ => None,
        })
        .fold(Aabb::EMPTY, Aabb::union);
    Ok(TopLevel {
        nodes,
        depth,
        instances,
        bounds,
    })
}

/// `n` as a 32-bit index of the two-level arrays, or an error naming `what` outgrew them.
pub(crate) fn index(n: usize, what: &str) -> Result<u32> {
    u32::try_from(n)
        .ok()
        .filter(|&i| i < LEAF_BIT)
        .ok_or_else(|| {
            Error::param(
                "scene",
                format!(
                    "the meshes' {what} ({n}) outgrow the 31-bit indices of a two-level structure"
                ),
            )
        })
}

/// A bottom level's leaves, which can be aimed along another ray: the ray in an instance's mesh
/// space, or the world's again, keeping the nearest hit found.
pub(crate) trait Aim {
    fn aim(&mut self, ray: &Ray);
}

/// The two-level hook around a bottom level's `leaves`: the top level's instance leaves enter
/// instances, the meshes' leaves are `leaves`' own, tested in the mesh's space (the grafted
/// mesh's in the top level, with the world ray, named [`GRAFTED`]).
pub(crate) struct InstanceHook<'a, L> {
    leaves: L,
    instances: &'a [GpuInstance],
    world: Ray,
    /// The instance the ray is in, if any.
    entered: Option<u32>,
    /// The instance of the nearest hit kept.
    best: Option<u32>,
}

impl<'a, L> InstanceHook<'a, L> {
    /// `leaves` (aimed along the world `ray`) under a top level over `instances`.
    pub(crate) fn new(leaves: L, instances: &'a [GpuInstance], ray: &Ray) -> Self {
        InstanceHook {
            leaves,
            instances,
            world: *ray,
            entered: None,
            best: None,
        }
    }

    /// The nearest hit: what the bottom level's leaves kept (`hit` finishes them, reading what
    /// the device reads once the ray is done), named by its instance, its normal taken to world
    /// space. The read of the instance goes to `probe`, as the device makes it.
    pub(crate) fn finish<P: Probe>(self, probe: &mut P, hit: impl FnOnce(L, &mut P) -> Hit) -> Hit {
        let hit = hit(self.leaves, probe);
        let Some(k) = self.best.filter(|_| hit.is_hit()) else {
            return Hit::MISS;
        };
        probe.read(element::<GpuInstance>(Array::Instances, k as usize));
        let n = self.instances[k as usize].normal_out(hit.normal());
        Hit {
            normal: n.to_array(),
            instance: k,
            ..hit
        }
    }
}

impl<P: Probe, L: Leaves<P> + Aim> Leaves<P> for InstanceHook<'_, L> {
    fn enter_instance(&mut self, reference: u32, _count: u32, probe: &mut P) -> Option<(Ray, u32)> {
        // The traversal hands over top-level leaves of count INSTANCE_LEAF alone.
        let k = reference & !LEAF_BIT;
        let instance = self.instances.get(k as usize)?;
        // The device reads the record here; the two-level RBVH's reads it again at the start of
        // each round inside the instance (`rbvh_level_ray`), the same lines, which the traffic
        // model's distinct lines and caches count once, so they are not reported.
        probe.read(element::<GpuInstance>(Array::Instances, k as usize));
        // A root of u32::MAX (RBVH_INVALID, which no builder writes) names no mesh: no instance,
        // as the device's rbvh_instance_root reads it.
        if instance.root == u32::MAX {
            return None;
        }
        let ray = instance.ray_into(&self.world);
        self.leaves.aim(&ray);
        self.entered = Some(k);
        Some((ray, instance.root))
    }

    fn exit_instance(&mut self) {
        self.leaves.aim(&self.world);
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
        // The traversal hands over the leaves met inside an instance, and in the top level the
        // grafted instance's.
        let k = self.entered.unwrap_or(GRAFTED);
        let found = self.leaves.test(reference, count, t_closest, stats, probe);
        if found {
            self.best = Some(k);
        }
        found
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;

    /// A mesh of `depth` levels (its nodes not needed: its box stands for them).
    fn mesh(depth: u32) -> BottomLevel {
        BottomLevel {
            root: 0,
            nodes: 0,
            first_triangle: 0,
            triangles: 1,
            depth,
            bounds: Aabb {
                min: Vec3::ZERO,
                max: Vec3::ONE,
            },
        }
    }

    /// The two levels together must fit the traversal's stack: the top level's entries, the
    /// instance's end and the deepest mesh's entries. A placement that would overflow it is
    /// refused, naming both depths; the grafted first instance counts as any other.
    #[test]
    fn levels_deeper_than_the_stack_together_are_refused() {
        let apart = |k: f32| Mat4::from_translation(Vec3::new(2.0 * k, 0.0, 0.0));
        for first in [Mat4::IDENTITY, apart(3.0)] {
            let transforms = [first, apart(1.0)];
            let fits = [mesh(STACK_SIZE - 2)];
            let top = top_node_count(&fits, &[0, 0]);
            let placed = place(&fits, &[], &transforms, &[0, 0], top).unwrap();
            assert_eq!(placed.depth, 1);
            let deep = [mesh(STACK_SIZE - 1)];
            let e = place(&deep, &[], &transforms, &[0, 0], top)
                .err()
                .unwrap()
                .to_string();
            assert!(
                e.contains("(depth 1)")
                    && e.contains(&format!("(depth {})", STACK_SIZE - 1))
                    && e.contains(&format!("{STACK_SIZE}-entry traversal stack")),
                "{e}"
            );
        }
    }
}
