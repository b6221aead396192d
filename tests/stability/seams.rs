//! Grazing rays, texel boundaries and tile seams.

use super::*;

/// World position of frame coordinates `(s, t)` at height 0 of height-field leaf `l`, in f64.
fn leaf_point(l: &rbvh::rbvh::GpuHeightfield, s: f64, t: f64) -> DVec3 {
    let (u, v) = (
        Vec3::from(l.axis_u).as_dvec3(),
        Vec3::from(l.axis_v).as_dvec3(),
    );
    Vec3::from(l.origin).as_dvec3() + s * u / u.length_squared() + t * v / v.length_squared()
}

/// Targets on and next to every leaf's border: its border samples, the midpoints of the cell
/// edges between them, and the centres of its border cells (texel space: sample `i` at `i + ½`);
/// at most about `cap`, evenly spread over all leaves.
fn border_targets(r: &Rbvh, cap: usize) -> Vec<DVec3> {
    let mut out = Vec::new();
    for l in &r.heightfields {
        let (nu, nv) = (l.res_u as f64, l.res_v as f64);
        let mut st = Vec::new();
        let mut along = |n: f64, fixed: &[f64], swap: bool| {
            let mut x = 0.5;
            while x <= n - 0.5 {
                for &f in fixed {
                    st.push(if swap { (f, x) } else { (x, f) });
                }
                x += 0.5;
            }
        };
        along(nu, &[0.5, 1.0, nv - 1.0, nv - 0.5], false);
        along(nv, &[0.5, 1.0, nu - 1.0, nu - 0.5], true);
        out.extend(st.into_iter().map(|(s, t)| leaf_point(l, s, t)));
    }
    // At most about `cap` of them, evenly spread.
    let stride = (out.len() / cap).max(1);
    out.into_iter().step_by(stride).collect()
}

/// **Bound: no leaks at texel boundaries and tile seams, t within 2e-5 relative.** The built-in
/// plane as an RBVH at Q2 is cut into many 64-sample tiles (and with `max_tile = 4` into
/// hundreds of 4-sample tiles, nearly all seams). Rays aimed exactly at every leaf's border
/// samples, the edge midpoints between them and its border cells' centres — where neighbouring
/// tiles meet — inside the plane's square, from straight above (`±0` components) to grazing
/// (5° and 0.2° elevation), along the tile axes and diagonally: every ray hits, at `t = 2`
/// within 2e-5 relative (the plane's heights are exact), on the GPU and the CPU. The exact path
/// gets the same rays with 1e-6. Rays *in* the plane (y = 0 exactly) are well formed (hits lie in
/// the plane) and the march stays within its cell bound.
#[test]
fn plane_tiles_do_not_leak_at_seams_samples_or_grazing_angles() {
    let ctx = common::context();
    let plane = Scene::builtin("plane").unwrap();
    let exact = Structure::from(Bvh::build(&plane).unwrap());
    for params in [
        q(2),
        RbvhParams {
            max_tile: 4,
            ..q(0)
        },
    ] {
        let r = Arc::new(Rbvh::build(&plane, &params).unwrap());
        assert!(r.heightfields.len() > 8, "{} leaves", r.heightfields.len());
        let u = Vec3::from(r.heightfields[0].axis_u).normalize();
        let v = Vec3::from(r.heightfields[0].axis_v).normalize();
        let azimuths = [u, v, (u + v).normalize(), (v - u).normalize(), -u];
        let mut rays = Vec::new();
        for (k, p) in border_targets(&r, 8000).into_iter().enumerate() {
            if p.x.abs() > 0.999 || p.z.abs() > 0.999 {
                continue;
            }
            let target = p.as_vec3();
            let a = azimuths[k % azimuths.len()];
            for dir in [
                Vec3::new(0.0, -1.0, -0.0),
                (a - Vec3::Y).normalize(),
                (a - 0.0875 * Vec3::Y).normalize(),
                (a - 0.0035 * Vec3::Y).normalize(),
            ] {
                rays.push(Ray::new(target - 2.0 * dir, dir, 0.0, f32::INFINITY));
            }
        }
        let check = |what: &str, hits: &[Hit], rel: f32| {
            let bad: Vec<_> = rays
                .iter()
                .zip(hits)
                .filter(|(_, h)| !h.is_hit() || (h.t - 2.0).abs() > 2.0 * rel)
                .collect();
            assert!(
                bad.is_empty(),
                "{what}: {} of {} rays leak or miss t = 2, first {:?}",
                bad.len(),
                rays.len(),
                bad[0]
            );
        };
        let level = format!(
            "max_tile {}, {} leaves",
            params.max_tile,
            r.heightfields.len()
        );
        for (which, hits) in PATHS.iter().zip(rbvh_hits(&ctx, &r, &rays, Query::Closest)) {
            check(&format!("RBVH {level} {which}"), &hits, 2e-5);
        }
        for (which, hits) in PATHS
            .iter()
            .zip(exact_hits(&ctx, &exact, &rays, Query::Closest))
        {
            check(&format!("exact {which}"), &hits, 1e-6);
        }

        // In the plane: no NaN, hits (if any) in the plane, marches bounded.
        let cell_bound: u32 = r.heightfields.iter().map(|l| 2 * (l.res_u + l.res_v)).sum();
        let mut in_plane = Vec::new();
        for k in 0..64 {
            let phi = 0.1 * k as f32;
            let d = Vec3::new(phi.cos(), 0.0, phi.sin());
            let o = Vec3::new(0.01 * k as f32 - 0.3, 0.0, 0.2) - 3.0 * d;
            in_plane.push(Ray::new(o, d, 0.0, f32::INFINITY));
        }
        let hits = rbvh_hits(&ctx, &r, &in_plane, Query::Closest)
            .into_iter()
            .chain(exact_hits(&ctx, &exact, &in_plane, Query::Closest));
        for hits in hits {
            for (ray, h) in in_plane.iter().zip(&hits) {
                assert_well_formed("in-plane", ray, h);
                if h.is_hit() {
                    let p = ray.origin() + h.t * ray.dir();
                    assert!(p.y.abs() < 1e-5, "{ray:?} hit off the plane at {p}");
                }
            }
        }
        for ray in &in_plane {
            let (_, stats) = r.closest_hit(ray);
            assert!(
                !stats.overflow && stats.counters.cells <= cell_bound,
                "{stats:?}"
            );
        }
    }
}

