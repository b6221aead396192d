//! Scale and offset.

use super::*;

/// `f32`'s spacing at `x`.
fn ulp(x: f32) -> f32 {
    let x = x.abs();
    f32::from_bits(x.to_bits() + 1) - x
}

struct Placement {
    scale: f32,
    offset: f32,
}

/// Rays from outside the sphere placed by `p`, aimed within 0.6 radii of its centre (incidence
/// cosine ≥ 0.8), built in f32; the oracle `t` is computed in f64 from the rounded f32 rays.
fn placed_sphere_rays(p: &Placement, n: usize, seed: u64) -> (Vec<Ray>, Vec<f64>) {
    let c = Vec3::splat(p.offset);
    let mut rng = common::Rng::new(seed);
    let mut rays = Vec::new();
    let mut truth = Vec::new();
    while rays.len() < n {
        let o = c + rng.unit_vector() * 3.0 * p.scale;
        let target = c + rng.unit_vector() * 0.6 * p.scale;
        let ray = Ray::new(o, target - o, 0.0, f32::INFINITY);
        if let Some(t) = sphere_t(ray.origin(), ray.dir(), c.as_dvec3(), p.scale as f64) {
            rays.push(ray);
            truth.push(t);
        }
    }
    (rays, truth)
}

/// Worst `|t − t_true|·|d|` (world units) over the rays both hit, and how many rays missed.
/// Where the sphere lies at the origin (f32 resolves it at any scale), every hit's normal must
/// face its ray, which comes from outside: a normal scaled wrongly would point anywhere.
fn placed_errors(p: &Placement, rays: &[Ray], truth: &[f64], hits: &[Hit]) -> (f64, usize) {
    let mut worst = 0.0f64;
    let mut misses = 0;
    for ((r, t), h) in rays.iter().zip(truth).zip(hits) {
        assert_well_formed("placed sphere", r, h);
        if h.is_hit() {
            worst = worst.max((h.t as f64 - t).abs() * r.dir().as_dvec3().length());
            assert!(
                p.offset != 0.0 || h.normal().dot(r.dir()) < 0.0,
                "scale {:e}: {r:?} hit with normal {:?}",
                p.scale,
                h.normal
            );
        } else {
            misses += 1;
        }
    }
    (worst, misses)
}

