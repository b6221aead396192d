//! The RBVH of a scene with instances, in two levels (issue "Instances"): each mesh rasterized
//! once in its own space, traced through the top level the exact BVH's two levels have too. The
//! device traces it as its CPU twin does, ray for ray; the two-level exact BVH is its referee;
//! moving instances rebuilds and uploads the top level alone. (That its hits are, bit for bit,
//! those of each mesh's RBVH traced alone is a unit test of `src/rbvh/instanced.rs`.)

mod common;

use common::{random_rays, Rng};
use glam::{Mat4, Quat, Vec3};
use rbvh::bvh::InstancedBvh;
use rbvh::geom::Ray;
use rbvh::gpu::{Addressing, Query, Tracer};
use rbvh::lod::{Cones, LodParams};
use rbvh::rbvh::{InstancedRbvh, RbvhParams, TexelFormat};
use rbvh::scene::{Instance, InstancedScene, Scene};
use rbvh::structure::Structure;

/// Two built-in meshes placed nine times: turned, scaled unevenly and at several sizes (a mesh's
/// texel is its largest placement's), one mirrored, overlapping.
fn placed() -> InstancedScene {
    let meshes: Vec<Scene> = ["bumpy-sphere", "torus"]
        .iter()
        .map(|name| Scene::builtin(name).unwrap())
        .collect();
    let instances = (0..9u32)
        .map(|k| {
            let turn = Quat::from_euler(glam::EulerRot::XYZ, 0.5 * k as f32, 0.8 * k as f32, 0.3);
            let mirror = if k == 4 { -1.0 } else { 1.0 };
            let scale = Vec3::new(mirror * (0.4 + 0.15 * k as f32), 0.6, 0.5 + 0.05 * k as f32);
            let at = Vec3::new(
                (k % 3) as f32 * 1.1 - 1.1,
                (k / 3) as f32 * 0.9 - 0.9,
                0.15 * k as f32,
            );
            Instance {
                mesh: k % 2,
                transform: Mat4::from_scale_rotation_translation(scale, turn, at),
            }
        })
        .collect();
    InstancedScene {
        name: "placed".into(),
        meshes,
        instances,
        ..InstancedScene::default()
    }
}

fn rays(scene: &InstancedScene, n: usize, seed: u64) -> Vec<Ray> {
    let flat = scene.clone().into_flat();
    let mut rays = random_rays(&flat, n, &mut Rng::new(seed));
    rays.extend(flat.camera_or_framed(1.0).primary_rays(40, 40));
    rays
}

/// [`placed`] with a first instance placing the torus where it is, which the top level grafts
/// (`bvh::GRAFTED`): its mesh walked in the top level with the world ray.
fn grafted() -> InstancedScene {
    let mut scene = placed();
    scene.instances.insert(
        0,
        Instance {
            mesh: 1,
            transform: Mat4::IDENTITY,
        },
    );
    scene
}

/// The device traces the two-level RBVH as its twin does, ray for ray: the same hits (instance,
/// id, `t` to 1e-5 relative, normal) and the same counters, closest and any hit, with both texel
/// formats, through bindings and device addresses (under the validation layers where installed),
/// with and without a grafted first instance.
#[test]
fn the_device_traces_the_two_level_rbvh_as_its_twin_does() {
    for (scene, (level, texels)) in [
        (placed(), (2, TexelFormat::HeightNormal)),
        (placed(), (1, TexelFormat::Height)),
        (grafted(), (2, TexelFormat::HeightNormal)),
        (grafted(), (1, TexelFormat::Height)),
    ] {
        let in_top_level = device_traces_as_twin(&scene, level, texels);
        let first = scene.instances[0].transform;
        assert_eq!(in_top_level > 0, first == Mat4::IDENTITY, "{in_top_level}");
    }
}