/// **Bound: no cracks along a flat tile's sample grid.** A flat tile's box is a slab thinner
/// than the rounding of frame coordinates tens of texels from its origin, so the walk could
/// start a cell late (or end one early) where a ray met the surface on a cell boundary, while
/// the watertight test reported the hit in the cell skipped: on the default scene's ground,
/// three in four of the seam rays that passed through (242 of a million at Q1). Rays from
/// 8 texels away, aimed exactly at samples, at points on sample rows and on sample columns
/// across the tiles of the plane at Q2, tilted by up to 22° towards eight azimuths: every ray
/// hits at its target (within 1e-4 of its length), on the GPU and the CPU.
#[test]
fn flat_tiles_have_no_cracks_along_their_sample_grid() {
    let ctx = common::context();
    let plane = Scene::builtin("plane").unwrap();
    let r = Arc::new(Rbvh::build(&plane, &q(2)).unwrap());
    let reach = 8.0 * r.texel_size;
    let mut rays = Vec::new();
    for (n, l) in r.heightfields.iter().enumerate() {
        let w = Vec3::from(l.axis_w);
        let (u, v) = (
            Vec3::from(l.axis_u).normalize(),
            Vec3::from(l.axis_v).normalize(),
        );
        // Every third sample of the tile's interior, shifted per leaf so that all residues
        // of the coordinates occur.
        for j in (1 + n as u32 % 3..l.res_v - 1).step_by(3) {
            for i in (1 + (n as u32 / 3) % 3..l.res_u - 1).step_by(3) {
                let (s, t) = (i as f64 + 0.5, j as f64 + 0.5);
                for (k, (ds, dt)) in [(0.0, 0.0), (0.37, 0.0), (0.0, 0.61)]
                    .into_iter()
                    .enumerate()
                {
                    let target = leaf_point(l, s + ds, t + dt).as_vec3();
                    let azimuth = 0.785 * ((i + 2 * j) as usize + k) as f32;
                    let tilt = 0.4 * [0.3f32, 0.7, 1.0][(i + j) as usize % 3];
                    let out = (w + tilt * (azimuth.cos() * u + azimuth.sin() * v)).normalize();
                    rays.push(Ray::new(target + reach * out, -out, 0.0, f32::INFINITY));
                }
            }
        }
    }
    assert!(rays.len() > 10_000, "{} rays", rays.len());
    for (which, hits) in PATHS.iter().zip(rbvh_hits(&ctx, &r, &rays, Query::Closest)) {
        let bad: Vec<_> = rays
            .iter()
            .zip(&hits)
            .filter(|(_, h)| !h.is_hit() || (h.t - reach).abs() > 1e-4 * reach)
            .collect();
        assert!(
            bad.is_empty(),
            "{which}: {} of {} rays miss their target, first {:?}",
            bad.len(),
            rays.len(),
            bad[0]
        );
    }
}

