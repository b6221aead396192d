//! Step 4 of rasterizing a leaf (see [`super`]), its **ring from the surface itself** (issue "No
//! leaks between height fields"): the holes around the written samples, and at the corners of
//! the cells the leaf's triangles overlap, sampled from the scene's triangles by two short rays
//! along `±w`, so that neighbouring leaves overlap on the real surface rather than on a linear
//! extrapolation.

use glam::Vec3;

use super::cells::cell_corners;
use super::sample::EDGE_ON_COS;
use super::{written_at, Frame, NONE};
use crate::bvh::LinearBvh;
use crate::geom::{Aabb, Ray};
use crate::rbvh::Refinement;

/// How far from its written neighbours' mean height a ring sample may find the surface, in
/// texels, at least: 2 where 3 made leaf boxes taller for nothing (dragon at the presets: the
/// same or fewer seam leaks, t p99 the same or better, 3% fewer cells per ray at Q0; 1.5 lost
/// accuracy, t p99 +7%; 3 and 4 for every leaf cost its Q0 t p99 0.150 → 0.155 and 0.170%).
pub(super) const RING_REACH: f32 = 2.0;

/// How far a ring sample may find the surface at most, in texels ([`ring_reach`]): at 8 the ring
/// of leaves seen nearly edge-on reached other sheets across creases (dragon at φ_max 89.5°:
/// t p99 0.207 → 0.301%, where 4 gave 0.193%).
const MAX_RING_REACH: f32 = 4.0;

/// How far from its written neighbours' mean height a leaf's ring sample may find the surface,
/// in texels, for a leaf built to `refinement`: the slope the criterion lets its surface have
/// (the tangent of the largest angle between its normals and its axis, or of the angle whose
/// cosine is the least projected area ratio), within [`RING_REACH`] and [`MAX_RING_REACH`]. The
/// presets' 60° allows 1.7 texels a texel, so they keep 2; leaves seen nearly edge-on rise
/// further within the texel to their ring, and with 2 their rings found no surface over many
/// corners, left bare (1M seam rays at Q0, 2 → 4: φ_max 89.5° dragon 21 → 3 leaks, bunny
/// 75 → 50; A⊥/A 0.01 dragon 4,475 → 2,887, bunny 3,916 → 3,173; t p99 better on all four).
pub(in crate::rbvh) fn ring_reach(refinement: Refinement) -> f32 {
    let cos = match refinement {
        Refinement::NormalCone { max_angle_deg } => max_angle_deg.to_radians().cos(),
        Refinement::ProjectedArea { min_ratio } => min_ratio,
    };
    // `refinement` is validated: the cosine lies in (0, 1].
    let slope = (1.0 - cos * cos).max(0.0).sqrt() / cos;
    slope.clamp(RING_REACH, MAX_RING_REACH)
}

/// Where a leaf's ring of samples comes from (step 4 of [`super`]): the scene's triangles in a
/// BVH, searched `reach` texels either side of each sample's estimate ([`ring_reach`]).
#[derive(Clone, Copy)]
pub struct Ring<'a> {
    /// The scene's triangles, the leaf's own among them.
    pub surface: &'a LinearBvh<'a>,
    /// How far from its estimate a ring sample may find the surface, in texels.
    pub reach: f32,
}

/// A ring sample taken from the surface itself: its height, the normal of the triangle it lies
/// on, and the index in the leaf's triangles of the one it stands beside (whose source it reports
/// for colours).
pub(super) struct RingSample {
    pub(super) height: f32,
    pub(super) normal: Vec3,
    pub(super) input: u32,
}

/// The [`cell_corners`] the ring asks for: holes with no written sample (`source`) among their
/// eight neighbours, at the corners of any of the leaf's triangles' cells.
pub(super) fn ring_corners(
    triangles: &[[Vec3; 3]],
    frame: &Frame,
    source: &[u32],
) -> Vec<(usize, f32, u32)> {
    let written = |i: i64, j: i64| written_at(source, frame.res_u as usize, i, j).is_some();
    cell_corners(
        triangles,
        frame,
        |_| true,
        |ci, cj| !(-1..=1).any(|dj| (-1..=1).any(|di| written(ci + di, cj + dj))),
    )
}

