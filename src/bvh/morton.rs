//! A linear BVH: the triangles sorted along a Morton curve of their centroids and split where
//! the codes' highest bit differs, so that every node is a cell of the curve's octree (Lauterbach
//! et al., "Fast BVH Construction on GPUs", 2009; the split search of Karras, "Maximizing
//! Parallelism in the Construction of BVHs, Octrees, and k-d Trees", 2012).
//!
//! For builders that need *a* tree of the scene quickly rather than a good one: the RBVH builder
//! samples the ring around each leaf by rays a few texels long ([`crate::rbvh`]'s `raster/ring.rs`),
//! for which node quality matters little, while a median-split [`super::Bvh`] cost a third of the whole
//! RBVH build at the paper's scale (a selection over scattered centroids per level, and a copy of
//! every triangle: 1 GB there). Here one parallel sort does the ordering, each split is a binary
//! search, boxes are merged bottom-up once, and leaves read the scene's own triangles through
//! the sorted order.

use rayon::prelude::*;

use super::build::{check_triangles, free, join_halves, pack, BuildNode, PARALLEL_THRESHOLD};
use super::layout::{ChildRef, GpuNode, LEAF_BIT};
use super::traverse::{traverse_from, Leaves};
use glam::Vec3;

use crate::geom::{intersect_triangle, Aabb, Hit, Ray, RayShear};
use crate::probe::TraceStats;
use crate::scene::Scene;
use crate::Result;

/// Bits per axis of a code (63 in all).
const BITS: u32 = 21;

/// How far, relative to the scene's size (its box's extent plus its largest coordinate), a box
/// must stay from a region for [`LinearBvh::subtree_over`] to take it as missed by every ray
/// within the region: far beyond the few ulps by which the robust box test's distances may err
/// (Ize 2013: relative errors of a few 2^-24 in the coordinates and distances).
const SUBTREE_SLACK: f32 = 1e-4;

/// Depth from which nodes are split at the middle of their range rather than at a bit: equal
/// codes have no bit to split at, and bit splits may peel off one triangle a level (codes 1, 2,
/// 4, …: up to 63 levels). Keeps the depth within `MIDDLE_BELOW_DEPTH + log2(n) < STACK_SIZE`
/// for any input below 2^31 triangles.
const MIDDLE_BELOW_DEPTH: u32 = 32;

/// A linear BVH over a scene's triangles, which it reads in place.
pub(crate) struct LinearBvh<'s> {
    scene: &'s Scene,
    /// Node 0 is the root; leaves index [`LinearBvh::order`].
    nodes: Vec<GpuNode>,
    /// Scene triangle indices in leaf order.
    order: Vec<u32>,
    /// [`SUBTREE_SLACK`] of this scene.
    slack: f32,
}

impl<'s> LinearBvh<'s> {
    /// The linear BVH of `scene`'s triangles with leaves of at most `max_leaf` (at least 1), with
    /// the same checks and errors as [`super::Bvh::build_with`].
    pub(crate) fn build(scene: &'s Scene, max_leaf: usize) -> Result<Self> {
        check_triangles(scene)?;
        // Each triangle's box's centre, read from the scene in place rather than gathered with
        // its box (a copy of 40 bytes a triangle, 0.9 GB at the paper's scale).
        let centroid = |i: usize| Aabb::from_points(scene.triangle(i)).center();
        let count = scene.triangle_count();
        let centroids = (0..count)
            .into_par_iter()
            .map(|i| Aabb::EMPTY.grow(centroid(i)))
            .reduce(|| Aabb::EMPTY, Aabb::union);
        // Codes over the centroids' box; all 0 where it has no extent to scale (one point).
        let scale = ((1u32 << BITS) - 1) as f32 / centroids.extent().max_element();
        let scale = if scale.is_finite() { scale } else { 0.0 };
        let mut keyed: Vec<(u64, u32)> = (0..count)
            .into_par_iter()
            .map(|i| {
                let cell = ((centroid(i) - centroids.min) * scale)
                    .to_array()
                    .map(|x| x as u32);
                (morton(cell), i as u32)
            })
            .collect();
        keyed.par_sort_unstable();
        let codes: Vec<u64> = keyed.par_iter().map(|k| k.0).collect();
        let order: Vec<u32> = keyed.par_iter().map(|k| k.1).collect();
        drop(keyed);
        let builder = Linear {
            scene,
            codes: &codes,
            order: &order,
            max_leaf: max_leaf.max(1),
        };
        let root = (!order.is_empty()).then(|| builder.build(0, order.len(), 0));
        let (nodes, _) = pack(root.as_ref(), "scene")?;
        let bounds = root.as_ref().map_or(Aabb::EMPTY, BuildNode::bounds);
        if let Some(root) = root {
            free(root);
        }
        let size = if bounds.is_empty() {
            0.0
        } else {
            bounds.extent().max_element() + bounds.min.abs().max(bounds.max.abs()).max_element()
        };
        Ok(LinearBvh {
            scene,
            nodes,
            order,
            slack: SUBTREE_SLACK * size,
        })
    }

