//! Invalid rays from a ray file.

use super::*;

/// The invalid rays of the README (NaN or ±inf in any field where it matters, a zero direction,
/// `tmin < 0`, `tmin > tmax`) and a few valid controls, aimed at the unit sphere from −z.
fn odd_rays() -> (Vec<Ray>, Vec<bool>) {
    let o = Vec3::new(0.1, 0.05, -3.0);
    let good = Ray::new(o, Vec3::Z, 0.0, f32::INFINITY);
    let mut rays = vec![good];
    let mut valid = vec![true];
    let with = |f: &dyn Fn(&mut [f32; 8])| {
        let mut w: [f32; 8] = bytemuck::cast(good);
        f(&mut w);
        bytemuck::cast::<[f32; 8], Ray>(w)
    };
    for field in 0..8 {
        for x in [f32::NAN, -f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            // tmax = +inf is valid; tmin = +inf ≤ tmax = +inf is valid but finds nothing.
            let ray = with(&|w| w[field] = x);
            if field == 7 && x == f32::INFINITY {
                continue;
            }
            rays.push(ray);
            valid.push(false);
        }
    }
    for ray in [
        Ray::new(o, Vec3::ZERO, 0.0, f32::INFINITY),
        Ray::new(o, Vec3::new(-0.0, 0.0, -0.0), 0.0, f32::INFINITY),
        Ray::new(o, Vec3::Z, -1e-30, f32::INFINITY),
        Ray::new(o, Vec3::Z, -0.5, 10.0),
        Ray::new(o, Vec3::Z, 5.0, 4.0),
        Ray::new(o, Vec3::Z, 2.5, 2.5),
    ] {
        rays.push(ray);
        valid.push(false);
    }
    for ray in [
        Ray::new(o, Vec3::Z, -0.0, f32::INFINITY),
        Ray::new(o, Vec3::new(-0.0, 0.0, 1e-3), 0.0, f32::INFINITY),
        Ray::new(o, Vec3::new(1e-40, -0.0, 1.0), 0.0, 1e30),
    ] {
        rays.push(ray);
        valid.push(true);
    }
    (rays, valid)
}

/// **Bound: NaN and inf in rays from a ray file are misses** (README: "A ray with a NaN/inf
/// component, a zero direction, `tmin < 0` or `tmin > tmax` is answered as a miss"): a ray file
/// with every field set to ±NaN and ±inf in turn (tmin = tmax = +inf finds nothing either), zero
/// and signed-zero directions, negative `tmin` (even −1e-30) and `tmin > tmax`, read back
/// bit-exactly, answers each with exactly `Hit::MISS` — exact and RBVH, GPU and CPU, closest and
/// any — while the valid controls in the same file (`tmin = −0`, denormal side components) hit.
/// The same through `rbvh trace` (GPU and `--cpu`, `--method exact` and `rbvh`).
#[test]
fn nan_and_inf_rays_from_a_ray_file_are_misses() {
    let ctx = common::context();
    let (rays, valid) = odd_rays();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("odd.rays");
    rbvh::io::write_rays(&path, &rays).unwrap();
    let read = rbvh::io::read_rays(&path).unwrap();
    assert_eq!(
        bytemuck::cast_slice::<Ray, u32>(&read),
        bytemuck::cast_slice::<Ray, u32>(&rays)
    );
    let scene = Scene::builtin("sphere").unwrap();
    let exact = Structure::from(Bvh::build(&scene).unwrap());
    let r = Arc::new(Rbvh::build(&scene, &q(0)).unwrap());
    let check = |what: &str, hits: &[Hit]| {
        assert_eq!(hits.len(), read.len());
        for ((ray, ok), h) in read.iter().zip(&valid).zip(hits) {
            if *ok {
                assert!(h.is_hit(), "{what}: valid {ray:?} missed");
            } else {
                assert_eq!(*h, Hit::MISS, "{what}: invalid {ray:?}");
            }
        }
    };
    for query in [Query::Closest, Query::Any] {
        for (which, hits) in PATHS.iter().zip(exact_hits(&ctx, &exact, &read, query)) {
            check(&format!("exact {which} {query:?}"), &hits);
        }
        for (which, hits) in PATHS.iter().zip(rbvh_hits(&ctx, &r, &read, query)) {
            check(&format!("RBVH {which} {query:?}"), &hits);
        }
    }
    for args in [
        &["--method", "exact"][..],
        &["--method", "exact", "--cpu"][..],
        &["--method", "rbvh", "--quality", "0"][..],
        &["--method", "rbvh", "--quality", "0", "--cpu", "--any-hit"][..],
    ] {
        let hits_path = dir.path().join("odd.hits");
        let out = Command::new(env!("CARGO_BIN_EXE_rbvh"))
            .args(["trace", "--scene", "sphere", "--rays"])
            .arg(&path)
            .arg("--hits")
            .arg(&hits_path)
            .args(args)
            .env("RBVH_VALIDATION", "auto")
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        check(
            &format!("rbvh trace {args:?}"),
            &rbvh::io::read_hits(&hits_path).unwrap(),
        );
    }
}
