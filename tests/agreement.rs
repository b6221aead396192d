//! The GPU tracer and the CPU reference tracer agree on the same rays: ≥ 100k rays over several
//! scenes, closest-hit and any-hit. A hit/miss disagreement is allowed only for a ray that passes
//! within a relative 1e-4 (in barycentric terms) of an edge of the triangle one side hit, where the
//! last-bit rounding of the two tracers may legitimately differ; a matching hit's `t` agrees to
//! 1e-5 relative. The disagreement rate is printed.

mod common;

use glam::Vec3;
use rbvh::bvh::Bvh;
use rbvh::geom::{Hit, Ray};
use rbvh::gpu::{Query, Tracer};
use rbvh::lod::Cones;
use rbvh::scene::Scene;
use rbvh::structure::Structure;

/// Smallest barycentric coordinate of the point where `ray` meets the plane of triangle `id`.
fn edge_closeness(scene: &Scene, ray: &Ray, hit: &Hit) -> f32 {
    let [a, b, c] = scene.triangle(hit.id as usize);
    let p = ray.origin() + hit.t * ray.dir();
    let (v0, v1, v2) = (b - a, c - a, p - a);
    let (d00, d01, d11, d20, d21) = (v0.dot(v0), v0.dot(v1), v1.dot(v1), v2.dot(v0), v2.dot(v1));
    let denom = d00 * d11 - d01 * d01;
    let v = (d11 * d20 - d01 * d21) / denom;
    let w = (d00 * d21 - d01 * d20) / denom;
    (1.0 - v - w).min(v).min(w).abs()
}

struct Tally {
    rays: usize,
    hit_miss_edge: usize,
}

fn compare(
    scene: &Scene,
    rays: &[Ray],
    gpu: &[Hit],
    cpu: &[Hit],
    any_hit: bool,
    tally: &mut Tally,
) {
    assert_eq!(gpu.len(), cpu.len());
    for (i, ((r, g), c)) in rays.iter().zip(gpu).zip(cpu).enumerate() {
        tally.rays += 1;
        if g.is_hit() != c.is_hit() {
            let h = if g.is_hit() { g } else { c };
            let closeness = edge_closeness(scene, r, h);
            assert!(
                closeness < 1e-4,
                "{}: ray {i} {r:?}: GPU {g:?} vs CPU {c:?}, not near an edge ({closeness})",
                scene.name
            );
            tally.hit_miss_edge += 1;
            continue;
        }
        if !g.is_hit() || any_hit {
            continue;
        }
        let rel = (g.t - c.t).abs() / c.t.abs().max(1e-30);
        assert!(
            rel <= 1e-5,
            "{}: ray {i}: t GPU {} vs CPU {} (rel {rel})",
            scene.name,
            g.t,
            c.t
        );
        if g.id == c.id {
            assert!(
                g.normal().dot(c.normal()) > 0.99999,
                "{}: ray {i}: normals differ",
                scene.name
            );
        }
    }
}

/// Camera rays plus random rays through the scene's bounds, with varied tmin/tmax.
fn rays_for(scene: &Scene, camera_side: u32, random: usize, seed: u64) -> Vec<Ray> {
    let mut rays = scene
        .camera_or_framed(1.0)
        .primary_rays(camera_side, camera_side);
    let b = scene.bounds();
    let (c, r) = (b.center(), 0.5 * b.diagonal());
    let mut rng = common::Rng::new(seed);
    for _ in 0..random {
        let origin = c + rng.unit_vector() * r * 1.5 * (0.2 + rng.next_f32());
        let target = c + rng.unit_vector() * r * 0.5;
        let tmin = if rng.next_f32() < 0.2 {
            rng.next_f32() * 0.5
        } else {
            0.0
        };
        let tmax = if rng.next_f32() < 0.2 {
            0.5 + rng.next_f32()
        } else {
            f32::INFINITY
        };
        rays.push(Ray::new(origin, target - origin, tmin, tmax));
    }
    rays
}

