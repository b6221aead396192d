//! The skirts of the height-field march (with step 4 of [`super`]; issue "No leaks between height
//! fields"): a skirt hangs [`SKIRT_TEXELS`] under a cell's edge that a ray enters from a cell
//! with a hole or through the tile's side, and [`DIAGONAL_SKIRT_TEXELS`] under the diagonal of a
//! cell of three samples that faces its hole, so that a ray cannot slip under a rim where
//! neighbouring leaves meet. `layout.rs` says how deep and why.

use glam::Vec3;

use super::cell::first_triangle;
use super::leaf::{texel, Cells};
use super::normal::{facet_normal, HitNormal};
use crate::geom::grid::height_at;
use crate::probe::Probe;
use crate::rbvh::layout::{
    Texel, MARCH_DIAGONAL_SKIRT_TEXELS as DIAGONAL_SKIRT_TEXELS, MARCH_SKIRT_TEXELS as SKIRT_TEXELS,
};
use crate::rbvh::TexelFormat;

impl Cells<'_> {
    /// The skirt ([`SKIRT_TEXELS`]) under the edge of cell `(ci, cj)` that the ray entered at
    /// `t_in` from a cell with fewer than four samples or through the tile's side:
    /// the edge on `axis` (0: an `s` boundary, 1: a `t` boundary) crossed by a ray stepping
    /// `step` along it, when both its samples are present (so the cell's surface has that edge).
    /// A hit at `t_in` when the ray is below the edge by at most the skirt's depth there
    /// ([`Cells::skirt_depth`] of [`SKIRT_TEXELS`]).
    pub(super) fn skirt<P: Probe>(
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
    pub(super) fn diagonal_skirt<P: Probe>(
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
        // The device read the cell's four corners before this test, as for any cell: a row's two
        // codes together.
        for row in 0..2 {
            if let (_, Some(index)) = texel(atlas, leaf, ci, cj + row) {
                probe.read(atlas.pair_read(index));
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
    use glam::Vec3;

    use super::super::tests::*;
    use crate::geom::Ray;
    use crate::rbvh::layout::{Texel, LEAF_BIT};
    use crate::rbvh::Rbvh;

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
}
