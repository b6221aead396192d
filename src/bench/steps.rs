//! Where a ray's steps go (issue "A tree that earns its leaves", item 1): the CPU twin of a
//! method traces the rays again, its reads ([`crate::probe::Read`]) telling which nodes it
//! visited and which height-field leaves it handed to the march, and each of those leaves is
//! marched once more on its own to say what came of it:
//!
//! * **tile missed**: the ray entered the leaf's box in the tree but not its tile's box (the box
//!   of the tile's frame, which a tilted tile's axis-aligned box holds loosely);
//! * **no surface**: it crossed the tile's box and met no cell's surface;
//! * **behind**: it met the leaf's surface behind the nearest hit: entered because the leaf's box
//!   reached in front of that hit (boxes that overlap, or a near-first order that guessed wrong);
//! * **nearest**: the leaf holding the nearest hit.
//!
//! With the nodes visited per ray at each depth of the tree, and the leaf boxes that hold a hit's
//! point (1 where leaf boxes do not overlap there), these say whether a tree's steps go to depth
//! (too many nodes above the leaves), to loose leaf boxes, or to overlap. The exact BVH is
//! counted alike: its nodes by depth and its leaf boxes at the hit.

use glam::Vec3;
use rayon::prelude::*;
use serde::Serialize;

use crate::bvh::{Bvh, GpuNode};
use crate::geom::{Hit, Ray};
use crate::probe::{Array, Read};
use crate::rbvh::{GpuHeightfield, Rbvh};

/// Tree levels per depth band of [`StepsRecord::nodes_by_depth`].
pub const DEPTH_BAND: usize = 8;

/// Depth bands of [`StepsRecord::nodes_by_depth`]: levels 0–7, 8–15, 16–23, 24–31 and 32 on.
pub const DEPTH_BANDS: usize = 5;

/// Where one method's steps went on one ray type, per ray (means over the rays).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct StepsRecord {
    /// Inner nodes visited per ray by depth, in bands of [`DEPTH_BAND`] levels (the root is
    /// level 0; the last band holds every level from 32 on).
    pub nodes_by_depth: [f64; DEPTH_BANDS],
    /// Mean depth of a visited inner node.
    pub node_depth_mean: f64,
    /// Height-field leaves handed to the march whose tile box the ray missed.
    pub leaves_tile_missed: f64,
    /// Leaves whose tile box the ray crossed without meeting the surface.
    pub leaves_no_surface: f64,
    /// Leaves whose surface the ray met behind the nearest hit.
    pub leaves_behind: f64,
    /// Leaves that held the nearest hit (at most one a ray, but for ties).
    pub leaves_nearest: f64,
    /// Leaf boxes (height fields and triangle leaves alike) that hold a hit's point, over the
    /// rays that hit: 1 where the leaves' boxes do not overlap there.
    pub boxes_at_hit: f64,
}

/// What one ray's reads and hit tell, before averaging.
#[derive(Clone, Copy, Default)]
struct RaySteps {
    nodes_by_depth: [u32; DEPTH_BANDS],
    depth_sum: u64,
    nodes: u32,
    leaves: [u32; 4],
    boxes_at_hit: Option<u32>,
}

/// The steps of the exact BVH `bvh` on `rays` (closest hits, or any hits).
pub fn exact_steps(bvh: &Bvh, rays: &[Ray], any_hit: bool) -> StepsRecord {
    let depth = node_depths(&bvh.nodes);
    let per_ray: Vec<RaySteps> = rays
        .par_iter()
        .map(|ray| {
            let mut reads = Vec::new();
            let (hit, _) = bvh.trace_probed(ray, any_hit, &mut reads);
            ray_steps(&bvh.nodes, &depth, &reads, ray, &hit, |_| None)
        })
        .collect();
    mean(&per_ray)
}

/// The steps of `rbvh` on `rays`, traced by its device twin with block jumps on or off as the
/// device traced them (the same leaves either way).
pub fn rbvh_steps(rbvh: &Rbvh, rays: &[Ray], any_hit: bool, block_jumps: bool) -> StepsRecord {
    let depth = node_depths(&rbvh.nodes);
    let twin = rbvh.device_twin().with_block_jumps(block_jumps);
    let per_ray: Vec<RaySteps> = rays
        .par_iter()
        .map(|ray| {
            let mut reads = Vec::new();
            let (hit, _) = twin.trace(ray, any_hit, &mut reads);
            ray_steps(&rbvh.nodes, &depth, &reads, ray, &hit, |leaf| {
                Some(rbvh.march_alone(leaf, ray))
            })
        })
        .collect();
    mean(&per_ray)
}

