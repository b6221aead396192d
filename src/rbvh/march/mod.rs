//! CPU reference caster of the RBVH, on exactly the packed data the GPU reads ([`super::layout`]).
//! It is the oracle of the GLSL march: every step below is meant to be mirrored line by line.
//!
//! **Tree**: the one traversal of `crate::bvh` (`traverse.rs`), with this module's leaves as its
//! hook (`RbvhLeafHook`): nearest child first, the same tie rule, the same bounded stack, the same
//! robust box test (Ize, "Robust BVH Ray Traversal", JCGT 2013). Every leaf takes an inner node's
//! near-first/stack path and is handled when it comes up — the order the one traversal of
//! `glsl/traverse.glsl` needs to keep its loop lean: a triangle leaf tested with the watertight
//! test of Woop, Benthin & Wald ("Watertight Ray/Triangle Intersection", JCGT 2013), a
//! height-field leaf (Novák & Dachsbacher 2012) marched. The
//! paper (Novák & Dachsbacher, "Rasterized Bounding Volume Hierarchies", Computer Graphics Forum
//! 31(2), Eurographics 2012) gives no detail of the march; this is our reading of it:
//!
//! 1. **Frame**: the ray is moved into the leaf's frame `(s, t, h)`. The map is affine, so the ray
//!    parameter is the same in both spaces and a hit's `t` needs no conversion.
//! 2. **Clip** to the tile's box `s, t ∈ [½, res − ½]`, `h ∈ [0, MAX_CODE·h_scale]`, padded (see
//!    [`super::layout::MARCH_SLACK`], [`super::layout::MARCH_EDGE_PAD`]) so that the box never
//!    decides a hit: the triangles do.
//! 3. **Walk** the cells the ray crosses, front to back, with the 2D DDA of Amanatides & Woo, "A
//!    Fast Voxel Traversal Algorithm for Ray Tracing" (Eurographics 1987), from the cell holding
//!    the entry point. Cell `(i, j)` spans `s ∈ [i + ½, i + 3⁄2]`, `t ∈ [j + ½, j + 3⁄2]`, between
//!    samples `(i, j)` and `(i + 1, j + 1)`. Where the ray passes a grid vertex closer than
//!    rounding can resolve, the cell on the other side of the vertex is tested too; where it
//!    enters (leaves) the tile's box that close to a cell boundary, the walk starts in the cell
//!    behind it (goes on into the cell ahead).
//! 4. **Cell**: its surface is two triangles through the four corner samples (three with one
//!    hole, none with more), tested after a cheap height rejection with the same watertight test
//!    in frame space. Neighbouring cells share their edge's two vertices bit for bit, so no ray
//!    slips between cells. The first cell with a hit ends the march.
//! 5. **Normal**: the stored normal of the corner sample nearest the hit; with height-only texels
//!    ([`super::TexelFormat::Height`]) the normal of the cell triangle hit.
//!
//! Corrupt data never panics and never loops forever: every index goes through `get` (out of range
//! = absent), node visits are capped by the node count, a march by the tile's cell count.
//!
//! ## Files
//! [`leaf`]: one leaf's march as every step sees it (the ray in its frame, its texels);
//! [`walk`]: steps 1–3, the march itself ([`blocks`]: the device's block jumps); [`cell`]: step
//! 4, the cell test; [`skirt`]: the skirts under rims; [`normal`]: step 5, a hit's normal and the
//! device's reads for it; [`hook`]: the leaves in the tree traversal. Here: the caster's entry
//! points and the device twin.

mod blocks;
mod cell;
mod hook;
mod leaf;
mod normal;
mod skirt;
mod walk;

use rayon::prelude::*;

pub(crate) use hook::{trace_instanced, RbvhLeafHook};

use super::ranges::block_ranges;
use super::words::rank_directory;
use super::Rbvh;
use crate::bvh::GpuInstance;
use crate::geom::{Hit, Ray};
use crate::probe::{Probe, TraceStats};