/// **Bounds: scale and offset.** The unit sphere scaled by `s` and translated by `(o, o, o)`,
/// traced with 1500 rays from outside aimed within 0.6 radii of the centre (incidence cosine
/// ≥ 0.8), both paths, GPU and CPU; errors are world distances `|t − t_true|·|d|` against the f64
/// analytic sphere, and `u = ulp(|o| + 3s)` is f32's spacing at the scene.
/// * Exact path, every placement where f32 resolves the mesh (`u` ≪ chord): error
///   ≤ `(chord·s + 4u) / 0.8` and no miss. Scaling by 1e-4 and 1e4 changes the relative error
///   (error / diagonal) by nothing measurable (both ~1e-4, the tessellation).
/// * RBVH (Q0, texel = diagonal/256) wherever `u` is below the texel: error
///   ≤ `(chord·s + ½ texel + 8u) / 0.8`, no miss, no leak. This covers 1e5 from the origin,
///   where an ulp (0.0078) is 0.6 texel of a unit sphere: before the fix of this issue
///   (tile origins rounded to f32 without margin, windows sharing only their border samples), the
///   RBVH leaked through ~0.2% of such rays, and through some already at 1e3.
/// * Where f32 cannot resolve the scene, measured and asserted as such:
///   - at 1e6 (`u` = 0.0625 = 4.6 texels at Q0) the RBVH cannot place its texels: ~2% of the rays
///     leak through to the far side (asserted < 5%); hits stay within the sphere's box. The exact
///     path still holds its bound (its vertices are shared, so rounding moves but never opens
///     the mesh).
///   - at 1e7 (`u` = 1, the radius): vertices snap to the unit lattice, so the "sphere" is a
///     lattice polyhedron and ~4.5% of the rays aimed inside 0.6 r miss it on the exact path
///     (asserted < 10%); hits are within 2 ulp (2 units) of the sphere. The RBVH is meaningless
///     there: ~60% of the rays miss or leak; only well-formedness and the box are asserted.
///
///   The tracers cannot fix this loss of precision; `Scene::precision_warning` tells the user
///   (tests/scenes.rs, tests/cli.rs).
/// * A large sphere far away (s = 1e4 at 1e7: `u`/s = 1e-4) is as accurate as at the origin.
/// * A tiny sphere (s = 1e-12 and 1e-18) keeps both paths' bounds, with unit normals: a hit's
///   normal is scaled by powers of two before it is normalized (`geom::unit_normal`), where
///   plainly normalized its squared length underflowed f32 and the device's normal was infinite.
///   Its triangles' squared areas underflow f32 too: at 1e-12 the RBVH builder builds it scaled
///   up by a power of two and scales the result back (`geom::scale`), height fields and all, in
///   the RBVH path's bounds; at 1e-18, whose texel no tracer could follow, it samples none of
///   them and traces them all exactly (right hits, no height field), and
///   `Scene::precision_warning` says so.
/// * A vast sphere (s = 1e12), whose squared areas overflow f32 (the builder refused it, asking
///   for infinitely many texels), is built scaled down the same way, in the same bounds.
#[test]
fn scale_and_offset_keep_their_bounds_or_degrade_as_measured() {
    let ctx = common::context();
    let (_, _, chord) = common::sphere_oracle();
    let unit = Scene::builtin("sphere").unwrap();
    let cases = [
        Placement {
            scale: 1e-12,
            offset: 0.0,
        },
        Placement {
            scale: 1e-18,
            offset: 0.0,
        },
        Placement {
            scale: 1e12,
            offset: 0.0,
        },
        Placement {
            scale: 1e-4,
            offset: 0.0,
        },
        Placement {
            scale: 1e4,
            offset: 0.0,
        },
        Placement {
            scale: 1.0,
            offset: 1e5,
        },
        Placement {
            scale: 1e4,
            offset: 1e7,
        },
        Placement {
            scale: 1.0,
            offset: 1e6,
        },
        Placement {
            scale: 1.0,
            offset: 1e7,
        },
    ];
    for (k, p) in cases.iter().enumerate() {
        let mut scene = Scene::new("placed");
        scene.append(
            &unit,
            Mat4::from_translation(Vec3::splat(p.offset)) * Mat4::from_scale(Vec3::splat(p.scale)),
        );
        let (rays, truth) = placed_sphere_rays(p, 1500, k as u64 + 40);
        let u = ulp(p.offset + 3.0 * p.scale) as f64;
        let diag = scene.bounds().diagonal() as f64;
        let what = format!("scale {:e} offset {:e}", p.scale, p.offset);
        let warned = scene
            .precision_warning()
            .is_some_and(|w| w.contains("cannot square their areas"));
        assert_eq!(
            warned,
            p.scale < 1e-15,
            "{what}: {:?}",
            scene.precision_warning()
        );

        let exact = Structure::from(Bvh::build(&scene).unwrap());
        for (which, hits) in PATHS
            .iter()
            .zip(exact_hits(&ctx, &exact, &rays, Query::Closest))
        {
            let (worst, misses) = placed_errors(p, &rays, &truth, &hits);
            println!(
                "{what} exact {which}: worst error {worst:.3e} ({:.2e} of the diagonal), {misses} misses",
                worst / diag
            );
            if p.offset < 1e7 || p.scale >= 1e4 {
                let bound = (chord as f64 * p.scale as f64 + 4.0 * u) / 0.8;
                assert!(worst <= bound, "{what} exact {which}: {worst} > {bound}");
                assert_eq!(misses, 0, "{what} exact {which}");
            } else {
                // 1e7, unit sphere: the mesh is a lattice polyhedron.
                assert!(worst <= 2.0 * u / 0.8, "{what} exact {which}: {worst}");
                assert!(misses < rays.len() / 10, "{what} exact {which}: {misses}");
            }
        }

        let r = Arc::new(Rbvh::build(&scene, &q(0)).unwrap());
        // What the warning says: no height field where the areas underflow.
        assert_eq!(
            warned,
            r.stats.heightfield_leaves == 0,
            "{what}: warned {warned}, {} height fields",
            r.stats.heightfield_leaves
        );
        for (which, hits) in PATHS.iter().zip(rbvh_hits(&ctx, &r, &rays, Query::Closest)) {
            let (worst, misses) = placed_errors(p, &rays, &truth, &hits);
            let leaks = rays
                .iter()
                .zip(&truth)
                .zip(&hits)
                .filter(|((ray, t), h)| {
                    h.is_hit()
                        && (h.t as f64 - **t) * ray.dir().as_dvec3().length() > 0.1 * p.scale as f64
                })
                .count();
            println!(
                "{what} RBVH Q0 {which}: worst error {worst:.3e} ({:.2e} of the diagonal), {misses} misses, {leaks} leaks; texel {:.2e}, ulp {u:.2e}; {} height fields, {} triangle leaves",
                worst / diag,
                r.texel_size,
                r.stats.heightfield_leaves,
                r.stats.triangle_leaves
            );
            if u < r.texel_size as f64 {
                let bound =
                    (chord as f64 * p.scale as f64 + 0.5 * r.texel_size as f64 + 8.0 * u) / 0.8;
                assert!(worst <= bound, "{what} RBVH {which}: {worst} > {bound}");
                assert_eq!(misses + leaks, 0, "{what} RBVH {which}");
            } else {
                // Beyond f32's resolution: hits stay within the sphere's box (a leak runs through
                // to the far side). At 1e6 a few percent of the rays go wrong, at 1e7 most.
                assert!(worst <= diag + 2.0 * u, "{what} RBVH {which}: {worst}");
                if p.offset <= 1e6 {
                    assert!(
                        (misses + leaks) * 20 < rays.len(),
                        "{what} RBVH {which}: {misses} misses, {leaks} leaks"
                    );
                }
            }
        }
    }
}
