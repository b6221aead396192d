//! Secondary rays.

use super::*;

/// Directions in the hemisphere around `n`.
fn hemisphere(rng: &mut common::Rng, n: Vec3) -> Vec3 {
    let d = rng.unit_vector();
    if d.dot(n) < 0.0 {
        -d
    } else {
        d
    }
}

/// **Bound: no self-intersection acne on a convex surface.** Primary rays hit the unit sphere
/// (scaled by 1e-4, 1 and 1e4); from each hit point, offset by a scale-aware epsilon along the
/// facing normal — `1e-4 · diagonal` along the geometric normal on the exact path, half a texel
/// along the stored normal on the RBVH path (Q0, Q2, Q4) — rays into the whole hemisphere around
/// that normal leave the convex surface: zero hits, closest-hit and any-hit, GPU and CPU.
#[test]
fn secondary_rays_leave_a_convex_surface_without_acne() {
    let ctx = common::context();
    let unit = Scene::builtin("sphere").unwrap();
    for scale in [1e-4f32, 1.0, 1e4] {
        let mut scene = Scene::new("scaled sphere");
        scene.append(&unit, Mat4::from_scale(Vec3::splat(scale)));
        let diag = scene.bounds().diagonal();
        let mut rng = common::Rng::new(scale.to_bits() as u64);
        let primary: Vec<Ray> = (0..1000)
            .map(|_| {
                let o = rng.unit_vector() * 3.0 * scale;
                let d = (rng.unit_vector() * 0.9 * scale - o).normalize();
                Ray::new(o, d, 0.0, f32::INFINITY)
            })
            .collect();
        let secondary = |hits: &[Hit], eps: f32, rng: &mut common::Rng| -> Vec<Ray> {
            let mut out = Vec::new();
            for (r, h) in primary.iter().zip(hits) {
                assert!(h.is_hit(), "primary {r:?} missed");
                let n = h.normal();
                let n = if n.dot(r.dir()) < 0.0 { n } else { -n };
                let origin = r.origin() + h.t * r.dir() + eps * n;
                for _ in 0..4 {
                    out.push(Ray::new(origin, hemisphere(rng, n), 0.0, f32::INFINITY));
                }
            }
            out
        };
        let exact = Structure::from(Bvh::build(&scene).unwrap());
        let hits = exact.trace_cpu(&primary, Cones::None, false).unwrap();
        let rays = secondary(&hits, 1e-4 * diag, &mut rng);
        for query in [Query::Closest, Query::Any] {
            for (which, hits) in PATHS.iter().zip(exact_hits(&ctx, &exact, &rays, query)) {
                let acne = hits.iter().filter(|h| h.is_hit()).count();
                assert_eq!(acne, 0, "scale {scale} exact {which} {query:?}: acne");
            }
        }
        for level in [0, 2, 4] {
            let r = Arc::new(Rbvh::build(&scene, &q(level)).unwrap());
            let hits = r.trace_cpu(&primary, false);
            let rays = secondary(&hits, 0.5 * r.texel_size, &mut rng);
            for query in [Query::Closest, Query::Any] {
                for (which, hits) in PATHS.iter().zip(rbvh_hits(&ctx, &r, &rays, query)) {
                    let acne = hits.iter().filter(|h| h.is_hit()).count();
                    assert_eq!(
                        acne, 0,
                        "scale {scale} RBVH Q{level} {which} {query:?}: acne"
                    );
                }
            }
        }
    }
}

/// A closed box with walls `wall` thick: the outer cube [-1, 1]³ (facing out) and the inner cube
/// [-(1 − wall), 1 − wall]³ facing into the cavity, as two objects.
fn hollow_box(wall: f32) -> Scene {
    let cube = Scene::builtin("cube").unwrap();
    let mut s = Scene::new("hollow box");
    s.append(&cube, Mat4::IDENTITY);
    let inner: Vec<Vec3> = cube.positions.iter().map(|p| *p * (1.0 - wall)).collect();
    let reversed: Vec<[u32; 3]> = cube.triangles.iter().map(|&[a, b, c]| [a, c, b]).collect();
    s.push_object("cavity", &inner, &reversed);
    s
}

