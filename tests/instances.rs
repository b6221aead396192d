//! Scenes with instances (issue "Instances"): scene files that place meshes without copying them,
//! and the exact two-level BVH, whose hits must be those of the same meshes copied into a flat
//! scene and traced by the exact BVH, the referee, within float error: rotations, non-uniform
//! scales and mirrors included.

mod common;

use common::{random_rays, Rng};
use glam::{Mat4, Quat, Vec3};
use rbvh::bvh::{Bvh, InstancedBvh, GRAFTED, STACK_SIZE};
use rbvh::geom::{Hit, Ray};
use rbvh::scene::{Instance, InstancedScene, Scene};

/// Three built-in meshes placed eleven times: turned, scaled unevenly, mirrored along one axis or
/// three, overlapping, and one mesh placed once where it is.
fn placed() -> InstancedScene {
    let meshes: Vec<Scene> = ["torus", "bumpy-sphere", "cube"]
        .iter()
        .map(|name| Scene::builtin(name).unwrap())
        .collect();
    let mut instances = vec![Instance {
        mesh: 2,
        transform: Mat4::IDENTITY,
    }];
    for k in 0..10u32 {
        let turn = Quat::from_euler(glam::EulerRot::XYZ, 0.3 * k as f32, 0.7 * k as f32, 0.2);
        let mirror = match k % 4 {
            0 => Vec3::new(-1.0, 1.0, 1.0),
            1 => Vec3::splat(-1.0),
            _ => Vec3::ONE,
        };
        let scale = mirror * Vec3::new(0.4 + 0.1 * k as f32, 0.6, 0.3 + 0.05 * k as f32);
        let at = Vec3::new(
            (k % 4) as f32 * 0.9 - 1.3,
            (k / 4) as f32 * 0.8 - 0.7,
            0.3 * k as f32,
        );
        instances.push(Instance {
            mesh: k % 2,
            transform: Mat4::from_scale_rotation_translation(scale, turn, at),
        });
    }
    InstancedScene {
        name: "placed".into(),
        meshes,
        instances,
        ..InstancedScene::default()
    }
}

/// Compares the two-level hits with the flat exact BVH's on `rays`: the same triangle (the flat
/// index of the instance's triangle), `t` to 1e-4 relative or 1e-5 of the scene's diagonal,
/// normals to 1e-3, and hit/miss
/// disagreements (a ray through a shared edge, decided in two spaces) at most `max_rate`.
fn compare(scene: &InstancedScene, two: &InstancedBvh, flat: &Bvh, rays: &[Ray], any: bool) {
    let bases = scene.flat_bases();
    let diagonal = scene.bounds().diagonal();
    let first = scene.instances[GRAFTED as usize];
    let grafted_nodes = match first.transform == Mat4::IDENTITY {
        true => two.meshes[first.mesh as usize].nodes,
        false => 0,
    };
    let (mut disagree, mut other_triangle) = (0usize, 0usize);
    for (i, ray) in rays.iter().enumerate() {
        let (h, stats) = if any {
            two.any_hit(ray)
        } else {
            two.closest_hit(ray)
        };
        let (f, _) = if any {
            flat.any_hit(ray)
        } else {
            flat.closest_hit(ray)
        };
        assert!(!stats.overflow, "ray {i} overflowed");
        // Counted per level: the top level's nodes among all, an instance entered per mesh
        // tree walked, and a hit only inside one, or in the mesh the top level grafts (the
        // first instance, placed where it is).
        let c = stats.counters;
        assert!(
            c.top_nodes <= c.nodes && c.top_nodes <= two.top_nodes + grafted_nodes,
            "ray {i}: {c:?}"
        );
        assert!(
            c.instances <= scene.instances.len() as u32,
            "ray {i}: {c:?}"
        );
        assert!(
            !h.is_hit() || c.instances >= 1 || (grafted_nodes > 0 && h.instance == GRAFTED),
            "ray {i}: {c:?}"
        );
        if h.is_hit() != f.is_hit() {
            disagree += 1;
            continue;
        }
        if !h.is_hit() || any {
            continue;
        }
        assert!(
            (h.instance as usize) < scene.instances.len(),
            "ray {i}: instance {}",
            h.instance
        );
        if bases[h.instance as usize] + h.id != f.id {
            other_triangle += 1;
        }
        // The flat copy's vertices were rounded where they were placed, the instance's ray where
        // it was taken into the mesh's space: distances agree to float error of the scene's size.
        let off = (h.t - f.t).abs() * ray.dir().length();
        assert!(
            off <= 1e-4 * f.t * ray.dir().length() + 1e-5 * diagonal,
            "ray {i}: t {} two-level vs {} flat",
            h.t,
            f.t
        );
        assert!(
            h.normal().dot(f.normal()) > 1.0 - 1e-3,
            "ray {i}: normal {:?} two-level vs {:?} flat",
            h.normal,
            f.normal
        );
    }
    // An edge shared by two triangles, or a corner where two instances overlap, may be decided
    // either way in two spaces; nothing more.
    assert!(
        disagree * 2000 <= rays.len() && other_triangle * 500 <= rays.len(),
        "{disagree} hit/miss and {other_triangle} triangle disagreements in {} rays",
        rays.len()
    );
}

