//! CPU reference tracer for the exact BVH: the same traversal order, box test and triangle test as
//! `glsl/bvh.glsl`, so that CPU and GPU answers can be compared ray by ray, with the same counters
//! ([`crate::probe::RayCounters`]: nodes, triangle leaves, triangles) and the same reads.

use rayon::prelude::*;

use super::layout::{ChildRef, GpuNode, GpuTriangle, LEAF_BIT, STACK_SIZE};
use super::Bvh;
use crate::geom::{intersect_triangle, safe_inverse, Hit, Ray, RayShear};
use crate::probe::{element, Array, Probe, TraceStats};

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
        let mut stats = TraceStats::default();
        if !ray.is_valid() {
            return (Hit::MISS, stats);
        }
        let origin = ray.origin();
        let inv_dir = safe_inverse(ray.dir());
        let shear = RayShear::new(ray);
        let mut t_closest = ray.tmax;
        let mut best = None;
        // Children as (reference, count); leaves are pushed and popped like inner nodes and
        // tested when they come up, in the order of glsl/bvh.glsl's "while-while" traversal.
        let mut stack = [(0u32, 0u32); STACK_SIZE as usize];
        let mut sp = 0usize;
        let mut node = (0u32, 0u32);
        loop {
            let (reference, count) = node;
            let mut next = None;
            if reference & LEAF_BIT != 0 {
                let first = (reference & !LEAF_BIT) as usize;
                stats.counters.triangle_leaves += 1;
                for slot in first..first + count as usize {
                    stats.counters.triangles += 1;
                    probe.read(element::<GpuTriangle>(Array::Triangles, slot));
                    let [a, b, c] = self.triangles[slot].vertices();
                    if let Some(t) = intersect_triangle(&shear, a, b, c, ray.tmin, t_closest) {
                        t_closest = t;
                        best = Some(slot);
                        if any_hit {
                            return (self.hit(slot, t_closest, probe), stats);
                        }
                    }
                }
            } else {
                stats.counters.nodes += 1;
                probe.read(element::<GpuNode>(Array::Nodes, reference as usize));
                let children = self.nodes[reference as usize].children();
                let entry = |c: &ChildRef| c.bounds.intersect(origin, inv_dir, ray.tmin, t_closest);
                let (ta, tb) = (entry(&children[0]), entry(&children[1]));
                // Nearest child first; `b` only goes first when strictly nearer (same rule as GLSL).
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
                    if next.is_none() {
                        next = Some((c.child, c.count));
                    } else if sp < STACK_SIZE as usize {
                        stack[sp] = (c.child, c.count);
                        sp += 1;
                    } else {
                        stats.overflow = true;
                    }
                }
            }
            node = match next {
                Some(n) => n,
                None if sp > 0 => {
                    sp -= 1;
                    stack[sp]
                }
                None => break,
            };
        }
        let hit = best.map_or(Hit::MISS, |slot| self.hit(slot, t_closest, probe));
        (hit, stats)
    }

    /// The hit record of triangle slot `slot` (its position in leaf order) at distance `t`; the
    /// device reads the triangle once more for it.
    fn hit<P: Probe>(&self, slot: usize, t: f32, probe: &mut P) -> Hit {
        probe.read(element::<GpuTriangle>(Array::Triangles, slot));
        let tri = &self.triangles[slot];
        Hit {
            t,
            normal: tri.normal().to_array(),
            id: tri.prim,
            reserved: [0; 3],
        }
    }
}
