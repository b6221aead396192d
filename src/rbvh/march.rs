//! CPU reference caster of the RBVH, on exactly the packed data the GPU reads ([`super::layout`]).
//! It is the oracle of the GLSL march: every step below is meant to be mirrored line by line.
//!
//! **Tree**: the one traversal of `crate::bvh` (`traverse.rs`), with this module's leaves as its
//! hook (`RbvhLeaves`): nearest child first, the same tie rule, the same bounded stack, the same
//! robust box test (Ize, "Robust BVH Ray Traversal", JCGT 2013). A triangle-leaf child is tested in place with the watertight test of
//! Woop, Benthin & Wald ("Watertight Ray/Triangle Intersection", JCGT 2013); a height-field leaf
//! (Novák & Dachsbacher 2012) takes an inner node's near-first/stack path and is marched when it
//! comes up — the order the one traversal of `glsl/traverse.glsl` needs to keep its loop lean. The
//! paper (Novák & Dachsbacher, "Rasterized Bounding Volume Hierarchies", Computer Graphics Forum
//! 31(2), Eurographics 2012) gives no detail of the march; this is our reading of it:
//!
//! 1. **Frame**: the ray is moved into the leaf's frame `(s, t, h)`. The map is affine, so the ray
//!    parameter is the same in both spaces and a hit's `t` needs no conversion.
//! 2. **Clip** to the tile's box `s, t ∈ [½, res − ½]`, `h ∈ [0, MAX_CODE·h_scale]`, padded (see
//!    [`SLACK`], [`EDGE_PAD`]) so that the box never decides a hit: the triangles do.
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

use glam::Vec3;
use rayon::prelude::*;

use super::layout::{
    Atlas, GpuHeightfield, Texel, HEIGHTFIELD_COUNT, LEAF_BIT,
    MARCH_DIAGONAL_SKIRT_TEXELS as DIAGONAL_SKIRT_TEXELS, MARCH_EDGE_PAD as EDGE_PAD,
    MARCH_SKIRT_TEXELS as SKIRT_TEXELS, MARCH_SLACK as SLACK,
};
use super::ranges::{block_ranges, BLOCK};
use super::{Rbvh, TexelFormat};
use crate::bvh::{Leaves, Triangles};
use crate::geom::grid::{height_at, step_of, Grid, GridWalk};
use crate::geom::{intersect_triangle, safe_inverse, Aabb, Hit, Ray, RayShear};
use crate::probe::{element, Array, Probe, Read, TraceStats};

/// The cells the walk steps through: between the tile's samples.
const CELLS: Grid = Grid::BETWEEN_SAMPLES;

/// How the caster walks a leaf's cells.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Walk<'a> {
    /// Every cell the ray crosses: the referee of the device's block jumps, and the twin of a
    /// device that does not jump ([`DeviceTwin::with_block_jumps`]).
    Plain,
    /// As the device does: on entering an 8×8 block whose height range (`ranges`, as
    /// [`block_ranges`] gives them) the ray passes wholly above or below, straight to the block's
    /// exit cell (`src/rbvh/ranges.rs`). Same hits, fewer cells.
    Blocks(&'a [u32]),
}

/// The device's twin, read for read: traces as `glsl/rbvh.glsl` does, with block jumps (the
/// default) or without ([`DeviceTwin::with_block_jumps`]; pass the tracer's
/// [`crate::gpu::Tracer::block_jumps`], which is off on CPU devices), so that its [`TraceStats`]
/// equal the device's counters ray by ray, and reports to a [`Probe`] every
/// read the shader makes of the structure's arrays, at its byte offset in the device buffers
/// (`src/gpu/tracer.rs` binds them in [`Array`] order; the atlas buffer holds the texels, then the
/// block ranges). Made by [`Rbvh::device_twin`]; with level of detail, `crate::lod::LodTwin`.
pub struct DeviceTwin<'a> {
    rbvh: &'a Rbvh,
    ranges: Vec<u32>,
    block_jumps: bool,
}

impl<'a> DeviceTwin<'a> {
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
        if self.block_jumps {
            Walk::Blocks(&self.ranges)
        } else {
            Walk::Plain
        }
    }
}

/// An RBVH's leaves for the shared traversal (`crate::bvh::traverse`): hybrid triangle leaves
/// tested exactly, height fields marched. Level of detail wraps it (`crate::lod`'s `LodLeaves`),
/// recording the hits of the coarse nodes it marches here ([`RbvhLeaves::record`]).
pub(crate) struct RbvhLeaves<'a> {
    rbvh: &'a Rbvh,
    ray: &'a Ray,
    /// The hybrid triangle leaves, tested as the exact BVH tests its own.
    triangles: Triangles<'a>,
    walk: Walk<'a>,
    /// The nearest hit on a height field (or a coarse node): the best unless a triangle's is
    /// nearer.
    best: Hit,
    /// Whether the triangles' hit is the nearest.
    triangle_nearest: bool,
    /// The texels the device reads for `best`'s normal once the ray is done.
    normal_reads: NormalReads,
}

impl<'a> RbvhLeaves<'a> {
    /// The ray traced.
    pub(crate) fn ray(&self) -> &'a Ray {
        self.ray
    }

    /// Keeps a hit at `t` with `normal` and `id` found by a hook around these leaves.
    pub(crate) fn record(&mut self, t: f32, normal: Vec3, id: u32) {
        self.best = Hit {
            t,
            normal: normal.to_array(),
            id,
            reserved: [0; 3],
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
                probe.read(
                    self.rbvh
                        .atlas
                        .code_read(texel as usize, TexelFormat::Height),
                );
            }
        } else {
            for texel in self.normal_reads.iter() {
                for read in self.rbvh.atlas.normal_reads(texel as usize) {
                    probe.read(read);
                }
            }
        }
        self.best
    }
}

impl<P: Probe> Leaves<P> for RbvhLeaves<'_> {
    fn test(
        &mut self,
        node: u32,
        count: u32,
        t_closest: &mut f32,
        stats: &mut TraceStats,
        probe: &mut P,
    ) -> bool {
        let (ray, rbvh) = (self.ray, self.rbvh);
        if count != HEIGHTFIELD_COUNT {
            // A triangle leaf (hybrid RBVH): tested exactly.
            let found = self.triangles.test(node, count, t_closest, stats, probe);
            self.triangle_nearest |= found;
            return found;
        }
        // A height-field leaf that came up from the near-first order or the stack.
        stats.counters.leaves += 1;
        let Some((t, normal)) =
            rbvh.march(node & !LEAF_BIT, ray, *t_closest, self.walk, stats, probe)
        else {
            return false;
        };
        *t_closest = t;
        self.record(t, normal.normal, node);
        self.normal_reads = normal.reads;
        true
    }
}

impl Rbvh {
    /// Closest hit of one ray, or [`Hit::MISS`]. Invalid rays ([`Ray::is_valid`]) miss.
    ///
    /// The hit `id` tells the two kinds of leaf apart: a triangle-leaf hit reports the scene
    /// triangle index (`prim`, below 2³¹); a height-field hit reports `LEAF_BIT | leaf index`
    /// (bit 31 set; the index is into [`Rbvh::leaves`]). A height-field hit's normal is the stored
    /// (world-space, dilated, octahedral-quantized) normal of the sample nearest the hit (with
    /// height-only texels, the normal of the cell triangle hit); a triangle's is its geometric
    /// normal as wound.
    pub fn closest_hit(&self, ray: &Ray) -> (Hit, TraceStats) {
        self.traverse(ray, false, Walk::Plain, &mut ())
    }

    /// Whether anything is hit in `[tmin, tmax)`: the hit returned is *some* hit, not the closest.
    /// Ids and normals as in [`Rbvh::closest_hit`].
    pub fn any_hit(&self, ray: &Ray) -> (Hit, TraceStats) {
        self.traverse(ray, true, Walk::Plain, &mut ())
    }

