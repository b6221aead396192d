//! The one nearest-first traversal of the node array, for every structure (the madmann91/bvh
//! `intersect(ray, ..., leaf_fn)` and obvhs `traverse(ray, hit, intersection_fn)` shape): the
//! exact BVH's triangle leaves, an RBVH's height fields and hybrid triangles, and coarse columns
//! with level of detail are each a [`Leaves`] hook, as they are in GLSL, where `glsl/traverse.glsl`
//! is the one traversal that `bvh.glsl`, `rbvh.glsl` and `lod.glsl` instantiate with their hooks.
//! It follows that "while-while" loop step for step (nearest child first with the same tie
//! rule, leaves pushed and popped like inner nodes and handled when they come up, the same
//! bounded stack and robust box test), so that CPU and GPU answers and counters compare ray by
//! ray. The exact BVH's CPU reference tracer below is its first user.
//!
//! Corrupt data never panics and never loops forever: a node index out of range has no
//! children, and more node visits than nodes (only a cycle can make them) end the ray as an
//! overflow.

use glam::Vec3;
use rayon::prelude::*;

use super::layout::{ChildRef, GpuNode, GpuTriangle, INSTANCE_LEAF, LEAF_BIT, STACK_SIZE};
use super::Bvh;
use crate::geom::{intersect_triangle, safe_inverse, Hit, Ray, RayShear};
use crate::probe::{element, Array, Probe, Read, TraceStats};

/// What a traversal does where it stops descending: the leaf test of one structure.
pub(crate) trait Leaves<P: Probe> {
    /// Whether child reference `reference` is handled by [`Leaves::test`] rather than descended
    /// into; by default the leaves ([`LEAF_BIT`]).
    fn is_leaf(&self, reference: u32) -> bool {
        reference & LEAF_BIT != 0
    }

    /// The reference an inner child `child`, entered at `t_entry`, is pushed as: itself by
    /// default, or one that [`Leaves::is_leaf`] takes (level of detail marks a node whose coarse
    /// representation the ray selects).
    fn enter(&self, child: u32, _t_entry: f32) -> u32 {
        child
    }

    /// Enters the instance that top-level leaf `reference` with `count`
    /// [`INSTANCE_LEAF`] names, if it names one (where [`Leaves::has_instances`]): the hook takes
    /// the ray into the instance's mesh space and returns that ray (the same `t` along it) and
    /// the root node of the mesh's tree, where the traversal goes on, on the same stack, until it
    /// pops the instance's end and calls [`Leaves::exit_instance`]. `None` for an instance leaf
    /// that names nothing to enter, which holds nothing (as the shaders skip it). Every other
    /// leaf goes to [`Leaves::test`]: inside an instance the mesh's, in the top level the grafted
    /// mesh's ([`GRAFTED`](super::GRAFTED)).
    fn enter_instance(
        &mut self,
        _reference: u32,
        _count: u32,
        _probe: &mut P,
    ) -> Option<(Ray, u32)> {
        None
    }

    /// Leaves the instance entered last: the ray is the world's again.
    fn exit_instance(&mut self) {}

    /// Whether the structure has a top level over instances, whose inner nodes are counted as
    /// such ([`crate::probe::RayCounters::top_nodes`]); false by default.
    fn has_instances(&self) -> bool {
        false
    }

    /// Tests leaf `reference` (with its child `count`) for the ray's interval `[tmin,
    /// *t_closest)`: on a hit, lowers `*t_closest`, keeps the hit and returns true.
    fn test(
        &mut self,
        reference: u32,
        count: u32,
        t_closest: &mut f32,
        stats: &mut TraceStats,
        probe: &mut P,
    ) -> bool;
}