/// The ring around the written samples (holes with a written sample among their eight
/// neighbours) and the `corners` ([`cell_corners`]), sampled from `ring.surface` — the scene's
/// triangles, the leaf's own among them — where one of them lies over the sample within
/// `ring.reach` texels of an estimate (the nearest such): the written neighbours' mean height,
/// or for a corner without any the plane of the triangle that needs it. The leaf's surface then
/// continues onto its neighbours' real surface, corners included, instead of a linear
/// extrapolation that sticks out at silhouettes. Each ring sample is found by two short rays
/// along `±w` from its estimate (the second only as far as the first one's hit), so the cost follows the ring's length, not how many triangles lie
/// near the tile: gathering and rasterizing those grew without bound where triangles are much
/// smaller than a texel (the paper-scale scene's Q2 took 98 s; 22 s by rays, below its exact BVH).
pub(super) fn ring_from_surface(
    ring: Ring,
    frame: &Frame,
    height: &[f32],
    source: &[u32],
    input_index: &[u32],
    corners: &[(usize, f32, u32)],
) -> Vec<(usize, RingSample)> {
    let (res_u, res_v) = (frame.res_u as usize, frame.res_v as usize);
    let reach = ring.reach * frame.texel;
    // Each ring sample's estimate, then the rays: they all lie within `reach` of their
    // estimates along `±w`, so each is traced from the subtree of the scene's BVH over that
    // region, in the same steps as from its root.
    let mut estimates = Vec::new();
    for j in 0..res_v {
        for i in 0..res_u {
            let k = j * res_u + i;
            if source[k] != NONE {
                continue;
            }
            let (mut sum, mut n, mut beside) = (0.0f32, 0u32, NONE);
            for dj in -1i64..=1 {
                for di in -1i64..=1 {
                    if let Some(q) = written_at(source, res_u, i as i64 + di, j as i64 + dj) {
                        sum += height[q];
                        n += 1;
                        beside = source[q];
                    }
                }
            }
            // Beside written samples, their mean height; else the plane of a triangle whose cell
            // needs the sample as a corner.
            let (estimate, input) = if n > 0 {
                (sum / n as f32, input_index[beside as usize])
            } else if let Ok(c) = corners.binary_search_by_key(&k, |&(k, _, _)| k) {
                (corners[c].1, corners[c].2)
            } else {
                continue;
            };
            let from = frame.origin
                + (i as f32 + 0.5) * frame.texel * frame.u
                + (j as f32 + 0.5) * frame.texel * frame.v
                + estimate * frame.w;
            estimates.push((k, estimate, input, from));
        }
    }
    // A sample whose estimate is not finite casts rays that trace nothing (`Ray::is_valid`);
    // its NaN would make the box forget the samples before it.
    let region = estimates
        .iter()
        .filter(|&&(_, _, _, from)| from.is_finite())
        .fold(Aabb::EMPTY, |b, &(_, _, _, from)| {
            b.grow(from - reach * frame.w).grow(from + reach * frame.w)
        });
    let root = ring.surface.subtree_over(region);
    // The nearest hit before `tmax` along `dir` from `from` on a face not seen edge-on (which
    // covers no sample centre in a way that defines one height, as in step 1).
    let probe = |from: Vec3, dir: Vec3, tmax: f32| {
        let facing = |n: Vec3| n.dot(frame.w).abs() > EDGE_ON_COS;
        let hit = ring
            .surface
            .closest_hit_from(root, &Ray::new(from, dir, 0.0, tmax), facing);
        hit.is_hit().then_some(hit)
    };
    let mut ring = Vec::new();
    for (k, estimate, input, from) in estimates {
        // Downwards only as far as the surface found upwards: only nearer counts (nothing
        // is nearer than a hit at the estimate itself).
        let up = probe(from, frame.w, reach);
        let down = match up {
            Some(h) if h.t == 0.0 => None,
            _ => probe(from, -frame.w, up.map_or(reach, |h| h.t)),
        };
        let nearest = match (up, down) {
            (_, Some(down)) => Some((estimate - down.t, down)),
            (Some(up), None) => Some((estimate + up.t, up)),
            (None, None) => None,
        };
        if let Some((height, hit)) = nearest {
            ring.push((
                k,
                RingSample {
                    height,
                    normal: hit.normal(),
                    input,
                },
            ));
        }
    }
    ring
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::super::rasterize;
    use super::super::tests::{decoded, plain, quantum, square, xy_frame};
    use super::*;

    /// A scene of one object, `name`, made of the triangles `tris` (unshared corners): the
    /// surface a leaf's ring samples.
    fn scene_of(name: &str, tris: &[[Vec3; 3]]) -> crate::scene::Scene {
        let mut scene = crate::scene::Scene::new(name);
        let positions: Vec<Vec3> = tris.iter().flatten().copied().collect();
        let indices: Vec<[u32; 3]> = (0..tris.len() as u32)
            .map(|k| [3 * k, 3 * k + 1, 3 * k + 2])
            .collect();
        scene.push_object(name, &positions, &indices);
        scene
    }

    #[test]
    fn the_ring_reaches_as_far_as_the_criterion_lets_the_surface_rise() {
        let cone = |max_angle_deg| ring_reach(Refinement::NormalCone { max_angle_deg });
        let area = |min_ratio| ring_reach(Refinement::ProjectedArea { min_ratio });
        // The presets' 60° (1.73 texels a texel) and anything flatter keep the least reach.
        assert_eq!(cone(60.0), RING_REACH);
        assert_eq!(cone(0.5), RING_REACH);
        assert_eq!(area(1.0), RING_REACH);
        // Steeper, the slope: tan 70° = 2.75.
        assert!((cone(70.0) - 70f32.to_radians().tan()).abs() < 1e-5);
        assert!((area(0.3) - (1.0f32 - 0.09).sqrt() / 0.3).abs() < 1e-5);
        // Nearly edge-on, at most MAX_RING_REACH.
        assert_eq!(cone(89.5), MAX_RING_REACH);
        assert_eq!(area(0.01), MAX_RING_REACH);
    }

    #[test]
    fn the_ring_follows_the_neighbouring_surface_nearest_the_rim() {
        let frame = xy_frame(16);
        // The leaf: flat at height 3 over samples 4..=11. Beyond its +u side the scene bends up
        // (slope 1), and a decoy layer lies 1.9 above the rim there, also within reach.
        let own = square(&frame, 4.0, 12.0, |_, _| 3.0);
        let bend = |s: f32, _: f32| 3.0 + (s - 12.0);
        let p = |s: f32, t: f32, h: f32| Vec3::new(s, t, h);
        let mut scene_tris = own.clone();
        scene_tris.push([p(12.0, 4.0, 3.0), p(16.0, 4.0, 7.0), p(16.0, 12.0, 7.0)]);
        scene_tris.push([p(12.0, 4.0, 3.0), p(16.0, 12.0, 7.0), p(12.0, 12.0, 3.0)]);
        scene_tris.push([p(12.0, 4.0, 4.9), p(16.0, 4.0, 4.9), p(16.0, 12.0, 4.9)]);
        scene_tris.push([p(12.0, 4.0, 4.9), p(16.0, 12.0, 4.9), p(12.0, 12.0, 4.9)]);
        let scene = scene_of("bend", &scene_tris);
        let surface = LinearBvh::build(&scene, 4).expect("builds");
        let ring = Ring {
            surface: &surface,
            reach: RING_REACH,
        };
        let tile = rasterize(&own, &frame, 0.01, None, Some(ring), &[]).unwrap();
        let plain = plain(&own, &frame, 0.01).unwrap();
        for j in 4..=11u32 {
            // +u: the bent surface at the ring sample's centre, not the flat extrapolation
            // nor the decoy, marked as sampled; -u, where no surface continues: the
            // extrapolation, marked as such (no skirt hangs under it).
            let k = (j * 16 + 12) as usize;
            let got = decoded(&tile, k, frame.origin);
            assert!(
                (got - bend(12.5, 0.0)).abs() < quantum(&tile) + 1e-3,
                "({j}): {got}"
            );
            assert!(tile.texels[k].is_sampled());
            assert!((decoded(&plain, k, frame.origin) - 3.0).abs() < quantum(&plain) + 1e-3);
            assert!(!plain.texels[k].is_sampled());
            let k = (j * 16 + 3) as usize;
            assert!((decoded(&tile, k, frame.origin) - 3.0).abs() < quantum(&tile) + 1e-3);
            assert!(!tile.texels[k].is_sampled());
        }
    }

    /// The lid's sink follows the ring's reach through [`rasterize`]
    /// (`exposed::lid_sink_texels`): a sliver of the leaf's own, a texel under the lid over its
    /// rim (a cell whose outer corners the ring extrapolated: no surface continues there), is
    /// traced exactly where the ring reaches as far as an edge-on criterion's, not where it
    /// reaches the presets'.
    #[test]
    fn a_sliver_a_texel_under_the_lid_is_exact_only_at_edge_on_criteria() {
        let frame = xy_frame(16);
        // The leaf: flat at height 3 over samples 4..=11; the cells between samples 3 and 4
        // have their -u corners extrapolated. The sliver lies inside one of them, holding no
        // sample centre, at height 2, facing +w.
        let mut own = square(&frame, 4.0, 12.0, |_, _| 3.0);
        let p = |x: f32, y: f32| Vec3::new(x, y, 2.0);
        own.push([p(3.7, 6.7), p(4.3, 6.7), p(3.9, 7.3)]);
        let sliver = (own.len() - 1) as u32;
        let scene = scene_of("lid", &own);
        let surface = LinearBvh::build(&scene, 4).expect("builds");
        for (reach, exact) in [(RING_REACH, false), (MAX_RING_REACH, true)] {
            let ring = Ring {
                surface: &surface,
                reach,
            };
            let tile = rasterize(&own, &frame, 0.01, None, Some(ring), &[]).unwrap();
            // Its cell's -u corners are extrapolated, its +u corners sampled at 3.
            let (rim, inner) = ((6 * 16 + 3) as usize, (6 * 16 + 4) as usize);
            assert!(!tile.texels[rim].is_sampled() && tile.texels[inner].is_sampled());
            let found = tile.exposed.iter().any(|e| e.input == sliver);
            assert_eq!(found, exact, "reach {reach}: {:?}", tile.exposed);
        }
    }

    #[test]
    fn cells_under_a_triangle_without_sample_centres_get_their_corners() {
        let frame = xy_frame(8);
        // A triangle inside the cell between samples 3 and 4 on both axes, holding no centre,
        // on the plane h = 2 + x (sample space): nothing written, four corners wanted.
        let p = |x: f32, y: f32| Vec3::new(x + 0.5, y + 0.5, 2.0 + x);
        let sliver = [[p(3.2, 3.2), p(3.8, 3.3), p(3.3, 3.8)]];
        let source = vec![NONE; 64];
        let corners = ring_corners(&sliver, &frame, &source);
        let at: Vec<(usize, f32)> = corners.iter().map(|&(k, h, _)| (k, h)).collect();
        // Corners (3, 3), (4, 3), (3, 4), (4, 4); heights from the plane, clamped to the
        // triangle's own range [5.2, 5.8].
        assert_eq!(at, [(27, 5.2), (28, 5.8), (35, 5.2), (36, 5.8)]);
        // Beside a written sample, a corner is left to the ring around it.
        let mut written = source.clone();
        written[26] = 0;
        let corners = ring_corners(&sliver, &frame, &written);
        assert!(
            corners.iter().all(|&(k, _, _)| k == 36 || k == 28),
            "{corners:?}"
        );
        // Seen edge-on, a triangle wants nothing.
        let edge_on = [[
            Vec3::new(3.6, 3.6, 0.0),
            Vec3::new(4.4, 3.6, 0.0),
            Vec3::new(3.6, 3.6, 1.0),
        ]];
        assert!(ring_corners(&edge_on, &frame, &source).is_empty());
    }
}