/// Traces `scene`'s RBVH at `level` on the device and its twin, comparing them ray for ray;
/// returns how many closest hits lay in the top level (named, entering no instance).
fn device_traces_as_twin(scene: &InstancedScene, level: u32, texels: TexelFormat) -> usize {
    let rays = rays(scene, 4_000, 5);
    let params = RbvhParams {
        texels,
        ..RbvhParams::quality(level).unwrap()
    };
    let two = InstancedRbvh::build(scene, &params).unwrap();
    assert!(two.stats().heightfield_leaves > 0);
    let structure = Structure::from(two.clone());
    let mut in_top_level = 0;
    for addressing in [Addressing::Bindings, Addressing::DeviceAddress] {
        let ctx = common::context_with(addressing);
        let tracer = Tracer::new(&ctx, &structure).unwrap();
        let twin = two.device_twin().with_block_jumps(tracer.block_jumps());
        for query in [Query::Closest, Query::Any] {
            let any = query == Query::Any;
            let traced = tracer.trace_with(&rays, Cones::None, query, true).unwrap();
            let counters = traced.counters.unwrap();
            let mut hits = 0;
            for (i, ray) in rays.iter().enumerate() {
                let (cpu, stats) = twin.trace(ray, any, &mut ());
                in_top_level += usize::from(!any && cpu.is_hit() && stats.counters.instances == 0);
                let gpu = traced.hits[i];
                let at = format!("Q{level} {addressing:?} {query:?} ray {i}");
                assert_eq!(gpu.is_hit(), cpu.is_hit(), "{at}");
                assert_eq!(counters[i], stats.counters, "{at}: counters");
                if any || !gpu.is_hit() {
                    continue;
                }
                hits += 1;
                assert_eq!((gpu.instance, gpu.id), (cpu.instance, cpu.id), "{at}");
                assert!(
                    (gpu.t - cpu.t).abs() <= 1e-5 * cpu.t,
                    "{at}: t {} vs {}",
                    gpu.t,
                    cpu.t
                );
                assert!(gpu.normal().dot(cpu.normal()) > 0.9999, "{at}: normals");
            }
            assert!(any || hits * 4 > rays.len(), "{hits} hits");
        }
    }
    in_top_level
}

/// The two-level exact BVH referees the two-level RBVH as the exact BVH referees a flat one:
/// the same rays hit, at distances within a few texels of the instance's mesh, at Q2, with and
/// without a grafted first instance.
#[test]
fn the_two_level_exact_bvh_referees_the_two_level_rbvh() {
    for scene in [placed(), grafted()] {
        referee(&scene);
    }
}

/// The two-level RBVH at Q2 against the two-level exact BVH of `scene`.
fn referee(scene: &InstancedScene) {
    let rays = rays(scene, 6_000, 17);
    let exact = InstancedBvh::build(scene).unwrap();
    let two = InstancedRbvh::build(scene, &RbvhParams::quality(2).unwrap()).unwrap();
    let (mut both, mut disagree, mut far) = (0usize, 0usize, 0usize);
    for ray in &rays {
        let (e, _) = exact.closest_hit(ray);
        let (r, stats) = two.closest_hit(ray);
        assert!(!stats.overflow);
        if e.is_hit() != r.is_hit() {
            disagree += 1;
            continue;
        }
        if !e.is_hit() {
            continue;
        }
        both += 1;
        // The texel of the mesh hit, in world units along the ray: its mesh texel times the
        // largest stretch of the instance (a bound on how far one texel reaches in the world).
        let instance = &scene.instances[e.instance as usize];
        let m = glam::Mat3::from_mat4(instance.transform);
        let stretch = [m.x_axis, m.y_axis, m.z_axis]
            .iter()
            .map(|c| c.length())
            .fold(0.0f32, f32::max);
        let texel = two.mesh_texels[instance.mesh as usize] * stretch;
        if (r.t - e.t).abs() * ray.dir().length() > 4.0 * texel {
            far += 1;
        }
    }
    assert!(both * 3 > rays.len(), "{both} hits");
    assert!(
        disagree * 50 <= rays.len(),
        "{disagree} hit/miss disagreements of {}",
        rays.len()
    );
    assert!(far * 50 <= both, "{far} of {both} hits beyond 4 texels");
}

