//! Parameter extremes.

use super::*;

/// **Bounds: parameter extremes of the RBVH**, on the sphere and the blob at Q0 with one
/// parameter pushed to its extreme, 2500 camera and random rays:
/// * every extreme builds; depth ≤ `STACK_SIZE`; GPU and CPU agree (hit/miss on fewer than 1 in
///   1000 rays, `t` to 1e-4 relative otherwise); nothing is NaN.
/// * against the exact path: `max_tile` 4 and 4096, `min_leaf_texels` 0 and 1e4,
///   `sampled_criterion_texels` 0 and 1e4, φ_max = 10°,
///   A⊥/A = 0.9 and 4096 texels per diagonal keep the preset's accuracy: hit/miss on ≤ 0.5% of
///   the rays, leaks ≤ 0.1%. (Not zero: where four height fields meet at a corner, one dilation
///   ring can leave a gap; the Q0 preset itself lets ~1 in 40 000 random rays through on the
///   blob, at its top, and so do `max_tile` 4 and 4096 there.)
/// * measured limitations (asserted as measured, with headroom), not bugs of the marcher:
///   - φ_max = 0.5° and A⊥/A = 1.0 make leaves of single ~2-texel triangles; one dilation ring
///     does not cover their acute corners, so ~0.05% (0.5°) and ~1% (1.0) of rays slip through
///     at vertices where such leaves meet (two dilation passes would close them; see the report);
///   - φ_max = 89.5° and A⊥/A = 0.01 accept near-vertical leaves (hemispheres seen along their
///     axis) whose rims a texel grid cannot hold: up to ~2% of the rays pass through the rims.
///
///   These stay below 3% leaks and 1% hit/miss.
/// * sampling rates: 1 and 2 texels per diagonal build valid, very coarse results (a sphere is 8
///   tiles of 3×3), traced without error; 4096 is exact to 2e-5 of the diagonal.
/// * out of range: each gives `InvalidParameter` naming the parameter and its range, and a rate
///   whose texels would exceed the builder's limit (1e5 per diagonal: ~1e10 texels) an error
///   naming `texels_per_diagonal` and saying to lower it — before any memory is spent.
#[test]
fn parameter_extremes_build_valid_results_or_clear_errors() {
    let ctx = common::context();
    let base = q(0);
    let cone = |a: f32| Refinement::NormalCone { max_angle_deg: a };
    let area = |r: f32| Refinement::ProjectedArea { min_ratio: r };
    // (what, params, max hit/miss vs exact, max leaks vs exact) — fractions of the rays.
    let cases: Vec<(&str, RbvhParams, f64, f64)> = vec![
        (
            "φ_max 0.5°",
            RbvhParams {
                refinement: cone(0.5),
                ..base
            },
            0.01,
            0.03,
        ),
        (
            "φ_max 10°",
            RbvhParams {
                refinement: cone(10.0),
                ..base
            },
            0.005,
            0.001,
        ),
        (
            "φ_max 89.5°",
            RbvhParams {
                refinement: cone(89.5),
                ..base
            },
            0.01,
            0.03,
        ),
        (
            "A⊥/A 0.01",
            RbvhParams {
                refinement: area(0.01),
                ..base
            },
            0.01,
            0.03,
        ),
        (
            "A⊥/A 0.9",
            RbvhParams {
                refinement: area(0.9),
                ..base
            },
            0.005,
            0.001,
        ),
        (
            "A⊥/A 1.0",
            RbvhParams {
                refinement: area(1.0),
                ..base
            },
            0.01,
            0.03,
        ),
        (
            "max_tile 4",
            RbvhParams {
                max_tile: 4,
                ..base
            },
            0.005,
            0.001,
        ),
        (
            "max_tile 4096",
            RbvhParams {
                max_tile: 4096,
                ..base
            },
            0.005,
            0.001,
        ),
        (
            "sampled_criterion_texels 0",
            RbvhParams {
                sampled_criterion_texels: 0.0,
                ..base
            },
            0.005,
            0.001,
        ),
        (
            "sampled_criterion_texels 1e4",
            RbvhParams {
                sampled_criterion_texels: 1e4,
                ..base
            },
            0.005,
            0.001,
        ),
        (
            "min_leaf_texels 0",
            RbvhParams {
                min_leaf_texels: 0.0,
                ..base
            },
            0.005,
            0.001,
        ),
        (
            "min_leaf_texels 1e4",
            RbvhParams {
                min_leaf_texels: 1e4,
                ..base
            },
            0.005,
            0.001,
        ),
        (
            "rate 1",
            RbvhParams {
                texels_per_diagonal: 1.0,
                ..base
            },
            1.0,
            1.0,
        ),
        (
            "rate 2",
            RbvhParams {
                texels_per_diagonal: 2.0,
                ..base
            },
            1.0,
            1.0,
        ),
        (
            "rate 4096",
            RbvhParams {
                texels_per_diagonal: 4096.0,
                ..base
            },
            0.005,
            0.001,
        ),
    ];
    for name in ["sphere", "blob"] {
        let scene = Scene::builtin(name).unwrap();
        let diag = scene.bounds().diagonal();
        let mut rays = scene.camera_or_framed(1.0).primary_rays(30, 30);
        let mut rng = common::Rng::new(90);
        rays.extend((0..1600).map(|_| {
            let o = rng.unit_vector() * 3.0;
            let t = rng.unit_vector() * 0.6;
            Ray::new(o, t - o, 0.0, f32::INFINITY)
        }));
        let exact = Bvh::build(&scene).unwrap().trace_cpu(&rays, false);
        for (what, params, max_mismatch, max_leaks) in &cases {
            let r = Arc::new(
                Rbvh::build(&scene, params).unwrap_or_else(|e| panic!("{name} {what}: {e}")),
            );
            assert!(r.depth <= STACK_SIZE, "{name} {what}: depth {}", r.depth);
            let [gpu, cpu] = rbvh_hits(&ctx, &r, &rays, Query::Closest);
            for (ray, h) in rays.iter().zip(gpu.iter().chain(&cpu)) {
                assert_well_formed(what, ray, h);
            }
            let (hit_miss, t) = disagreements(&gpu, &cpu, 1e-4);
            assert!(
                hit_miss * 1000 < rays.len() && t == 0,
                "{name} {what}: GPU/CPU disagree: {hit_miss} hit/miss, {t} t"
            );
            let (mismatch, _) = disagreements(&cpu, &exact, f32::INFINITY);
            let leaks = cpu
                .iter()
                .zip(&exact)
                .filter(|(a, e)| a.is_hit() && e.is_hit() && a.t - e.t > 0.05 * diag)
                .count();
            println!(
                "{name} {what}: {} leaves ({} triangle), {} texels; vs exact: hit/miss {mismatch}, leaks {leaks} of {}",
                r.heightfields.len(),
                r.stats.triangle_leaves,
                r.stats.tile_texels,
                rays.len()
            );
            let n = rays.len() as f64;
            assert!(
                mismatch as f64 <= max_mismatch * n && leaks as f64 <= max_leaks * n,
                "{name} {what}: hit/miss {mismatch}, leaks {leaks} of {n}"
            );
            if *what == "rate 4096" {
                let worst = cpu
                    .iter()
                    .zip(&exact)
                    .filter(|(a, e)| a.is_hit() && e.is_hit())
                    .map(|(a, e)| (a.t - e.t).abs())
                    .fold(0.0, f32::max);
                // 1e-5 of the diagonal before the tiles' planes; since, tiles of the sphere that
                // were 16-bit over their rise are 8-bit over their plane, their heights within
                // 1/128 texel, and a grazing ray's distance errs by that over the sine of its
                // angle: 4.7e-5 world units at worst here, 1.4e-5 of the diagonal (these rays'
                // angles, not a bound; an accuracy the narrow quantum trades for bytes).
                assert!(worst <= 2e-5 * diag, "{name} rate 4096: {worst}");
            }
        }
    }

    let sphere = Scene::builtin("sphere").unwrap();
    let bad: Vec<(RbvhParams, &str)> = vec![
        (
            RbvhParams {
                texels_per_diagonal: 0.5,
                ..base
            },
            "texels_per_diagonal",
        ),
        (
            RbvhParams {
                texels_per_diagonal: 1e7,
                ..base
            },
            "texels_per_diagonal",
        ),
        (
            RbvhParams {
                texels_per_diagonal: f32::INFINITY,
                ..base
            },
            "texels_per_diagonal",
        ),
        (
            RbvhParams {
                texels_per_diagonal: f32::NAN,
                ..base
            },
            "texels_per_diagonal",
        ),
        (
            RbvhParams {
                refinement: cone(0.0),
                ..base
            },
            "max_angle_deg",
        ),
        (
            RbvhParams {
                refinement: cone(90.0),
                ..base
            },
            "max_angle_deg",
        ),
        (
            RbvhParams {
                refinement: cone(f32::NAN),
                ..base
            },
            "max_angle_deg",
        ),
        (
            RbvhParams {
                refinement: area(0.0),
                ..base
            },
            "min_ratio",
        ),
        (
            RbvhParams {
                refinement: area(1.0001),
                ..base
            },
            "min_ratio",
        ),
        (
            RbvhParams {
                refinement: area(f32::NAN),
                ..base
            },
            "min_ratio",
        ),
        (
            RbvhParams {
                max_tile: 3,
                ..base
            },
            "max_tile",
        ),
        (
            RbvhParams {
                max_tile: 4097,
                ..base
            },
            "max_tile",
        ),
        (
            RbvhParams {
                min_leaf_texels: -1.0,
                ..base
            },
            "min_leaf_texels",
        ),
        (
            RbvhParams {
                min_leaf_texels: f32::NAN,
                ..base
            },
            "min_leaf_texels",
        ),
    ];
    common::every_case(bad, |(params, name)| match Rbvh::build(&sphere, &params) {
        Err(e @ Error::InvalidParameter { .. }) => {
            let text = e.to_string();
            common::ensure(text.contains(name) && text.contains("outside"), || {
                format!("{params:?}: {text}")
            })
        }
        other => Err(format!(
            "{params:?}: expected an invalid parameter, got {other:?}"
        )),
    });
    let start = std::time::Instant::now();
    let err = Rbvh::build(
        &sphere,
        &RbvhParams {
            texels_per_diagonal: 1e5,
            max_tile: 4096,
            ..base
        },
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("texels_per_diagonal") && err.contains("lower"),
        "{err}"
    );
    assert!(
        start.elapsed().as_secs_f64() < 2.0,
        "refused only after building"
    );
}