#[test]
fn gpu_and_cpu_tracers_agree() {
    let ctx = common::context();
    let mut tally = Tally {
        rays: 0,
        hit_miss_edge: 0,
    };
    let cases = [
        ("default", 224, 20_000),
        ("sphere", 128, 15_000),
        ("torus", 128, 10_000),
        ("scenes/mesh.toml", 96, 5_000),
    ];
    for (k, (name, side, random)) in cases.into_iter().enumerate() {
        let scene = Scene::load(name).unwrap();
        let exact = Structure::from(Bvh::build(&scene).unwrap());
        let tracer = Tracer::new(&ctx, &exact).unwrap();
        let rays = rays_for(&scene, side, random, k as u64 + 1);
        for (query, any) in [(Query::Closest, false), (Query::Any, true)] {
            let gpu = tracer.trace(&rays, query).unwrap().hits;
            let cpu = exact.trace_cpu(&rays, Cones::None, any).unwrap();
            compare(&scene, &rays, &gpu, &cpu, any, &mut tally);
        }
    }
    println!(
        "GPU/CPU agreement: {} rays, {} hit/miss disagreements at edges ({:.2e})",
        tally.rays,
        tally.hit_miss_edge,
        tally.hit_miss_edge as f64 / tally.rays as f64
    );
    assert!(tally.rays >= 200_000);
    assert!((tally.hit_miss_edge as f64) < 1e-3 * tally.rays as f64);
}

/// A hit lies in `[tmin, tmax)` on the device too, whatever the rounding: each primary hit, cast
/// again with `tmax` at its distance, is not met there, through the exact BVH and the RBVH (cell
/// triangles, skirts and exact triangles), closest and any hit. Before the watertight test
/// checked its quotient, 7-10% of them were (a point aimed at on a surface occluded by it).
#[test]
fn a_hit_cast_again_to_its_distance_is_not_met_there() {
    let ctx = common::context();
    for name in ["default", "blob"] {
        let scene = Scene::builtin(name).unwrap();
        let rays = scene.camera_or_framed(1.0).primary_rays(128, 128);
        let mut rbvh_params = rbvh::rbvh::RbvhParams::quality(2).unwrap();
        let mut structures = vec![
            Structure::from(Bvh::build(&scene).unwrap()),
            Structure::from(rbvh::rbvh::Rbvh::build(&scene, &rbvh_params).unwrap()),
        ];
        rbvh_params.texels = rbvh::rbvh::params::TexelFormat::Height;
        structures.push(Structure::from(
            rbvh::rbvh::Rbvh::build(&scene, &rbvh_params).unwrap(),
        ));
        for structure in &structures {
            let tracer = Tracer::new(&ctx, structure).unwrap();
            let first = tracer.trace(&rays, Query::Closest).unwrap().hits;
            let again: Vec<Ray> = rays
                .iter()
                .zip(&first)
                .filter(|(_, h)| h.is_hit())
                .map(|(ray, h)| Ray { tmax: h.t, ..*ray })
                .collect();
            assert!(again.len() > 3000, "{name}: {} hits", again.len());
            for query in [Query::Closest, Query::Any] {
                let hits = tracer.trace(&again, query).unwrap().hits;
                let met = again
                    .iter()
                    .zip(&hits)
                    .filter(|(ray, h)| h.is_hit() && h.t >= ray.tmax)
                    .count();
                assert_eq!(met, 0, "{name} {:?} {query:?}", structure.kind());
            }
        }
    }
}

#[test]
fn invalid_rays_miss_on_the_gpu() {
    let ctx = common::context();
    let bvh = Bvh::build(&Scene::builtin("sphere").unwrap()).unwrap();
    let tracer = Tracer::new(&ctx, &Structure::from(bvh)).unwrap();
    let o = Vec3::new(0.0, 0.0, -3.0);
    let rays = [
        Ray::new(Vec3::splat(f32::NAN), Vec3::Z, 0.0, f32::INFINITY),
        Ray::new(o, Vec3::ZERO, 0.0, f32::INFINITY),
        Ray::new(o, Vec3::new(0.0, f32::INFINITY, 1.0), 0.0, f32::INFINITY),
        Ray::new(o, Vec3::Z, 2.5, 1.0),
        Ray::new(o, Vec3::Z, -1.0, 10.0),
        Ray::new(o, Vec3::Z, 0.0, f32::INFINITY),
    ];
    let hits = tracer.trace(&rays, Query::Closest).unwrap().hits;
    assert!(hits[..5].iter().all(|h| *h == Hit::MISS), "{hits:?}");
    assert!(hits[5].is_hit());
}