/// One ray's steps from its `reads` and its `hit`; `march(leaf)` marches a height-field leaf
/// alone (whether a walk started, and its hit distance).
fn ray_steps(
    nodes: &[GpuNode],
    depth: &[u32],
    reads: &[Read],
    ray: &Ray,
    hit: &Hit,
    march: impl Fn(u32) -> Option<(bool, Option<f32>)>,
) -> RaySteps {
    let mut out = RaySteps::default();
    let leaf_size = std::mem::size_of::<GpuHeightfield>() as u64;
    let node_size = std::mem::size_of::<GpuNode>() as u64;
    for read in reads {
        match read.array {
            // A node visit reads the whole node; a leaf popped off the stack reads its child and
            // count from its parent again, which is no visit.
            Array::Nodes if u64::from(read.bytes) == node_size => {
                let d = depth[(read.offset / node_size) as usize];
                out.nodes_by_depth[(d as usize / DEPTH_BAND).min(DEPTH_BANDS - 1)] += 1;
                out.depth_sum += u64::from(d);
                out.nodes += 1;
            }
            // A march reads its leaf's whole record; a height-only hit's facet reads parts of it
            // again once the ray is done, which is no march.
            Array::Heightfields if u64::from(read.bytes) == leaf_size => {
                let leaf = (read.offset / leaf_size) as u32;
                let Some((walked, t)) = march(leaf) else {
                    continue;
                };
                let kind = match t {
                    _ if !walked => 0,
                    None => 1,
                    Some(t) if hit.is_hit() && t > hit.t => 2,
                    Some(_) => 3,
                };
                out.leaves[kind] += 1;
            }
            _ => {}
        }
    }
    if hit.is_hit() {
        out.boxes_at_hit = Some(leaf_boxes_holding(nodes, ray.origin() + ray.dir() * hit.t));
    }
    out
}

/// The means over rays of their steps.
fn mean(per_ray: &[RaySteps]) -> StepsRecord {
    let n = per_ray.len().max(1) as f64;
    let sum = |f: &dyn Fn(&RaySteps) -> f64| per_ray.iter().map(f).sum::<f64>();
    let nodes = sum(&|r| f64::from(r.nodes));
    let hits = per_ray.iter().filter(|r| r.boxes_at_hit.is_some()).count();
    StepsRecord {
        nodes_by_depth: std::array::from_fn(|b| sum(&|r| f64::from(r.nodes_by_depth[b])) / n),
        node_depth_mean: if nodes > 0.0 {
            sum(&|r| r.depth_sum as f64) / nodes
        } else {
            0.0
        },
        leaves_tile_missed: sum(&|r| f64::from(r.leaves[0])) / n,
        leaves_no_surface: sum(&|r| f64::from(r.leaves[1])) / n,
        leaves_behind: sum(&|r| f64::from(r.leaves[2])) / n,
        leaves_nearest: sum(&|r| f64::from(r.leaves[3])) / n,
        boxes_at_hit: if hits > 0 {
            sum(&|r| f64::from(r.boxes_at_hit.unwrap_or(0))) / hits as f64
        } else {
            0.0
        },
    }
}

/// Each node's depth (the root, node 0, at 0). Nodes are packed depth-first, so a parent comes
/// before its children.
fn node_depths(nodes: &[GpuNode]) -> Vec<u32> {
    let mut depth = vec![0u32; nodes.len()];
    for (i, node) in nodes.iter().enumerate() {
        let below = depth[i] + 1;
        for c in node.children() {
            if !c.is_leaf() {
                if let Some(d) = depth.get_mut(c.child as usize) {
                    *d = below;
                }
            }
        }
    }
    depth
}