/// How the caster walks a leaf's cells, and what it knows of the device's atlas words beyond
/// the texels, to report the reads the device makes of them.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Walk<'a> {
    /// `None`: every cell the ray crosses, the referee of the device's block jumps, and the twin
    /// of a device that does not jump ([`DeviceTwin::with_block_jumps`]). `Some(ranges)`: as
    /// the device does, on entering an 8×8 block whose height range (`ranges`, as
    /// [`block_ranges`] gives them) the ray passes wholly above or below, straight to the
    /// block's exit cell (`src/rbvh/ranges.rs`). Same hits, fewer cells.
    pub(crate) blocks: Option<&'a [u32]>,
    /// The atlas's rank directory ([`rank_directory`]), where a hit's normal lies among the
    /// device's words: the twin's; empty where no read is reported (`Probe::RECORDS` false).
    pub(crate) ranks: &'a [u32],
}

impl Walk<'_> {
    /// Every cell, no reads reported: the CPU reference.
    pub(crate) const PLAIN: Walk<'static> = Walk {
        blocks: None,
        ranks: &[],
    };
}

/// The device's twin, read for read: traces as `glsl/rbvh.glsl` does, with block jumps (the
/// default) or without ([`DeviceTwin::with_block_jumps`]; pass the tracer's
/// [`crate::gpu::Tracer::block_jumps`], which is off on CPU devices), so that its [`TraceStats`]
/// equal the device's counters ray by ray, and reports to a [`Probe`] every
/// read the shader makes of the structure's arrays, at its byte offset in the device buffers
/// (`src/gpu/tracer.rs` binds them in [`Array`](crate::probe::Array) order; the atlas buffer
/// holds the texels' codes, the block ranges, then the rank directory and the normals:
/// `src/rbvh/words.rs`). Made by [`Rbvh::device_twin`]; with level of detail, `crate::lod::LodTwin`.
pub struct DeviceTwin<'a> {
    rbvh: &'a Rbvh,
    /// The instances of a two-level RBVH (`crate::rbvh::InstancedRbvh`), whose arrays `rbvh`
    /// holds; empty for one RBVH.
    instances: &'a [GpuInstance],
    ranges: Vec<u32>,
    ranks: Vec<u32>,
    block_jumps: bool,
}

impl<'a> DeviceTwin<'a> {
    /// The twin of `rbvh`'s trace, with block jumps on; of a two-level RBVH's where `instances`
    /// are its instances (`rbvh` its arrays).
    pub(crate) fn new(rbvh: &'a Rbvh, instances: &'a [GpuInstance]) -> Self {
        DeviceTwin {
            rbvh,
            instances,
            ranges: block_ranges(&rbvh.atlas),
            ranks: rank_directory(&rbvh.atlas.texels),
            block_jumps: true,
        }
    }

    /// The twin of a device trace with block jumps on (the default) or off
    /// ([`crate::gpu::Tracer::block_jumps`]): off, it walks every cell, as the CPU reference does.
    pub fn with_block_jumps(self, on: bool) -> Self {
        DeviceTwin {
            block_jumps: on,
            ..self
        }
    }

    /// Traces one ray (closest hit, or any hit) as the device does, reporting its reads to
    /// `probe`.
    pub fn trace<P: Probe>(&self, ray: &Ray, any_hit: bool, probe: &mut P) -> (Hit, TraceStats) {
        if !self.instances.is_empty() {
            return trace_instanced(self.rbvh, self.instances, ray, any_hit, self.walk(), probe);
        }
        self.rbvh.traverse_with(
            self.rbvh.leaf_hook(ray, any_hit, self.walk()),
            ray,
            any_hit,
            probe,
        )
    }

    /// The RBVH it traces.
    pub(crate) fn rbvh(&self) -> &'a Rbvh {
        self.rbvh
    }

    /// How it walks a leaf's cells.
    pub(crate) fn walk(&self) -> Walk<'_> {
        Walk {
            blocks: self.block_jumps.then_some(&self.ranges[..]),
            ranks: &self.ranks,
        }
    }
}