#[test]
fn two_levels_hit_what_the_flat_copy_hits() {
    let scene = placed();
    let two = InstancedBvh::build(&scene).unwrap();
    let flat_scene = scene.clone().into_flat();
    let flat = Bvh::build(&flat_scene).unwrap();
    let rays = random_rays(&flat_scene, 20_000, &mut Rng::new(7));
    compare(&scene, &two, &flat, &rays, false);
    compare(&scene, &two, &flat, &rays, true);

    // Each mesh is stored once, however often it is placed.
    assert_eq!(
        two.triangles.len(),
        scene.stored_triangle_count(),
        "triangles stored"
    );
    assert!(scene.placed_triangle_count() > 4 * scene.stored_triangle_count());
    assert_eq!(two.instances.len(), scene.instances.len());
    assert!(two.top_depth + 1 + two.meshes.iter().map(|m| m.depth).max().unwrap() <= STACK_SIZE);
    let b = flat_scene.bounds();
    assert!(two.bounds.min.cmple(b.min).all() && two.bounds.max.cmpge(b.max).all());
}

#[test]
fn rays_that_start_inside_and_end_short_agree() {
    let scene = placed();
    let two = InstancedBvh::build(&scene).unwrap();
    let flat_scene = scene.clone().into_flat();
    let flat = Bvh::build(&flat_scene).unwrap();
    let mut rng = Rng::new(11);
    let b = flat_scene.bounds();
    let rays: Vec<Ray> = (0..5_000)
        .map(|_| {
            let p =
                b.min + (b.max - b.min) * Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
            let d = rng.unit_vector() * (0.2 + 3.0 * rng.next_f32());
            Ray::new(p, d, 0.01 * rng.next_f32(), 0.2 + rng.next_f32())
        })
        .collect();
    compare(&scene, &two, &flat, &rays, false);
    compare(&scene, &two, &flat, &rays, true);
}

#[test]
fn moving_instances_rebuilds_the_top_level_as_a_fresh_build() {
    let mut scene = placed();
    let mut two = InstancedBvh::build(&scene).unwrap();
    let meshes_before = two.nodes[two.top_nodes as usize..].to_vec();
    let moved: Vec<Mat4> = scene
        .instances
        .iter()
        .enumerate()
        .map(|(k, i)| Mat4::from_translation(Vec3::new(0.1 * k as f32, -0.5, 2.0)) * i.transform)
        .collect();
    two.set_transforms(&moved).unwrap();
    for (instance, m) in scene.instances.iter_mut().zip(&moved) {
        instance.transform = *m;
    }
    let fresh = InstancedBvh::build(&scene).unwrap();
    assert_eq!(two.nodes, fresh.nodes);
    assert_eq!(two.instances, fresh.instances);
    assert_eq!(two.bounds, fresh.bounds);
    assert_eq!(&two.nodes[two.top_nodes as usize..], &meshes_before[..]);

    let flat_scene = scene.clone().into_flat();
    let flat = Bvh::build(&flat_scene).unwrap();
    let rays = random_rays(&flat_scene, 5_000, &mut Rng::new(5));
    compare(&scene, &two, &flat, &rays, false);
}

