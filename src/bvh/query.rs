//! Which triangles lie near a region: a box query over the node array, for builders that sample
//! the surface around one piece of it (the RBVH's ring of samples, `crate::rbvh::raster`).

use glam::Vec3;

use super::layout::LEAF_BIT;
use super::Bvh;
use crate::geom::Aabb;

impl Bvh {
    /// The triangles whose boxes overlap `query` (a superset of those inside it), in leaf order,
    /// appended to `out`: what lies near a region, for builders that sample the surface
    /// around one piece of it. Bounded like the traversal: at most one visit per node.
    pub(crate) fn triangles_near(&self, query: &Aabb, out: &mut Vec<[Vec3; 3]>) {
        let overlaps = |b: &Aabb| b.min.cmple(query.max).all() && b.max.cmpge(query.min).all();
        let mut stack = vec![0u32];
        let mut visits = 0usize;
        while let Some(index) = stack.pop() {
            let Some(node) = self.nodes.get(index as usize) else {
                continue;
            };
            visits += 1;
            if visits > self.nodes.len() {
                break;
            }
            for c in node.children() {
                if !overlaps(&c.bounds) {
                    continue;
                }
                if c.is_leaf() {
                    let first = (c.child & !LEAF_BIT) as usize;
                    let end = first
                        .saturating_add(c.count as usize)
                        .min(self.triangles.len());
                    out.extend(
                        self.triangles[first.min(end)..end]
                            .iter()
                            .map(|t| t.vertices())
                            .filter(|v| overlaps(&Aabb::from_points(*v))),
                    );
                } else {
                    stack.push(c.child);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;

    #[test]
    fn every_triangle_overlapping_the_box_is_found() {
        let scene = Scene::builtin("blob").unwrap();
        let bvh = Bvh::build(&scene).unwrap();
        let bounds = scene.bounds();
        let (center, reach) = (bounds.center(), 0.2 * bounds.diagonal());
        let query = Aabb {
            min: center - Vec3::splat(reach) + Vec3::new(0.0, 0.0, 0.3 * reach),
            max: center + Vec3::splat(reach),
        };
        let mut near = Vec::new();
        bvh.triangles_near(&query, &mut near);
        let inside: Vec<[Vec3; 3]> = (0..scene.triangle_count())
            .map(|i| scene.triangle(i))
            .filter(|t| {
                let b = Aabb::from_points(*t);
                b.min.cmple(query.max).all() && b.max.cmpge(query.min).all()
            })
            .collect();
        assert!(!inside.is_empty() && near.len() < scene.triangle_count());
        for t in &inside {
            assert!(near.contains(t), "{t:?} missed");
        }
    }
}