impl Rbvh {
    /// Closest hit of one ray, or [`Hit::MISS`]. Invalid rays ([`Ray::is_valid`]) miss.
    ///
    /// The hit `id` tells the two kinds of leaf apart: a triangle-leaf hit reports the scene
    /// triangle index (`prim`, below 2³¹); a height-field hit reports `LEAF_BIT | leaf index`
    /// (bit 31 set; the index is into [`Rbvh::heightfields`]). A height-field hit's normal is the stored
    /// (world-space, dilated, octahedral-quantized) normal of the sample nearest the hit (with
    /// height-only texels, the normal of the cell triangle hit); a triangle's is its geometric
    /// normal as wound.
    pub fn closest_hit(&self, ray: &Ray) -> (Hit, TraceStats) {
        self.traverse(ray, false, Walk::PLAIN, &mut ())
    }

    /// Whether anything is hit in `[tmin, tmax)`: the hit returned is *some* hit, not the closest.
    /// Ids and normals as in [`Rbvh::closest_hit`].
    pub fn any_hit(&self, ray: &Ray) -> (Hit, TraceStats) {
        self.traverse(ray, true, Walk::PLAIN, &mut ())
    }

    /// The device's twin ([`DeviceTwin`]); with level of detail, `Lod::device_twin`.
    pub fn device_twin(&self) -> DeviceTwin<'_> {
        DeviceTwin::new(self, &[])
    }

    /// Traces many rays in parallel with `rayon`; hits in ray order.
    pub fn trace_cpu(&self, rays: &[Ray], any_hit: bool) -> Vec<Hit> {
        rays.par_iter()
            .map(|r| self.traverse(r, any_hit, Walk::PLAIN, &mut ()).0)
            .collect()
    }

    /// Marches height-field leaf `leaf_index` alone over the ray's whole interval: whether a walk
    /// started (the ray crosses the tile's box) and the distance of its hit, if any. What came of
    /// a leaf the traversal handed to the march (`crate::bench::steps`).
    pub(crate) fn march_alone(&self, leaf_index: u32, ray: &Ray) -> (bool, Option<f32>) {
        let mut stats = TraceStats::default();
        let hit = self.march(leaf_index, ray, ray.tmax, Walk::PLAIN, &mut stats, &mut ());
        (stats.counters.walks > 0, hit.map(|(t, _)| t))
    }
}

#[cfg(test)]
pub(super) mod tests {
    use glam::Vec3;

    use super::*;
    use crate::bvh::{ChildRef, GpuNode, GpuTriangle};
    use crate::geom::Aabb;
    use crate::probe::{Array, Read};
    use crate::rbvh::child::Child;
    use crate::rbvh::layout::{Atlas, GpuHeightfield, Texel, LEAF_BIT};
    use crate::rbvh::ExactTriangles;
    use crate::rbvh::{RbvhParams, RbvhStats};

    /// World size of one texel in the test leaves.
    pub(super) const TS: f32 = 0.5;
    pub(super) const MISS_ID: u32 = u32::MAX;

    /// A leaf looking down at the plane `y = y0`: `u = +x`, `v = +z`, `w = +y`, origin
    /// `(-2, y0, -2)`, so sample `(i, j)` is at world `x = -2 + (i + ½)·TS`, `z = -2 + (j + ½)·TS`.
    pub(in crate::rbvh) fn flat_leaf(
        y0: f32,
        res_u: u32,
        res_v: u32,
        h_scale: f32,
    ) -> GpuHeightfield {
        GpuHeightfield {
            origin: [-2.0, y0, -2.0],
            atlas_base: 0,
            axis_u: [1.0 / TS, 0.0, 0.0],
            res_u,
            axis_v: [0.0, 0.0, 1.0 / TS],
            res_v,
            axis_w: [0.0, 1.0, 0.0],
            h_scale,
        }
    }

    /// The world point at frame coordinates `(s, t, h)` (the axes are orthogonal).
    pub(super) fn world(l: &GpuHeightfield, s: f32, t: f32, h: f32) -> Vec3 {
        let (u, v) = (Vec3::from(l.axis_u), Vec3::from(l.axis_v));
        Vec3::from(l.origin)
            + s * u / u.length_squared()
            + t * v / v.length_squared()
            + h * Vec3::from(l.axis_w)
    }