/// Moving instances rewrites the device's top level and instance records alone: the hits are a
/// fresh upload's bit for bit. A two-level RBVH is not a two-level exact BVH to move, and has no
/// levels of detail.
#[test]
fn moving_rbvh_instances_uploads_the_top_level_alone() {
    let scene = placed();
    let mut two = InstancedRbvh::build(&scene, &RbvhParams::quality(1).unwrap()).unwrap();
    let ctx = common::context();
    let mut tracer = Tracer::new(&ctx, &Structure::from(two.clone())).unwrap();
    let rays = rays(&scene, 2_000, 3);
    let before = tracer.trace(&rays, Query::Closest).unwrap().hits;
    let moved: Vec<Mat4> = scene
        .instances
        .iter()
        .enumerate()
        .map(|(k, i)| Mat4::from_translation(Vec3::new(0.0, 0.05 * k as f32, 0.0)) * i.transform)
        .collect();
    two.set_transforms(&moved).unwrap();
    tracer.update_instances(&two).unwrap();
    common::moved_as_fresh(&ctx, &tracer, Structure::from(two.clone()), &rays, &before);

    let exact = InstancedBvh::build(&scene).unwrap();
    let e = tracer.update_instances(&exact).unwrap_err().to_string();
    assert!(e.contains("not a two-level exact BVH"), "{e}");
    let e = Structure::from(two)
        .with_levels(&LodParams::default())
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("not over instances"), "{e}");
}

/// A two-level RBVH saved and loaded is the one built (its top level built again on load, the
/// same), and saving it again gives the same bytes; a flat reader refuses it and the two-level
/// reader a flat file, by name. Checked against a scene, the file takes the scene's placements
/// (moved instances trace as a fresh build's) and refuses another scene's meshes or instances;
/// a file's table tells which loader it takes.
#[test]
fn two_level_rbvh_files_hold_every_mesh_and_instance() {
    let scene = placed();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("placed.rbvh");
    for texels in [TexelFormat::HeightNormal, TexelFormat::Height] {
        let params = RbvhParams {
            texels,
            ..RbvhParams::quality(2).unwrap()
        };
        let built = InstancedRbvh::build(&scene, &params).unwrap();
        built.save(&path).unwrap();
        let loaded = InstancedRbvh::load(&path).unwrap();
        assert_eq!(loaded, built, "{texels:?}");
        assert_eq!(loaded.to_bytes(), std::fs::read(&path).unwrap());
        let flat = rbvh::rbvh::Rbvh::load(&path).unwrap_err().to_string();
        assert!(
            flat.contains("a two-level RBVH (2 meshes, 9 instances"),
            "{flat}"
        );
    }
    // A grafted first instance: the top level built again on load grafts it as the build did.
    let grafted_file = dir.path().join("grafted.rbvh");
    let built = InstancedRbvh::build(&grafted(), &RbvhParams::quality(1).unwrap()).unwrap();
    built.save(&grafted_file).unwrap();
    assert_eq!(InstancedRbvh::load(&grafted_file).unwrap(), built);
    let flat_file = dir.path().join("flat.rbvh");
    let flat = scene.clone().into_flat();
    rbvh::rbvh::Rbvh::build(&flat, &RbvhParams::quality(0).unwrap())
        .unwrap()
        .save(&flat_file)
        .unwrap();
    let e = InstancedRbvh::load(&flat_file).unwrap_err().to_string();
    assert!(e.contains("a flat RBVH (no sections MESH and PLAC)"), "{e}");

    // Which loader a file takes, from its table alone; other bytes are neither's (its loader
    // names the fault), a missing file an error.
    use rbvh::rbvh::file::holds_instances;
    assert!(holds_instances(&path).unwrap());
    assert!(!holds_instances(&flat_file).unwrap());
    let bytes = std::fs::read(&path).unwrap();
    for (name, cut) in [("short.rbvh", 20), ("head.rbvh", 10), ("none.rbvh", 0)] {
        let short = dir.path().join(name);
        std::fs::write(&short, &bytes[..cut]).unwrap();
        assert!(!holds_instances(&short).unwrap(), "{name}");
    }
    let missing = holds_instances(&dir.path().join("missing.rbvh")).unwrap_err();
    assert!(missing.to_string().contains("missing.rbvh"), "{missing}");

    // The scene's own placements, moved: the file follows them.
    let mut loaded = InstancedRbvh::load(&path).unwrap();
    let mut moved = scene.clone();
    for (k, instance) in moved.instances.iter_mut().enumerate() {
        instance.transform =
            Mat4::from_translation(Vec3::new(0.0, 0.3 * k as f32, 0.0)) * instance.transform;
    }
    loaded.check_built_from(&moved).unwrap();
    let mut fresh = InstancedRbvh::build(&scene, loaded.params()).unwrap();
    fresh
        .set_transforms(
            &moved
                .instances
                .iter()
                .map(|i| i.transform)
                .collect::<Vec<_>>(),
        )
        .unwrap();
    let probe = rays(&moved, 500, 11);
    assert_eq!(
        loaded.trace_cpu(&probe, false),
        fresh.trace_cpu(&probe, false)
    );

    // Another scene: fewer instances, another mesh in an instance, another mesh's shape.
    let mut fewer = scene.clone();
    fewer.instances.pop();
    let mut other_mesh = scene.clone();
    other_mesh.instances[0].mesh = 1;
    let mut other_shape = scene.clone();
    other_shape.meshes[1] = Scene::builtin("cube").unwrap();
    for (what, other) in [
        ("instances", fewer),
        ("places mesh", other_mesh),
        ("mesh 1's box", other_shape),
    ] {
        let mut loaded = InstancedRbvh::load(&path).unwrap();
        let e = loaded.check_built_from(&other).unwrap_err().to_string();
        assert!(
            e.contains("built for another scene") && e.contains(what),
            "{what}: {e}"
        );
    }
}