    /// The inner node from which [`LinearBvh::closest_hit_from`] finds, for any ray whose
    /// segment lies in `region`, what it finds from the root (node 0), in the same steps: down
    /// from the root while one child's box alone comes within the slack of the region and is an
    /// inner node. Every box beside that path is missed by such a ray, so the traversal from the
    /// root reaches the node with nothing pushed. The ring of samples around a leaf is traced by
    /// short rays near it (`raster/ring.rs`), which skip that walk: at the paper's scale it saved
    /// little (docs/paper-scale.md, "Build time at 461a407"), the nodes every ray shares being
    /// those the caches hold.
    pub(crate) fn subtree_over(&self, region: Aabb) -> u32 {
        let region = Aabb {
            min: region.min - self.slack,
            max: region.max + self.slack,
        };
        let near = |c: &ChildRef| {
            !c.is_absent()
                && c.bounds.min.cmple(region.max).all()
                && region.min.cmple(c.bounds.max).all()
        };
        let mut node = 0u32;
        // A tree of n nodes is at most n deep; corrupt data could not loop here either.
        for _ in 0..self.nodes.len() {
            let Some(inner) = self.nodes.get(node as usize) else {
                return 0;
            };
            let [a, b] = inner.children();
            node = match (near(&a), near(&b)) {
                (true, false) if !a.is_leaf() => a.child,
                (false, true) if !b.is_leaf() => b.child,
                _ => return node,
            };
        }
        0
    }

    /// The closest hit of `ray` on a triangle whose unit normal (as wound) `accept`s, its `id`
    /// the scene triangle's index; or [`Hit::MISS`]. Triangles refused are passed through, as
    /// if absent, so a nearer one refused hides nothing behind it. The traversal starts at inner
    /// node `root`: the root (0), or what [`LinearBvh::subtree_over`] gives for a region holding
    /// the ray's segment.
    pub(crate) fn closest_hit_from(
        &self,
        root: u32,
        ray: &Ray,
        accept: impl Fn(Vec3) -> bool,
    ) -> Hit {
        let mut leaves = SceneTriangles {
            bvh: self,
            shear: RayShear::new(ray),
            tmin: ray.tmin,
            accept,
            best: None,
        };
        traverse_from(&self.nodes, root, ray, false, &mut leaves, &mut ());
        leaves.best.map_or(Hit::MISS, |(prim, t)| {
            let [a, b, c] = self.scene.triangle(prim as usize);
            Hit {
                t,
                normal: crate::geom::unit_normal(a, b, c).to_array(),
                id: prim,
                instance: 0,
                reserved: [0; 2],
            }
        })
    }
}

/// The leaf hook of [`LinearBvh`]: the scene's triangles through the leaf order, those whose
/// normal `accept` refuses passed through.
struct SceneTriangles<'b, 's, F> {
    bvh: &'b LinearBvh<'s>,
    shear: RayShear,
    tmin: f32,
    accept: F,
    /// The scene index and distance of the nearest hit so far.
    best: Option<(u32, f32)>,
}