/// The top-level children that lead into a mesh's tree rather than to an instance leaf.
fn grafted_roots(two: &InstancedBvh) -> Vec<u32> {
    two.nodes[..two.top_nodes as usize]
        .iter()
        .flat_map(|n| n.children())
        .filter(|c| !c.is_absent() && !c.is_leaf() && c.child >= two.top_nodes)
        .map(|c| c.child)
        .collect()
}

/// The first instance, placed where it is, lies in the top level: its mesh's tree is walked with
/// the world ray and its hits are named without entering an instance; moved, it is entered as any
/// other, and placed back where it was, grafted again. No other instance is grafted, though it
/// places its mesh where it is.
#[test]
fn the_first_instance_where_it_is_lies_in_the_top_level() {
    let mut scene = placed();
    scene.instances.push(Instance {
        mesh: 0,
        transform: Mat4::IDENTITY,
    });
    let mut two = InstancedBvh::build(&scene).unwrap();
    let cube = two.meshes[scene.instances[GRAFTED as usize].mesh as usize];
    assert_eq!(grafted_roots(&two), vec![cube.root]);

    let mut moved: Vec<Mat4> = scene.instances.iter().map(|i| i.transform).collect();
    moved[GRAFTED as usize] = Mat4::from_translation(Vec3::new(0.0, 0.0, 0.5));
    two.set_transforms(&moved).unwrap();
    assert!(grafted_roots(&two).is_empty());
    moved[GRAFTED as usize] = Mat4::IDENTITY;
    two.set_transforms(&moved).unwrap();
    assert_eq!(grafted_roots(&two), vec![cube.root]);

    // A scene of one mesh placed once where it is: every ray walks the mesh in the top level.
    let sphere = Scene::builtin("sphere").unwrap();
    let mut single = InstancedScene::single(sphere.clone());
    let rays = random_rays(&sphere, 1_000, &mut Rng::new(9));
    for moved in [false, true] {
        if moved {
            single.instances[0].transform = Mat4::from_translation(Vec3::X);
        }
        let two = InstancedBvh::build(&single).unwrap();
        let flat = Bvh::build(&single.clone().into_flat()).unwrap();
        let mut hits = 0;
        for ray in &rays {
            let (h, stats) = two.closest_hit(ray);
            let entered = stats.counters.instances;
            assert_eq!(
                entered,
                u32::from(moved && stats.counters.nodes > 1),
                "{ray:?}"
            );
            // Grafted, the mesh is walked as the flat scene is: the same hits, bit for bit.
            let (f, _) = flat.closest_hit(ray);
            assert_eq!(h.is_hit(), f.is_hit(), "{ray:?}");
            if h.is_hit() {
                hits += 1;
                assert_eq!(h.id, f.id, "{ray:?}");
                if !moved {
                    assert_eq!(h.t, f.t, "{ray:?}");
                }
            }
        }
        assert!(hits > 100, "{hits} hits");
    }
}