#[test]
fn empty_scene_and_empty_batch() {
    let ctx = common::context();
    let empty = Scene {
        name: "empty".into(),
        positions: vec![],
        triangles: vec![],
        object_of_triangle: vec![],
        object_names: vec![],
        camera: None,
        light: None,
        surface: None,
        points: None,
    };
    let bvh = Bvh::build(&empty).unwrap();
    let tracer = Tracer::new(&ctx, &Structure::from(bvh)).unwrap();
    let rays = [Ray::new(Vec3::ZERO, Vec3::X, 0.0, f32::INFINITY)];
    assert_eq!(
        tracer.trace(&rays, Query::Closest).unwrap().hits,
        vec![Hit::MISS]
    );
    assert!(tracer.trace(&[], Query::Closest).unwrap().hits.is_empty());
}

#[test]
fn repeated_passes_trace_the_same_hits_and_time_one_pass() {
    let ctx = common::context();
    let scene = Scene::builtin("torus").unwrap();
    let bvh = Bvh::build(&scene).unwrap();
    let rbvh =
        rbvh::rbvh::Rbvh::build(&scene, &rbvh::rbvh::RbvhParams::quality(1).unwrap()).unwrap();
    let rays = rays_for(&scene, 48, 500, 9);
    for tracer in [
        Tracer::new(&ctx, &Structure::from(bvh)).unwrap(),
        Tracer::new(&ctx, &Structure::from(rbvh)).unwrap(),
    ] {
        for query in [Query::Closest, Query::Any] {
            let once = tracer.trace(&rays, query).unwrap();
            let thrice = tracer.trace_repeated(&rays, Cones::None, query, 3).unwrap();
            // Each pass sees the last one's writes and writes the same hits again.
            assert_eq!(once.hits, thrice.hits, "{query:?}");
            assert!(thrice.timing.ms() > 0.0 && thrice.timing.wall_ms > 0.0);
        }
        let err = tracer
            .trace_repeated(&rays, Cones::None, Query::Closest, 0)
            .unwrap_err()
            .to_string();
        assert!(err.contains("at least one pass"), "{err}");
    }
}

/// Corrupt exact BVHs neither hang nor read out of bounds, and the device answers as the CPU
/// reference does (`glsl/traverse.glsl` and `crate::bvh::traverse` share the guards): a child
/// index past the nodes has no children; a triangle leaf whose count runs past the array (and
/// past `u32::MAX` when added to its first slot) tests the triangles up to the array's end; a
/// cycle ends the rays that enter it as overflows (more visits than nodes), an error on the GPU.
#[test]
fn corrupt_exact_bvhs_are_bounded_on_the_device_as_on_the_cpu() {
    use rbvh::bvh::LEAF_BIT;
    use rbvh::Error;
    let ctx = common::context();
    let scene = Scene::builtin("sphere").unwrap();
    let rays = rays_for(&scene, 32, 500, 3);
    let built = Bvh::build(&scene).unwrap();
    let leaf = built
        .nodes
        .iter()
        .position(|n| n.a_child & LEAF_BIT != 0)
        .expect("a node with a triangle leaf");
    let inner = built
        .nodes
        .iter()
        .position(|n| n.a_child & LEAF_BIT == 0)
        .expect("a node with an inner child");

    let mut far_child = built.clone();
    far_child.nodes[inner].a_child = far_child.nodes.len() as u32 + 5;
    let mut long_leaf = built.clone();
    long_leaf.nodes[leaf].a_count = u32::MAX;
    for (what, bvh) in [
        ("child past the nodes", far_child),
        ("count past the triangles", long_leaf),
    ] {
        let cpu = bvh.trace_cpu(&rays, false);
        let gpu = Tracer::new(&ctx, &Structure::from(bvh))
            .unwrap()
            .trace(&rays, Query::Closest)
            .unwrap_or_else(|e| panic!("{what}: {e}"))
            .hits;
        let differ = gpu.iter().zip(&cpu).filter(|(g, c)| g.id != c.id).count();
        assert!(differ * 1000 <= rays.len(), "{what}: {differ} rays differ");
    }

    let mut cycle = built.clone();
    cycle.nodes[inner].a_child = 0;
    let overflows = rays
        .iter()
        .filter(|r| cycle.closest_hit(r).1.overflow)
        .count();
    assert!(overflows > 0, "no ray entered the cycle");
    match Tracer::new(&ctx, &Structure::from(cycle))
        .unwrap()
        .trace(&rays, Query::Closest)
    {
        Err(Error::StackOverflow { .. }) => {}
        other => panic!("a cycle on the device: {:?}", other.map(|t| t.hits.len())),
    }
}