impl<F: Fn(Vec3) -> bool> Leaves<()> for SceneTriangles<'_, '_, F> {
    fn test(
        &mut self,
        reference: u32,
        count: u32,
        t_closest: &mut f32,
        stats: &mut TraceStats,
        _probe: &mut (),
    ) -> bool {
        let order = &self.bvh.order;
        let first = ((reference & !LEAF_BIT) as usize).min(order.len());
        let end = first.saturating_add(count as usize).min(order.len());
        let mut found = false;
        for &prim in &order[first..end] {
            stats.counters.triangles += 1;
            let [a, b, c] = self.bvh.scene.triangle(prim as usize);
            let hit = intersect_triangle(&self.shear, a, b, c, self.tmin, *t_closest);
            let normal = || crate::geom::unit_normal(a, b, c);
            if let Some(t) = hit.filter(|_| (self.accept)(normal())) {
                *t_closest = t;
                self.best = Some((prim, t));
                found = true;
            }
        }
        found
    }
}

/// The 3·[`BITS`]-bit code interleaving `cell`'s coordinates (x in the lowest bit of each
/// triple); coordinates are clamped to [`BITS`] bits.
fn morton(cell: [u32; 3]) -> u64 {
    let spread = |x: u32| {
        let mut x = u64::from(x.min((1 << BITS) - 1));
        x = (x | x << 32) & 0x001f_0000_0000_ffff;
        x = (x | x << 16) & 0x001f_0000_ff00_00ff;
        x = (x | x << 8) & 0x100f_00f0_0f00_f00f;
        x = (x | x << 4) & 0x10c3_0c30_c30c_30c3;
        (x | x << 2) & 0x1249_2492_4924_9249
    };
    spread(cell[0]) | spread(cell[1]) << 1 | spread(cell[2]) << 2
}

struct Linear<'a> {
    scene: &'a Scene,
    /// Sorted codes, `order[k]`'s at `k`.
    codes: &'a [u64],
    order: &'a [u32],
    max_leaf: usize,
}