    /// The world box of the leaf's tile box (its eight corners).
    pub(super) fn leaf_box(l: &GpuHeightfield) -> Aabb {
        let (s1, t1) = (l.res_u as f32 - 0.5, l.res_v as f32 - 0.5);
        let h1 = Texel::MAX_CODE as f32 * l.h_scale;
        let mut b = Aabb::EMPTY;
        for s in [0.5, s1] {
            for t in [0.5, t1] {
                for h in [0.0, h1] {
                    b = b.grow(world(l, s, t, h));
                }
            }
        }
        b
    }

    pub(super) fn hf_child(l: &GpuHeightfield, index: u32) -> ChildRef {
        Child::Heightfield(index).with_bounds(leaf_box(l))
    }

    /// A tile of `res_u × res_v` texels (pitch `res_u`) from `f(i, j)`.
    pub(super) fn tile(res_u: u32, res_v: u32, f: impl Fn(u32, u32) -> Texel) -> Vec<Texel> {
        let mut texels = Vec::new();
        for j in 0..res_v {
            for i in 0..res_u {
                texels.push(f(i, j));
            }
        }
        texels
    }

    pub(super) fn rbvh(
        nodes: Vec<GpuNode>,
        triangles: Vec<GpuTriangle>,
        heightfields: Vec<GpuHeightfield>,
        atlas: Atlas,
    ) -> Rbvh {
        Rbvh {
            params: RbvhParams::quality(2).unwrap(),
            nodes,
            triangles: ExactTriangles::new(triangles),
            heightfields,
            atlas,
            bounds: Aabb::EMPTY,
            depth: 1,
            texel_size: TS,
            stats: RbvhStats::default(),
            colours: None,
        }
    }

    /// One height-field leaf under the root, its tile at texel 0 of an atlas of pitch `res_u`.
    pub(super) fn single(l: GpuHeightfield, texels: Vec<Texel>) -> Rbvh {
        let pitch = l.res_u.max(1);
        let atlas = Atlas {
            pitch,
            rows: texels.len() as u32 / pitch,
            packed_rows: [0; 3],
            texels,
        };
        let root = GpuNode::new(hf_child(&l, 0), ChildRef::ABSENT);
        rbvh(vec![root], vec![], vec![l], atlas)
    }

    pub(super) fn flat_plane() -> Rbvh {
        single(
            flat_leaf(1.0, 8, 8, 0.0),
            tile(8, 8, |_, _| Texel::new(0, Vec3::Y)),
        )
    }

    /// A ray straight down onto world `(x, z)` from `y = 10`.
    pub(super) fn down(x: f32, z: f32) -> Ray {
        Ray::new(Vec3::new(x, 10.0, z), -Vec3::Y, 0.0, f32::INFINITY)
    }

    /// A ray with direction `dir` (y = -1) that reaches world `(x, y0, z)` at t = `t`.
    pub(super) fn towards(x: f32, y0: f32, z: f32, dir: Vec3, t: f32) -> Ray {
        Ray::new(Vec3::new(x, y0, z) - t * dir, dir, 0.0, f32::INFINITY)
    }

    pub(super) fn assert_hit(r: &Rbvh, ray: &Ray, t: f32, id: u32) -> Hit {
        let (hit, _) = r.closest_hit(ray);
        assert_eq!(hit.id, id, "{ray:?} → {hit:?}");
        assert!(
            (hit.t - t).abs() <= 1e-5 * t.max(1.0),
            "{ray:?}: t {} expected {t}",
            hit.t
        );
        hit
    }

    pub(super) fn assert_miss(r: &Rbvh, ray: &Ray) {
        let (hit, _) = r.closest_hit(ray);
        assert_eq!(hit, Hit::MISS, "{ray:?}");
        assert_eq!(r.any_hit(ray).0, Hit::MISS, "{ray:?}");
    }