#[test]
fn bad_transforms_are_refused_and_change_nothing() {
    let scene = placed();
    let mut two = InstancedBvh::build(&scene).unwrap();
    let before = two.clone();
    let good: Vec<Mat4> = scene.instances.iter().map(|i| i.transform).collect();
    for (k, bad, what) in [
        (
            3,
            Mat4::from_scale(Vec3::new(1.0, 0.0, 1.0)),
            "not invertible",
        ),
        (
            4,
            Mat4::from_translation(Vec3::new(0.0, f32::NAN, 0.0)),
            "not finite",
        ),
        (
            5,
            Mat4::from_scale(Vec3::splat(f32::INFINITY)),
            "not finite",
        ),
    ] {
        let mut transforms = good.clone();
        transforms[k] = bad;
        let e = two.set_transforms(&transforms).unwrap_err().to_string();
        assert!(
            e.contains(&format!("instance {k}")) && e.contains(what),
            "{e}"
        );
        assert_eq!(two.nodes, before.nodes);
        assert_eq!(two.instances, before.instances);
    }
    let e = two.set_transforms(&good[1..]).unwrap_err().to_string();
    assert!(e.contains("10 transforms for 11 instances"), "{e}");

    let mut missing = scene.clone();
    missing.instances[2].mesh = 7;
    let e = InstancedBvh::build(&missing).unwrap_err().to_string();
    assert!(e.contains("instance 2 places mesh 7"), "{e}");
}

#[test]
fn corrupt_instances_end_rays_without_panics() {
    let scene = placed();
    let mut two = InstancedBvh::build(&scene).unwrap();
    // Roots out of range, and one that points back at the top level (not the first instance's:
    // placed where it is, it is grafted, its record's root not read).
    two.instances[4].root = u32::MAX >> 1;
    two.instances[1].root = 0;
    two.instances[2].world_to_mesh = [[f32::NAN; 4]; 3];
    // A root of u32::MAX (RBVH_INVALID) names no mesh: no instance, as on the device, so rays
    // neither enter it nor hit it.
    two.instances[3].root = u32::MAX;
    let flat_scene = scene.clone().into_flat();
    for ray in random_rays(&flat_scene, 2_000, &mut Rng::new(3)) {
        let (hit, _) = two.closest_hit(&ray);
        assert!(hit.t.is_nan() || hit.t >= ray.tmin || !hit.is_hit());
        assert!(!hit.is_hit() || hit.instance != 3);
    }
}

#[test]
fn a_scene_without_instances_is_one_placed_once() {
    let sphere = Scene::builtin("sphere").unwrap();
    let single = InstancedScene::single(sphere.clone());
    // Unwrapped, it is the scene again; a scene placing anything else is not one.
    assert_eq!(single.clone().into_single().as_ref(), Some(&sphere));
    let mut moved = single.clone();
    moved.instances[0].transform = glam::Mat4::from_translation(Vec3::X);
    assert!(moved.into_single().is_none());
    let two = InstancedBvh::build(&single).unwrap();
    let flat = Bvh::build(&sphere).unwrap();
    let rays = random_rays(&sphere, 2_000, &mut Rng::new(1));
    for ray in &rays {
        let (h, _) = two.closest_hit(ray);
        let (f, _) = flat.closest_hit(ray);
        assert_eq!(h.is_hit(), f.is_hit());
        if h.is_hit() {
            assert_eq!((h.id, h.instance), (f.id, 0));
            assert!((h.t - f.t).abs() <= 1e-6 * f.t);
        }
    }
    // No instances at all: every ray misses.
    let empty = InstancedScene {
        name: "empty".into(),
        meshes: vec![sphere],
        ..InstancedScene::default()
    };
    let two = InstancedBvh::build(&empty).unwrap();
    assert!(rays.iter().all(|r| two.closest_hit(r).0 == Hit::MISS));
}