impl Linear<'_> {
    /// The subtree over the sorted range `lo..hi` (non-empty).
    fn build(&self, lo: usize, hi: usize, depth: u32) -> BuildNode {
        let n = hi - lo;
        if n <= self.max_leaf {
            let bounds = self.order[lo..hi].iter().fold(Aabb::EMPTY, |b, &i| {
                b.union(Aabb::from_points(self.scene.triangle(i as usize)))
            });
            return BuildNode::Leaf {
                bounds,
                start: lo as u32,
                count: n as u32,
            };
        }
        let (first, last) = (self.codes[lo], self.codes[hi - 1]);
        let mid = if depth < MIDDLE_BELOW_DEPTH && first != last {
            // The codes share every bit above the highest that differs between the range's ends;
            // those with it clear come first.
            let bit = 63 - (first ^ last).leading_zeros();
            lo + self.codes[lo..hi].partition_point(|&c| c >> bit & 1 == 0)
        } else {
            lo + n / 2
        };
        let (a, b) = join_halves(
            n >= PARALLEL_THRESHOLD,
            || self.build(lo, mid, depth + 1),
            || self.build(mid, hi, depth + 1),
        );
        BuildNode::inner(a.bounds().union(b.bounds()), a, b)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Bvh;

    #[test]
    fn codes_interleave_the_axes_from_x_up() {
        assert_eq!(morton([1, 0, 0]), 0b001);
        assert_eq!(morton([0, 1, 0]), 0b010);
        assert_eq!(morton([0, 0, 1]), 0b100);
        assert_eq!(morton([3, 0, 1]), 0b001_101);
        let top = (1 << BITS) - 1;
        assert_eq!(morton([top, top, top]), (1u64 << 63) - 1);
        assert_eq!(morton([u32::MAX, 0, 0]), morton([top, 0, 0]));
    }

    #[test]
    fn the_linear_bvh_finds_what_the_sah_bvh_finds() {
        let scene = Scene::builtin("default").expect("built-in scene");
        let linear = LinearBvh::build(&scene, 4).expect("builds");
        let sah = Bvh::build(&scene).expect("builds");
        let mut order = linear.order.clone();
        order.sort_unstable();
        assert!(order.iter().copied().eq(0..scene.triangle_count() as u32));
        let rays = scene.camera_or_framed(1.0).primary_rays(64, 64);
        let mut hits = 0;
        for ray in &rays {
            let a = linear.closest_hit_from(0, ray, |_| true);
            let (b, _) = sah.closest_hit(ray);
            assert_eq!(a.is_hit(), b.is_hit());
            if a.is_hit() {
                hits += 1;
                assert_eq!(a.t, b.t);
                assert_eq!(a.normal, b.normal);
            }
        }
        assert!(hits > rays.len() / 8, "{hits} of {} rays hit", rays.len());
    }

    #[test]
    fn rays_within_a_region_find_from_its_subtree_what_they_find_from_the_root() {
        let scene = Scene::builtin("default").expect("built-in scene");
        let linear = LinearBvh::build(&scene, 4).expect("builds");
        let size = scene.bounds().extent().max_element();
        let mut rng = crate::random::SplitMix64::new(11);
        let mut unit = || Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
        let (mut below_root, mut hits, mut rays) = (0, 0, 0);
        for r in 0..300 {
            // Regions about a point of the surface, from a hundredth of the scene to a tenth.
            let [a, b, c] = scene.triangle(r * 7919 % scene.triangle_count());
            let centre = (a + b + c) / 3.0;
            let half = size * (0.005 + 0.05 * unit().x);
            let region = Aabb {
                min: centre - half,
                max: centre + half,
            };
            let root = linear.subtree_over(region);
            below_root += usize::from(root != 0);
            for _ in 0..20 {
                let from = region.min + unit() * 2.0 * half;
                let to = region.min + unit() * 2.0 * half;
                let ray = Ray::new(from, to - from, 0.0, 1.0);
                let facing = |n: Vec3| n.z.abs() > 0.2;
                for accept in [&(|_: Vec3| true) as &dyn Fn(Vec3) -> bool, &facing] {
                    let whole = linear.closest_hit_from(0, &ray, accept);
                    let part = linear.closest_hit_from(root, &ray, accept);
                    assert_eq!(
                        (whole.t.to_bits(), whole.normal, whole.id),
                        (part.t.to_bits(), part.normal, part.id),
                        "{ray:?} from node {root}"
                    );
                    hits += usize::from(whole.is_hit());
                    rays += 1;
                }
            }
        }
        assert!(
            below_root > 250,
            "{below_root} of 300 regions below the root"
        );
        assert!(hits > rays / 4, "{hits} of {rays} rays hit");
    }

    #[test]
    fn equal_centroids_split_at_the_middle_within_the_stack() {
        let mut scene = Scene::new("stack");
        let triangles = vec![[0, 1, 2]; 5000];
        scene.push_object(
            "one triangle, many times",
            &[Vec3::ZERO, Vec3::X, Vec3::Y],
            &triangles,
        );
        let bvh = LinearBvh::build(&scene, 1).expect("builds");
        assert_eq!(bvh.order.len(), 5000);
        // Middle splits all the way (depth 13, which `pack` checks against the stack).
        assert_eq!(
            bvh.nodes.len(),
            4999,
            "a binary tree over 5000 leaves of one"
        );
        let down = Ray::new(Vec3::new(0.25, 0.25, 1.0), Vec3::NEG_Z, 0.0, f32::INFINITY);
        let hit = bvh.closest_hit_from(0, &down, |_| true);
        assert_eq!((hit.t, hit.normal), (1.0, [0.0, 0.0, 1.0]));
        // Refused triangles are passed through: all 5000 here.
        assert!(!bvh.closest_hit_from(0, &down, |n| n.z < 0.0).is_hit());
    }
}