/// **Bound: no light leaks through a thin closed wall.** A hollow box whose wall is 1e-3 of its
/// size (0.07 texel at Q0): rays from points well inside the cavity (at least 0.1 from the walls)
/// towards the outside always hit, no further than the outer wall plus ½ texel (RBVH) or 1e-5
/// (exact), closest-hit; occlusion (any-hit) rays to lights outside the box are all blocked. The
/// same from the cavity's hit points, offset by the path's epsilon (1e-4·diagonal, ½ texel)
/// back into the cavity: the cavity is closed, every ray hits. GPU and CPU, both paths.
#[test]
fn thin_closed_walls_do_not_leak_light() {
    let ctx = common::context();
    let wall = 1e-3;
    let scene = hollow_box(wall);
    let mut rng = common::Rng::new(77);
    let origins: Vec<Vec3> = (0..500)
        .map(|_| (Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - 1.0) * 0.9)
        .collect();
    let mut rays = Vec::new();
    let mut walls = Vec::new();
    for o in &origins {
        for _ in 0..4 {
            let d = rng.unit_vector();
            // Distance to the outer wall along d (the box [-1, 1]³).
            let t_out = (0..3)
                .map(|k| (d[k].signum() - o[k]) / d[k])
                .fold(f32::INFINITY, f32::min);
            rays.push(Ray::new(*o, d, 0.0, f32::INFINITY));
            walls.push(t_out);
        }
    }
    // Lights outside: shadow rays with tmax just before the light.
    let lights = [Vec3::new(3.0, 2.0, 1.0), Vec3::new(-2.0, -4.0, 0.5)];
    let shadow: Vec<Ray> = origins
        .iter()
        .flat_map(|o| {
            lights
                .iter()
                .map(move |l| Ray::new(*o, *l - *o, 0.0, 0.999))
        })
        .collect();
    let exact = Structure::from(Bvh::build(&scene).unwrap());
    let check = |what: &str, hits: &[Hit], slack: f32| {
        for ((r, h), t_out) in rays.iter().zip(hits).zip(&walls) {
            assert!(h.is_hit(), "{what}: {r:?} leaked out of the box");
            assert!(
                h.t <= t_out + slack,
                "{what}: {r:?} hit at {} > {t_out}",
                h.t
            );
        }
    };
    let offset_rays = |hits: &[Hit], eps: f32| -> Vec<Ray> {
        let mut rng = common::Rng::new(78);
        rays.iter()
            .zip(hits)
            .map(|(r, h)| {
                let n = h.normal();
                let n = if n.dot(r.dir()) < 0.0 { n } else { -n };
                let o = r.origin() + h.t * r.dir() + eps * n;
                Ray::new(o, hemisphere(&mut rng, n), 0.0, f32::INFINITY)
            })
            .collect()
    };
    for (which, hits) in PATHS
        .iter()
        .zip(exact_hits(&ctx, &exact, &rays, Query::Closest))
    {
        check(&format!("exact {which}"), &hits, 1e-5);
        let again = offset_rays(&hits, 1e-4 * scene.bounds().diagonal());
        let back = exact_hits(&ctx, &exact, &again, Query::Closest);
        for hits in back {
            assert!(
                hits.iter().all(Hit::is_hit),
                "exact {which}: a bounce left the box"
            );
        }
    }
    for (which, hits) in PATHS
        .iter()
        .zip(exact_hits(&ctx, &exact, &shadow, Query::Any))
    {
        assert!(
            hits.iter().all(Hit::is_hit),
            "exact {which}: light leaked in"
        );
    }
    for level in [0, 2] {
        let r = Arc::new(Rbvh::build(&scene, &q(level)).unwrap());
        for (which, hits) in PATHS.iter().zip(rbvh_hits(&ctx, &r, &rays, Query::Closest)) {
            check(&format!("RBVH Q{level} {which}"), &hits, 0.5 * r.texel_size);
            let again = offset_rays(&hits, 0.5 * r.texel_size);
            for hits in rbvh_hits(&ctx, &r, &again, Query::Closest) {
                assert!(
                    hits.iter().all(Hit::is_hit),
                    "RBVH Q{level} {which}: a bounce left the box"
                );
            }
        }
        for (which, hits) in PATHS.iter().zip(rbvh_hits(&ctx, &r, &shadow, Query::Any)) {
            assert!(
                hits.iter().all(Hit::is_hit),
                "RBVH Q{level} {which}: light leaked in"
            );
        }
    }
}
