//! Steps 1–3 of the height-field march (see [`super`]): the ray moved into the leaf's frame,
//! clipped to the tile's padded box, and walked through the cells it crosses, front to back, by
//! the 2D DDA of Amanatides & Woo ("A Fast Voxel Traversal Algorithm for Ray Tracing",
//! Eurographics 1987; [`crate::geom::grid`]), with the device's block jumps ([`super::blocks`]);
//! each cell goes to step 4 ([`super::cell`]) and its skirts ([`super::skirt`]).

use glam::Vec3;

use super::blocks::{Blocks, Clearance, Jump};
use super::leaf::{Cells, FrameRay};
use super::normal::HitNormal;
use super::Walk;
use crate::geom::grid::{Grid, GridRay, GridWalk};
use crate::geom::{safe_inverse, Aabb, Ray, RayShear};
use crate::probe::{element, Array, Probe, TraceStats};
use crate::rbvh::layout::{
    tile_fits, GpuHeightfield, Texel, MARCH_EDGE_PAD as EDGE_PAD,
    MARCH_SKIRT_TEXELS as SKIRT_TEXELS, MARCH_SLACK as SLACK,
};
use crate::rbvh::Rbvh;

/// The cells the walk steps through: between the tile's samples.
const CELLS: Grid = Grid::BETWEEN_SAMPLES;

impl Rbvh {
    /// Marches height-field leaf `leaf_index` for the ray's interval `[tmin, t_closest)`; returns
    /// the hit distance and the world-space normal. Steps as numbered in the module docs; with
    /// [`Walk::blocks`], the block jumps of `glsl/rbvh.glsl`'s `rbvh_march`, statement for
    /// statement.
    pub(super) fn march<P: Probe>(
        &self,
        leaf_index: u32,
        ray: &Ray,
        t_closest: f32,
        walk: Walk,
        stats: &mut TraceStats,
        probe: &mut P,
    ) -> Option<(f32, HitNormal)> {
        let leaf = self.heightfields.get(leaf_index as usize)?;
        probe.read(element::<GpuHeightfield>(
            Array::Heightfields,
            leaf_index as usize,
        ));
        // A tile needs two samples along each side to have a cell at all.
        if leaf.res_u < 2 || leaf.res_v < 2 || !tile_fits(leaf, &self.atlas) {
            return None;
        }
        // 1. Frame.
        let frame = frame_ray(leaf, ray, t_closest)?;
        let (o, d) = (frame.origin(), frame.dir());
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
        // The edge (its axis: 0 for s, 1 for t) the current cell was entered across, for the
        // skirt: the first cell's when the ray enters the tile's box through its s or t side, not
        // through its top or bottom nor from inside it.
        let near = ((tile.min - o) * inv).min((tile.max - o) * inv);
        let mut entered = if t0 <= frame.tmin {
            None
        } else if t0 == near.x {
            Some(0)
        } else if t0 == near.y {
            Some(1)
        } else {
            None
        };
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

        // 3. Walk. Where the ray passes a grid vertex closer than rounding can resolve, the walk
        // goes round it on one side while the watertight test may report the hit in the cell on
        // the other side; that cell is then tested too. `corner_slack` bounds, in texels, the
        // rounding of the frame coordinates the two tests work on. The same rounding at the
        // walk's ends: a flat tile's box is a slab thinner than it, tens of texels from the
        // origin, so where the entry lies that close to a boundary behind it the walk starts in
        // the cell behind (and where the box's exit lies that close to the boundary ahead, it
        // goes on into the cell there, below), lest the watertight test report the hit in a cell
        // the walk skipped (the default scene's ground: three in four of the rays aimed at its
        // leaves' rims that passed through).
        let corner_slack = SLACK * (o.x.abs() + o.y.abs() + leaf.res_u as f32 + leaf.res_v as f32);
        let grid = GridRay::new(
            CELLS,
            [o.x, o.y],
            [d.x, d.y],
            [inv.x, inv.y],
            [i64::from(leaf.res_u) - 2, i64::from(leaf.res_v) - 2],
        );
        let entry = o + d * t0;
        let mut w = GridWalk::new(
            grid,
            grid.start_cell([entry.x, entry.y], t0, corner_slack),
            t0,
        );
        // A straight line crosses each of the (res − 2) inner boundaries per axis at most once, so
        // it takes at most this many steps, each visiting one cell (two near a grid vertex).
        let max_steps = u64::from(leaf.res_u - 1) + u64::from(leaf.res_v - 1) - 1;
        let blocks = walk
            .blocks
            .map(|ranges| Blocks::of(&self.atlas, leaf, ranges, self.atlas.code_words()));
        let clearance = Clearance {
            o_h: o.z,
            d_h: d.z,
            h_scale: leaf.h_scale,
            slack,
            skirt_h: 1.001 * SKIRT_TEXELS / cells.uu.sqrt(),
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
                let past = entered.map(|axis| (w.t_in - t1) * grid.d[axis].abs());
                if !past.is_some_and(|past| past <= corner_slack) {
                    break;
                }
            }
            if let Some(b) = &blocks {
                match b.jump(&mut w, &mut checked_block, &clearance, t1, probe) {
                    Jump::Stay => {}
                    Jump::Jumped(crossed) => {
                        stats.counters.jumps += 1;
                        entered = crossed.or(entered);
                    }
                    Jump::Ended => {
                        stats.counters.jumps += 1;
                        break;
                    }
                }
            }
            // 4. The cell, and the skirts under its rims. (The device first leaves out the rims
            // a ray passes too high or too low to reach, `rbvh_rim_reach`: a filter that keeps
            // its inner loop small and changes no hit, which the skirt tests here decide alone.)
            stats.counters.cells += 1;
            let [ci, cj] = w.cell;
            let t_out = w.t_out().min(t1);
            let corner = cells.corners(ci, cj);
            let valid = corner.iter().filter(|c| !c.is_hole()).count();
            if let (Some(axis), true, true) = (entered, prev_open, valid >= 3) {
                let step = grid.step[axis];
                let hit = cells.skirt(&corner, (ci, cj), axis, step, w.t_in, probe);
                if hit.is_some() {
                    return hit;
                }
            }
            if valid == 3 {
                let hit = cells.diagonal_skirt(&corner, (ci, cj), w.t_in, t_out, probe);
                if hit.is_some() {
                    return hit;
                }
            }
            prev_open = valid < 4;
            let hit = cells.hit(ci, cj, w.t_in, t_out, stats, probe);
            if hit.is_some() {
                return hit;
            }
            if let Some([xi, xj]) = w.across_vertex(corner_slack) {
                stats.counters.cells += 1;
                let t_x = w.next[0].max(w.next[1]).min(t1);
                let hit = cells.hit(xi, xj, t_out, t_x, stats, probe);
                if hit.is_some() {
                    return hit;
                }
            }
            match w.advance() {
                Some(axis) => entered = Some(axis),
                None => break,
            }
        }
        None
    }
}

