//! Tracing with level of detail: the RBVH's leaves (`rbvh::march`'s) wrapped in a hook of the
//! shared traversal (`crate::bvh::traverse`) that also chooses, per ray, the coarse
//! representation of an inner node its cone selects ([`selects`] at the child's box entry),
//! pushes it as `LOD_BIT | node`, and marches its columns when it comes up (`march.rs`) instead
//! of descending. A hit on a coarse representation reports `id = LEAF_BIT | LOD_BIT | node`; the
//! columns it visits count as `cells`. Level of detail depends on the RBVH, not the other way
//! round, so this lives here rather than in the RBVH's caster.

use rayon::prelude::*;

use super::march::march;
use super::{selects, Cones, GpuLod, Lod, RayCone, LOD_BIT};
use crate::bvh::{Leaves, LEAF_BIT};
use crate::geom::{Hit, Ray};
use crate::probe::{element, Array, Probe, TraceStats};
use crate::rbvh::march::{DeviceTwin, RbvhLeafHook, Walk};
use crate::rbvh::Rbvh;
use crate::{Error, Result};

/// The RBVH's leaves, and the coarse nodes `cone` selects in `lod`.
struct RbvhLodLeafHook<'a> {
    inner: RbvhLeafHook<'a>,
    lod: &'a Lod,
    cone: &'a RayCone,
}

impl<'a> From<RbvhLodLeafHook<'a>> for RbvhLeafHook<'a> {
    fn from(leaves: RbvhLodLeafHook<'a>) -> Self {
        leaves.inner
    }
}

impl<P: Probe> Leaves<P> for RbvhLodLeafHook<'_> {
    fn is_leaf(&self, reference: u32) -> bool {
        reference & (LEAF_BIT | LOD_BIT) != 0
    }

    fn enter(&self, child: u32, t_entry: f32) -> u32 {
        let l = self.lod;
        let coarse = l
            .nodes
            .get(child as usize)
            .is_some_and(|r| selects(l.params.selection_width(r.texel_size), self.cone, t_entry));
        if coarse {
            LOD_BIT | child
        } else {
            child
        }
    }

    fn test(
        &mut self,
        node: u32,
        count: u32,
        t_closest: &mut f32,
        stats: &mut TraceStats,
        probe: &mut P,
    ) -> bool {
        // A leaf's reference may have bit 30 set (a triangle slot from 2^30 on); only an inner
        // node's carries LOD_BIT alone.
        if node & (LEAF_BIT | LOD_BIT) != LOD_BIT {
            return self.inner.test(node, count, t_closest, stats, probe);
        }
        // A coarse representation chosen for this ray.
        let n = node & !LOD_BIT;
        stats.counters.leaves += 1;
        let record = match self.lod.nodes.get(n as usize) {
            Some(r) => {
                probe.read(element::<GpuLod>(Array::LodRecords, n as usize));
                r
            }
            None => &GpuLod::NONE,
        };
        let ray = self.inner.ray();
        let Some((t, normal)) = march(
            record,
            &self.lod.texels,
            ray,
            *t_closest,
            &mut stats.counters,
            probe,
        ) else {
            return false;
        };
        *t_closest = t;
        self.inner.record(t, normal, LEAF_BIT | node);
        true
    }
}

/// Traces `ray` through `rbvh`'s nodes with its leaves walked as `walk`, and `lod`'s coarse
/// nodes as `cone` selects them.
fn trace<P: Probe>(
    rbvh: &Rbvh,
    lod: &Lod,
    ray: &Ray,
    cone: &RayCone,
    any_hit: bool,
    walk: Walk,
    probe: &mut P,
) -> (Hit, TraceStats) {
    let leaves = RbvhLodLeafHook {
        inner: rbvh.leaf_hook(ray, any_hit, walk),
        lod,
        cone,
    };
    rbvh.traverse_with(leaves, ray, any_hit, probe)
}

impl Rbvh {
    /// As [`Rbvh::closest_hit`] (or [`Rbvh::any_hit`]) with level of detail: an inner child whose
    /// coarse representation in `lod` (built for this RBVH) is selected by `cone` at the child's
    /// box entry ([`crate::lod::selects`]) is marched instead of descended into. A hit on a
    /// coarse representation reports `id = LEAF_BIT | LOD_BIT | node`. The columns it visits
    /// count as `cells`. Fails, as [`Rbvh::trace_cpu_lod`] does, where `lod` was not built for
    /// this RBVH ([`Lod::check_for`]): its grids would be marched for other nodes.
    pub fn hit_lod(
        &self,
        lod: &Lod,
        ray: &Ray,
        cone: &RayCone,
        any_hit: bool,
    ) -> Result<(Hit, TraceStats)> {
        lod.check_for(self)?;
        Ok(trace(self, lod, ray, cone, any_hit, Walk::PLAIN, &mut ()))
    }

    /// [`Rbvh::hit_lod`] for many rays, each with its footprint in `cones` (one per ray, or one
    /// for all), in parallel; hits in ray order. Fails when `lod` was built for another tree, or
    /// the rays have no footprints or not one per ray.
    pub fn trace_cpu_lod<'c>(
        &self,
        lod: &Lod,
        rays: &[Ray],
        cones: impl Into<Cones<'c>>,
        any_hit: bool,
    ) -> Result<Vec<Hit>> {
        lod.check_for(self)?;
        let cones = cones.into();
        if !cones.is_some() {
            return Err(Error::param(
                "cones",
                "a trace with levels of detail needs the rays' footprints: one cone per ray, or \
                 one for all"
                    .to_string(),
            ));
        }
        cones.check(rays)?;
        Ok(rays
            .par_iter()
            .enumerate()
            .map(|(i, r)| {
                let cone = cones.get(i).unwrap_or(RayCone::POINT);
                trace(self, lod, r, &cone, any_hit, Walk::PLAIN, &mut ()).0
            })
            .collect())
    }
}

/// The device's twin of a trace with level of detail ([`DeviceTwin`] with `lod`'s coarse nodes,
/// read for read as `glsl/lod.glsl` reads them). Made by [`Lod::device_twin`].
pub struct LodTwin<'a> {
    twin: DeviceTwin<'a>,
    lod: &'a Lod,
}

impl<'a> LodTwin<'a> {
    /// With block jumps on (the default) or off, as [`DeviceTwin::with_block_jumps`].
    pub fn with_block_jumps(self, on: bool) -> Self {
        LodTwin {
            twin: self.twin.with_block_jumps(on),
            ..self
        }
    }

    /// Traces one ray with its footprint `cone` as the device does, reporting its reads to
    /// `probe`.
    pub fn trace<P: Probe>(
        &self,
        ray: &Ray,
        any_hit: bool,
        cone: &RayCone,
        probe: &mut P,
    ) -> (Hit, TraceStats) {
        trace(
            self.twin.rbvh(),
            self.lod,
            ray,
            cone,
            any_hit,
            self.twin.walk(),
            probe,
        )
    }
}

impl Lod {
    /// The device's twin of a trace of `rbvh` with these levels of detail ([`LodTwin`]). Fails
    /// when they were built for another tree.
    pub fn device_twin<'a>(&'a self, rbvh: &'a Rbvh) -> Result<LodTwin<'a>> {
        self.check_for(rbvh)?;
        Ok(LodTwin {
            twin: rbvh.device_twin(),
            lod: self,
        })
    }
}
