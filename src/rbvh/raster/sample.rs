//! Steps 1–2 of rasterizing a leaf (see [`super`]): each triangle's samples — the texel centres
//! it covers, by 2D edge functions inclusive of the edges and evaluated in a canonical order so
//! that two triangles sharing an edge lose no sample between them (the argument of Woop, Benthin
//! & Wald, "Watertight Ray/Triangle Intersection", JCGT 2013, in 2D) — and its height there.
//! [`super::rasterize`] keeps the first writer of each sample and refuses a fold.

use glam::{DVec2, Vec3};

use super::Frame;

/// Triangles whose unit normal makes `|n·w|` at most this are treated as edge-on and skipped. A
/// triangle exactly edge-on projects, after f32 rounding of its vertices and of the frame axes,
/// to `|n·w|` of order 1e-7; 1e-5 leaves a margin above that while dropping only triangles within
/// 0.0006° of the projection direction.
pub(super) const EDGE_ON_COS: f32 = 1.0e-5;

/// Step 1 for one triangle: `visit(k, h)` for every sample `k` of `frame` it covers (inclusive
/// edge functions, canonical edge order; see the module docs) with its height `h` there, until
/// `visit` returns false; then its unit normal as wound. None, visiting nothing, for a triangle
/// that is degenerate, seen edge-on, not finite, or beside the tile.
pub(super) fn covered_samples(
    tri: &[Vec3; 3],
    frame: &Frame,
    mut visit: impl FnMut(usize, f32) -> bool,
) -> Option<Vec3> {
    let (res_u, res_v) = (frame.res_u as usize, frame.res_v as usize);
    let normal = unit_normal(tri)?;
    if normal.dot(frame.w).abs() <= EDGE_ON_COS {
        return None;
    }
    let p = tri.map(|q| frame.project(q));
    if !p.iter().all(|q| q.is_finite()) {
        return None;
    }
    let [a, b, c] = p.map(|q| DVec2::new(q.x, q.y));
    let lo = a.min(b).min(c).ceil().max(DVec2::ZERO);
    let hi = a
        .max(b)
        .max(c)
        .floor()
        .min(DVec2::new(res_u as f64 - 1.0, res_v as f64 - 1.0));
    if lo.x > hi.x || lo.y > hi.y {
        return None;
    }
    for j in lo.y as usize..=hi.y as usize {
        for i in lo.x as usize..=hi.x as usize {
            let s = DVec2::new(i as f64, j as f64);
            let e = [edge(b, c, s), edge(c, a, s), edge(a, b, s)];
            let inside = e.iter().all(|&x| x >= 0.0) || e.iter().all(|&x| x <= 0.0);
            let sum = e[0] + e[1] + e[2];
            if !inside || sum == 0.0 {
                continue;
            }
            let h = ((e[0] * p[0].z + e[1] * p[1].z + e[2] * p[2].z) / sum) as f32;
            if !visit(j * res_u + i, h) {
                return Some(normal);
            }
        }
    }
    Some(normal)
}

/// A triangle's unit normal as wound (step 1); None when it has no area.
pub(super) fn unit_normal(tri: &[Vec3; 3]) -> Option<Vec3> {
    (tri[1] - tri[0]).cross(tri[2] - tri[0]).try_normalize()
}

