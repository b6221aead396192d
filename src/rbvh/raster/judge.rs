//! Step 3 of rasterizing a leaf (see [`super`]): judging the surface as sampled, not the
//! triangles, by the leaf's refinement criterion — beyond the paper (Novák & Dachsbacher 2012),
//! which judges the triangles: below the sampling rate a scan's noise cannot be represented, and
//! judging it would cut the scan into leaves of a few texels. The cells are the march's own
//! ([`cell_triangles`]).

use glam::DVec3;

use super::NONE;
use crate::rbvh::layout::cell_triangles;
use crate::rbvh::Refinement;

/// Step 3's judgement: whether the surface as sampled (`height`, world units along `w`, where
/// `source` is not [`NONE`]) passes `refinement`. Sample `(i, j)` is the point
/// `(i·texel, j·texel, height)`; each cell contributes the march's triangles over its written
/// corners ([`cell_triangles`]), each judged by its normal's `w` component.
pub(in crate::rbvh) fn sampled_passes(
    refinement: Refinement,
    height: &[f32],
    source: &[u32],
    res_u: usize,
    res_v: usize,
    texel: f32,
) -> bool {
    let texel = texel as f64;
    let point = |i: usize, j: usize| {
        let k = j * res_u + i;
        (source[k] != NONE)
            .then(|| DVec3::new(i as f64 * texel, j as f64 * texel, height[k] as f64))
    };
    // Σ |n·w|, Σ |n| over the cell triangles (twice their projected and true areas), and the
    // smallest cosine between a cell normal and `w`.
    let (mut projected, mut total, mut min_cos) = (0.0f64, 0.0f64, 1.0f64);
    let mut judged = false;
    for j in 0..res_v.saturating_sub(1) {
        for i in 0..res_u.saturating_sub(1) {
            let corners = [
                point(i, j),
                point(i + 1, j),
                point(i + 1, j + 1),
                point(i, j + 1),
            ];
            for [a, b, c] in cell_triangles(corners) {
                let n = (b - a).cross(c - a);
                let len = n.length();
                if len > 0.0 {
                    judged = true;
                    projected += n.z.abs();
                    total += len;
                    min_cos = min_cos.min(n.z.abs() / len);
                }
            }
        }
    }
    judged
        && match refinement {
            Refinement::NormalCone { max_angle_deg } => {
                min_cos >= f64::from(max_angle_deg).to_radians().cos()
            }
            Refinement::ProjectedArea { min_ratio } => projected >= f64::from(min_ratio) * total,
        }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::super::rasterize;
    use super::super::tests::{plain, xy_frame};
    use crate::rbvh::Refinement;

    /// A grid of `n × n` vertices spaced `spacing` over the xy plane at heights `h(i, j)`, two
    /// triangles per grid cell, wound to face +z.
    fn grid_mesh(n: usize, spacing: f32, h: impl Fn(usize, usize) -> f32) -> Vec<[Vec3; 3]> {
        let p = |i: usize, j: usize| Vec3::new(i as f32 * spacing, j as f32 * spacing, h(i, j));
        let mut tris = Vec::new();
        for j in 0..n - 1 {
            for i in 0..n - 1 {
                tris.push([p(i, j), p(i + 1, j), p(i + 1, j + 1)]);
                tris.push([p(i, j), p(i + 1, j + 1), p(i, j + 1)]);
            }
        }
        tris
    }

    /// Sub-texel noise (a checkerboard of 0.4-texel bumps on a quarter-texel mesh: its triangles
    /// slope 66° off the axis) fails the triangles' cone of 60° and their projected-area ratio of
    /// 0.9, but its samples (at texel centres, every fourth vertex, all at height 0) pass both; a ridge sloping 63°
    /// at texel scale fails both on its samples as well.
    #[test]
    fn the_sampled_surface_is_judged_at_the_sampling_rate() {
        let frame = xy_frame(8);
        let noisy = grid_mesh(33, 0.25, |i, j| if (i + j) % 2 == 1 { 0.4 } else { 0.0 });
        let ridge = grid_mesh(33, 0.25, |i, _| 2.0 * (i as f32 * 0.25 - 4.0).abs());
        let criteria = [
            Refinement::NormalCone {
                max_angle_deg: 60.0,
            },
            Refinement::ProjectedArea { min_ratio: 0.9 },
        ];
        for criterion in criteria {
            for tris in [&noisy, &ridge] {
                assert!(!crate::rbvh::frame::passes(
                    criterion,
                    &crate::rbvh::frame::triangle_elements(tris),
                    Vec3::Z
                ));
                assert!(plain(tris, &frame, 1.0).is_some());
            }
            let tile =
                rasterize(&noisy, &frame, 1.0, Some(criterion), None, &[]).expect("noise passes");
            assert_eq!(tile.covered, 64);
            assert!(
                rasterize(&ridge, &frame, 1.0, Some(criterion), None, &[]).is_none(),
                "{criterion:?}: the ridge passed"
            );
        }
        // At 70° the ridge's 63° passes on its samples.
        let wide = Refinement::NormalCone {
            max_angle_deg: 70.0,
        };
        assert!(rasterize(&ridge, &frame, 1.0, Some(wide), None, &[]).is_some());
    }

    /// A tile whose written samples form no cell (one sliver covering a single sample centre) has
    /// no sampled surface to judge, so it fails: the judgement never passes for want of cells.
    #[test]
    fn a_tile_without_cells_fails_the_sampled_judgement() {
        let frame = xy_frame(4);
        let sliver = vec![[
            Vec3::new(1.4, 1.4, 0.0),
            Vec3::new(1.6, 1.4, 0.0),
            Vec3::new(1.5, 1.7, 0.0),
        ]];
        let criterion = Refinement::NormalCone {
            max_angle_deg: 60.0,
        };
        assert_eq!(plain(&sliver, &frame, 1.0).unwrap().covered, 1);
        assert!(rasterize(&sliver, &frame, 1.0, Some(criterion), None, &[]).is_none());
    }
}