/// A two-level RBVH's file that lies about its meshes or placements is refused, naming the
/// section: a mesh's tree outside the nodes, a tree deeper than the stack, a box without a
/// tree, an instance of a mesh that does not exist, a transform that is not invertible, a
/// mesh's node that names the top level.
#[test]
fn corrupt_two_level_rbvh_files_are_refused_by_section() {
    let scene = placed();
    let built = InstancedRbvh::build(&scene, &RbvhParams::quality(1).unwrap()).unwrap();
    let bytes = built.to_bytes();
    let table = rbvh::rbvh::file::section_table(&bytes, std::path::Path::new("x")).unwrap();
    let at = |tag: &[u8; 4]| table.iter().find(|s| &s.tag == tag).unwrap().offset as usize;
    let (meshes, placements, nodes) = (at(b"MESH"), at(b"PLAC"), at(b"NODE"));
    let top = built.top_nodes as usize;
    let node_bytes = std::mem::size_of::<rbvh::bvh::GpuNode>();
    let a_child = std::mem::offset_of!(rbvh::bvh::GpuNode, a_child);
    // Per case, the section named and the words written (byte offset, value).
    let cases: [(&str, Vec<(usize, u32)>); 6] = [
        ("MESH", vec![(meshes, u32::MAX - 4)]),
        // A depth past the stack; no tree under a box (the root then unchecked).
        ("MESH", vec![(meshes + 16, u32::MAX)]),
        ("MESH", vec![(meshes, 0), (meshes + 4, 0)]),
        ("PLAC", vec![(placements, 7)]),
        ("PLAC", (1..13).map(|k| (placements + 4 * k, 0)).collect()),
        ("NODE", vec![(nodes + node_bytes * top + a_child, 0)]),
    ];
    for (k, (section, words)) in cases.iter().enumerate() {
        let mut bad = bytes.clone();
        for &(at, x) in words {
            bad[at..at + 4].copy_from_slice(&x.to_le_bytes());
        }
        let e = InstancedRbvh::from_bytes(&bad, std::path::Path::new("bad.rbvh"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("bad.rbvh") && e.contains(&format!("section {section}")),
            "case {k}: {e}"
        );
    }
}

/// A secondary ray leaves a two-level RBVH's surface by the hit instance's own texel: the
/// largest placement's is the flat scene's texel, a smaller one's smaller by its scale.
#[test]
fn surface_offsets_scale_with_each_instance() {
    let scene = placed();
    let two = InstancedRbvh::build(&scene, &RbvhParams::quality(2).unwrap()).unwrap();
    let structure = Structure::from(two.clone());
    let offsets: Vec<f32> = (0..scene.instances.len() as u32)
        .map(|k| {
            structure.surface_offset(&rbvh::geom::Hit {
                instance: k,
                ..rbvh::geom::Hit::MISS
            })
        })
        .collect();
    let largest = offsets.iter().copied().fold(0.0f32, f32::max);
    assert!(
        (largest - two.texel_size()).abs() <= 1e-6 * two.texel_size(),
        "{offsets:?}"
    );
    // Instance 0 places the bumpy sphere at its smallest: its longest axis 0.6, instance 8's 1.6.
    assert!(offsets[0] < 0.5 * offsets[8], "{offsets:?}");
    assert!(offsets
        .iter()
        .all(|&o| o > 0.0 && o <= two.texel_size() * (1.0 + 1e-6)));
    // Moved to a larger scale than it was built at, an instance's texel grows with it.
    let mut moved = two.clone();
    let mut transforms = moved.transforms.clone();
    transforms[8] *= Mat4::from_scale(Vec3::splat(3.0));
    moved.set_transforms(&transforms).unwrap();
    let grown = Structure::from(moved).surface_offset(&rbvh::geom::Hit {
        instance: 8,
        ..rbvh::geom::Hit::MISS
    });
    assert!(
        (grown - 3.0 * offsets[8]).abs() <= 1e-5 * grown,
        "{grown} vs {offsets:?}"
    );
}

/// A mirrored instance leaks as its mesh does, which the bench's seam count for two levels
/// relies on (it aims at each mesh in its own space, `bench::harness`): the mesh's seam rays,
/// taken into the world by a mirroring, turning, scaling placement, are refereed by the flat
/// copy's exact BVH (whose winding the mirror reversed, so that its outside stays outside) and
/// traced through the two-level RBVH. As many rays enter the solid as in the mesh's space, and
/// none leaks or passes through, there as here, on the closed blob.
#[test]
fn a_mirrored_instance_leaks_as_its_mesh_does() {
    use rbvh::bench::seams::{closed_triangles, count_leaks, exact_entries};
    use rbvh::bvh::Bvh;
    use rbvh::rbvh::Rbvh;

    let mesh = Scene::builtin("blob").unwrap();
    let scale = 1.5;
    let place = Mat4::from_scale_rotation_translation(
        Vec3::new(-scale, scale, scale),
        Quat::from_rotation_y(0.7),
        Vec3::new(0.3, -0.2, 0.1),
    );
    let mut scene = InstancedScene::single(mesh.clone());
    scene.instances[0].transform = place;
    let params = RbvhParams::quality(1).unwrap();
    let two = InstancedRbvh::build(&scene, &params).unwrap();
    // The mesh alone at the two-level RBVH's texel for it (its placed box, turned, is not its
    // box scaled), so that the seam rays aim at the seams of the leaves the instance shows.
    let at_texel = RbvhParams {
        texels_per_diagonal: mesh.bounds().diagonal() / two.mesh_texels[0],
        ..params
    };
    let own = Rbvh::build(&mesh, &at_texel).unwrap();
    assert!((own.texel_size / two.mesh_texels[0] - 1.0).abs() < 1e-5);
    let seam = own.seam_rays(50_000, 11);

    let bvh = Bvh::build(&mesh).unwrap();
    let inside = exact_entries(&bvh, &seam.rays, &seam.texels, &closed_triangles(&mesh));
    let approx = own.trace_cpu(&seam.rays, false);
    let in_mesh = count_leaks(&bvh, &seam.rays, &inside, &approx, &seam.texels);

    let rays: Vec<Ray> = seam
        .rays
        .iter()
        .map(|r| {
            let dir = place.transform_vector3(r.dir()) / scale;
            Ray::new(
                place.transform_point3(r.origin()),
                dir,
                r.tmin * scale,
                r.tmax * scale,
            )
        })
        .collect();
    let texels: Vec<f32> = seam.texels.iter().map(|t| t * scale).collect();
    let flat = scene.clone().into_flat();
    let world = Bvh::build(&flat).unwrap();
    let entered = exact_entries(&world, &rays, &texels, &closed_triangles(&flat));
    let approx = two.trace_cpu(&rays, false);
    let in_world = count_leaks(&world, &rays, &entered, &approx, &texels);

    let count = |e: &[Option<rbvh::bench::seams::Entry>]| e.iter().filter(|e| e.is_some()).count();
    let (n_mesh, n_world) = (count(&inside), count(&entered));
    assert!(
        n_mesh * 2 > seam.rays.len(),
        "{n_mesh} of {} enter",
        seam.rays.len()
    );
    assert!(
        n_mesh.abs_diff(n_world) * 1000 <= seam.rays.len(),
        "{n_mesh} rays enter the mesh, {n_world} its mirrored placement"
    );
    assert_eq!((in_mesh.leaks, in_mesh.through), (0, 0), "{in_mesh:?}");
    assert_eq!((in_world.leaks, in_world.through), (0, 0), "{in_world:?}");
}