/// Twice the signed area of `(a, b, p)`. The endpoints are put in a canonical (lexicographic) order
/// and the result negated when swapped, so `edge(a, b, p) == -edge(b, a, p)` exactly: the shared
/// edge of two triangles classifies every point consistently for both.
fn edge(a: DVec2, b: DVec2, p: DVec2) -> f64 {
    let orient = |a: DVec2, b: DVec2| (b.x - a.x) * (p.y - a.y) - (b.y - a.y) * (p.x - a.x);
    if (a.x, a.y) <= (b.x, b.y) {
        orient(a, b)
    } else {
        -orient(b, a)
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::super::tests::{plain, square, xy_frame};
    use super::super::Frame;

    #[test]
    fn parallel_layers_fold_unless_within_tolerance() {
        let frame = xy_frame(8);
        let mut two = square(&frame, 0.0, 8.0, |_, _| 0.0);
        two.extend(square(&frame, 0.0, 8.0, |_, _| 10.0));
        assert_eq!(plain(&two, &frame, 1.0), None);

        let mut close = square(&frame, 0.0, 8.0, |_, _| 0.0);
        close.extend(square(&frame, 0.0, 8.0, |_, _| 0.05));
        let tile = plain(&close, &frame, 0.1).unwrap();
        assert_eq!(tile.covered, 64);
        // First writer wins: the lower layer.
        assert_eq!(tile.frame.origin.z, 0.0);
        assert_eq!(tile.h_scale, 0.0);
    }

    #[test]
    fn shared_edges_through_sample_centres_lose_no_sample() {
        // A rotated, offset frame with an odd texel size, and a mesh reaching past the frame whose
        // vertices lie on sample centres (up to f32 rounding): its edges, diagonals included, run
        // through sample centres, and every sample must still be covered.
        let (c, s) = (0.6f32.cos(), 0.6f32.sin());
        let frame = Frame {
            origin: Vec3::new(123.37, -45.1, 7.3),
            u: Vec3::new(c, s, 0.0),
            v: Vec3::new(-s, c, 0.0),
            w: Vec3::Z,
            texel: 0.1,
            res_u: 17,
            res_v: 17,
        };
        let p = |i: i32, j: i32| {
            let (x, y) = (i as f32 + 0.5, j as f32 + 0.5);
            frame.origin
                + x * frame.texel * frame.u
                + y * frame.texel * frame.v
                + (0.01 * x - 0.02 * y) * frame.w
        };
        let mut tris = Vec::new();
        for j in (-2..18).step_by(2) {
            for i in (-2..18).step_by(2) {
                let q = [p(i, j), p(i + 2, j), p(i + 2, j + 2), p(i, j + 2)];
                if (i + j).rem_euclid(4) == 0 {
                    tris.push([q[0], q[1], q[2]]);
                    tris.push([q[0], q[2], q[3]]);
                } else {
                    tris.push([q[0], q[1], q[3]]);
                    tris.push([q[1], q[2], q[3]]);
                }
            }
        }
        let tile = plain(&tris, &frame, 1e-3).unwrap();
        assert_eq!(tile.covered, 17 * 17);
    }

    #[test]
    fn degenerate_input_gives_holes_without_panic() {
        let frame = xy_frame(8);
        let a = Vec3::new(1.0, 1.0, 0.0);
        let b = Vec3::new(6.0, 5.0, 1.0);
        let inputs: [Vec<[Vec3; 3]>; 4] = [
            vec![],
            vec![[a, a, b]],
            vec![[a, b, 0.5 * (a + b)]],
            // Edge-on: the plane y = 4.5 runs exactly through a row of sample centres.
            vec![[
                Vec3::new(0.0, 4.5, 0.0),
                Vec3::new(8.0, 4.5, 0.0),
                Vec3::new(4.0, 4.5, 5.0),
            ]],
        ];
        for tris in inputs {
            let tile = plain(&tris, &frame, 0.1).unwrap();
            assert_eq!(tile.covered, 0);
            assert_eq!(tile.h_scale, 0.0);
            assert_eq!(tile.texels.len(), 64);
            assert!(tile.texels.iter().all(|t| t.is_hole()));
        }
        let empty = Frame {
            res_u: 0,
            res_v: 0,
            ..frame
        };
        let tile = plain(&square(&frame, 0.0, 8.0, |_, _| 1.0), &empty, 0.1).unwrap();
        assert!(tile.texels.is_empty() && tile.covered == 0);
        let zero_texel = Frame {
            texel: 0.0,
            ..frame
        };
        let tile = plain(&square(&frame, 0.0, 8.0, |_, _| 1.0), &zero_texel, 0.1).unwrap();
        assert_eq!(tile.covered, 0);
    }
}
