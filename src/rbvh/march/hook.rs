//! The march's leaves in the one tree traversal of `crate::bvh` (`traverse.rs`), as its hook
//! ([`RbvhLeafHook`]): a triangle leaf tested exactly, as the exact BVH tests its own, and a
//! height-field leaf marched ([`super::walk`]), each when it comes up from the near-first order or
//! the stack. A new kind of leaf is told apart in [`crate::rbvh::child`] and tested here.

use glam::Vec3;

use super::normal::NormalReads;
use super::Walk;
use crate::bvh::{traverse, Aim, BvhLeafHook, GpuInstance, InstanceHook, Leaves};
use crate::geom::{Hit, Ray};
use crate::probe::{Probe, TraceStats};
use crate::rbvh::child::Child;
use crate::rbvh::{ExactTriangles, Rbvh};

/// An RBVH's leaves for the shared traversal (`crate::bvh::traverse`): hybrid triangle leaves
/// tested exactly, height fields marched. Level of detail wraps it (`crate::lod`'s `RbvhLodLeafHook`),
/// recording the hits of the coarse nodes it marches here ([`RbvhLeafHook::record`]).
pub(crate) struct RbvhLeafHook<'a> {
    rbvh: &'a Rbvh,
    /// The ray of the level traversed: the world's, or in a two-level RBVH the ray in the mesh
    /// space of the instance entered ([`RbvhLeafHook::aim`]).
    ray: Ray,
    /// The hybrid triangle leaves, tested as the exact BVH tests its own.
    triangles: BvhLeafHook<'a, ExactTriangles>,
    walk: Walk<'a>,
    /// The nearest hit on a height field (or a coarse node): the best unless a triangle's is
    /// nearer.
    best: Hit,
    /// Whether the triangles' hit is the nearest.
    triangle_nearest: bool,
    /// The texels the device reads for `best`'s normal once the ray is done.
    normal_reads: NormalReads,
}

impl<'a> RbvhLeafHook<'a> {
    /// The ray traced, in the space of the level traversed.
    pub(crate) fn ray(&self) -> &Ray {
        &self.ray
    }

    /// Marches and tests leaves along `ray` from here on: the ray in an instance's mesh space,
    /// or the world's again. The nearest hit kept stays.
    pub(crate) fn aim(&mut self, ray: &Ray) {
        self.ray = *ray;
        self.triangles.aim(ray);
    }

    /// Keeps a hit at `t` with `normal` and `id` found by a hook around these leaves.
    pub(crate) fn record(&mut self, t: f32, normal: Vec3, id: u32) {
        self.best = Hit {
            t,
            normal: normal.to_array(),
            id,
            instance: 0,
            reserved: [0; 2],
        };
        self.triangle_nearest = false;
        self.normal_reads = NormalReads::default();
    }

    /// The hit kept. The device reads the nearest triangle once more, after its loops, for the
    /// hit's id and normal, when the best hit is a triangle, and a height field's texels for its
    /// normal: those reads go to `probe`.
    pub(crate) fn finish<P: Probe>(self, probe: &mut P) -> Hit {
        if self.triangle_nearest {
            return self.triangles.hit(probe).unwrap_or(Hit::MISS);
        }
        if let Some((leaf, skirt)) = self.normal_reads.facet {
            for read in NormalReads::facet_leaf_reads(leaf, skirt) {
                probe.read(read);
            }
            for texel in self.normal_reads.iter() {
                probe.read(self.rbvh.atlas.pair_read(texel as usize));
            }
        } else if P::RECORDS {
            for texel in self.normal_reads.iter() {
                let reads = self
                    .rbvh
                    .atlas
                    .normal_reads(texel as usize, self.walk.ranks);
                for read in reads {
                    probe.read(read);
                }
            }
        }
        self.best
    }
}

impl<P: Probe> Leaves<P> for RbvhLeafHook<'_> {
    fn test(
        &mut self,
        node: u32,
        count: u32,
        t_closest: &mut f32,
        stats: &mut TraceStats,
        probe: &mut P,
    ) -> bool {
        let (ray, rbvh) = (&self.ray, self.rbvh);
        let index = match Child::decode(node, count) {
            Child::Heightfield(index) => index,
            // A triangle leaf (hybrid RBVH), or an absent one: tested exactly (the traversal
            // hands the hook leaves only, so `Inner` never comes; as a leaf of no triangles it
            // would find nothing).
            Child::Triangles { .. } | Child::Absent | Child::Inner(_) => {
                let found = self.triangles.test(node, count, t_closest, stats, probe);
                self.triangle_nearest |= found;
                return found;
            }
        };
        // A height-field leaf that came up from the near-first order or the stack.
        stats.counters.leaves += 1;
        let Some((t, normal)) = rbvh.march(index, ray, *t_closest, self.walk, stats, probe) else {
            return false;
        };
        *t_closest = t;
        self.record(t, normal.normal, node);
        self.normal_reads = normal.reads;
        true
    }
}

impl Rbvh {
    pub(super) fn traverse<P: Probe>(
        &self,
        ray: &Ray,
        any_hit: bool,
        walk: Walk,
        probe: &mut P,
    ) -> (Hit, TraceStats) {
        self.traverse_with(self.leaf_hook(ray, any_hit, walk), ray, any_hit, probe)
    }

    /// This RBVH's leaves for `ray`, walking cells as `walk` says.
    pub(crate) fn leaf_hook<'a>(
        &'a self,
        ray: &Ray,
        any_hit: bool,
        walk: Walk<'a>,
    ) -> RbvhLeafHook<'a> {
        RbvhLeafHook {
            rbvh: self,
            ray: *ray,
            triangles: BvhLeafHook::new(&self.triangles, ray, any_hit),
            walk,
            best: Hit::MISS,
            triangle_nearest: false,
            normal_reads: NormalReads::default(),
        }
    }

    /// The shared traversal of this RBVH's nodes with `leaves` (its own, or a hook around them),
    /// and the hit they kept.
    pub(crate) fn traverse_with<'a, P: Probe, L>(
        &self,
        mut leaves: L,
        ray: &Ray,
        any_hit: bool,
        probe: &mut P,
    ) -> (Hit, TraceStats)
    where
        L: Leaves<P> + Into<RbvhLeafHook<'a>>,
    {
        let stats = crate::bvh::traverse(&self.nodes, ray, any_hit, &mut leaves, probe);
        (leaves.into().finish(probe), stats)
    }
}

impl Aim for RbvhLeafHook<'_> {
    fn aim(&mut self, ray: &Ray) {
        RbvhLeafHook::aim(self, ray);
    }
}

/// One ray through the arrays `rbvh` of a two-level RBVH (`crate::rbvh::InstancedRbvh`) over
/// `instances`: the top level's instance leaves enter instances ([`InstanceHook`]), inside which
/// the RBVH's own leaves are marched and tested, walking cells as `walk` says (the grafted mesh's
/// in the top level, [`crate::bvh::GRAFTED`]).
pub(crate) fn trace_instanced<P: Probe>(
    rbvh: &Rbvh,
    instances: &[GpuInstance],
    ray: &Ray,
    any_hit: bool,
    walk: Walk,
    probe: &mut P,
) -> (Hit, TraceStats) {
    let mut leaves = InstanceHook::new(rbvh.leaf_hook(ray, any_hit, walk), instances, ray);
    let stats = traverse(&rbvh.nodes, ray, any_hit, &mut leaves, probe);
    (leaves.finish(probe, RbvhLeafHook::finish), stats)
}