/// Traverses `nodes` (node 0 the root) for `ray`, handing leaves to `leaves`, which keeps the
/// hit; with `any_hit`, stops at the first leaf that reports one. Counts inner nodes and reports
/// each node read to `probe`, as the shaders read them. Invalid rays ([`Ray::is_valid`]) visit
/// nothing.
///
/// Two levels, one loop: where [`Leaves::enter_instance`] takes a leaf as an instance, the
/// traversal pushes the instance's end (an entry at distance −∞, which no nearest hit drops),
/// goes on from the mesh's root with the ray in the mesh's space, and takes the world ray back
/// when it pops that entry. Distances are the same along both rays (the direction is
/// transformed, not normalized), so the nearest hit bounds both levels. The stack holds the top
/// level's entries, the end and the mesh's: [`InstancedBvh`](super::InstancedBvh) keeps their
/// depths together within it. Visits are bounded per level: a mesh placed twice may be visited
/// twice. A mesh the top level grafts ([`GRAFTED`](super::GRAFTED)) is walked as part of the
/// top level, its leaves (whose counts are not [`INSTANCE_LEAF`]) tested with the world ray.
pub(crate) fn traverse<P: Probe, L: Leaves<P>>(
    nodes: &[GpuNode],
    ray: &Ray,
    any_hit: bool,
    leaves: &mut L,
    probe: &mut P,
) -> TraceStats {
    traverse_from(nodes, 0, ray, any_hit, leaves, probe)
}

/// [`traverse`] from inner node `root` rather than node 0: the same visits in the same order, but
/// for the path down to `root`, where the ray misses every box beside it (as
/// [`LinearBvh::subtree_over`](super::LinearBvh::subtree_over) finds it for rays within a
/// region), so that the traversal from node 0 arrives there with an empty stack.
pub(crate) fn traverse_from<P: Probe, L: Leaves<P>>(
    nodes: &[GpuNode],
    root: u32,
    ray: &Ray,
    any_hit: bool,
    leaves: &mut L,
    probe: &mut P,
) -> TraceStats {
    let mut stats = TraceStats::default();
    if !ray.is_valid() {
        return stats;
    }
    let mut origin = ray.origin();
    let mut inv_dir = safe_inverse(ray.dir());
    let mut t_closest = ray.tmax;
    // Inner nodes visited in the top level, and in the instance entered last (if any).
    let mut visits = [0usize; 2];
    let mut inside = false;
    // One stack of (entry, distance) pairs, as in traverse.glsl: [`StackEntry`]'s word and the
    // distance at which the child's box was entered, so that an entry whose box now lies beyond
    // the nearest hit is dropped when popped instead of visited or marched.
    let mut stack = [(0u32, 0f32); STACK_SIZE as usize];
    let mut sp = 0usize;
    let mut entry = Some((root, 0u32));
    loop {
        let (reference, count) = match entry {
            Some(e) => e,
            None => {
                let mut popped = None;
                while sp > 0 {
                    sp -= 1;
                    let (word, t_entry) = stack[sp];
                    if t_entry == INSTANCE_END {
                        leaves.exit_instance();
                        origin = ray.origin();
                        inv_dir = safe_inverse(ray.dir());
                        inside = false;
                        continue;
                    }
                    if t_entry <= t_closest {
                        popped = Some(StackEntry(word).resolve(nodes, probe));
                        break;
                    }
                }
                match popped {
                    Some(e) => e,
                    None => break,
                }
            }
        };
        entry = None;
        if leaves.is_leaf(reference) {
            // In the top level, a leaf of count INSTANCE_LEAF is an instance; any other is the
            // grafted mesh's (super::GRAFTED), tested as inside an instance.
            let instance_leaf = !inside && leaves.has_instances() && count == INSTANCE_LEAF;
            let instance = match instance_leaf {
                true => leaves.enter_instance(reference, count, probe),
                false => None,
            };
            if let Some((mesh_ray, root)) = instance {
                if sp < STACK_SIZE as usize {
                    stats.counters.instances += 1;
                    stack[sp] = (0, INSTANCE_END);
                    sp += 1;
                    origin = mesh_ray.origin();
                    inv_dir = safe_inverse(mesh_ray.dir());
                    inside = true;
                    visits[1] = 0;
                    entry = Some((root, 0));
                } else {
                    leaves.exit_instance();
                    stats.overflow = true;
                }
            } else if !instance_leaf
                && leaves.test(reference, count, &mut t_closest, &mut stats, probe)
                && any_hit
            {
                return stats;
            }
        } else if let Some(node) = nodes.get(reference as usize) {
            // In a tree every node is entered at most once per ray (per instance entered); more
            // visits than nodes can only come from a cycle in corrupt data.
            let level = &mut visits[usize::from(inside)];
            if *level >= nodes.len() {
                stats.overflow = true;
                break;
            }
            *level += 1;
            stats.counters.nodes += 1;
            if !inside {
                stats.counters.top_nodes += u32::from(leaves.has_instances());
            }
            probe.read(element::<GpuNode>(Array::Nodes, reference as usize));
            let children = node.children();
            let enter = |c: &ChildRef| c.bounds.intersect(origin, inv_dir, ray.tmin, t_closest);
            let (ta, tb) = (enter(&children[0]), enter(&children[1]));
            // Nearest child first; `b` only goes first when strictly nearer (as the shaders do).
            let order = match (ta, tb) {
                (Some(a), Some(b)) if b < a => [1, 0],
                _ => [0, 1],
            };
            for k in order {
                let c = &children[k];
                let Some(t_entry) = [ta, tb][k] else { continue };
                if t_entry > t_closest {
                    continue;
                }
                let child = if c.child & LEAF_BIT == 0 {
                    leaves.enter(c.child, t_entry)
                } else {
                    c.child
                };
                if entry.is_none() {
                    entry = Some((child, c.count));
                } else if sp < STACK_SIZE as usize {
                    stack[sp] = (StackEntry::of(child, reference, k == 1).0, t_entry);
                    sp += 1;
                } else {
                    stats.overflow = true;
                }
            }
        }
    }
    stats
}

