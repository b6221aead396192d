//! Step 4 of rasterizing a leaf (see [`super`]), after the ring: the **walls**. Where the
//! leaf's own triangles fall (or rise) further than an extrapolated sample within the texel
//! beside the rim, the sample takes their extreme, so that the cell walls the surface down to
//! where the leaf's triangles end (issue "No leaks between height fields").

use glam::{DVec3, Vec3};

use super::{Frame, NONE};

/// Step 4's walls: for each extrapolated sample (dilated, not taken from the surface by the
/// ring) and each `written` 4-neighbour it extends, that direction's extrapolation is replaced
/// by the lowest height of the leaf's own triangles between the two where the extrapolation goes
/// down and the triangles fall further (the highest, where both rise), and the sample takes the
/// mean over the directions, as `dilate` does. Where a leaf's surface turns edge-on at its rim (a
/// silhouette seen from `w`), the linear extrapolation stops short of where the surface ends, and
/// the gap to the neighbouring leaf, tens of texels tall on a hemisphere seen from its pole, let
/// rays through; the cell from the last sample to the moved one walls it off, within the texel
/// beside the rim. Where the triangles end before they pass the extrapolation (a plane, a gentle
/// crease, an open boundary) nothing moves. Returns the samples it moved that lie a texel or more
/// above or below a written 4-neighbour (a cell steeper than 45°): their heights lie on the
/// surface's edge-on rim, so `rasterize` marks them sampled, and the skirt hangs under them.
pub(super) fn walls(
    triangles: &[[Vec3; 3]],
    frame: &Frame,
    written: &[bool],
    source: &[u32],
    sampled: &[bool],
    height: &mut [f32],
) -> Vec<usize> {
    let (res_u, res_v) = (frame.res_u as i64, frame.res_v as i64);
    let wanted = |i: i64, j: i64| {
        (0..res_u).contains(&i)
            && (0..res_v).contains(&j)
            && source[(j * res_u + i) as usize] != NONE
            && !sampled[(j * res_u + i) as usize]
    };
    let is_written = |i: i64, j: i64| {
        (0..res_u).contains(&i) && (0..res_v).contains(&j) && written[(j * res_u + i) as usize]
    };
    const DIRECTIONS: [(i64, i64); 4] = [(-1, 0), (1, 0), (0, -1), (0, 1)];
    // Per extrapolated sample met (`slot` into `ranges`, in `samples`) and direction towards a
    // written neighbour, the height range of the own triangles over the segment between them.
    let mut slot = vec![u32::MAX; source.len()];
    let mut ranges: Vec<[(f64, f64); 4]> = Vec::new();
    let mut samples: Vec<usize> = Vec::new();
    for tri in triangles {
        let p = tri.map(|q| frame.project(q));
        if p.iter().any(|q| !q.is_finite()) {
            continue;
        }
        let lo = p[0].min(p[1]).min(p[2]);
        let hi = p[0].max(p[1]).max(p[2]);
        for j in (lo.y.floor() as i64 - 1).max(0)..=(hi.y.ceil() as i64 + 1).min(res_v - 1) {
            for i in (lo.x.floor() as i64 - 1).max(0)..=(hi.x.ceil() as i64 + 1).min(res_u - 1) {
                if !wanted(i, j) {
                    continue;
                }
                for (dir, &(di, dj)) in DIRECTIONS.iter().enumerate() {
                    if !is_written(i + di, j + dj) {
                        continue;
                    }
                    // The segment from the neighbour to the sample, along x (dj = 0) or y.
                    let along_x = dj == 0;
                    let (plane, a0, a1) = if along_x {
                        (j as f64, (i + di).min(i) as f64, (i + di).max(i) as f64)
                    } else {
                        (i as f64, (j + dj).min(j) as f64, (j + dj).max(j) as f64)
                    };
                    let off = |q: DVec3| if along_x { q.y - plane } else { q.x - plane };
                    let pos = |q: DVec3| if along_x { q.x } else { q.y };
                    // Where the triangle meets the segment's vertical plane: at most a corner
                    // and a crossing per edge.
                    let mut pts = [(0.0f64, 0.0f64); 6];
                    let mut count = 0;
                    for e in 0..3 {
                        let (a, b) = (p[e], p[(e + 1) % 3]);
                        let (da, db) = (off(a), off(b));
                        if da == 0.0 {
                            pts[count] = (pos(a), a.z);
                            count += 1;
                        }
                        if (da < 0.0 && db > 0.0) || (da > 0.0 && db < 0.0) {
                            let t = da / (da - db);
                            let q = a + (b - a) * t;
                            pts[count] = (pos(q), q.z);
                            count += 1;
                        }
                    }
                    let pts = &pts[..count];
                    let k = (j * res_u + i) as usize;
                    if slot[k] == u32::MAX {
                        slot[k] = ranges.len() as u32;
                        ranges.push([(f64::INFINITY, f64::NEG_INFINITY); 4]);
                        samples.push(k);
                    }
                    let entry = &mut ranges[slot[k] as usize][dir];
                    for x in 0..pts.len() {
                        for y in x..pts.len() {
                            let ((xa, ha), (xb, hb)) = (pts[x], pts[y]);
                            let (ta, tb) = if xa == xb {
                                if xa < a0 || xa > a1 {
                                    continue;
                                }
                                (0.0, 1.0)
                            } else {
                                let t0 = ((a0 - xa) / (xb - xa)).clamp(0.0, 1.0);
                                let t1 = ((a1 - xa) / (xb - xa)).clamp(0.0, 1.0);
                                let (t0, t1) = (t0.min(t1), t0.max(t1));
                                let (x0, x1) = (xa + (xb - xa) * t0, xa + (xb - xa) * t1);
                                if x1 < a0 || x0 > a1 {
                                    continue;
                                }
                                (t0, t1)
                            };
                            for t in [ta, tb] {
                                let h = ha + (hb - ha) * t;
                                entry.0 = entry.0.min(h);
                                entry.1 = entry.1.max(h);
                            }
                        }
                    }
                }
            }
        }
    }
    // Per sample, each direction whose extrapolation the triangles pass that way: the lowest
    // (highest) of their extremes where some fall (rise) further; the sample as dilated where
    // none do.
    let mut steep_walls = Vec::new();
    samples.sort_unstable();
    for k in samples {
        let (i, j) = ((k as i64) % res_u, (k as i64) / res_u);
        let (mut down, mut up) = (f64::INFINITY, f64::NEG_INFINITY);
        for (dir, &(di, dj)) in DIRECTIONS.iter().enumerate() {
            let (lo, hi) = ranges[slot[k] as usize][dir];
            if lo > hi {
                continue;
            }
            let h1 = height[((j + dj) * res_u + i + di) as usize] as f64;
            let e = if is_written(i + 2 * di, j + 2 * dj) {
                2.0 * h1 - height[((j + 2 * dj) * res_u + i + 2 * di) as usize] as f64
            } else {
                h1
            };
            if e <= h1 && lo < e {
                down = down.min(lo);
            } else if e >= h1 && hi > e {
                up = up.max(hi);
            }
        }
        // Down wins where directions disagree: the wall under a silhouette.
        let before = height[k];
        if down.is_finite() {
            height[k] = height[k].min(down as f32);
        } else if up.is_finite() {
            height[k] = height[k].max(up as f32);
        }
        let steep = || {
            DIRECTIONS.iter().any(|&(di, dj)| {
                is_written(i + di, j + dj)
                    && (height[((j + dj) * res_u + i + di) as usize] - height[k]).abs()
                        >= frame.texel
            })
        };
        if height[k] != before && steep() {
            steep_walls.push(k);
        }
    }
    steep_walls
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::super::tests::{decoded, plain, quantum, square, xy_frame};

    /// A flat top (height 5) whose last texel falls steeply (slope 5) to height 0 at s = 8.2:
    /// the dilated sample beyond it (i = 8) would continue the slope only to 2; the wall takes
    /// it down to 0, where the leaf's own triangles end, and marks it sampled (steeper than 45°:
    /// the skirt hangs under it). The flat side (i = 1) extends flat, unmoved.
    #[test]
    fn walls_take_extrapolated_samples_down_to_where_the_own_surface_ends() {
        let frame = xy_frame(16);
        let p = |s: f32, t: f32, h: f32| Vec3::new(s, t, h);
        let tris = vec![
            [p(2.0, 2.0, 5.0), p(7.2, 2.0, 5.0), p(7.2, 12.0, 5.0)],
            [p(2.0, 2.0, 5.0), p(7.2, 12.0, 5.0), p(2.0, 12.0, 5.0)],
            [p(7.2, 2.0, 5.0), p(8.2, 2.0, 0.0), p(8.2, 12.0, 0.0)],
            [p(7.2, 2.0, 5.0), p(8.2, 12.0, 0.0), p(7.2, 12.0, 5.0)],
        ];
        let tile = plain(&tris, &frame, 0.01).unwrap();
        let at = |i: usize, j: usize| (j * 16 + i, tile.texels[j * 16 + i]);
        for j in 3..=10 {
            let (k, steep) = at(7, j);
            assert!((decoded(&tile, k, frame.origin) - 3.5).abs() < quantum(&tile) + 1e-3);
            assert!(steep.is_sampled());
            let (k, wall) = at(8, j);
            let h = decoded(&tile, k, frame.origin);
            assert!(h.abs() < quantum(&tile) + 1e-3, "({j}): {h}");
            // 3.5 texels below its written neighbour: a steep wall, marked for the skirt.
            assert!(wall.is_sampled());
            let (k, flat) = at(1, j);
            assert!((decoded(&tile, k, frame.origin) - 5.0).abs() < quantum(&tile) + 1e-3);
            assert!(!flat.is_sampled());
        }
        // A rim that falls only half a texel: the wall moves the sample down to 4.5 all the
        // same, a third of a texel below its written neighbour, and leaves it extrapolated.
        let gentle = vec![
            tris[0],
            tris[1],
            [p(7.2, 2.0, 5.0), p(8.2, 2.0, 4.5), p(8.2, 12.0, 4.5)],
            [p(7.2, 2.0, 5.0), p(8.2, 12.0, 4.5), p(7.2, 12.0, 5.0)],
        ];
        let tile = plain(&gentle, &frame, 0.01).unwrap();
        for j in 3..=10 {
            let k = j * 16 + 8;
            let h = decoded(&tile, k, frame.origin);
            assert!((h - 4.5).abs() < quantum(&tile) + 1e-3, "({j}): {h}");
            assert!(!tile.texels[k].is_sampled());
        }
    }

    /// An L-shaped patch of the plane h = 2s − t: the hole in its inner corner extends two
    /// written samples (one each way), and the walls leave it on the plane, as dilation put it.
    #[test]
    fn walls_leave_planes_extended_exactly() {
        let frame = xy_frame(16);
        let plane = |s: f32, t: f32| 2.0 * s - t;
        let mut tris = square(&frame, 2.0, 6.0, plane);
        let p = |s: f32, t: f32| Vec3::new(s, t, plane(s, t));
        tris.extend([
            [p(6.0, 2.0), p(10.0, 2.0), p(10.0, 6.0)],
            [p(6.0, 2.0), p(10.0, 6.0), p(6.0, 6.0)],
            [p(2.0, 6.0), p(6.0, 6.0), p(6.0, 10.0)],
            [p(2.0, 6.0), p(6.0, 10.0), p(2.0, 10.0)],
        ]);
        let tile = plain(&tris, &frame, 0.01).unwrap();
        let bound = quantum(&tile) + 1e-4;
        for (i, j) in [(6, 6), (10, 4), (4, 10), (1, 4), (4, 1)] {
            let k = j * 16 + i;
            let got = decoded(&tile, k, frame.origin);
            let want = plane(i as f32 + 0.5, j as f32 + 0.5);
            assert!((got - want).abs() <= bound, "({i}, {j}): {got} vs {want}");
            assert!(!tile.texels[k].is_sampled(), "({i}, {j})");
        }
    }
}