    /// The device's twin ([`DeviceTwin`]); with level of detail, `Lod::device_twin`.
    pub fn device_twin(&self) -> DeviceTwin<'_> {
        DeviceTwin {
            rbvh: self,
            ranges: block_ranges(&self.atlas),
            block_jumps: true,
        }
    }

    /// Traces many rays in parallel with `rayon`; hits in ray order.
    pub fn trace_cpu(&self, rays: &[Ray], any_hit: bool) -> Vec<Hit> {
        rays.par_iter()
            .map(|r| self.traverse(r, any_hit, Walk::Plain, &mut ()).0)
            .collect()
    }

    fn traverse<P: Probe>(
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
        ray: &'a Ray,
        any_hit: bool,
        walk: Walk<'a>,
    ) -> RbvhLeaves<'a> {
        RbvhLeaves {
            rbvh: self,
            ray,
            triangles: Triangles::new(&self.triangles, ray, any_hit),
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
        L: Leaves<P> + Into<RbvhLeaves<'a>>,
    {
        let stats = crate::bvh::traverse(&self.nodes, ray, any_hit, &mut leaves, probe);
        (leaves.into().finish(probe), stats)
    }

    /// Marches height-field leaf `leaf_index` alone over the ray's whole interval: whether a walk
    /// started (the ray crosses the tile's box) and the distance of its hit, if any. What came of
    /// a leaf the traversal handed to the march (`crate::bench::steps`).
    pub(crate) fn march_alone(&self, leaf_index: u32, ray: &Ray) -> (bool, Option<f32>) {
        let mut stats = TraceStats::default();
        let hit = self.march(leaf_index, ray, ray.tmax, Walk::Plain, &mut stats, &mut ());
        (stats.counters.walks > 0, hit.map(|(t, _)| t))
    }

    /// Marches height-field leaf `leaf_index` for the ray's interval `[tmin, t_closest)`; returns
    /// the hit distance and the world-space normal. Steps as numbered in the module docs; with
    /// [`Walk::Blocks`], the block jumps of `glsl/rbvh.glsl`'s `rbvh_march`, statement for
    /// statement.
    fn march<P: Probe>(
        &self,
        leaf_index: u32,
        ray: &Ray,
        t_closest: f32,
        walk: Walk,
        stats: &mut TraceStats,
        probe: &mut P,
    ) -> Option<(f32, HitNormal)> {
        let leaf = self.leaves.get(leaf_index as usize)?;
        probe.read(element::<GpuHeightfield>(
            Array::Leaves,
            leaf_index as usize,
        ));
        // A tile needs two samples along each side to have a cell at all.
        if leaf.res_u < 2 || leaf.res_v < 2 || !tile_fits(leaf, &self.atlas) {
            return None;
        }
        // 1. Frame.
        let (u, v, w) = (
            Vec3::from(leaf.axis_u),
            Vec3::from(leaf.axis_v),
            Vec3::from(leaf.axis_w),
        );
        let rel = ray.origin() - Vec3::from(leaf.origin);
        let d = ray.dir();
        let frame = Ray::new(
            Vec3::new(rel.dot(u), rel.dot(v), rel.dot(w)),
            Vec3::new(d.dot(u), d.dot(v), d.dot(w)),
            ray.tmin,
            t_closest,
        );
        // Degenerate or non-finite axes (corrupt data) give a ray no test can answer.
        if !frame.is_valid() {
            return None;
        }
        let o = frame.origin();
        let d = frame.dir();
        let inv = safe_inverse(d);
        // 2. Clip to the tile's box, padded in height by `slack`: a flat tile (h_scale 0) would
        // otherwise have a box of zero height, whose entry point *is* the hit, and rounding in
        // that point could start the walk in the neighbour of the cell whose triangle reports
        // the hit. Padded along s and t by EDGE_PAD.
        let h_top = Texel::MAX_CODE as f32 * leaf.h_scale;
        let slack = SLACK * (o.z.abs() + h_top.abs()) + leaf.h_scale.abs();
        let tile = Aabb {
            min: Vec3::new(0.5 - EDGE_PAD, 0.5 - EDGE_PAD, -slack),
            max: Vec3::new(
                leaf.res_u as f32 - 0.5 + EDGE_PAD,
                leaf.res_v as f32 - 0.5 + EDGE_PAD,
                h_top + slack,
            ),
        };
        let t0 = tile.intersect(o, inv, frame.tmin, frame.tmax)?;
        stats.counters.walks += 1;
        let t1 = box_exit(&tile, o, inv).min(frame.tmax);
        let fr = FrameRay {
            shear: RayShear::new(&frame),
            ray: frame,
            slack,
        };
        let cells = Cells {
            atlas: &self.atlas,
            leaf,
            leaf_index,
            fr: &fr,
            dir: ray.dir(),
            format: self.params.texels,
            uu: Vec3::from(leaf.axis_u).length_squared(),
        };
        // The edge (its axis: 0 for s, 1 for t) the current cell was entered across, for the
        // skirt: the first cell's when the ray enters the tile's box through its s or t side, not
        // through its top or bottom nor from inside it.
        let near = ((tile.min - o) * inv).min((tile.max - o) * inv);
        let skirt_h = 1.001 * SKIRT_TEXELS / cells.uu.sqrt();
        let mut entered = if t0 <= frame.tmin {
            None
        } else if t0 == near.x {
            Some(0)
        } else if t0 == near.y {
            Some(1)
        } else {
            None
        };

        // 3. Walk. The start cell is the one holding the entry point, clamped so that the padding
        // and rounding at the tile's border cannot put it outside.
        let last_i = i64::from(leaf.res_u) - 2;
        let last_j = i64::from(leaf.res_v) - 2;
        let entry = o + d * t0;
        let step_i = step_of(d.x);
        let step_j = step_of(d.y);
        // Where the ray passes a grid vertex closer than rounding can resolve, the walk goes
        // round it on one side while the watertight test may report the hit in the cell on the
        // other side; that cell is then tested too. `corner_slack` bounds, in texels, the
        // rounding of the frame coordinates the two tests work on.
        let corner_slack = SLACK * (o.x.abs() + o.y.abs() + leaf.res_u as f32 + leaf.res_v as f32);
        // The same rounding at the walk's ends: a flat tile's box is a slab thinner than it,
        // tens of texels from the origin, so where the entry lies that close to a boundary
        // behind it the walk starts in the cell behind (and where the box's exit lies that close
        // to the boundary ahead, it goes on into the cell there, below), lest the watertight test
        // report the hit in a cell the walk skipped (the default scene's ground: three in four
        // of the rays aimed at its leaves' rims that passed through).
        let start = |entry: f32, step: i64, last: i64, o: f32, inv: f32, d: f32| {
            let c = CELLS.cell_of(entry, last);
            let back = c - step;
            let behind = step != 0
                && (0..=last).contains(&back)
                && (t0 - CELLS.boundary_t(back, step, o, inv)) * d.abs() <= corner_slack;
            if behind {
                back
            } else {
                c
            }
        };
        let start_cell = (
            start(entry.x, step_i, last_i, o.x, inv.x, d.x),
            start(entry.y, step_j, last_j, o.y, inv.y, d.y),
        );
        let (step, last, o2, inv2) = (
            (step_i, step_j),
            (last_i, last_j),
            (o.x, o.y),
            (inv.x, inv.y),
        );
        let mut w = GridWalk::new(CELLS, start_cell, step, o2, inv2, t0);
        // A straight line crosses each of the (res − 2) inner boundaries per axis at most once, so
        // it takes at most this many steps, each visiting one cell (two near a grid vertex).
        let max_steps = u64::from(leaf.res_u - 1) + u64::from(leaf.res_v - 1) - 1;
        let blocks = match walk {
            Walk::Plain => None,
            Walk::Blocks(ranges) => Some(Blocks::of(&self.atlas, leaf, ranges)),
        };
        let mut checked_block = None;
        // Whether the last main cell walked had fewer than four samples, or there was none (the
        // ray came in through the tile's side): a skirt hangs under an edge of a cell's surface
        // where the ray comes from a cell with a hole, if not from under a surface there (a cell
        // of three covers the edge, but a ray may have come through its hole's half). A block
        // jump leaves it as it was: the ray passes the jumped cells above the block's heights or
        // below them by more than the skirt's depth, so no skirt can catch it in the cell it
        // lands in.
        let mut prev_open = true;
        for _ in 0..max_steps {
            // Past the box's exit, the cell stepped into within rounding of it is walked too.
            if w.t_in > t1 {
                let across = if entered == Some(0) { d.x } else { d.y };
                let past = (w.t_in - t1) * across.abs();
                if entered.is_none() || past > corner_slack || past.is_nan() {
                    break;
                }
            }
            if let Some(b) = &blocks {
                // On entering a block whose height range the ray passes wholly above or below,
                // straight to the block's exit cell, as the walk would reach it cell by cell.
                let block = b.index(w.ci, w.cj);
                if checked_block != Some(block) && block < b.count {
                    checked_block = Some(block);
                    let (i0, j0) = b.first_cell(w.ci, w.cj);
                    let edge_i = if step_i > 0 {
                        (i0 + BLOCK as i64 - 1).min(last_i)
                    } else {
                        i0.max(0)
                    };
                    let edge_j = if step_j > 0 {
                        (j0 + BLOCK as i64 - 1).min(last_j)
                    } else {
                        j0.max(0)
                    };
                    let leave_i = CELLS.boundary_t(edge_i, step_i, o.x, inv.x);
                    let leave_j = CELLS.boundary_t(edge_j, step_j, o.y, inv.y);
                    probe.read(Read {
                        array: Array::Atlas,
                        offset: 4 * (self.atlas.texel_words(self.params.texels) + block),
                        bytes: 4,
                    });
                    let range = b.range(block);
                    let (code_lo, code_hi) = (range & 0xFFFF, range >> 16);
                    // A block the ray passes below by less than the skirt's depth may hold a
                    // skirt hit: only a ray below that (with a margin for the square root's
                    // rounding on the device) jumps.
                    let lo_s = code_lo as f32 * leaf.h_scale - slack - skirt_h;
                    let hi_s = code_hi as f32 * leaf.h_scale + slack;
                    let h_a = height_at(o.z, d.z, w.t_in);
                    let h_b = height_at(o.z, d.z, leave_i.min(leave_j).min(t1));
                    if code_lo > code_hi || h_a.max(h_b) < lo_s || h_a.min(h_b) > hi_s {
                        stats.counters.jumps += 1;
                        if t1 < leave_i.min(leave_j) {
                            break;
                        }
                        // Leaving through the i side (first on a tie, as the walk steps i
                        // first): the j steps before it, then the step into the edge column; or
                        // the same with i and j swapped. One loop for both, as glsl/rbvh.glsl.
                        let out_i = leave_i <= leave_j;
                        let leave = if out_i { leave_i } else { leave_j };
                        let before = |t: f32| if out_i { t < leave } else { t <= leave };
                        let mut t_last = w.t_in;
                        let (minor, minor_next, minor_step, minor_o, minor_inv) = if out_i {
                            (&mut w.cj, &mut w.next_j, step_j, o.y, inv.y)
                        } else {
                            (&mut w.ci, &mut w.next_i, step_i, o.x, inv.x)
                        };
                        let (minor_axis, major_axis) = if out_i { (1, 0) } else { (0, 1) };
                        for _ in 0..BLOCK {
                            if minor_step == 0 || !before(*minor_next) {
                                break;
                            }
                            t_last = *minor_next;
                            entered = Some(minor_axis);
                            *minor += minor_step;
                            *minor_next = CELLS.boundary_t(*minor, minor_step, minor_o, minor_inv);
                        }
                        let (major, major_next, major_step, major_o, major_inv, edge) = if out_i {
                            (&mut w.ci, &mut w.next_i, step_i, o.x, inv.x, edge_i)
                        } else {
                            (&mut w.cj, &mut w.next_j, step_j, o.y, inv.y, edge_j)
                        };
                        if *major != edge {
                            let into_edge =
                                CELLS.boundary_t(edge - major_step, major_step, major_o, major_inv);
                            if into_edge >= t_last {
                                entered = Some(major_axis);
                            }
                            t_last = t_last.max(into_edge);
                            *major = edge;
                            *major_next = leave;
                        }
                        w.t_in = t_last;
                    }
                }
            }
            stats.counters.cells += 1;
            let t_out = w.next_i.min(w.next_j).min(t1);
            let corner = cells.corners(w.ci, w.cj);
            let valid = corner.iter().filter(|c| !c.is_hole()).count();
            if let (Some(axis), true, true) = (entered, prev_open, valid >= 3) {
                let step = if axis == 0 { step_i } else { step_j };
                let hit = cells.skirt(&corner, (w.ci, w.cj), axis, step, w.t_in, probe);
                if hit.is_some() {
                    return hit;
                }
            }
            if valid == 3 {
                let hit = cells.diagonal_skirt(&corner, (w.ci, w.cj), w.t_in, t_out, probe);
                if hit.is_some() {
                    return hit;
                }
            }
            prev_open = valid < 4;
            let hit = cells.hit(w.ci, w.cj, w.t_in, t_out, stats, probe);
            if hit.is_some() {
                return hit;
            }
            // Step across the nearer boundary; on a tie (the ray through a grid vertex) `s` goes
            // first. Both boundaries infinite: the ray runs along `h`, one cell is all.
            let across_s = w.next_i <= w.next_j;
            if step_i != 0 && step_j != 0 {
                // The gap, in texels, by which the ray misses the vertex the step passes.
                let gap = if across_s {
                    (w.next_j - w.next_i) * d.y.abs()
                } else {
                    (w.next_i - w.next_j) * d.x.abs()
                };
                let (xi, xj) = if across_s {
                    (w.ci, w.cj + step_j)
                } else {
                    (w.ci + step_i, w.cj)
                };
                if gap <= corner_slack && xi >= 0 && xi <= last_i && xj >= 0 && xj <= last_j {
                    stats.counters.cells += 1;
                    let t_x = w.next_i.max(w.next_j).min(t1);
                    let hit = cells.hit(xi, xj, t_out, t_x, stats, probe);
                    if hit.is_some() {
                        return hit;
                    }
                }
            }
            match w.advance(CELLS, step, last, o2, inv2) {
                Some(axis) => entered = Some(axis),
                None => break,
            }
        }
        None
    }
}

