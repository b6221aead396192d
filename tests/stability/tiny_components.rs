//! Signed zeros, tiny and denormal components.

use super::*;

/// Direction components that stress the shear and the slab test: signed zeros, 1e-30,
/// denormals, the smallest normal.
const TINY: [f32; 8] = [
    0.0,
    -0.0,
    1e-30,
    -1e-30,
    1e-40,
    -1e-45,
    f32::MIN_POSITIVE,
    -f32::MIN_POSITIVE,
];

/// **Bounds.** Axis-parallel rays with `+0`/`−0` in the other components, or components of 1e-30,
/// denormals and ±`f32::MIN_POSITIVE`, hit the analytic surfaces of `builtin::analytic`:
/// * plane ("plane", y = 0): from above and below, at the mesh's own vertices (multiples of
///   0.25: shared edges and vertices) and at random points: every ray hits; the exact path's `t`
///   is within 1e-6 relative of `|o_y / d_y|`, the RBVH's (Q2, flat tiles) within 2e-5. Pure
///   axis directions scaled by 1e-30 and 1e30 give `t` scaled inversely, same bounds.
/// * sphere ("sphere"): rays along ±x, ±y, ±z, offset sideways up to 0.6: the exact hit point is
///   within the tessellation's chord error of the sphere, the RBVH's (Q0, Q2) within the chord
///   error + half a texel (the bound of `tests/rbvh.rs`).
/// * everywhere: no NaN — misses are exactly `Hit::MISS`, hits have finite `t` and unit normals.
/// * a direction whose *every* component is denormal (so `1/d` overflows) is answered as a miss
///   on both paths, even 1e-5 above the plane where the hit distance (1e35) would fit an f32:
///   measured behaviour, not in the README.
/// * measured limit: hit distances beyond ~1e35 (directions ~1e-37 long) may be missed by the
///   exact path's box test, which stands in `±1/f32::MAX` for the inverse of a zero component:
///   `distance · f32::MAX` stops acting as infinity once `t` approaches it. Such rays get a miss
///   or the right `t`, never a NaN.
#[test]
fn signed_zero_and_tiny_direction_components_hit_the_analytic_surfaces() {
    let ctx = common::context();
    // --- Plane.
    let plane = Scene::builtin("plane").unwrap();
    let exact = Structure::from(Bvh::build(&plane).unwrap());
    let rbvh = Arc::new(Rbvh::build(&plane, &q(2)).unwrap());
    let mut rng = common::Rng::new(21);
    let mut points: Vec<(f32, f32)> = Vec::new();
    for i in -3..=3 {
        for j in -3..=3 {
            points.push((0.25 * i as f32, 0.25 * j as f32));
        }
    }
    for _ in 0..40 {
        points.push((1.9 * rng.next_f32() - 0.95, 1.9 * rng.next_f32() - 0.95));
    }
    let mut rays = Vec::new();
    let mut expect = Vec::new();
    for &(x, z) in &points {
        for side in [1.0f32, -1.0] {
            for (a, b) in TINY.iter().zip(TINY.iter().rev()) {
                let o = Vec3::new(x, 2.0 * side, z);
                rays.push(Ray::new(o, Vec3::new(*a, -side, *b), 0.0, f32::INFINITY));
                expect.push(2.0);
            }
            for scale in [1e-30f32, 1e30] {
                let o = Vec3::new(x, 2.0 * side, z);
                rays.push(Ray::new(
                    o,
                    Vec3::new(0.0, -side * scale, -0.0),
                    0.0,
                    f32::INFINITY,
                ));
                expect.push(2.0 / scale);
            }
        }
    }
    let check_plane = |path: &str, hits: &[Hit], rel: f32| {
        for ((r, h), &t) in rays.iter().zip(hits).zip(&expect) {
            assert_well_formed(path, r, h);
            assert!(h.is_hit(), "{path}: {r:?} missed the plane");
            assert!(
                (h.t - t).abs() <= rel * t,
                "{path}: {r:?}: t {} vs {t}",
                h.t
            );
            assert!(h.normal().y.abs() > 0.9999, "{path}: normal {:?}", h.normal);
        }
    };
    for (which, hits) in PATHS
        .iter()
        .zip(exact_hits(&ctx, &exact, &rays, Query::Closest))
    {
        check_plane(&format!("plane exact {which}"), &hits, 1e-6);
    }
    for (which, hits) in PATHS
        .iter()
        .zip(rbvh_hits(&ctx, &rbvh, &rays, Query::Closest))
    {
        check_plane(&format!("plane RBVH Q2 {which}"), &hits, 2e-5);
    }

    // Hit distances near the top of the f32 range: a miss or right, never a NaN.
    let far: Vec<Ray> = points
        .iter()
        .map(|&(x, z)| {
            Ray::new(
                Vec3::new(x, 2.0, z),
                Vec3::new(0.0, -1e-37, -0.0),
                0.0,
                f32::INFINITY,
            )
        })
        .collect();
    let all = exact_hits(&ctx, &exact, &far, Query::Closest)
        .into_iter()
        .chain(rbvh_hits(&ctx, &rbvh, &far, Query::Closest));
    for hits in all {
        for (r, h) in far.iter().zip(&hits) {
            assert_well_formed("t near f32::MAX", r, h);
            assert!(
                !h.is_hit() || (h.t - 2e37).abs() <= 1e-5 * 2e37,
                "{r:?}: {}",
                h.t
            );
        }
    }

    // Directions with every component denormal: a miss everywhere, never a NaN.
    let denormal = [
        Ray::new(
            Vec3::new(0.1, 0.5, 0.2),
            Vec3::new(0.0, -1e-40, 0.0),
            0.0,
            f32::INFINITY,
        ),
        Ray::new(
            Vec3::new(0.1, 1e-5, 0.2),
            Vec3::new(0.0, -1e-40, -0.0),
            0.0,
            f32::INFINITY,
        ),
        Ray::new(
            Vec3::new(0.1, 1e-5, 0.2),
            Vec3::new(1e-41, -1e-40, 1e-42),
            0.0,
            f32::INFINITY,
        ),
    ];
    let all = exact_hits(&ctx, &exact, &denormal, Query::Closest)
        .into_iter()
        .chain(rbvh_hits(&ctx, &rbvh, &denormal, Query::Closest));
    for hits in all {
        assert!(hits.iter().all(|h| *h == Hit::MISS), "{hits:?}");
    }

    // --- Sphere.
    let (center, radius, chord) = common::sphere_oracle();
    let sphere = Scene::builtin("sphere").unwrap();
    let exact = Structure::from(Bvh::build(&sphere).unwrap());
    let mut rays = Vec::new();
    for axis in 0..3 {
        for sign in [1.0f32, -1.0] {
            for (a, b) in [
                (0.0f32, 0.0f32),
                (0.3, 0.0),
                (0.0, -0.3),
                (0.6, 0.6),
                (-0.4, 0.25),
            ] {
                for (ta, tb) in TINY.iter().zip(TINY.iter().rev()) {
                    let (ka, kb) = ((axis + 1) % 3, (axis + 2) % 3);
                    let mut o = center;
                    o[axis] += 3.0 * sign;
                    o[ka] += a;
                    o[kb] += b;
                    let mut d = Vec3::ZERO;
                    d[axis] = -sign;
                    d[ka] = *ta;
                    d[kb] = *tb;
                    rays.push(Ray::new(o, d, 0.0, f32::INFINITY));
                }
            }
        }
    }
    let check_sphere = |path: &str, hits: &[Hit], slack: f32| {
        for (r, h) in rays.iter().zip(hits) {
            assert_well_formed(path, r, h);
            assert!(h.is_hit(), "{path}: {r:?} missed the sphere");
            let p = r.origin() + h.t * r.dir();
            let err = (p - center).length() - radius;
            assert!(
                err >= -chord - slack - 1e-5 && err <= slack + 1e-5,
                "{path}: {r:?}: radial error {err}"
            );
        }
    };
    for (which, hits) in PATHS
        .iter()
        .zip(exact_hits(&ctx, &exact, &rays, Query::Closest))
    {
        check_sphere(&format!("sphere exact {which}"), &hits, 0.0);
    }
    for level in [0, 2] {
        let r = Arc::new(Rbvh::build(&sphere, &q(level)).unwrap());
        for (which, hits) in PATHS.iter().zip(rbvh_hits(&ctx, &r, &rays, Query::Closest)) {
            check_sphere(
                &format!("sphere RBVH Q{level} {which}"),
                &hits,
                0.5 * r.texel_size,
            );
        }
    }
}