/// A scene file with `[[mesh]]` and `[[instance]]` entries, written where the test can read it.
fn scene_file(name: &str, text: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("rbvh-instances-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn scene_files_place_instances_without_copying_them() {
    let instanced = scene_file(
        "instanced.toml",
        r#"
name = "placed"
[[mesh]]
builtin = "plane"
[[instance]]
builtin = "sphere"
translate = [1.0, 0.0, 0.0]
[[instance]]
builtin = "sphere"
translate = [-1.0, 0.0, 0.0]
rotate = [0.0, 90.0, 0.0]
scale = [-1.0, 1.0, 2.0]
[[instance]]
builtin = "cube"
"#,
    );
    let copied = scene_file(
        "copied.toml",
        r#"
name = "placed"
[[mesh]]
builtin = "plane"
[[mesh]]
builtin = "sphere"
translate = [1.0, 0.0, 0.0]
[[mesh]]
builtin = "sphere"
translate = [-1.0, 0.0, 0.0]
rotate = [0.0, 90.0, 0.0]
scale = [-1.0, 1.0, 2.0]
[[mesh]]
builtin = "cube"
"#,
    );
    let scene = InstancedScene::load(instanced.to_str().unwrap()).unwrap();
    assert_eq!(scene.name, "placed");
    assert_eq!(
        scene.meshes.len(),
        3,
        "the copied part, the sphere once, the cube"
    );
    assert_eq!(
        scene.instances.iter().map(|i| i.mesh).collect::<Vec<_>>(),
        [0, 1, 1, 2]
    );
    // Flattened, it is the file that copies every mesh.
    let flat = Scene::load(instanced.to_str().unwrap()).unwrap();
    let expected = Scene::load(copied.to_str().unwrap()).unwrap();
    assert_eq!(flat.triangles, expected.triangles);
    assert_eq!(flat.positions, expected.positions);
    assert_eq!(flat.object_names, expected.object_names);
    assert_eq!(flat, expected);
    // What is measured against, found without flattening: the boxes as placed, bit for bit.
    assert_eq!(scene.placed_bounds(), flat.bounds());
    let boxes: Vec<_> = scene.placed_object_bounds().into_iter().flatten().collect();
    assert_eq!(boxes, flat.object_bounds());
    assert!(scene.repeats_a_mesh());
    // A mesh or built-in scene alone is one mesh placed once.
    let one = InstancedScene::load("cube").unwrap();
    assert_eq!((one.meshes.len(), one.instances.len()), (1, 1));
    assert!(!one.repeats_a_mesh());
}

#[test]
fn bad_instances_in_scene_files_name_their_line() {
    for (text, line, what) in [
        (
            "[[instance]]\nbuiltin = \"cube\"\nscale = [1.0, 1e-5, 1e-5]\n",
            1,
            "not invertible",
        ),
        (
            "[[mesh]]\nbuiltin = \"cube\"\n[[instance]]\nbuiltin = \"nothing\"\n",
            4,
            "unknown scene",
        ),
        (
            "[[instance]]\nbuiltin = \"cube\"\nscale = 0.0\n",
            3,
            "non-zero",
        ),
        ("name = \"x\"\n", 0, "[[instance]]"),
    ] {
        let path = scene_file("bad.toml", text);
        let e = InstancedScene::load(path.to_str().unwrap())
            .unwrap_err()
            .to_string();
        assert!(e.contains(what), "{text}: {e}");
        if line > 0 {
            assert!(
                e.contains(&format!(":{line}")) || e.contains(&format!("line {line}")),
                "{text}: {e}"
            );
        }
        // The flat load refuses it the same way.
        assert!(Scene::load(path.to_str().unwrap()).is_err());
    }
}

/// The device traces the two-level BVH as its CPU twin does, ray for ray: the same hits (the same
/// instance and triangle, `t` to 1e-5 relative, the same normal), hit/miss disagreements only where
/// a ray grazes an edge (none in practice), and the same counters; under the validation layers
/// where installed, through bindings and through device addresses.
#[test]
fn the_device_traces_two_levels_as_the_cpu_does() {
    use rbvh::gpu::{Addressing, Query, Tracer};
    use rbvh::lod::Cones;
    use rbvh::structure::Structure;

    let scene = placed();
    let two = InstancedBvh::build(&scene).unwrap();
    let flat_scene = scene.clone().into_flat();
    let mut rays = random_rays(&flat_scene, 6_000, &mut Rng::new(21));
    rays.extend(flat_scene.camera_or_framed(1.0).primary_rays(48, 48));
    let structure = Structure::from(two.clone());
    for addressing in [Addressing::Bindings, Addressing::DeviceAddress] {
        let ctx = common::context_with(addressing);
        let tracer = Tracer::new(&ctx, &structure).unwrap();
        for query in [Query::Closest, Query::Any] {
            let any = query == Query::Any;
            let traced = tracer.trace_with(&rays, Cones::None, query, true).unwrap();
            let counters = traced.counters.unwrap();
            let mut disagree = 0;
            for (i, ray) in rays.iter().enumerate() {
                let (cpu, stats) = if any {
                    two.any_hit(ray)
                } else {
                    two.closest_hit(ray)
                };
                let gpu = traced.hits[i];
                if gpu.is_hit() != cpu.is_hit() {
                    disagree += 1;
                    continue;
                }
                if !any && gpu.is_hit() {
                    assert_eq!((gpu.instance, gpu.id), (cpu.instance, cpu.id), "ray {i}");
                    assert!(
                        (gpu.t - cpu.t).abs() <= 1e-5 * cpu.t,
                        "ray {i}: t {} vs {}",
                        gpu.t,
                        cpu.t
                    );
                    assert!(gpu.normal().dot(cpu.normal()) > 0.9999, "ray {i}: normals");
                }
                if disagree == 0 && !any {
                    assert_eq!(
                        counters[i], stats.counters,
                        "{addressing:?} ray {i}: counters"
                    );
                }
            }
            assert!(
                disagree * 5000 <= rays.len(),
                "{disagree} hit/miss disagreements"
            );
        }
    }
}

/// Moving instances on the device rewrites the top level and the instance records alone: the
/// moved tracer's hits are a fresh upload's, bit for bit, and the CPU's. Another structure, or a
/// two-level BVH of other sizes, is refused by name.
#[test]
fn moving_instances_on_the_device_uploads_the_top_level_alone() {
    use rbvh::gpu::{Query, Tracer};
    use rbvh::structure::Structure;

    let scene = placed();
    let mut two = InstancedBvh::build(&scene).unwrap();
    let ctx = common::context();
    let mut tracer = Tracer::new(&ctx, &Structure::from(two.clone())).unwrap();
    let rays = random_rays(&scene.clone().into_flat(), 3_000, &mut Rng::new(9));
    let before = tracer.trace(&rays, Query::Closest).unwrap().hits;
    let moved: Vec<Mat4> = scene
        .instances
        .iter()
        .enumerate()
        .map(|(k, i)| Mat4::from_rotation_y(0.2 * (k + 1) as f32) * i.transform)
        .collect();
    // The first instance, grafted where it is, moves too (entered as an instance), then comes
    // back (grafted again): the device follows both.
    let original: Vec<Mat4> = scene.instances.iter().map(|i| i.transform).collect();
    let mut last = before.clone();
    for transforms in [moved, original] {
        two.set_transforms(&transforms).unwrap();
        tracer.update_instances(&two).unwrap();
        let after =
            common::moved_as_fresh(&ctx, &tracer, Structure::from(two.clone()), &rays, &last);
        for (i, (ray, hit)) in rays.iter().zip(&after).enumerate() {
            let (cpu, _) = two.closest_hit(ray);
            assert_eq!(
                (hit.is_hit(), hit.instance, hit.id),
                (cpu.is_hit(), cpu.instance, cpu.id),
                "ray {i}"
            );
        }
        last = after;
    }
    assert_eq!(last, before, "back where they were");

    let e = tracer.update_instances(
        &InstancedBvh::build(&InstancedScene::single(Scene::builtin("cube").unwrap())).unwrap(),
    );
    assert!(e
        .unwrap_err()
        .to_string()
        .contains("not the uploaded structure"));
    let mut flat = Tracer::new(
        &ctx,
        &Structure::from(Bvh::build(&Scene::builtin("cube").unwrap()).unwrap()),
    )
    .unwrap();
    let e = flat.update_instances(&two).unwrap_err().to_string();
    assert!(e.contains("not a two-level exact BVH"), "{e}");
}

/// "grove-instanced" holds the blob once and places it 400 times; flattened, it is "grove"'s
/// triangles at "grove"'s places, bit for bit (grove stays flat: its level of detail is measured
/// on it).
#[test]
fn the_instanced_grove_flattened_is_the_grove() {
    let placed = InstancedScene::load("grove-instanced").unwrap();
    assert_eq!((placed.meshes.len(), placed.instances.len()), (2, 401));
    assert!(placed.stored_triangle_count() * 100 < placed.placed_triangle_count());
    let flat = placed.into_flat();
    let grove = Scene::load("grove").unwrap();
    assert_eq!(flat.positions, grove.positions);
    assert_eq!(flat.triangles, grove.triangles);
    assert_eq!(flat.camera, grove.camera);
    assert_eq!(
        Scene::load("grove-instanced").unwrap().positions,
        grove.positions
    );
}

/// A scene of instances too large to copy in place is refused before it is flattened, by name,
/// with its triangles and the memory it would take; one that fits, or where the memory is not
/// known, is flattened.
#[test]
fn flattening_is_refused_where_it_would_not_fit_in_memory() {
    let scene = placed();
    let needed = scene.placed_triangle_count() as u64 * rbvh::scene::FLAT_BYTES_PER_TRIANGLE;
    assert!(scene.check_flat_fits(None).is_ok());
    assert!(scene.check_flat_fits(Some(needed)).is_ok());
    let e = scene
        .check_flat_fits(Some(needed - 1))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("placed") && e.contains(&scene.placed_triangle_count().to_string()),
        "{e}"
    );
    assert!(e.contains("two levels"), "{e}");
}