/// The atlas-aligned 8×8 blocks a leaf's tile lies in (`src/rbvh/ranges.rs`), addressed as
/// `rbvh_march` does.
struct Blocks<'a> {
    ranges: &'a [u32],
    /// The tile's corner in the atlas.
    tile_u: u64,
    tile_v: u64,
    pitch: u64,
    count: u64,
}

impl<'a> Blocks<'a> {
    fn of(atlas: &Atlas, leaf: &GpuHeightfield, ranges: &'a [u32]) -> Blocks<'a> {
        let pitch = u64::from(atlas.pitch.max(1));
        // Rows as the device counts them: from the texel count (the loader makes it a whole
        // number of rows).
        let rows = atlas.texels.len() as u64 / pitch;
        let block = u64::from(BLOCK);
        Blocks {
            ranges,
            tile_u: u64::from(leaf.atlas_base) % pitch,
            tile_v: u64::from(leaf.atlas_base) / pitch,
            pitch: pitch.div_ceil(block),
            count: rows.div_ceil(block) * pitch.div_ceil(block),
        }
    }

    /// The block holding cell `(ci, cj)` (both ≥ 0: the walk never leaves the tile).
    fn index(&self, ci: i64, cj: i64) -> u64 {
        let block = u64::from(BLOCK);
        let (ax, ay) = (self.tile_u + ci as u64, self.tile_v + cj as u64);
        (ay / block) * self.pitch + ax / block
    }

    /// The tile cell at the block's first atlas column and row (negative before the tile).
    fn first_cell(&self, ci: i64, cj: i64) -> (i64, i64) {
        let block = u64::from(BLOCK);
        let (ax, ay) = (self.tile_u + ci as u64, self.tile_v + cj as u64);
        (
            (ax / block * block) as i64 - self.tile_u as i64,
            (ay / block * block) as i64 - self.tile_v as i64,
        )
    }

    /// The block's height-code range word; a block without one (only in data the loader
    /// refuses) gets the full range, which never jumps.
    fn range(&self, block: u64) -> u32 {
        usize::try_from(block)
            .ok()
            .and_then(|b| self.ranges.get(b))
            .copied()
            .unwrap_or(0xFFFF_0000)
    }
}

/// A ray in a leaf's frame `(s, t, h)` with its interval `[tmin, t_closest)`, its shear for the
/// watertight test, and its height `slack` (see [`SLACK`]); computed once per leaf.
struct FrameRay {
    ray: Ray,
    shear: RayShear,
    slack: f32,
}

/// Whether every texel of `leaf`'s tile lies in the atlas: at least one sample per side, each tile
/// row within one atlas row, and its last texel `atlas_base + (res_v − 1)·pitch + res_u − 1` in
/// range.
/// The loader rejects files with a leaf that does not fit; the march treats one as empty.
pub(super) fn tile_fits(leaf: &GpuHeightfield, atlas: &Atlas) -> bool {
    if leaf.res_u == 0 || leaf.res_v == 0 || leaf.res_u > atlas.pitch {
        return false;
    }
    // A tile must not wrap across atlas rows: its rows are atlas rows (and the device march's
    // block jumps, `src/rbvh/ranges.rs`, count on it).
    if leaf.atlas_base % atlas.pitch + leaf.res_u > atlas.pitch {
        return false;
    }
    let last = u64::from(leaf.atlas_base)
        + u64::from(leaf.res_v - 1) * u64::from(atlas.pitch)
        + u64::from(leaf.res_u - 1);
    last < atlas.texels.len() as u64
}

/// A height-field hit's normal, and what the device reads for it once its ray is done: what
/// [`RbvhLeaves::finish`] reports.
#[derive(Clone, Copy, Debug)]
pub(crate) struct HitNormal {
    pub(crate) normal: Vec3,
    reads: NormalReads,
}

/// Atlas indices of the texels read for a hit's normal, in order: at most the nearest corner and
/// then the four corners; for a facet's normal (height-only texels), the cell's corner codes
/// present in the atlas, after the leaf's record (`facet`).
#[derive(Clone, Copy, Debug, Default)]
struct NormalReads {
    texels: [u32; 5],
    len: usize,
    /// A facet's leaf, and whether the hit is a skirt's: the device makes the facet once the ray
    /// is done from the leaf's frame and the cell's codes, read again
    /// (`rbvh_height_field_facet` in `glsl/rbvh.glsl`), and a skirt's from the frame ray too,
    /// which needs the leaf's origin.
    facet: Option<(u32, bool)>,
}

impl NormalReads {
    /// The device's reads of leaf `leaf`'s record for a facet: from `atlas_base` to `h_scale`
    /// (the frame and the tile), and the origin before them for a skirt. Never the whole record,
    /// which only a march reads.
    fn facet_leaf_reads(leaf: u32, skirt: bool) -> impl Iterator<Item = Read> {
        let base = u64::from(leaf) * std::mem::size_of::<GpuHeightfield>() as u64;
        let frame = Read {
            array: Array::Leaves,
            offset: base + 12,
            bytes: 52,
        };
        let origin = Read {
            array: Array::Leaves,
            offset: base,
            bytes: 12,
        };
        std::iter::once(frame).chain(skirt.then_some(origin))
    }
}

impl NormalReads {
    fn push(&mut self, texel: u32) {
        self.texels[self.len] = texel;
        self.len += 1;
    }

    fn iter(&self) -> impl Iterator<Item = u32> + '_ {
        self.texels[..self.len].iter().copied()
    }
}

/// The world-space unit normal of the cell triangle `(a, b, c)` (frame coordinates, counter-
/// clockwise in `(s, t)`, so the normal points along `+h`, the side the leaf's surface faces):
/// the frame maps world offsets by the rows `axis_u`, `axis_v`, `axis_w`, so normals map back by
/// its transpose. The hit normal of a height-only RBVH; `glsl/rbvh.glsl` computes it in the same
/// order.
fn facet_normal(leaf: &GpuHeightfield, a: Vec3, b: Vec3, c: Vec3) -> Vec3 {
    let n = (b - a).cross(c - a);
    let (u, v, w) = (
        Vec3::from(leaf.axis_u),
        Vec3::from(leaf.axis_v),
        Vec3::from(leaf.axis_w),
    );
    (u * n.x + v * n.y + w * n.z).normalize()
}

/// The exit distance of a ray from `b`: the far end of the slab test of [`Aabb::intersect`]. It
/// needs no widening against rounding here: the box is already `slack` taller than any surface.
fn box_exit(b: &Aabb, o: Vec3, inv: Vec3) -> f32 {
    let t0 = (b.min - o) * inv;
    let t1 = (b.max - o) * inv;
    t0.max(t1).min_element()
}

/// Texel `(i, j)` of the leaf's tile and its index in the atlas, or a hole (and no index) when
/// the index leaves the atlas. The march only asks for `(i, j)` inside a tile that
/// [`tile_fits`], so the index cannot overflow; the checked read is the last line of defence.
fn texel(atlas: &Atlas, leaf: &GpuHeightfield, i: i64, j: i64) -> (Texel, Option<usize>) {
    let index = i64::from(leaf.atlas_base) + j * i64::from(atlas.pitch) + i;
    let Ok(index) = usize::try_from(index) else {
        return (Texel::HOLE, None);
    };
    match atlas.texels.get(index) {
        Some(&t) => (t, Some(index)),
        None => (Texel::HOLE, None),
    }
}