    #[test]
    fn the_device_twin_counts_and_reports_each_read() {
        let r = flat_plane();
        let twin = r.device_twin();
        let mut reads = Vec::new();
        let (hit, stats) = twin.trace(&down(0.3, 0.2), false, &mut reads);
        assert_eq!(hit.id, LEAF_BIT);
        let c = stats.counters;
        assert_eq!(
            (c.nodes, c.leaves, c.walks, c.cells, c.cells_tested, c.jumps),
            (1, 1, 1, 1, 1, 0)
        );
        assert_eq!((c.triangle_leaves, c.triangles), (0, 0));
        // World (0.3, 0.2) is frame (4.6, 4.4): cell (4, 3), texels 28, 29, 36, 37 of the 8 × 8
        // tile, a row's two codes read together (16 bits each, two to a word); the block range
        // word follows the 64 texels' 32 words. Once the ray is done, the hit's normal: that of
        // texel 36, the sample nearest the hit, whose rank (36, no hole before it) is its
        // span's count (word 33, after the range) and its group's byte (word 34) and the codes
        // of texels 32–35 before it in its group; its normal is the low half of word 37 + 18
        // (after the span's three words and the total).
        let read = |array, offset, bytes| Read {
            array,
            offset,
            bytes,
        };
        assert_eq!(
            reads,
            [
                read(Array::Nodes, 0, 48),
                read(Array::Heightfields, 0, 64),
                read(Array::Atlas, 4 * 32, 4),
                read(Array::Atlas, 4 * 14, 8),
                read(Array::Atlas, 4 * 18, 8),
                read(Array::Atlas, 4 * 33, 4),
                read(Array::Atlas, 4 * 34, 4),
                read(Array::Atlas, 4 * 16, 8),
                read(Array::Atlas, 4 * 17, 8),
                read(Array::Atlas, 4 * (37 + 18), 4),
            ]
        );
    }

    /// Root: inner node 1 and a triangle leaf; node 1: height-field leaves 0 (the plane y = 1)
    /// and 1 (the plane y = 1 shifted by +10 in x).
    pub(super) fn hybrid(triangle_y: f32) -> Rbvh {
        let l0 = flat_leaf(1.0, 8, 8, 0.0);
        let mut l1 = flat_leaf(1.0, 8, 8, 0.0);
        l1.atlas_base = 64;
        l1.origin[0] += 10.0;
        let tri = GpuTriangle::new(
            [
                Vec3::new(-1.0, triangle_y, -1.0),
                Vec3::new(1.0, triangle_y, -1.0),
                Vec3::new(-1.0, triangle_y, 1.0),
            ],
            7,
        );
        let tri_leaf =
            Child::Triangles { first: 0, count: 1 }.with_bounds(Aabb::from_points(tri.vertices()));
        let node1 = GpuNode::new(hf_child(&l0, 0), hf_child(&l1, 1));
        let inner = Child::Inner(1).with_bounds(leaf_box(&l0).union(leaf_box(&l1)));
        let root = GpuNode::new(inner, tri_leaf);
        let mut texels = tile(8, 8, |_, _| Texel::new(0, Vec3::Y));
        texels.extend(tile(8, 8, |_, _| Texel::new(0, -Vec3::Y)));
        let atlas = Atlas {
            pitch: 8,
            rows: 16,
            packed_rows: [0; 3],
            texels,
        };
        rbvh(vec![root, node1], vec![tri], vec![l0, l1], atlas)
    }

    #[test]
    fn hybrid_tree_returns_the_nearer_leaf() {
        let r = hybrid(2.0);
        let hit = assert_hit(&r, &down(-0.5, -0.5), 8.0, 7);
        assert!(hit.normal().y.abs() > 0.9999);
        assert_hit(&r, &down(1.5, 1.5), 9.0, LEAF_BIT);
        let hit = assert_hit(&r, &down(10.5, 0.0), 9.0, LEAF_BIT | 1);
        assert!(hit.normal().dot(-Vec3::Y) > 0.9999);
        assert_miss(&r, &down(5.0, 0.0));
        // A triangle below the plane is hidden by it.
        let r = hybrid(0.5);
        assert_hit(&r, &down(-0.5, -0.5), 9.0, LEAF_BIT);
        // Up from between the two: the triangle at 0.5 first.
        let up = Ray::new(Vec3::new(-0.5, -5.0, -0.5), Vec3::Y, 0.0, f32::INFINITY);
        assert_hit(&r, &up, 5.5, 7);
    }