/// The distance of the stack entry that ends an instance: below every box's entry distance (at
/// least the ray's `tmin`, at least 0), so no nearest hit drops it.
const INSTANCE_END: f32 = f32::NEG_INFINITY;

/// A traversal stack entry's word (`rbvh_stack_entry` in `glsl/bvh.glsl`): an inner child's
/// reference as [`Leaves::enter`] made it, or, for a leaf, [`LEAF_BIT`] | parent node << 1 | side,
/// from which [`StackEntry::resolve`] reads the leaf's reference and count back from the node when
/// it is popped. So an entry is one word and a distance: a leaf's count does not fit beside its
/// first triangle in one word, and the read it costs is of a node this ray has just read. Node
/// indices stay below 2^30 ([`crate::bvh::MAX_NODES`]).
struct StackEntry(u32);

impl StackEntry {
    /// The entry for `child`, child `b` (or `a`) of inner node `node`.
    fn of(child: u32, node: u32, b: bool) -> StackEntry {
        if child & LEAF_BIT == 0 {
            StackEntry(child)
        } else {
            StackEntry(LEAF_BIT | node << 1 | u32::from(b))
        }
    }

    /// The reference and count the entry stands for (0 for an inner child: only leaves' counts
    /// are read), reporting the read of a leaf's from its node as the shaders make it.
    fn resolve<P: Probe>(self, nodes: &[GpuNode], probe: &mut P) -> (u32, u32) {
        if self.0 & LEAF_BIT == 0 {
            return (self.0, 0);
        }
        let node = ((self.0 & !LEAF_BIT) >> 1) as usize;
        let b = self.0 & 1 == 1;
        // The parent was visited, so it is in range.
        let n = &nodes[node];
        let field = if b {
            std::mem::offset_of!(GpuNode, b_child)
        } else {
            std::mem::offset_of!(GpuNode, a_child)
        };
        probe.read(Read {
            array: Array::Nodes,
            offset: (node * std::mem::size_of::<GpuNode>() + field) as u64,
            bytes: 8,
        });
        if b {
            (n.b_child, n.b_count)
        } else {
            (n.a_child, n.a_count)
        }
    }
}

/// Where triangle leaves read their triangles from, as the device reads them: the exact BVH's
/// gathered 48-byte triangles, or an RBVH's indexed ones (`crate::rbvh::ExactTriangles`).
pub(crate) trait TriangleSlots {
    /// Slots in the array (leaf reads are clamped to them, as on the device).
    fn slots(&self) -> usize;

    /// The vertices (winding kept) and scene index of the triangle in `slot`, reporting the
    /// device's reads of it to `probe`.
    fn read<P: Probe>(&self, slot: usize, probe: &mut P) -> ([Vec3; 3], u32);
}

/// One 48-byte read a triangle (`RBVH_BVH_TRIANGLE` in `glsl/bvh.glsl`).
impl TriangleSlots for [GpuTriangle] {
    fn slots(&self) -> usize {
        self.len()
    }