/// The cells of one leaf's march: what [`Cells::hit`] needs besides the cell.
struct Cells<'a> {
    atlas: &'a Atlas,
    leaf: &'a GpuHeightfield,
    /// Which leaf `leaf` is (for the reads again that a height-only hit's normal costs).
    leaf_index: u32,
    fr: &'a FrameRay,
    /// The world ray's direction, which a hit's normal should face.
    dir: Vec3,
    /// What the texels hold: the normal of a hit comes from its sample or from its facet.
    format: TexelFormat,
    /// `|axis_u|²`: one over the texel's size squared, in the frame's height units (for the
    /// skirt's depth without a square root).
    uu: f32,
}

impl Cells<'_> {
    /// A facet's `normal` (height-only texels) for a hit in cell `(ci, cj)`, on its skirt or not,
    /// with the reads the device makes for it once the ray is done ([`NormalReads::facet`]).
    fn facet(&self, normal: Vec3, (ci, cj): (i64, i64), skirt: bool) -> HitNormal {
        let mut reads = NormalReads {
            facet: Some((self.leaf_index, skirt)),
            ..NormalReads::default()
        };
        for k in 0..4 {
            let (_, index) = texel(
                self.atlas,
                self.leaf,
                ci + (k & 1) as i64,
                cj + (k >> 1) as i64,
            );
            if let Some(index) = index {
                reads.push(index as u32);
            }
        }
        HitNormal { normal, reads }
    }

    /// Steps 4 and 5: intersects the ray with cell `(ci, cj)`, which it crosses over
    /// `[t_in, t_out]`; returns the nearest hit distance of the cell's triangles within the frame
    /// ray's interval, and the normal. Counts the cell in `cells_tested` when it gets past the
    /// height rejection; reports the four texel reads.
    ///
    /// Corners are indexed `k = di + 2·dj`: c00, c10, c01, c11. With all four present the surface
    /// is (c00, c10, c11) and (c00, c11, c01); with one hole, the triangle of the other three taken
    /// in the cycle order c00, c10, c11, c01 (so the winding stays that of the quad); with two or
    /// more holes there is no surface.
    fn hit<P: Probe>(
        &self,
        ci: i64,
        cj: i64,
        t_in: f32,
        t_out: f32,
        stats: &mut TraceStats,
        probe: &mut P,
    ) -> Option<(f32, HitNormal)> {
        let (atlas, leaf, fr) = (self.atlas, self.leaf, self.fr);
        let mut corner = [Texel::HOLE; 4];
        let mut pos = [Vec3::ZERO; 4];
        let mut valid = 0;
        let mut lo = f32::INFINITY;
        let mut hi = f32::NEG_INFINITY;
        for k in 0..4 {
            let i = ci + (k & 1) as i64;
            let j = cj + (k >> 1) as i64;
            let (c, index) = texel(atlas, leaf, i, j);
            if let Some(index) = index {
                probe.read(atlas.code_read(index, self.format));
            }
            corner[k] = c;
            if !c.is_hole() {
                let h = c.height_code() as f32 * leaf.h_scale;
                pos[k] = Vec3::new(i as f32 + 0.5, j as f32 + 0.5, h);
                valid += 1;
                lo = lo.min(h);
                hi = hi.max(h);
            }
        }
        if valid < 3 {
            return None;
        }

        // Cheap rejection: the ray's height over the cell misses the corners' height range (by more
        // than the rounding slack covers).
        let o = fr.ray.origin();
        let d = fr.ray.dir();
        let h_a = height_at(o.z, d.z, t_in);
        let h_b = height_at(o.z, d.z, t_out);
        if h_a.max(h_b) < lo - fr.slack || h_a.min(h_b) > hi + fr.slack {
            return None;
        }
        stats.counters.cells_tested += 1;

        let first = first_triangle(&corner);
        let second = (valid == 4).then_some([0, 3, 2]);
        // The second triangle only counts when nearer than the first one's hit.
        let [a, b, c] = first;
        let mut t_hit =
            intersect_triangle(&fr.shear, pos[a], pos[b], pos[c], fr.ray.tmin, fr.ray.tmax);
        let mut hit_triangle = first;
        if let Some([a, b, c]) = second {
            let t_max = t_hit.unwrap_or(fr.ray.tmax);
            let t = intersect_triangle(&fr.shear, pos[a], pos[b], pos[c], fr.ray.tmin, t_max);
            if t.is_some() {
                t_hit = t;
                hit_triangle = [a, b, c];
            }
        }
        let t = t_hit?;
        if self.format == TexelFormat::Height {
            let [a, b, c] = hit_triangle.map(|k| pos[k]);
            let normal = facet_normal(leaf, a, b, c);
            return Some((t, self.facet(normal, (ci, cj), false)));
        }

        Some((t, self.nearest_normal(&corner, ci, cj, t)))
    }

    /// The normal of the corner sample nearest the point at `t` in cell `(ci, cj)`: sample i sits
    /// at s = i + ½, so the nearest is floor(s) (halves round up), clamped to the cell; a hole
    /// there falls back to the first present corner in the order c00, c10, c01, c11. Unless that
    /// normal faces away from the ray while another present corner's faces it: then the first
    /// such in the same order. Along a silhouette, the nearest sample may lie on the far side of
    /// a spike or a horn (its normal turned away from the viewer), and a hit shaded with it is a
    /// dark speck the exact surface does not have (issue "Small and valid at every scale",
    /// item 5: on the dragon close-up at Q0, 207 of 386 dark pixels).
    ///
    /// The device reads these texels once its ray is done (`rbvh_normal_texel`): the nearest, then
    /// while none faces the ray, each present corner in that order; `HitNormal::reads` lists them.
    fn nearest_normal(&self, corner: &[Texel; 4], ci: i64, cj: i64, t: f32) -> HitNormal {
        let (o, d) = (self.fr.ray.origin(), self.fr.ray.dir());
        let s = o.x + d.x * t;
        let r = o.y + d.y * t;
        let di = ((s.floor() as i64).clamp(ci, ci + 1) - ci) as usize;
        let dj = ((r.floor() as i64).clamp(cj, cj + 1) - cj) as usize;
        let mut k = di + 2 * dj;
        if corner[k].is_hole() {
            k = (0..4).find(|&q| !corner[q].is_hole()).unwrap_or(k);
        }
        let pitch = i64::from(self.atlas.pitch);
        let k00 = i64::from(self.leaf.atlas_base) + cj * pitch + ci;
        let index = |q: usize| (k00 + (q & 1) as i64 + (q >> 1) as i64 * pitch) as u32;
        let mut reads = NormalReads::default();
        reads.push(index(k));
        let mut nearest = corner[k];
        if !nearest.faces(self.dir) {
            for q in (0..4).filter(|&q| !corner[q].is_hole()) {
                reads.push(index(q));
                if corner[q].faces(self.dir) {
                    nearest = corner[q];
                    break;
                }
            }
        }
        HitNormal {
            normal: nearest.normal(),
            reads,
        }
    }

    /// The four corner texels of cell `(ci, cj)` (c00, c10, c01, c11), read without reporting:
    /// whether the cell is full, as the device knows from the corners it read for the cell test.
    fn corners(&self, ci: i64, cj: i64) -> [Texel; 4] {
        std::array::from_fn(|k| {
            texel(
                self.atlas,
                self.leaf,
                ci + (k & 1) as i64,
                cj + (k >> 1) as i64,
            )
            .0
        })
    }

    /// The skirt ([`SKIRT_TEXELS`]) under the edge of cell `(ci, cj)` that the ray entered at
    /// `t_in` from a cell with fewer than four samples or through the tile's side:
    /// the edge on `axis` (0: an `s` boundary, 1: a `t` boundary) crossed by a ray stepping
    /// `step` along it, when both its samples are present (so the cell's surface has that edge).
    /// A hit at `t_in` when the ray is below the edge by at most the skirt's depth there
    /// ([`Cells::skirt_depth`] of [`SKIRT_TEXELS`]).
    fn skirt<P: Probe>(
        &self,
        corner: &[Texel; 4],
        (ci, cj): (i64, i64),
        axis: usize,
        step: i64,
        t_in: f32,
        probe: &mut P,
    ) -> Option<(f32, HitNormal)> {
        // The entered edge's two corners: c00-c01 or c10-c11 across s, c00-c10 or c01-c11
        // across t.
        let edge = match (axis, step > 0) {
            (0, true) => [0, 2],
            (0, false) => [1, 3],
            (_, true) => [0, 1],
            (_, false) => [2, 3],
        };
        if edge.iter().any(|&k| corner[k].is_hole()) {
            return None;
        }
        let (o, d) = (self.fr.ray.origin(), self.fr.ray.dir());
        // The entry's fraction along the edge.
        let f = if axis == 0 {
            o.y + d.y * t_in - (cj as f32 + 0.5)
        } else {
            o.x + d.x * t_in - (ci as f32 + 0.5)
        };
        let edge = SkirtEdge {
            ends: edge,
            at: f,
            full: SKIRT_TEXELS,
        };
        self.skirt_hit(corner, (ci, cj), edge, t_in, probe)
    }

    /// The skirt under the diagonal of cell `(ci, cj)`, whose `corner`s are three samples and a
    /// hole: the edge of its one triangle that faces the hole, inside the cell. A hit where the
    /// ray crosses that edge's vertical plane within the cell, `[t_in, t_out]`, from the hole's
    /// side, below the edge by at most [`DIAGONAL_SKIRT_TEXELS`] there, tapered as
    /// [`Cells::skirt_depth`] tapers.
    fn diagonal_skirt<P: Probe>(
        &self,
        corner: &[Texel; 4],
        (ci, cj): (i64, i64),
        t_in: f32,
        t_out: f32,
        probe: &mut P,
    ) -> Option<(f32, HitNormal)> {
        let hole = corner.iter().position(|c| c.is_hole())?;
        // In the cell's own coordinates (fs, ft) ∈ [0, 1]²: the diagonal through c10 and c01
        // (fs + ft = 1) faces a hole at c00 or c11, the one through c00 and c11 (fs = ft) a
        // hole at c10 or c01; `side` is the hole's sign of `q`, zero on the diagonal, and the
        // fraction along the edge from its first corner is `ft` or `fs` (`along`, as the ray's
        // origin and direction give it).
        let (o, d) = (self.fr.ray.origin(), self.fr.ray.dir());
        let (fs0, ft0) = (o.x - (ci as f32 + 0.5), o.y - (cj as f32 + 0.5));
        let (edge, q0, dq, side, along) = match hole {
            0 | 3 => (
                [1, 2],
                fs0 + ft0 - 1.0,
                d.x + d.y,
                if hole == 0 { -1.0 } else { 1.0 },
                (ft0, d.y),
            ),
            _ => (
                [0, 3],
                fs0 - ft0,
                d.x - d.y,
                if hole == 1 { 1.0 } else { -1.0 },
                (fs0, d.x),
            ),
        };
        // Only a ray that crosses from the hole's side, and within the cell.
        if dq * side >= 0.0 {
            return None;
        }
        let t = -q0 / dq;
        if !(t >= t_in && t <= t_out) {
            return None;
        }
        let edge = SkirtEdge {
            ends: edge,
            at: along.0 + along.1 * t,
            full: DIAGONAL_SKIRT_TEXELS,
        };
        self.skirt_hit(corner, (ci, cj), edge, t, probe)
    }

    /// How deep the skirt hangs under `edge` where the ray meets it, in texels, and the edge's
    /// height there: all of `edge.full` under an edge whose samples were both taken from the
    /// surface ([`Texel::is_sampled`]); under an edge from such a sample to an extrapolated one,
    /// all of it at the sampled end, tapering to nothing half-way (beside an extrapolated
    /// sample it would hang in the air by a silhouette); None under an edge with both ends
    /// extrapolated.
    fn skirt_depth(&self, corner: &[Texel; 4], edge: &SkirtEdge) -> Option<(f32, f32)> {
        let f = edge.at.clamp(0.0, 1.0);
        let [a, b] = edge
            .ends
            .map(|k| corner[k].height_code() as f32 * self.leaf.h_scale);
        let share = match edge.ends.map(|k| corner[k].is_sampled()) {
            [true, true] => 1.0,
            [false, false] => return None,
            [true, false] => (1.0 - 2.0 * f).max(0.0),
            [false, true] => (2.0 * f - 1.0).max(0.0),
        };
        Some((edge.full * share, a + (b - a) * f))
    }

    /// A hit at `t` on the skirt under `edge` of cell `(ci, cj)`: when `t` lies in the ray's
    /// interval and the ray is below the edge there by at most the skirt's depth
    /// ([`Cells::skirt_depth`], compared squared with `uu`, so no square root is needed). The
    /// normal is the sample's nearest the point (height-only texels: the facet's under it).
    fn skirt_hit<P: Probe>(
        &self,
        corner: &[Texel; 4],
        (ci, cj): (i64, i64),
        edge: SkirtEdge,
        t: f32,
        probe: &mut P,
    ) -> Option<(f32, HitNormal)> {
        let (atlas, leaf, fr) = (self.atlas, self.leaf, self.fr);
        let (o, d) = (fr.ray.origin(), fr.ray.dir());
        let (depth, edge_h) = self.skirt_depth(corner, &edge)?;
        let below = edge_h - height_at(o.z, d.z, t);
        // Within the ray's interval, which ends before tmax as the triangle test's does.
        let within = t >= fr.ray.tmin && t < fr.ray.tmax;
        if !(within && below >= -fr.slack && below * below * self.uu <= depth * depth) {
            return None;
        }
        // The device read the cell's four corners before this test, as for any cell.
        for k in 0..4 {
            if let (_, Some(index)) = texel(atlas, leaf, ci + (k & 1) as i64, cj + (k >> 1) as i64)
            {
                probe.read(atlas.code_read(index, self.format));
            }
        }
        if self.format == TexelFormat::Height {
            let pos: [Vec3; 4] = std::array::from_fn(|k| {
                Vec3::new(
                    (ci + (k & 1) as i64) as f32 + 0.5,
                    (cj + (k >> 1) as i64) as f32 + 0.5,
                    corner[k].height_code() as f32 * leaf.h_scale,
                )
            });
            let fs = o.x + d.x * t - (ci as f32 + 0.5);
            let ft = o.y + d.y * t - (cj as f32 + 0.5);
            let [a, b, c] = surface_under(corner, fs, ft).map(|k| pos[k]);
            let normal = facet_normal(leaf, a, b, c);
            return Some((t, self.facet(normal, (ci, cj), true)));
        }
        Some((t, self.nearest_normal(corner, ci, cj, t)))
    }
}

