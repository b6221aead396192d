//! The exact BVH on the CPU: structure, determinism, degenerate input, and the reference tracer
//! against brute force.

mod common;

use glam::Vec3;
use rbvh::bvh::{Bvh, STACK_SIZE};
use rbvh::geom::{intersect_triangle, Ray, RayShear};
use rbvh::scene::{builtin, Scene};

fn scene_from(positions: Vec<Vec3>, triangles: Vec<[u32; 3]>) -> Scene {
    Scene {
        name: "test".into(),
        object_of_triangle: vec![0; triangles.len()],
        object_names: vec!["test".into()],
        positions,
        triangles,
        camera: None,
        light: None,
        surface: None,
        points: None,
    }
}

/// Closest hit by testing every triangle: the referee for the tree.
fn brute_force(scene: &Scene, ray: &Ray) -> f32 {
    let shear = RayShear::new(ray);
    (0..scene.triangle_count())
        .filter_map(|i| {
            let [a, b, c] = scene.triangle(i);
            intersect_triangle(&shear, a, b, c, ray.tmin, ray.tmax)
        })
        .fold(f32::INFINITY, f32::min)
}

#[test]
fn every_builtin_builds_a_valid_tree() {
    for name in builtin::NAMES {
        let scene = Scene::builtin(name).unwrap();
        let bvh = Bvh::build(&scene).unwrap();
        bvh.validate().unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(bvh.triangles.len(), scene.triangle_count());
        let mut prims: Vec<u32> = bvh.triangles.iter().map(|t| t.prim).collect();
        prims.sort_unstable();
        assert!(
            prims.iter().enumerate().all(|(i, &p)| p == i as u32),
            "{name}: prims not a permutation"
        );
    }
}

#[test]
fn build_is_identical_for_any_thread_count() {
    let scene = Scene::builtin("default").unwrap();
    let build = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| Bvh::build(&scene).unwrap())
    };
    let (a, b) = (build(1), build(4));
    assert_eq!(a.nodes, b.nodes);
    assert_eq!(a.triangles, b.triangles);
}

#[test]
fn reference_tracer_matches_brute_force() {
    let scene = Scene::builtin("sphere").unwrap();
    let bvh = Bvh::build(&scene).unwrap();
    let mut rng = common::Rng::new(7);
    for i in 0..2000 {
        let origin = rng.unit_vector() * 3.0;
        let target = rng.unit_vector() * 0.9;
        let ray = Ray::new(origin, target - origin, 0.0, f32::INFINITY);
        let expected = brute_force(&scene, &ray);
        let (hit, stats) = bvh.closest_hit(&ray);
        assert!(!stats.overflow);
        assert_eq!(hit.t, expected, "ray {i}");
        // Any-hit agrees on whether something is hit.
        assert_eq!(
            bvh.any_hit(&ray).0.is_hit(),
            expected.is_finite(),
            "ray {i}"
        );
    }
}

#[test]
fn degenerate_inputs_build_and_trace() {
    let ray = Ray::new(Vec3::new(0.2, 0.2, -5.0), Vec3::Z, 0.0, f32::INFINITY);
    // Empty scene: one root with two absent children; every ray misses.
    let empty = Bvh::build(&scene_from(vec![], vec![])).unwrap();
    empty.validate().unwrap();
    assert!(!empty.closest_hit(&ray).0.is_hit());
    // One triangle.
    let one = scene_from(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]]);
    let bvh = Bvh::build(&one).unwrap();
    bvh.validate().unwrap();
    let hit = bvh.closest_hit(&ray).0;
    assert_eq!(hit.id, 0);
    assert!((hit.t - 5.0).abs() <= 5.0 * f32::EPSILON, "{}", hit.t);
    assert_eq!(hit.normal(), Vec3::Z);
    // Zero-area triangles (a point, a line) next to a real one: never hit, never break the build.
    let degenerate = scene_from(
        vec![
            Vec3::ZERO,
            Vec3::X,
            Vec3::Y,
            Vec3::splat(0.3),
            Vec3::new(0.1, 0.1, 0.0),
            Vec3::new(0.4, 0.4, 0.0),
        ],
        vec![[3, 3, 3], [4, 5, 4], [0, 1, 2], [0, 0, 1]],
    );
    let bvh = Bvh::build(&degenerate).unwrap();
    bvh.validate().unwrap();
    assert_eq!(bvh.closest_hit(&ray).0.id, 2);
}

#[test]
fn depth_stays_within_the_stack_on_adversarial_input() {
    // 100k triangles in one spot (all centroids equal: SAH has no plane) ...
    let mut positions = Vec::new();
    let mut triangles = Vec::new();
    for i in 0..100_000u32 {
        let s = 1.0 + i as f32 * 1e-6;
        positions.extend(
            [Vec3::ZERO, Vec3::new(s, 0.0, 0.0), Vec3::new(0.0, s, 0.0)]
                .map(|p| p - Vec3::splat(s / 3.0)),
        );
        triangles.push([3 * i, 3 * i + 1, 3 * i + 2]);
    }
    let bvh = Bvh::build(&scene_from(positions, triangles)).unwrap();
    bvh.validate().unwrap();
    assert!(bvh.depth <= STACK_SIZE);
    // ... and a geometric series of sizes, which drives SAH into a long chain.
    let mut positions = Vec::new();
    let mut triangles = Vec::new();
    for i in 0..2000u32 {
        let s = 0.97f32.powi(i as i32);
        let base = positions.len() as u32;
        positions.extend([
            Vec3::new(s, 0.0, 0.0),
            Vec3::new(s, s * 0.01, 0.0),
            Vec3::new(s, 0.0, s * 0.01),
        ]);
        triangles.push([base, base + 1, base + 2]);
    }
    let scene = scene_from(positions, triangles);
    let bvh = Bvh::build(&scene).unwrap();
    bvh.validate().unwrap();
    let ray = Ray::new(Vec3::new(0.5, 0.001, -1.0), Vec3::Z, 0.0, f32::INFINITY);
    assert_eq!(bvh.closest_hit(&ray).0.t, brute_force(&scene, &ray));
}