    fn read<P: Probe>(&self, slot: usize, probe: &mut P) -> ([Vec3; 3], u32) {
        probe.read(element::<GpuTriangle>(Array::Triangles, slot));
        (self[slot].vertices(), self[slot].prim)
    }
}

/// Triangle leaves, tested with the watertight test: the exact BVH's leaves, and an RBVH's hybrid
/// ones. Keeps the slot (leaf order) and distance of the nearest hit. Named as its GLSL twin in
/// `glsl/bvh.glsl` is, as the RBVH's (`RbvhLeafHook`) and level of detail's (`RbvhLodLeafHook`)
/// hooks are.
pub(crate) struct BvhLeafHook<'a, T: TriangleSlots + ?Sized> {
    triangles: &'a T,
    shear: RayShear,
    tmin: f32,
    /// Stop at the first hit, in the leaf as in the tree.
    any_hit: bool,
    best: Option<(usize, f32)>,
}

impl<'a, T: TriangleSlots + ?Sized> BvhLeafHook<'a, T> {
    /// The leaves over `triangles` (in leaf order) for `ray`; with `any_hit`, a leaf stops at its
    /// first hit.
    pub(crate) fn new(triangles: &'a T, ray: &Ray, any_hit: bool) -> Self {
        BvhLeafHook {
            triangles,
            shear: RayShear::new(ray),
            tmin: ray.tmin,
            any_hit,
            best: None,
        }
    }

    /// Tests triangles against `ray` from here on: the ray in an instance's mesh space, or the
    /// world's again. The nearest hit kept stays.
    pub(crate) fn aim(&mut self, ray: &Ray) {
        self.shear = RayShear::new(ray);
        self.tmin = ray.tmin;
    }

    /// The nearest hit kept, if any. The device reads its triangle once more, after its loops,
    /// for the hit's id and normal ([`GpuTriangle::normal_of`]): those reads go to `probe`.
    pub(crate) fn hit<P: Probe>(&self, probe: &mut P) -> Option<Hit> {
        let (slot, t) = self.best?;
        let (vertices, prim) = self.triangles.read(slot, probe);
        Some(Hit {
            t,
            normal: GpuTriangle::normal_of(vertices).to_array(),
            id: prim,
            instance: 0,
            reserved: [0; 2],
        })
    }
}

impl<P: Probe, T: TriangleSlots + ?Sized> Leaves<P> for BvhLeafHook<'_, T> {
    fn test(
        &mut self,
        reference: u32,
        count: u32,
        t_closest: &mut f32,
        stats: &mut TraceStats,
        probe: &mut P,
    ) -> bool {
        let first = (reference & !LEAF_BIT) as usize;
        let end = first
            .saturating_add(count as usize)
            .min(self.triangles.slots());
        stats.counters.triangle_leaves += 1;
        let mut found = false;
        for slot in first..end {
            stats.counters.triangles += 1;
            let ([a, b, c], _) = self.triangles.read(slot, probe);
            if let Some(t) = intersect_triangle(&self.shear, a, b, c, self.tmin, *t_closest) {
                *t_closest = t;
                self.best = Some((slot, t));
                found = true;
                if self.any_hit {
                    break;
                }
            }
        }
        found
    }
}

impl Bvh {
    /// Closest hit of one ray, or [`Hit::MISS`]. Invalid rays ([`Ray::is_valid`]) miss.
    pub fn closest_hit(&self, ray: &Ray) -> (Hit, TraceStats) {
        self.traverse(ray, false, &mut ())
    }

    /// Whether anything is hit in `[tmin, tmax)`: the hit returned is *some* hit, not the closest.
    pub fn any_hit(&self, ray: &Ray) -> (Hit, TraceStats) {
        self.traverse(ray, true, &mut ())
    }

    /// One ray (closest hit, or any hit) as the device traces it, reporting to `probe` every read
    /// `glsl/bvh.glsl` makes of the node and triangle arrays (byte offsets in the device buffers).
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
        let mut leaves = BvhLeafHook::new(self.triangles.as_slice(), ray, any_hit);
        let stats = traverse(&self.nodes, ray, any_hit, &mut leaves, probe);
        (leaves.hit(probe).unwrap_or(Hit::MISS), stats)
    }
}