/// How many leaves' boxes (as the nodes decode them) hold the point `p`.
fn leaf_boxes_holding(nodes: &[GpuNode], p: Vec3) -> u32 {
    let mut stack = vec![0u32];
    let mut count = 0;
    // Bounded by the node count: each node is pushed at most once in a tree.
    let mut visits = 0;
    while let Some(index) = stack.pop() {
        visits += 1;
        let Some(node) = nodes.get(index as usize).filter(|_| visits <= nodes.len()) else {
            continue;
        };
        for c in node.children() {
            if c.is_absent() || !c.bounds.contains(p) {
                continue;
            }
            if c.is_leaf() {
                count += 1;
            } else {
                stack.push(c.child);
            }
        }
    }
    count
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bvh::ChildRef;
    use crate::geom::Aabb;
    use crate::rbvh::Child;

    fn leaf(min: [f32; 3], max: [f32; 3], first: u32) -> ChildRef {
        Child::Triangles { first, count: 1 }.with_bounds(Aabb {
            min: Vec3::from(min),
            max: Vec3::from(max),
        })
    }

    #[test]
    fn depths_and_overlapping_boxes_are_counted() {
        // Root: an inner node over two overlapping leaves, and a third leaf apart.
        let (a, b, c) = (
            leaf([0.0; 3], [2.0; 3], 0),
            leaf([1.0; 3], [3.0; 3], 1),
            leaf([5.0; 3], [6.0; 3], 2),
        );
        let inner = GpuNode::new(a, b);
        let root = GpuNode::new(
            ChildRef {
                bounds: a.bounds.union(b.bounds),
                child: 1,
                count: 0,
            },
            c,
        );
        let nodes = [root, inner];
        assert_eq!(node_depths(&nodes), [0, 1]);
        assert_eq!(leaf_boxes_holding(&nodes, Vec3::splat(1.5)), 2);
        assert_eq!(leaf_boxes_holding(&nodes, Vec3::splat(0.5)), 1);
        assert_eq!(leaf_boxes_holding(&nodes, Vec3::splat(5.5)), 1);
        assert_eq!(leaf_boxes_holding(&nodes, Vec3::splat(4.0)), 0);
    }

    #[test]
    fn a_ray_through_the_sphere_hands_its_leaves_over_for_a_reason() {
        let scene = crate::scene::Scene::builtin("sphere").unwrap();
        let rbvh = Rbvh::build(&scene, &crate::rbvh::RbvhParams::quality(0).unwrap()).unwrap();
        let bvh = Bvh::build(&scene).unwrap();
        let camera = scene.camera_or_framed(1.0).primary_rays(32, 32);
        let r = rbvh_steps(&rbvh, &camera, false, false);
        let e = exact_steps(&bvh, &camera, false);
        // Every leaf handed over is accounted for, and the ones that hit are at most one a ray.
        let device: f64 = camera
            .iter()
            .map(|ray| f64::from(rbvh.closest_hit(ray).1.counters.leaves))
            .sum::<f64>()
            / camera.len() as f64;
        let accounted =
            r.leaves_tile_missed + r.leaves_no_surface + r.leaves_behind + r.leaves_nearest;
        assert!((accounted - device).abs() < 1e-9, "{accounted} vs {device}");
        assert!(r.leaves_nearest > 0.0 && r.leaves_nearest <= 1.0, "{r:?}");
        // Every node visit is in a depth band, and nothing else is (a leaf popped off the stack
        // reads its parent again, which is no visit).
        let mean_nodes = |counts: Vec<u32>| {
            counts.iter().map(|&n| f64::from(n)).sum::<f64>() / camera.len() as f64
        };
        let rbvh_nodes = mean_nodes(
            camera
                .iter()
                .map(|ray| rbvh.closest_hit(ray).1.counters.nodes)
                .collect(),
        );
        let exact_nodes = mean_nodes(
            camera
                .iter()
                .map(|ray| bvh.closest_hit(ray).1.counters.nodes)
                .collect(),
        );
        let nodes: f64 = r.nodes_by_depth.iter().sum();
        assert!(nodes > 0.0 && r.node_depth_mean >= 0.0, "{r:?}");
        assert!((nodes - rbvh_nodes).abs() < 1e-9, "{nodes} vs {rbvh_nodes}");
        let exact: f64 = e.nodes_by_depth.iter().sum();
        assert!(
            (exact - exact_nodes).abs() < 1e-9,
            "{exact} vs {exact_nodes}"
        );
        // A hit's point lies in its own leaf's box, at least.
        assert!(
            r.boxes_at_hit >= 1.0 && e.boxes_at_hit >= 1.0,
            "{r:?} {e:?}"
        );
        assert_eq!(e.leaves_nearest, 0.0);
    }
}
