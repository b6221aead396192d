//! The cells of a leaf's tile that a projected triangle meets, and the holes at their corners
//! that the triangle's plane fills: the footprint that steps 4 (the ring, the open boundary) and
//! 6 (the exposed triangles) of rasterizing a leaf (see [`super`]) work over.

use glam::{DVec3, Vec3};

use super::sample::{unit_normal, EDGE_ON_COS};
use super::Frame;
use crate::geom::sat::triangle_meets_square;

/// The `wanted` samples `(i, j)` at a corner of a cell that one of the `triangles` that `which`
/// picks (by index) overlaps in projection, each with the height of that triangle's plane over
/// it (clamped to the triangle's own height range) and the triangle's index, the first such
/// triangle's; sorted by sample. A leaf's full cells must cover its whole footprint, not only
/// the surroundings of the sample centres its triangles happen to hold: a sliver, or a triangle
/// smaller than a texel (a leaf of one, where the criterion allows nothing larger), may hold
/// none, and the ring around written samples left the rest of it bare; so the ring asks for the
/// holes with no written sample among their eight neighbours (which it samples anyway), and the
/// open boundary for the holes left at the end. A short list, not a map over the tile: most
/// corners are written or beside written samples.
pub(super) fn cell_corners(
    triangles: &[[Vec3; 3]],
    frame: &Frame,
    which: impl Fn(usize) -> bool,
    wanted: impl Fn(i64, i64) -> bool,
) -> Vec<(usize, f32, u32)> {
    let (res_u, res_v) = (frame.res_u as i64, frame.res_v as i64);
    let mut out = Vec::new();
    for (input, tri) in triangles.iter().enumerate() {
        if !which(input) {
            continue;
        }
        // As step 1: a face seen edge-on defines no height over a sample.
        let facing = unit_normal(tri);
        if facing.is_none_or(|n| n.dot(frame.w).abs() <= EDGE_ON_COS) {
            continue;
        }
        let p = tri.map(|q| frame.project(q));
        let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
        let det = e1.x * e2.y - e2.x * e1.y;
        if !det.is_finite() || det == 0.0 {
            continue;
        }
        // The plane h(x, y) = h0 + a·(x − x0) + b·(y − y0) through the three projected corners.
        let a = (e1.z * e2.y - e2.z * e1.y) / det;
        let b = (e2.z * e1.x - e1.z * e2.x) / det;
        let lo = p[0].min(p[1]).min(p[2]);
        let hi = p[0].max(p[1]).max(p[2]);
        let [i0, j0, i1, j1] = cell_range(lo, hi, res_u, res_v);
        for j in j0..=j1 {
            for i in i0..=i1 {
                if !triangle_meets_square(&p, i as f64, j as f64) {
                    continue;
                }
                for (ci, cj) in [(i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1)] {
                    if !wanted(ci, cj) {
                        continue;
                    }
                    let h = p[0].z + a * (ci as f64 - p[0].x) + b * (cj as f64 - p[0].y);
                    let h = h.clamp(lo.z, hi.z) as f32;
                    out.push(((cj * res_u + ci) as usize, h, input as u32));
                }
            }
        }
    }
    // First triangle wins: a stable sort keeps the order of equal samples.
    out.sort_by_key(|&(k, _, _)| k);
    out.dedup_by_key(|&mut (k, _, _)| k);
    out
}

/// The cells `[i0, j0, i1, j1]` of a `res_u` × `res_v` tile (by their lowest corner) that the box
/// from `lo` to `hi` (x, y in sample space) meets.
pub(super) fn cell_range(lo: DVec3, hi: DVec3, res_u: i64, res_v: i64) -> [i64; 4] {
    [
        (lo.x.floor() as i64).max(0),
        (lo.y.floor() as i64).max(0),
        (hi.x.floor() as i64).min(res_u - 2),
        (hi.y.floor() as i64).min(res_v - 2),
    ]
}

/// The cells `(i, j)` (by their lowest corner) of a `res_u` × `res_v` tile that the projected
/// triangle `p` (x, y in sample space) meets, edges included.
pub(super) fn cells_met(
    p: &[DVec3; 3],
    res_u: i64,
    res_v: i64,
) -> impl Iterator<Item = (i64, i64)> + '_ {
    let (lo, hi) = (p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2]));
    let [i0, j0, i1, j1] = cell_range(lo, hi, res_u, res_v);
    (j0..=j1)
        .flat_map(move |j| (i0..=i1).map(move |i| (i, j)))
        .filter(|&(i, j)| triangle_meets_square(p, i as f64, j as f64))
}