/// An instance's world box is made from boxes of its mesh's tree, not from its mesh's box turned
/// (the box of a box twice), so that fewer rays enter an instance they miss: for a turned torus
/// it is smaller on every axis, and it still holds every placed vertex.
#[test]
fn turned_instances_get_boxes_closer_than_their_mesh_box_turned() {
    let torus = Scene::builtin("torus").unwrap();
    let turn = Mat4::from_rotation_translation(
        Quat::from_euler(glam::EulerRot::XYZ, 0.6, 0.785, 0.3),
        Vec3::new(2.0, -1.0, 0.5),
    );
    let scene = InstancedScene {
        name: "turned".into(),
        meshes: vec![torus.clone()],
        instances: vec![Instance {
            mesh: 0,
            transform: turn,
        }],
        ..InstancedScene::default()
    };
    let two = InstancedBvh::build(&scene).unwrap();
    let vertices =
        rbvh::geom::Aabb::from_points(torus.positions.iter().map(|&v| turn.transform_point3(v)));
    let whole = rbvh::scene::transformed_box(torus.bounds(), turn);
    assert!(
        two.bounds.min.cmple(vertices.min).all() && two.bounds.max.cmpge(vertices.max).all(),
        "{:?} does not hold the placed vertices {vertices:?}",
        two.bounds
    );
    assert!(
        two.bounds.extent().cmple(0.95 * whole.extent()).all(),
        "the instance's box {:?} is not closer than its mesh's box turned, {:?} (vertices {:?})",
        two.bounds.extent(),
        whole.extent(),
        vertices.extent()
    );

    // A mesh's tree whose root's one child is the root again (corrupt data: no file check
    // looks for cycles) still gets a box, within its mesh's, in bounded time (it looped).
    let mut corrupt = two.clone();
    let root = corrupt.meshes[0].root as usize;
    corrupt.nodes[root].a_child = root as u32;
    corrupt.nodes[root].a_count = 0;
    corrupt.nodes[root].b_child = rbvh::bvh::LEAF_BIT;
    corrupt.nodes[root].b_count = 0;
    corrupt.set_transforms(&[turn]).unwrap();
    let b = corrupt.bounds;
    assert!(!b.is_empty() && b.min.cmpge(whole.min).all() && b.max.cmple(whole.max).all());
}