#[test]
fn invalid_rays_miss() {
    let bvh = Bvh::build(&Scene::builtin("sphere").unwrap()).unwrap();
    let bad = [
        Ray::new(Vec3::splat(f32::NAN), Vec3::Z, 0.0, f32::INFINITY),
        Ray::new(Vec3::new(0.0, 0.0, -3.0), Vec3::ZERO, 0.0, f32::INFINITY),
        Ray::new(
            Vec3::new(0.0, 0.0, -3.0),
            Vec3::new(0.0, f32::INFINITY, 1.0),
            0.0,
            f32::INFINITY,
        ),
        Ray::new(Vec3::new(0.0, 0.0, -3.0), Vec3::Z, 2.0, 1.0),
        Ray::new(Vec3::new(0.0, 0.0, -3.0), Vec3::Z, -1.0, 10.0),
    ];
    for r in bad {
        assert!(!bvh.closest_hit(&r).0.is_hit(), "{r:?}");
    }
}

#[test]
fn rejects_non_finite_geometry() {
    let scene = scene_from(
        vec![Vec3::ZERO, Vec3::X, Vec3::new(0.0, f32::NAN, 0.0)],
        vec![[0, 1, 2]],
    );
    let err = Bvh::build(&scene).unwrap_err().to_string();
    assert!(err.contains("test"), "{err}");
}

/// A scene of triangles parallel to z = 0, each given by its three (x, y) corners and its z.
fn flat_triangles(tris: &[([[f32; 2]; 3], f32)]) -> Scene {
    let mut scene = Scene::new("flat");
    for (corners, z) in tris {
        let positions: Vec<Vec3> = corners.iter().map(|[x, y]| Vec3::new(*x, *y, *z)).collect();
        scene.push_object("t", &positions, &[[0, 1, 2]]);
    }
    scene
}

fn one_per_leaf(scene: &Scene) -> Bvh {
    let params = rbvh::bvh::BuildParams {
        max_leaf: 1,
        ..rbvh::bvh::BuildParams::DEFAULT
    };
    Bvh::build_with(scene, &params).unwrap()
}

/// A stack entry remembers where its box was entered: once a nearer hit is found, the far subtree
/// pushed before it is dropped when popped, not visited. One triangle at z = 1, two behind it at
/// z = 5 and 6 (a subtree of their own): the ray down the middle visits the root alone.
#[test]
fn entries_beyond_the_nearest_hit_are_dropped_unvisited() {
    let square = [[-1.0, -1.0], [3.0, -1.0], [-1.0, 3.0]];
    let scene = flat_triangles(&[(square, 1.0), (square, 5.0), (square, 6.0)]);
    let bvh = one_per_leaf(&scene);
    assert_eq!(bvh.nodes.len(), 2, "a root and the far pair's node");
    let ray = Ray::new(Vec3::new(0.0, 0.0, 0.0), Vec3::Z, 0.0, f32::INFINITY);
    let (hit, stats) = bvh.closest_hit(&ray);
    assert_eq!(hit.t, 1.0);
    assert_eq!(stats.counters.nodes, 1);
    assert_eq!(stats.counters.triangles, 1);
    // From z = 7 the pair comes first: the triangle at z = 6 is hit, and both the one at z = 5
    // and the one at z = 1, pushed before, are dropped untested.
    let back = Ray::new(Vec3::new(0.0, 0.0, 7.0), -Vec3::Z, 0.0, f32::INFINITY);
    let (hit, stats) = bvh.closest_hit(&back);
    assert_eq!(hit.t, 1.0);
    assert_eq!(stats.counters.nodes, 2);
    assert_eq!(stats.counters.triangles, 1);
}

/// A leaf that comes off the stack is read back from its parent node, with its count: the near
/// triangle's box holds the ray but the triangle does not, so the far leaf, pushed, is popped and
/// hit, and the probe sees its child and count read again (bytes 36..44 of the root, child b).
#[test]
fn a_popped_leaf_is_read_back_from_its_node() {
    let near = [[-1.0, -1.0], [1.0, -1.0], [-1.0, 1.0]];
    let far = [[-2.0, -2.0], [4.0, -2.0], [-2.0, 4.0]];
    let scene = flat_triangles(&[(near, 1.0), (far, 5.0)]);
    let bvh = one_per_leaf(&scene);
    assert_eq!(bvh.nodes.len(), 1);
    let ray = Ray::new(Vec3::new(0.5, 0.5, 0.0), Vec3::Z, 0.0, f32::INFINITY);
    let mut reads: Vec<rbvh::probe::Read> = Vec::new();
    let (hit, stats) = bvh.trace_probed(&ray, false, &mut reads);
    assert_eq!(hit.t, 5.0);
    assert_eq!(stats.counters.triangles, 2);
    let children = bvh.nodes[0].children();
    let side = if children[1].bounds.min.z > children[0].bounds.min.z {
        36
    } else {
        28
    };
    let rereads: Vec<_> = reads.iter().filter(|r| r.bytes == 8).collect();
    assert_eq!(rereads.len(), 1, "{reads:?}");
    assert_eq!(rereads[0].offset, side);
}