/// The ray in `leaf`'s frame `(s, t, h)` over `[tmin, t_closest)` (step 1), or `None` where
/// degenerate or non-finite axes (corrupt data) give a ray no test can answer.
fn frame_ray(leaf: &GpuHeightfield, ray: &Ray, t_closest: f32) -> Option<Ray> {
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
    frame.is_valid().then_some(frame)
}

/// The exit distance of a ray from `b`: the far end of the slab test of [`Aabb::intersect`]. It
/// needs no widening against rounding here: the box is already `slack` taller than any surface.
fn box_exit(b: &Aabb, o: Vec3, inv: Vec3) -> f32 {
    let t0 = (b.min - o) * inv;
    let t1 = (b.max - o) * inv;
    t0.max(t1).min_element()
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::super::tests::*;
    use super::*;
    use crate::bvh::{ChildRef, GpuNode};
    use crate::geom::{intersect_triangle, Hit, Ray};
    use crate::rbvh::layout::{cell_triangles, Atlas, GpuHeightfield, Texel, LEAF_BIT};
    use crate::rbvh::Rbvh;

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
        let l = loose.heightfields[0];
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
            packed_rows: [0; 3],
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
        let l = &r.heightfields[0];
        // The march's own frame, so that both test the same frame-space triangles.
        let frame = frame_ray(l, ray, ray.tmax).expect("the test's rays are valid");
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
        let l = r.heightfields[0];
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
    fn rays_through_grid_vertices_and_edges_agree_with_brute_force() {
        // Aimed exactly at every sample (a vertex shared by four cells) and every edge midpoint,
        // from all around, axis-aligned directions included: where the walk and the triangle
        // test could disagree about which cell a hit is in.
        let r = bumpy();
        let l = r.heightfields[0];
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