/// **Bounds: silhouettes and leaf seams of a curved surface.**
/// * Grazing rays past the unit sphere at impact parameter `b`: every ray with
///   `b ≤ 1 − chord − ½ texel` hits and every ray with `b ≥ 1 + ½ texel` misses (texel = 0 and
///   the chord error alone for the exact path, whose facets lie inside the sphere), Q0 and Q2,
///   GPU and CPU.
/// * Rays from outside aimed at the sphere points under every leaf's border samples — the seams
///   between neighbouring leaves: all hit, within chord + ½ texel of the sphere.
#[test]
fn sphere_silhouettes_and_leaf_seams_hold_their_bounds() {
    let ctx = common::context();
    let (center, radius, chord) = common::sphere_oracle();
    let sphere = Scene::builtin("sphere").unwrap();
    let exact = Structure::from(Bvh::build(&sphere).unwrap());
    let mut rng = common::Rng::new(31);
    // Impact parameters in [0.9, 1.1] of the radius, dense near 1.
    let grazing: Vec<(Ray, f32)> = (0..6000)
        .map(|k| {
            let b = radius * (1.0 + 0.1 * (2.0 * rng.next_f32() - 1.0).powi(3));
            let d = rng.unit_vector();
            let side = tangent(d) * (k as f32).cos() + d.cross(tangent(d)) * (k as f32).sin();
            let o = center + side * b - 3.0 * d;
            (Ray::new(o, d, 0.0, f32::INFINITY), b)
        })
        .collect();
    let rays: Vec<Ray> = grazing.iter().map(|g| g.0).collect();
    let check = |what: &str, hits: &[Hit], texel: f32| {
        for ((ray, b), h) in grazing.iter().zip(hits) {
            assert_well_formed(what, ray, h);
            if *b <= radius - chord - 0.5 * texel - 1e-5 {
                assert!(h.is_hit(), "{what}: b = {b} missed");
            }
            if *b >= radius + 0.5 * texel + 1e-5 {
                assert!(!h.is_hit(), "{what}: b = {b} hit at t {}", h.t);
            }
        }
    };
    for (which, hits) in PATHS
        .iter()
        .zip(exact_hits(&ctx, &exact, &rays, Query::Closest))
    {
        check(&format!("exact {which}"), &hits, 0.0);
    }
    for level in [0, 2] {
        let r = Arc::new(Rbvh::build(&sphere, &q(level)).unwrap());
        for (which, hits) in PATHS.iter().zip(rbvh_hits(&ctx, &r, &rays, Query::Closest)) {
            check(&format!("RBVH Q{level} {which}"), &hits, r.texel_size);
        }
        // Seams: the sphere points below every leaf's border targets.
        let mut seam_rays = Vec::new();
        for (k, p) in border_targets(&r, 5000).into_iter().enumerate() {
            let n = (p.as_vec3() - center).normalize();
            let tilt = tangent(n) * (0.4 * ((k % 5) as f32 - 2.0));
            let target = center + n * radius;
            let dir = -(n + tilt).normalize();
            seam_rays.push(Ray::new(target - 2.0 * dir, dir, 0.0, f32::INFINITY));
        }
        for (which, hits) in PATHS
            .iter()
            .zip(rbvh_hits(&ctx, &r, &seam_rays, Query::Closest))
        {
            for (ray, h) in seam_rays.iter().zip(&hits) {
                assert!(h.is_hit(), "Q{level} {which}: seam ray {ray:?} leaked");
                let err = (ray.origin() + h.t * ray.dir() - center).length() - radius;
                assert!(
                    err.abs() <= chord + 0.5 * r.texel_size + 1e-5,
                    "Q{level} {which}: seam ray {ray:?}: radial error {err}"
                );
            }
        }
    }
}