/// Where a ray meets a skirt: under the edge between the cell's corners `ends` (indexed as
/// [`Cells::hit`] indexes them), at fraction `at` along it from `ends[0]`, a skirt `full` texels
/// deep under a sampled end.
struct SkirtEdge {
    ends: [usize; 2],
    at: f32,
    full: f32,
}

/// The first triangle of a cell with three or four samples (`corner`: c00, c10, c01, c11):
/// (c00, c10, c11) with four; with three, the three present in the cycle order c00, c10, c11,
/// c01, so that the winding stays the quad's (`rbvh_first_triangle` in `glsl/rbvh.glsl`).
fn first_triangle(corner: &[Texel; 4]) -> [usize; 3] {
    let mut tri = [0; 3];
    for (n, k) in [0, 1, 3, 2]
        .into_iter()
        .filter(|&k| !corner[k].is_hole())
        .take(3)
        .enumerate()
    {
        tri[n] = k;
    }
    tri
}

/// The triangle of a cell with three or four samples over the point at `(fs, ft)` in the cell:
/// with four, the first (c00, c10, c11) where `fs ≥ ft`, else (c00, c11, c01); with three, the
/// one.
fn surface_under(corner: &[Texel; 4], fs: f32, ft: f32) -> [usize; 3] {
    if corner.iter().all(|c| !c.is_hole()) && fs < ft {
        return [0, 3, 2];
    }
    first_triangle(corner)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bvh::{ChildRef, GpuNode, GpuTriangle};
    use crate::rbvh::layout::cell_triangles;
    use crate::rbvh::{RbvhParams, RbvhStats};

    /// World size of one texel in the test leaves.
    const TS: f32 = 0.5;
    const MISS_ID: u32 = u32::MAX;

    /// A leaf looking down at the plane `y = y0`: `u = +x`, `v = +z`, `w = +y`, origin
    /// `(-2, y0, -2)`, so sample `(i, j)` is at world `x = -2 + (i + ½)·TS`, `z = -2 + (j + ½)·TS`.
    fn flat_leaf(y0: f32, res_u: u32, res_v: u32, h_scale: f32) -> GpuHeightfield {
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
    fn world(l: &GpuHeightfield, s: f32, t: f32, h: f32) -> Vec3 {
        let (u, v) = (Vec3::from(l.axis_u), Vec3::from(l.axis_v));
        Vec3::from(l.origin)
            + s * u / u.length_squared()
            + t * v / v.length_squared()
            + h * Vec3::from(l.axis_w)
    }

    /// The world box of the leaf's tile box (its eight corners).
    fn leaf_box(l: &GpuHeightfield) -> Aabb {
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

    fn hf_child(l: &GpuHeightfield, index: u32) -> ChildRef {
        ChildRef {
            bounds: leaf_box(l),
            child: LEAF_BIT | index,
            count: HEIGHTFIELD_COUNT,
        }
    }

    /// A tile of `res_u × res_v` texels (pitch `res_u`) from `f(i, j)`.
    fn tile(res_u: u32, res_v: u32, f: impl Fn(u32, u32) -> Texel) -> Vec<Texel> {
        let mut texels = Vec::new();
        for j in 0..res_v {
            for i in 0..res_u {
                texels.push(f(i, j));
            }
        }
        texels
    }

    fn rbvh(
        nodes: Vec<GpuNode>,
        triangles: Vec<GpuTriangle>,
        leaves: Vec<GpuHeightfield>,
        atlas: Atlas,
    ) -> Rbvh {
        Rbvh {
            params: RbvhParams::quality(2).unwrap(),
            nodes,
            triangles,
            leaves,
            atlas,
            bounds: Aabb::EMPTY,
            depth: 1,
            texel_size: TS,
            stats: RbvhStats::default(),
            colours: None,
        }
    }

    /// One height-field leaf under the root, its tile at texel 0 of an atlas of pitch `res_u`.
    fn single(l: GpuHeightfield, texels: Vec<Texel>) -> Rbvh {
        let pitch = l.res_u.max(1);
        let atlas = Atlas {
            pitch,
            rows: texels.len() as u32 / pitch,
            narrow_rows: 0,
            texels,
        };
        let root = GpuNode::new(hf_child(&l, 0), ChildRef::ABSENT);
        rbvh(vec![root], vec![], vec![l], atlas)
    }

    fn flat_plane() -> Rbvh {
        single(
            flat_leaf(1.0, 8, 8, 0.0),
            tile(8, 8, |_, _| Texel::new(0, Vec3::Y)),
        )
    }

    /// A ray straight down onto world `(x, z)` from `y = 10`.
    fn down(x: f32, z: f32) -> Ray {
        Ray::new(Vec3::new(x, 10.0, z), -Vec3::Y, 0.0, f32::INFINITY)
    }

    /// A ray with direction `dir` (y = -1) that reaches world `(x, y0, z)` at t = `t`.
    fn towards(x: f32, y0: f32, z: f32, dir: Vec3, t: f32) -> Ray {
        Ray::new(Vec3::new(x, y0, z) - t * dir, dir, 0.0, f32::INFINITY)
    }

    fn assert_hit(r: &Rbvh, ray: &Ray, t: f32, id: u32) -> Hit {
        let (hit, _) = r.closest_hit(ray);
        assert_eq!(hit.id, id, "{ray:?} → {hit:?}");
        assert!(
            (hit.t - t).abs() <= 1e-5 * t.max(1.0),
            "{ray:?}: t {} expected {t}",
            hit.t
        );
        hit
    }

    fn assert_miss(r: &Rbvh, ray: &Ray) {
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
        // tile; the block range word follows the 64 texels. Once the ray is done, the hit's
        // normal: that of texel 36, the sample nearest the hit.
        let read = |array, offset, bytes| Read {
            array,
            offset,
            bytes,
        };
        assert_eq!(
            reads,
            [
                read(Array::Nodes, 0, 48),
                read(Array::Leaves, 0, 64),
                read(Array::Atlas, 4 * 64, 4),
                read(Array::Atlas, 4 * 28, 4),
                read(Array::Atlas, 4 * 29, 4),
                read(Array::Atlas, 4 * 36, 4),
                read(Array::Atlas, 4 * 37, 4),
                read(Array::Atlas, 4 * 36, 4),
            ]
        );
    }

    #[test]
    fn flat_plane_is_hit_at_its_height() {
        let r = flat_plane();
        let hit = assert_hit(&r, &down(0.3, 0.2), 9.0, LEAF_BIT);
        assert!(hit.normal().dot(Vec3::Y) > 0.9999, "{hit:?}");
        assert_eq!(r.closest_hit(&down(0.3, 0.2)).1.counters.cells, 1);
        // Oblique rays from every quadrant, grazing ones included, hit at the same height.
        let dirs = [
            Vec3::new(0.1, -1.0, 0.05),
            Vec3::new(-0.7, -1.0, 0.3),
            Vec3::new(0.4, -1.0, -0.9),
            Vec3::new(-3.0, -1.0, -2.0),
            Vec3::new(40.0, -1.0, 7.0),
        ];
        for dir in dirs {
            for (x, z) in [(0.0, 0.0), (1.6, -1.6), (-1.7, 1.2), (-0.5, 0.75)] {
                let hit = assert_hit(&r, &towards(x, 1.0, z, dir, 9.0), 9.0, LEAF_BIT);
                assert!(hit.normal().dot(Vec3::Y) > 0.9999);
            }
        }
        // Sample centres and cell boundaries (shared edges and corners) are hit too.
        for k in 1..=13 {
            let x = -2.0 + (0.5 + 0.5 * k as f32) * TS;
            assert_hit(&r, &down(x, x), 9.0, LEAF_BIT);
            assert_hit(
                &r,
                &towards(x, 1.0, -x, Vec3::new(0.3, -1.0, 0.2), 9.0),
                9.0,
                LEAF_BIT,
            );
        }
        // So is the tile's border, whatever the sign of the ray's zero components in the frame.
        // (In the world, a tight node box decides for a ray in its face plane, as in the exact
        // BVH; the box here is loose, so that the march decides.)
        let mut loose = r.clone();
        let l = loose.leaves[0];
        let mut child = hf_child(&l, 0);
        child.bounds.min -= Vec3::splat(0.1);
        child.bounds.max += Vec3::splat(0.1);
        loose.nodes[0] = GpuNode::new(child, ChildRef::ABSENT);
        for x in [-1.75, 1.75] {
            for dir in [Vec3::new(0.0, -1.0, 0.0), Vec3::new(-0.0, -1.0, -0.0)] {
                let ray = Ray::new(Vec3::new(x, 10.0, x), dir, 0.0, f32::INFINITY);
                assert_hit(&loose, &ray, 9.0, LEAF_BIT);
            }
        }
    }

    #[test]
    fn rays_outside_the_tile_or_interval_miss() {
        let r = flat_plane();
        // The surface spans the sample centres: x, z in [-1.75, 1.75].
        for (x, z) in [(1.8, 0.0), (0.0, -1.8), (5.0, 5.0), (-1.76, -1.76)] {
            assert_miss(&r, &down(x, z));
        }
        assert_miss(
            &r,
            &Ray::new(Vec3::new(0.0, 10.0, 0.0), Vec3::Y, 0.0, f32::INFINITY),
        );
        assert_miss(&r, &Ray::new(Vec3::new(0.0, 10.0, 0.0), -Vec3::Y, 0.0, 8.9));
        assert_miss(
            &r,
            &Ray::new(Vec3::new(0.0, 10.0, 0.0), -Vec3::Y, 9.1, 20.0),
        );
        // tmax is exclusive, tmin inclusive, as for triangles.
        assert_miss(&r, &Ray::new(Vec3::new(0.0, 10.0, 0.0), -Vec3::Y, 0.0, 9.0));
        assert_hit(
            &r,
            &Ray::new(Vec3::new(0.0, 10.0, 0.0), -Vec3::Y, 9.0, 9.5),
            9.0,
            LEAF_BIT,
        );
        // Invalid rays miss.
        assert_miss(
            &r,
            &Ray::new(Vec3::new(f32::NAN, 10.0, 0.0), -Vec3::Y, 0.0, 20.0),
        );
        assert_miss(
            &r,
            &Ray::new(Vec3::new(0.0, 10.0, 0.0), Vec3::ZERO, 0.0, 20.0),
        );
    }

    #[test]
    fn tilted_plane_is_hit_at_its_height() {
        // Height i at sample i: h = s − ½ in frame units, i.e. y = 2x + 4.5 in the world.
        let n = Vec3::new(-2.0, 1.0, 0.0).normalize();
        let l = flat_leaf(1.0, 8, 8, 0.001);
        let r = single(l, tile(8, 8, |i, _| Texel::new((i * 1000) as u16, n)));
        let hit = assert_hit(&r, &down(0.3, 0.2), 10.0 - 5.1, LEAF_BIT);
        assert!(hit.normal().dot(n) > 0.9995, "{hit:?}");
        // Starting inside the tile's box, marching several cells before the hit:
        // y = 10 − t meets y = 2(−1.5 + 0.3t) + 4.5 at t = 8.5 / 1.6.
        let ray = Ray::new(
            Vec3::new(-1.5, 10.0, 0.0),
            Vec3::new(0.3, -1.0, 0.0),
            0.0,
            f32::INFINITY,
        );
        assert_hit(&r, &ray, 8.5 / 1.6, LEAF_BIT);
        assert!(r.closest_hit(&ray).1.counters.cells >= 3);
    }

    /// A plateau at frame height 1 over sample columns 2..=5 (holes beside it), its rim at
    /// column 2 sampled (an even code) or extrapolated (odd): a ray running along `s` under the
    /// surface enters it from the side, and the skirt (one texel, 0.5 here) catches it at the rim
    /// only when the rim was sampled and the ray is within the skirt's depth.
    #[test]
    fn a_skirt_hangs_one_texel_under_sampled_rims_only() {
        let l = flat_leaf(1.0, 8, 8, 0.001);
        let plateau = |rim: u16| {
            single(
                l,
                tile(8, 8, |i, _| match i {
                    2 => Texel::new(rim, Vec3::Y),
                    3..=5 => Texel::new(1000, Vec3::Y),
                    _ => Texel::HOLE,
                }),
            )
        };
        let (sampled, extrapolated) = (plateau(1000), plateau(1001));
        // Along +x at frame height h (world y = 1 + h), row t = 3.7, from x = -5: the rim column
        // s = 2.5 lies at world x = -2 + 2.5 · 0.5 = -0.75, t = 4.25.
        let along = |h: f32, dir: f32| {
            let p = world(&l, 3.0, 3.7, h);
            Ray::new(
                Vec3::new(-0.75 - 4.25 * dir, p.y, p.z),
                Vec3::new(dir, 0.0, 0.0),
                0.0,
                f32::INFINITY,
            )
        };
        assert_hit(&sampled, &along(0.7, 1.0), 4.25, LEAF_BIT);
        assert_hit(&sampled, &along(0.55, 1.0), 4.25, LEAF_BIT);
        // The ray's interval ends before tmax, for the skirt as for the triangles.
        let ends = |tmax: f32| {
            let ray = along(0.7, 1.0);
            Ray::new(ray.origin(), ray.dir(), 0.0, tmax)
        };
        assert_miss(&sampled, &ends(4.25));
        assert_hit(&sampled, &ends(4.2501), 4.25, LEAF_BIT);
        // Deeper than the skirt, over the surface, or under an extrapolated rim: nothing.
        assert_miss(&sampled, &along(0.45, 1.0));
        assert_miss(&sampled, &along(1.2, 1.0));
        assert_miss(&extrapolated, &along(0.7, 1.0));
        // From the other side the rim at s = 5.5 (x = 0.75) was sampled in both.
        let back = |r: &Rbvh| {
            let ray = Ray::new(
                Vec3::new(5.0, 1.7, along(0.7, 1.0).origin().z),
                Vec3::new(-1.0, 0.0, 0.0),
                0.0,
                f32::INFINITY,
            );
            assert_hit(r, &ray, 4.25, LEAF_BIT);
        };
        back(&sampled);
        back(&extrapolated);
    }

    /// The plateau of [`a_skirt_hangs_one_texel_under_sampled_rims_only`] with its rim column
    /// sampled in rows 0–3 and extrapolated in rows 4–7 (or the other way round): between rows 3
    /// and 4 the skirt tapers from a texel (0.5 here) under the sampled end to nothing half-way,
    /// so a ray along row t = 3.7 (a fifth of the way from row 3) meets 0.6 of it, and one along
    /// t = 4.3 (four fifths) none; the other way round, the reverse.
    #[test]
    fn a_skirt_tapers_to_nothing_half_way_to_an_extrapolated_end() {
        let l = flat_leaf(1.0, 8, 8, 0.001);
        let plateau = |low_rows: u16, high_rows: u16| {
            single(
                l,
                tile(8, 8, |i, j| match i {
                    2 => Texel::new(if j <= 3 { low_rows } else { high_rows }, Vec3::Y),
                    3..=5 => Texel::new(1000, Vec3::Y),
                    _ => Texel::HOLE,
                }),
            )
        };
        let along = |t: f32, h: f32| {
            let p = world(&l, 3.0, t, h);
            Ray::new(Vec3::new(-5.0, p.y, p.z), Vec3::X, 0.0, f32::INFINITY)
        };
        // Sampled below, extrapolated above: 0.3 deep at t = 3.7, nothing at t = 4.3.
        let sampled_low = plateau(1000, 1001);
        assert_hit(&sampled_low, &along(3.7, 0.75), 4.25, LEAF_BIT);
        assert_miss(&sampled_low, &along(3.7, 0.65));
        assert_miss(&sampled_low, &along(4.3, 0.99));
        // Extrapolated below, sampled above: the reverse.
        let sampled_high = plateau(1001, 1000);
        assert_hit(&sampled_high, &along(4.3, 0.75), 4.25, LEAF_BIT);
        assert_miss(&sampled_high, &along(4.3, 0.65));
        assert_miss(&sampled_high, &along(3.7, 0.99));
    }

    /// One cell of three samples (c00, c10, c01 at height 1) and a hole at c11: its triangle's
    /// diagonal faces the hole, and a skirt a tenth of a texel deep (`MARCH_DIAGONAL_SKIRT_TEXELS`,
    /// 0.05 here) hangs under it. A ray crossing the diagonal's midpoint from the hole's side
    /// within that depth hits there; deeper, or from the triangle's side, it passes.
    #[test]
    fn a_shallow_skirt_hangs_under_the_diagonal_that_faces_a_hole() {
        let l = flat_leaf(1.0, 8, 8, 0.001);
        let r = single(
            l,
            tile(8, 8, |i, j| match (i, j) {
                (3, 3) | (4, 3) | (3, 4) => Texel::new(1000, Vec3::Y),
                _ => Texel::HOLE,
            }),
        );
        // The diagonal's midpoint is frame (4, 4): sample space (3.5, 3.5) + (½, ½).
        let dir = Vec3::new(-1.0, 0.0, -1.0).normalize();
        let from_hole = |h: f32| {
            let p = world(&l, 4.0, 4.0, h);
            Ray::new(p - 3.0 * dir, dir, 0.0, f32::INFINITY)
        };
        let hit = assert_hit(&r, &from_hole(0.97), 3.0, LEAF_BIT);
        assert!(hit.normal().abs_diff_eq(Vec3::Y, 1e-2), "{hit:?}");
        assert_miss(&r, &from_hole(0.93));
        assert_miss(&r, &from_hole(1.2));
        // From under the triangle (frame (3.8, 3.8), inside the tile's box) towards the hole.
        let from_triangle = Ray::new(world(&l, 3.8, 3.8, 0.97), -dir, 0.0, f32::INFINITY);
        assert_miss(&r, &from_triangle);
    }

    #[test]
    fn a_cell_is_two_triangles_split_along_c00_c11() {
        // One cell, c11 raised by 1: on the diagonal the surface is at ½ (bilinear would say ¼).
        let l = flat_leaf(1.0, 2, 2, 0.001);
        let codes = [0, 0, 0, 1000];
        let r = single(
            l,
            tile(2, 2, |i, j| {
                Texel::new(codes[(i + 2 * j) as usize], Vec3::Y)
            }),
        );
        let at = |s: f32, t: f32| world(&l, s, t, 0.0);
        let p = at(1.0, 1.0);
        assert_hit(&r, &down(p.x, p.z), 10.0 - 1.5, LEAF_BIT);
        // Below the diagonal (t < s) the triangle (c00, c10, c11) has h = t − ½, above it h = s − ½.
        let p = at(1.25, 0.75);
        assert_hit(&r, &down(p.x, p.z), 10.0 - 1.25, LEAF_BIT);
        let p = at(0.75, 1.25);
        assert_hit(&r, &down(p.x, p.z), 10.0 - 1.25, LEAF_BIT);
    }

    #[test]
    fn one_hole_keeps_the_other_triangle_two_holes_none() {
        let normals = [Vec3::Y, Vec3::X, Vec3::Z, -Vec3::X];
        let with_holes = |holes: &[usize]| {
            let l = flat_leaf(1.0, 2, 2, 0.0);
            single(
                l,
                tile(2, 2, |i, j| {
                    let k = (i + 2 * j) as usize;
                    if holes.contains(&k) {
                        Texel::HOLE
                    } else {
                        Texel::new(0, normals[k])
                    }
                }),
            )
        };
        let l = flat_leaf(1.0, 2, 2, 0.0);
        let near_c00 = world(&l, 0.8, 0.8, 0.0);
        let near_c11 = world(&l, 1.3, 1.3, 0.0);
        // c11 missing: the triangle (c00, c10, c01) remains.
        let r = with_holes(&[3]);
        assert_hit(&r, &down(near_c00.x, near_c00.z), 9.0, LEAF_BIT);
        assert_miss(&r, &down(near_c11.x, near_c11.z));
        // At the cell centre the nearest sample is c11, a hole: the normal falls back to c00's.
        let centre = world(&l, 1.0, 1.0, 0.0);
        let hit = assert_hit(&r, &down(centre.x, centre.z), 9.0, LEAF_BIT);
        assert!(hit.normal().dot(normals[0]) > 0.9999, "{hit:?}");
        // c00 missing: the triangle (c10, c11, c01) remains.
        let r = with_holes(&[0]);
        assert_miss(&r, &down(near_c00.x, near_c00.z));
        assert_hit(&r, &down(near_c11.x, near_c11.z), 9.0, LEAF_BIT);
        // Two holes: no surface at all.
        let r = with_holes(&[1, 2]);
        assert_miss(&r, &down(near_c00.x, near_c00.z));
        assert_miss(&r, &down(near_c11.x, near_c11.z));
    }

    #[test]
    fn normal_is_the_nearest_samples() {
        let normal = |i: u32, j: u32| Vec3::new(i as f32 - 3.5, 8.0, j as f32 - 3.5).normalize();
        let l = flat_leaf(1.0, 8, 8, 0.0);
        let r = single(l, tile(8, 8, |i, j| Texel::new(0, normal(i, j))));
        for (s, t, i, j) in [
            (2.3, 3.8, 2, 3),
            (2.7, 3.2, 2, 3),
            (3.1, 0.6, 3, 0),
            (6.9, 7.4, 6, 7),
        ] {
            let p = world(&l, s, t, 0.0);
            let hit = assert_hit(&r, &down(p.x, p.z), 9.0, LEAF_BIT);
            assert!(
                hit.normal().dot(normal(i, j)) > 0.9999,
                "({s}, {t}) → {hit:?}"
            );
        }
    }

    #[test]
    fn a_hole_in_the_tile_lets_rays_through() {
        // Samples (3..=4, 3..=4) missing: the cells around them have two or more holes.
        let hole = |i: u32, j: u32| (3..=4).contains(&i) && (3..=4).contains(&j);
        let l = flat_leaf(1.0, 8, 8, 0.0);
        let r = single(
            l,
            tile(8, 8, |i, j| {
                if hole(i, j) {
                    Texel::HOLE
                } else {
                    Texel::new(0, Vec3::Y)
                }
            }),
        );
        for (s, t) in [(4.0, 4.0), (3.6, 4.4), (4.5, 4.0)] {
            let p = world(&l, s, t, 0.0);
            assert_miss(&r, &down(p.x, p.z));
            assert_miss(&r, &towards(p.x, 1.0, p.z, Vec3::new(0.2, -1.0, -0.1), 9.0));
        }
        for (s, t) in [(1.0, 1.0), (6.0, 4.0), (4.0, 1.2)] {
            let p = world(&l, s, t, 0.0);
            assert_hit(&r, &down(p.x, p.z), 9.0, LEAF_BIT);
        }
    }

    /// Root: inner node 1 and a triangle leaf; node 1: height-field leaves 0 (the plane y = 1)
    /// and 1 (the plane y = 1 shifted by +10 in x).
    fn hybrid(triangle_y: f32) -> Rbvh {
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
        let tri_leaf = ChildRef {
            bounds: Aabb::from_points(tri.vertices()),
            child: LEAF_BIT,
            count: 1,
        };
        let node1 = GpuNode::new(hf_child(&l0, 0), hf_child(&l1, 1));
        let inner = ChildRef {
            bounds: leaf_box(&l0).union(leaf_box(&l1)),
            child: 1,
            count: 0,
        };
        let root = GpuNode::new(inner, tri_leaf);
        let mut texels = tile(8, 8, |_, _| Texel::new(0, Vec3::Y));
        texels.extend(tile(8, 8, |_, _| Texel::new(0, -Vec3::Y)));
        let atlas = Atlas {
            pitch: 8,
            rows: 16,
            narrow_rows: 0,
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
            f(&mut r.leaves[0]);
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
            assert_eq!(hit, Hit::MISS, "{:?}", r.leaves[0]);
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
            with_root(ChildRef {
                child: LEAF_BIT | 5,
                count: HEIGHTFIELD_COUNT,
                ..big
            }),
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

    #[test]
    fn grazing_and_long_marches_end_within_the_cell_bound() {
        // Along the flat plane at its very height, and just above it.
        let r = flat_plane();
        for y in [1.0, 1.0 + 1e-7, 0.999_999] {
            for dir in [Vec3::X, Vec3::new(1.0, 0.0, 1.0), Vec3::new(-1.0, 0.0, 0.3)] {
                let ray = Ray::new(Vec3::new(0.0, y, 0.1) - 5.0 * dir, dir, 0.0, f32::INFINITY);
                let (_, stats) = r.closest_hit(&ray);
                assert!(stats.counters.cells <= 13, "{ray:?}: {stats:?}");
            }
        }
        // An empty tile's box crossed corner to corner: every cell on the way, and no more.
        let l = flat_leaf(1.0, 9, 6, 0.001);
        let r = single(l, tile(9, 6, |_, _| Texel::HOLE));
        let (a, b) = (world(&l, 0.5, 0.5, 1.0), world(&l, 8.5, 5.5, 2.0));
        let ray = Ray::new(a - (b - a), b - a, 0.0, f32::INFINITY);
        let (hit, stats) = r.closest_hit(&ray);
        assert_eq!(hit, Hit::MISS);
        assert!((8..=8 + 5 - 1).contains(&stats.counters.cells), "{stats:?}");
    }

    /// A deterministic bumpy tile with a few holes, in a rotated frame.
    fn bumpy() -> Rbvh {
        let w = Vec3::new(0.2, 1.0, -0.1).normalize();
        let u = w.cross(Vec3::Z).normalize();
        let v = w.cross(u);
        let (res_u, res_v) = (9, 7);
        let l = GpuHeightfield {
            origin: [-1.0, 0.5, 2.0],
            atlas_base: 3,
            axis_u: (u / 0.3).to_array(),
            res_u,
            axis_v: (v / 0.3).to_array(),
            res_v,
            axis_w: w.to_array(),
            h_scale: 1.0e-4,
        };
        // Odd codes (extrapolated heights): no skirt hangs under the rims, so the march meets the
        // cells' triangles alone, as the brute force does (the skirt has its own test).
        let code = |i: u32, j: u32| {
            let x = (i * 7919 + j * 104_729) % 65_521;
            (x * 13 % 30_000) as u16 | 1
        };
        // The tile starts 3 texels into each atlas row, after other (non-hole) texels.
        let samples = tile(res_u, res_v, |i, j| {
            if (i, j) == (4, 3) || (i, j) == (7, 1) || (i, j) == (1, 5) || (i, j) == (2, 5) {
                Texel::HOLE
            } else {
                Texel::new(code(i, j), w)
            }
        });
        let mut texels = Vec::new();
        for row in samples.chunks(res_u as usize) {
            texels.extend([Texel::new(0, Vec3::X); 3]);
            texels.extend_from_slice(row);
        }
        let atlas = Atlas {
            pitch: res_u + 3,
            rows: res_v,
            narrow_rows: 0,
            texels,
        };
        // A loose box, so that the march, not the box, decides at the tile's border.
        let mut child = hf_child(&l, 0);
        child.bounds.min -= Vec3::splat(0.1);
        child.bounds.max += Vec3::splat(0.1);
        let root = GpuNode::new(child, ChildRef::ABSENT);
        rbvh(vec![root], vec![], vec![l], atlas)
    }

    /// Every triangle of every cell, by brute force: the nearest hit in frame space.
    fn brute_force(r: &Rbvh, ray: &Ray) -> Option<f32> {
        let l = &r.leaves[0];
        let (u, v, w) = (
            Vec3::from(l.axis_u),
            Vec3::from(l.axis_v),
            Vec3::from(l.axis_w),
        );
        let rel = ray.origin() - Vec3::from(l.origin);
        let d = ray.dir();
        let frame = Ray::new(
            Vec3::new(rel.dot(u), rel.dot(v), rel.dot(w)),
            Vec3::new(d.dot(u), d.dot(v), d.dot(w)),
            ray.tmin,
            ray.tmax,
        );
        let shear = RayShear::new(&frame);
        let vertex = |i: u32, j: u32| {
            let t = r.atlas.texels[(l.atlas_base + j * r.atlas.pitch + i) as usize];
            (!t.is_hole()).then(|| {
                Vec3::new(
                    i as f32 + 0.5,
                    j as f32 + 0.5,
                    t.height_code() as f32 * l.h_scale,
                )
            })
        };
        let mut best: Option<f32> = None;
        for j in 0..l.res_v - 1 {
            for i in 0..l.res_u - 1 {
                let c = [
                    vertex(i, j),
                    vertex(i + 1, j),
                    vertex(i + 1, j + 1),
                    vertex(i, j + 1),
                ];
                for [a, b, c] in cell_triangles(c) {
                    if let Some(t) = intersect_triangle(&shear, a, b, c, frame.tmin, frame.tmax) {
                        best = Some(best.map_or(t, |x| x.min(t)));
                    }
                }
            }
        }
        best
    }

    #[test]
    fn march_agrees_with_brute_force_on_a_bumpy_tile() {
        let r = bumpy();
        let l = r.leaves[0];
        let mut hits = 0;
        let mut n = 0;
        for a in 0..12 {
            for b in 0..9 {
                n += 1;
                // Targets all over the tile and a little beyond; directions from steep to grazing,
                // from above and from below.
                let target = world(&l, -0.5 + 0.83 * a as f32, -0.3 + 0.81 * b as f32, 1.5);
                let phi = 0.7 * (a * 9 + b) as f32;
                let elevation = [0.05, 0.2, 0.6, 1.5, -0.3, 8.0][(a + b) as usize % 6];
                let dir = Vec3::new(phi.cos(), -elevation, phi.sin());
                let ray = Ray::new(target - 6.0 * dir, dir, 0.0, f32::INFINITY);
                let (hit, stats) = r.closest_hit(&ray);
                // At most 8 + 6 − 1 steps, each visiting one cell or two near a grid vertex.
                assert!(stats.counters.cells <= 2 * (8 + 6 - 1), "{stats:?}");
                let expected = brute_force(&r, &ray);
                assert_eq!(
                    hit.is_hit(),
                    expected.is_some(),
                    "ray {ray:?}: {hit:?} vs {expected:?}"
                );
                if let Some(t) = expected {
                    hits += 1;
                    assert_eq!(hit.t, t, "ray {ray:?}");
                    assert_eq!(hit.id, LEAF_BIT);
                }
            }
        }
        assert!(
            hits > n / 4 && hits < n,
            "{hits} of {n} hit: the test would not test much"
        );
    }

    #[test]
    fn tile_fits_checks_the_last_texel_and_refuses_rows_that_wrap() {
        let atlas = Atlas {
            pitch: 8,
            rows: 4,
            narrow_rows: 0,
            texels: vec![Texel::HOLE; 32],
        };
        let fits = |base, res_u, res_v| {
            tile_fits(
                &GpuHeightfield {
                    atlas_base: base,
                    ..flat_leaf(0.0, res_u, res_v, 0.0)
                },
                &atlas,
            )
        };
        assert!(fits(0, 8, 4) && fits(4, 4, 4) && fits(31, 1, 1));
        assert!(!fits(5, 4, 4) && !fits(0, 9, 1) && !fits(0, 0, 1) && !fits(32, 1, 1));
        assert!(!fits(u32::MAX, u32::MAX, u32::MAX));
        // Columns 6, 7 of one row, then 0, 1 of the next: in range, but wrapped.
        assert!(fits(6, 2, 2) && !fits(6, 3, 2) && !fits(14, 4, 1));
    }

    #[test]
    fn rays_through_grid_vertices_and_edges_agree_with_brute_force() {
        // Aimed exactly at every sample (a vertex shared by four cells) and every edge midpoint,
        // from all around, axis-aligned directions included: where the walk and the triangle
        // test could disagree about which cell a hit is in.
        let r = bumpy();
        let l = r.leaves[0];
        let mut n = 0;
        let mut hits = 0;
        for j in 0..l.res_v {
            for i in 0..l.res_u {
                let texel = r.atlas.texels[(l.atlas_base + j * r.atlas.pitch + i) as usize];
                let h = if texel.is_hole() {
                    1.0
                } else {
                    texel.height_code() as f32 * l.h_scale
                };
                for half in 0..4 {
                    let s = i as f32 + 0.5 + 0.5 * (half & 1) as f32;
                    let t = j as f32 + 0.5 + 0.5 * (half >> 1) as f32;
                    let target = world(&l, s, t, h);
                    for k in 0..24 {
                        let elevation = [0.02, 0.1, 0.3, 1.0, 3.0, -0.2][k % 6];
                        let phi = 0.37 * k as f32;
                        let dirs = [
                            Vec3::new(phi.cos(), -elevation, phi.sin()),
                            Vec3::new(1.0, -elevation, 0.0),
                            Vec3::new(0.0, -elevation, -1.0),
                            Vec3::new(-1.0, -elevation, 1.0),
                        ];
                        for dir in dirs {
                            let ray = Ray::new(target - 3.0 * dir, dir, 0.0, f32::INFINITY);
                            let (hit, _) = r.closest_hit(&ray);
                            let expected = brute_force(&r, &ray);
                            n += 1;
                            assert_eq!(hit.is_hit(), expected.is_some(), "{ray:?}: {hit:?}");
                            if let Some(t) = expected {
                                hits += 1;
                                assert!((hit.t - t).abs() <= 1e-5 * t, "{ray:?}: {} vs {t}", hit.t);
                            }
                        }
                    }
                }
            }
        }
        assert!(hits > n / 2, "{hits} of {n}");
    }
}
