//! Step 4 of the height-field march (see [`super`]): the **cell test**. A cell's surface is two
//! triangles through its four corner samples (three with one hole, none with more), tested after
//! a cheap height rejection with the watertight test of Woop, Benthin & Wald ("Watertight
//! Ray/Triangle Intersection", JCGT 2013) in frame space; neighbouring cells share their edge's
//! vertices bit for bit, so no ray slips between them.

use glam::Vec3;

use super::leaf::{texel, Cells};
use super::normal::{facet_normal, HitNormal};
use crate::geom::grid::height_at;
use crate::geom::intersect_triangle;
use crate::probe::{Probe, TraceStats};
use crate::rbvh::layout::Texel;
use crate::rbvh::TexelFormat;

impl Cells<'_> {
    /// Steps 4 and 5: intersects the ray with cell `(ci, cj)`, which it crosses over
    /// `[t_in, t_out]`; returns the nearest hit distance of the cell's triangles within the frame
    /// ray's interval, and the normal. Counts the cell in `cells_tested` when it gets past the
    /// height rejection; reports the four texel reads.
    ///
    /// Corners are indexed `k = di + 2·dj`: c00, c10, c01, c11. With all four present the surface
    /// is (c00, c10, c11) and (c00, c11, c01); with one hole, the triangle of the other three taken
    /// in the cycle order c00, c10, c11, c01 (so the winding stays that of the quad); with two or
    /// more holes there is no surface.
    pub(super) fn hit<P: Probe>(
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
            // The device reads a row's two codes together (`rbvh_atlas_tile_pair`).
            if let (0, Some(index)) = (k & 1, index) {
                probe.read(atlas.pair_read(index));
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

    /// The four corner texels of cell `(ci, cj)` (c00, c10, c01, c11), read without reporting:
    /// whether the cell is full, as the device knows from the corners it read for the cell test.
    pub(super) fn corners(&self, ci: i64, cj: i64) -> [Texel; 4] {
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
}

/// The first triangle of a cell with three or four samples (`corner`: c00, c10, c01, c11):
/// (c00, c10, c11) with four; with three, the three present in the cycle order c00, c10, c11,
/// c01, so that the winding stays the quad's (`rbvh_first_triangle` in `glsl/rbvh.glsl`).
pub(super) fn first_triangle(corner: &[Texel; 4]) -> [usize; 3] {
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

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::super::tests::*;
    use crate::rbvh::layout::{Texel, LEAF_BIT};

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
}