    #[test]
    fn any_hit_finds_a_hit_exactly_where_closest_does() {
        let r = hybrid(2.0);
        for k in 0..40 {
            let x = -3.0 + 0.4 * k as f32;
            let ray = towards(
                x,
                1.0,
                0.3 - 0.01 * k as f32,
                Vec3::new(0.1, -1.0, 0.05),
                9.0,
            );
            let (closest, _) = r.closest_hit(&ray);
            let (any, _) = r.any_hit(&ray);
            assert_eq!(closest.is_hit(), any.is_hit(), "{ray:?}");
            assert!(any.t >= closest.t);
        }
        let rays: Vec<Ray> = (0..30).map(|k| down(-2.0 + 0.5 * k as f32, 0.1)).collect();
        let hits = r.trace_cpu(&rays, false);
        for (ray, hit) in rays.iter().zip(&hits) {
            assert_eq!(*hit, r.closest_hit(ray).0);
        }
    }

    #[test]
    fn corrupt_data_misses_without_panicking() {
        let ray = down(0.0, 0.0);
        let good = flat_plane();
        assert_hit(&good, &ray, 9.0, LEAF_BIT);
        let with_leaf = |f: &dyn Fn(&mut GpuHeightfield)| {
            let mut r = good.clone();
            f(&mut r.heightfields[0]);
            r
        };
        let corrupt = [
            with_leaf(&|l| l.atlas_base = 1_000_000),
            with_leaf(&|l| l.atlas_base = u32::MAX),
            with_leaf(&|l| l.res_u = 0),
            with_leaf(&|l| l.res_v = 1),
            with_leaf(&|l| (l.res_u, l.res_v) = (u32::MAX, u32::MAX)),
            with_leaf(&|l| l.res_v = 9),
            with_leaf(&|l| l.axis_u = [f32::NAN; 3]),
            with_leaf(&|l| l.axis_w = [0.0; 3]),
        ];
        for r in &corrupt {
            let (hit, stats) = r.closest_hit(&ray);
            assert_eq!(hit, Hit::MISS, "{:?}", r.heightfields[0]);
            assert!(!stats.overflow);
        }
        let with_root = |a: ChildRef| {
            let mut r = good.clone();
            r.nodes[0] = GpuNode::new(a, ChildRef::ABSENT);
            r
        };
        let big = ChildRef {
            bounds: good.nodes[0].children()[0].bounds,
            ..ChildRef::ABSENT
        };
        let corrupt = [
            with_root(Child::Heightfield(5).with_bounds(big.bounds)),
            with_root(ChildRef {
                child: 99,
                count: 0,
                ..big
            }),
            with_root(ChildRef {
                child: LEAF_BIT | 3,
                count: u32::MAX - 1,
                ..big
            }),
            with_root(ChildRef {
                child: u32::MAX,
                count: u32::MAX - 1,
                ..big
            }),
        ];
        for r in &corrupt {
            assert_eq!(r.closest_hit(&ray).0, Hit::MISS, "{:?}", r.nodes[0]);
            assert_eq!(r.any_hit(&ray).0, Hit::MISS);
        }
        // A cycle (the root as its own child) ends, flagged.
        let r = with_root(ChildRef {
            child: 0,
            count: 0,
            ..big
        });
        let (hit, stats) = r.closest_hit(&ray);
        assert_eq!(hit.id, MISS_ID);
        assert!(stats.overflow && stats.counters.nodes == 1, "{stats:?}");
        // No nodes at all.
        let mut r = good.clone();
        r.nodes.clear();
        assert_eq!(r.closest_hit(&ray), (Hit::MISS, TraceStats::default()));
    }
}
