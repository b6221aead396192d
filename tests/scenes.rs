//! Scene loading through the public API: built-ins and their analytic oracles, OBJ, glTF, GLB
//! and scene files, the errors users see for broken input, and the camera.

mod common;

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::Vec3;
use rbvh::geom::Aabb;
use rbvh::scene::builtin;
use rbvh::scene::{Camera, InstancedScene, Light, Scene};
use rbvh::Error;

fn repo(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(path)
}

fn load(path: &Path) -> Result<Scene, Error> {
    Scene::load(path.to_str().expect("test paths are UTF-8"))
}

fn write(dir: &Path, name: &str, content: impl AsRef<[u8]>) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, content).unwrap();
    path
}

fn assert_close(a: Vec3, b: Vec3, eps: f32) {
    assert!((a - b).abs().max_element() <= eps, "{a} != {b}");
}

fn normal(t: [Vec3; 3]) -> Vec3 {
    (t[1] - t[0]).cross(t[2] - t[0])
}

fn object_triangles<'a>(scene: &'a Scene, object: usize) -> impl Iterator<Item = [Vec3; 3]> + 'a {
    (0..scene.triangle_count())
        .filter(move |&t| scene.object_of_triangle[t] as usize == object)
        .map(|t| scene.triangle(t))
}

/// Σ a·(b×c)/6: positive exactly when a closed mesh is wound outwards.
fn signed_volume(scene: &Scene, object: usize) -> f64 {
    object_triangles(scene, object)
        .map(|[a, b, c]| a.as_dvec3().dot(b.as_dvec3().cross(c.as_dvec3())) / 6.0)
        .sum()
}

/// Every directed edge, with vertices identified by their exact coordinates, is matched by the
/// reverse edge of a neighbour: the object is closed and consistently oriented.
fn is_closed(scene: &Scene, object: usize) -> bool {
    let key = |v: Vec3| v.to_array().map(f32::to_bits);
    let mut edges: HashMap<_, i32> = HashMap::new();
    for t in object_triangles(scene, object) {
        for i in 0..3 {
            let (a, b) = (key(t[i]), key(t[(i + 1) % 3]));
            if a == b {
                continue;
            }
            *edges.entry((a.min(b), a.max(b))).or_default() += if a < b { 1 } else { -1 };
        }
    }
    edges.values().all(|&n| n == 0)
}

#[test]
fn every_builtin_loads_and_closed_ones_wind_outwards() {
    for &name in builtin::NAMES {
        let scene = Scene::load(name).unwrap();
        scene.validate().unwrap();
        assert_eq!(scene.name, name);
        assert!(scene.triangle_count() > 0, "{name}");
        assert_eq!(scene.object_of_triangle.len(), scene.triangle_count());
        for (object, object_name) in scene.object_names.iter().enumerate() {
            // The open sheets: planes, grounds, and the hall's floor and walls.
            if matches!(object_name.as_str(), "plane" | "ground" | "floor")
                || object_name.ends_with(" wall")
            {
                continue;
            }
            assert!(
                is_closed(&scene, object),
                "{name}/{object_name} is not closed"
            );
            let volume = signed_volume(&scene, object);
            assert!(
                volume > 0.0,
                "{name}/{object_name} winds inwards: volume {volume}"
            );
        }
    }
}

#[test]
fn builtin_sizes_and_parts() {
    let count = |name| Scene::builtin(name).unwrap().triangle_count();
    assert!(
        (80_000..=200_000).contains(&count("default")),
        "{}",
        count("default")
    );
    assert!(
        (20_000..=50_000).contains(&count("blob")),
        "{}",
        count("blob")
    );
    assert!(
        (15_000..=30_000).contains(&count("sphere")),
        "{}",
        count("sphere")
    );

    let scene = Scene::builtin("default").unwrap();
    for part in [
        "ground",
        "sphere",
        "torus",
        "cube",
        "cylinder",
        "cone",
        "bumpy-sphere",
    ] {
        assert!(scene.object_names.iter().any(|n| n == part), "no {part}");
    }
    // Everything stands on the ground, and the ground holds it all.
    let ground = scene
        .object_names
        .iter()
        .position(|n| n == "ground")
        .unwrap();
    let ground_box = Aabb::from_points(object_triangles(&scene, ground).flatten());
    for object in (0..scene.object_names.len()).filter(|&o| o != ground) {
        let b = Aabb::from_points(object_triangles(&scene, object).flatten());
        let name = &scene.object_names[object];
        assert!(
            b.min.y >= -1e-5 && b.min.y < 0.05,
            "{name} floats or sinks: {b:?}"
        );
        assert!(
            b.min.x > ground_box.min.x && b.max.x < ground_box.max.x,
            "{name}"
        );
        assert!(
            b.min.z > ground_box.min.z && b.max.z < ground_box.max.z,
            "{name}"
        );
    }
}

#[test]
fn plane_matches_its_oracle() {
    let scene = Scene::builtin("plane").unwrap();
    let (point, n, half_extent) = common::plane_oracle();
    for t in 0..scene.triangle_count() {
        let tri = scene.triangle(t);
        assert!(
            normal(tri).normalize().dot(n) > 0.999_999,
            "triangle {t} faces away"
        );
        for p in tri {
            assert_eq!((p - point).dot(n), 0.0);
        }
    }
    let b = scene.bounds();
    assert_eq!(b.min, Vec3::new(-half_extent, 0.0, -half_extent));
    assert_eq!(b.max, Vec3::new(half_extent, 0.0, half_extent));
}

#[test]
fn sphere_matches_its_oracle_within_the_computed_chord_error() {
    let scene = Scene::builtin("sphere").unwrap();
    let (center, radius, max_chord_error) = common::sphere_oracle();
    assert_eq!((center, radius), (Vec3::ZERO, 1.0));
    for p in &scene.positions {
        assert!(
            (p.length() - 1.0).abs() <= 1e-6,
            "vertex at radius {}",
            p.length()
        );
    }
    assert!(
        max_chord_error > 0.0 && max_chord_error < 1e-3,
        "{max_chord_error}"
    );
    // Every point of the surface lies within the bound, and centroids come close to it.
    let mut deepest = 0.0f32;
    for t in 0..scene.triangle_count() {
        let [a, b, c] = scene.triangle(t);
        for (u, v) in [(1.0 / 3.0, 1.0 / 3.0), (0.5, 0.25), (0.1, 0.8), (0.5, 0.5)] {
            let r = (a + u * (b - a) + v * (c - a)).length();
            assert!((r - 1.0).abs() <= max_chord_error + 1e-6, "radius {r}");
            deepest = deepest.max(1.0 - r);
        }
    }
    assert!(
        deepest >= 0.5 * max_chord_error,
        "bound {max_chord_error} is loose: {deepest}"
    );
    assert!(builtin::analytic("torus").is_none());
}

#[test]
fn shipped_obj_loads_with_its_objects() {
    let scene = load(&repo("scenes/meshes/pyramid.obj")).unwrap();
    assert_eq!(scene.triangle_count(), 24);
    assert_eq!(scene.object_names, vec!["base", "top"]);
    assert_eq!(scene.bounds().min, Vec3::new(-1.0, 0.0, -1.0));
    assert_eq!(scene.bounds().max, Vec3::new(1.0, 1.0, 1.0));
    for object in 0..2 {
        assert!(is_closed(&scene, object));
        assert!(signed_volume(&scene, object) > 0.0);
    }
}

#[test]
fn obj_ignores_missing_materials_and_triangulates_polygons() {
    let dir = tempfile::tempdir().unwrap();
    let obj = "mtllib missing.mtl\nusemtl stone\n\
               v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0.5 1.5 0\nv 0 1 0\nf 1 2 3 4 5\n";
    // Upper-case extensions are accepted too.
    let scene = load(&write(dir.path(), "PENTAGON.OBJ", obj)).unwrap();
    assert_eq!(scene.triangle_count(), 3);
    for t in 0..3 {
        assert!(normal(scene.triangle(t)).z > 0.0);
    }
}

#[test]
fn obj_errors_name_the_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(
        dir.path(),
        "bad.obj",
        "v 0 0 0\nv 1 zero 0\nv 0 1 0\nf 1 2 3\n",
    );
    match load(&path) {
        Err(e @ Error::Parse { line: Some(2), .. }) => {
            assert!(e.to_string().contains("bad.obj:2"), "{e}");
        }
        other => panic!("expected a parse error at line 2, got {other:?}"),
    }
    let path = write(dir.path(), "face.obj", "v 0 0 0\nv 1 0 0\nf 1 2 x\n");
    assert!(matches!(
        load(&path),
        Err(Error::Parse { line: Some(3), .. })
    ));
}

#[test]
fn non_finite_obj_vertices_are_invalid_geometry_naming_file_and_vertex() {
    let dir = tempfile::tempdir().unwrap();
    for (file, value) in [("nan.obj", "nan"), ("inf.obj", "inf"), ("neg.obj", "-inf")] {
        let obj = format!("v 0 0 0\nv 1 0 0\nv 0 {value} 0\nf 1 2 3\n");
        let path = write(dir.path(), file, obj);
        match load(&path) {
            Err(e @ Error::InvalidGeometry { .. }) => {
                let text = e.to_string();
                assert!(text.contains(file) && text.contains("vertex 3"), "{text}");
                assert!(text.contains(&format!("{file}:3")), "no line in {text}");
            }
            other => panic!("{file}: expected invalid geometry, got {other:?}"),
        }
    }
}

/// A minimal glTF document; `buffer` is the JSON of the single buffer.
fn gltf_json(buffer: &str, extra_nodes: &str, scene_nodes: &str) -> String {
    format!(
        r#"{{
  "asset": {{ "version": "2.0" }},
  "scene": 0,
  "scenes": [{{ "nodes": {scene_nodes} }}],
  "nodes": [
    {{ "name": "root", "translation": [10, 0, 0], "scale": [2, 2, 2], "children": [1] }},
    {{ "name": "child", "rotation": [0, 0, 0.70710678, 0.70710678], "mesh": 0 }},
    {{ "name": "plain", "mesh": 0 }}{extra_nodes}
  ],
  "meshes": [{{ "name": "tri", "primitives": [
    {{ "attributes": {{ "POSITION": 0 }}, "indices": 1 }},
    {{ "attributes": {{ "POSITION": 0 }}, "mode": 5 }},
    {{ "attributes": {{ "POSITION": 0 }}, "mode": 1 }}
  ] }}],
  "buffers": [{buffer}],
  "bufferViews": [
    {{ "buffer": 0, "byteOffset": 0, "byteLength": 48 }},
    {{ "buffer": 0, "byteOffset": 48, "byteLength": 6 }}
  ],
  "accessors": [
    {{ "bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
       "min": [0, 0, 0], "max": [1, 1, 0] }},
    {{ "bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR" }}
  ]
}}"#
    )
}

/// Four positions (0,0,0), (1,0,0), (0,1,0), (1,1,0) and the u16 indices 0 1 2, padded to 56.
fn gltf_bin() -> Vec<u8> {
    let mut bin = Vec::new();
    for v in [0f32, 0., 0., 1., 0., 0., 0., 1., 0., 1., 1., 0.] {
        bin.extend(v.to_le_bytes());
    }
    for i in [0u16, 1, 2] {
        bin.extend(i.to_le_bytes());
    }
    bin.resize(56, 0);
    bin
}

/// Checks the scene of [`gltf_json`]: the indexed triangle under root·child (rotate 90° about
/// z, scale 2, translate 10 x), the strip's two triangles there too, and both again untransformed.
fn check_gltf_scene(scene: &Scene) {
    assert_eq!(
        scene.object_names,
        vec!["tri/prim0", "tri/prim1", "tri/prim0", "tri/prim1"]
    );
    assert_eq!(scene.triangle_count(), 6);
    let [a, b, c] = scene.triangle(0);
    assert_close(a, Vec3::new(10.0, 0.0, 0.0), 1e-5);
    assert_close(b, Vec3::new(10.0, 2.0, 0.0), 1e-5);
    assert_close(c, Vec3::new(8.0, 0.0, 0.0), 1e-5);
    assert_close(scene.bounds().min, Vec3::new(0.0, 0.0, 0.0), 1e-5);
    assert_close(scene.bounds().max, Vec3::new(10.0, 2.0, 0.0), 1e-5);
    // Strip triangles alternate in the file but come out with one orientation.
    for t in 0..scene.triangle_count() {
        assert!(normal(scene.triangle(t)).z > 0.0, "triangle {t} flipped");
    }
}

#[test]
fn gltf_with_bin_file_applies_node_transforms() {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), "data.bin", gltf_bin());
    let json = gltf_json(r#"{ "uri": "data.bin", "byteLength": 56 }"#, "", "[0, 2]");
    let scene = load(&write(dir.path(), "scene.gltf", json)).unwrap();
    check_gltf_scene(&scene);
}

/// A node rotation that is not a unit quaternion is refused, naming the node, where it used to
/// skew and scale the mesh; one off by float rounding is normalized; a node matrix that is not
/// affine is refused by the flat loader as by the two-level one (the flat one applied it with
/// its last row ignored).
#[test]
fn gltf_node_transforms_are_unit_rotations_and_affine() {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), "data.bin", gltf_bin());
    let buffer = r#"{ "uri": "data.bin", "byteLength": 56 }"#;
    let unit = r#""rotation": [0, 0, 0.70710678, 0.70710678]"#;
    let with_child = |name: &str, child: &str| {
        let json = gltf_json(buffer, "", "[0, 2]");
        assert!(json.contains(unit));
        write(dir.path(), name, json.replace(unit, child))
    };
    let skewed = with_child("skewed.gltf", r#""rotation": [0, 0, 1, 1]"#);
    for e in [
        load(&skewed).unwrap_err().to_string(),
        InstancedScene::load(skewed.to_str().unwrap())
            .unwrap_err()
            .to_string(),
    ] {
        assert!(
            e.contains("skewed.gltf")
                && e.contains("node 1 (\"child\")")
                && e.contains("unit quaternion"),
            "{e}"
        );
    }
    let rounded = with_child("rounded.gltf", r#""rotation": [0, 0, 0.7072, 0.7072]"#);
    check_gltf_scene(&load(&rounded).unwrap());
    let projective = with_child(
        "projective.gltf",
        r#""matrix": [0, 1, 0, 0, -1, 0, 0, 0, 0, 0, 1, 0.5, 0, 0, 0, 1]"#,
    );
    for e in [
        load(&projective).unwrap_err().to_string(),
        InstancedScene::load(projective.to_str().unwrap())
            .unwrap_err()
            .to_string(),
    ] {
        assert!(
            e.contains("projective.gltf") && e.contains("node 1") && e.contains("not 0 0 0 1"),
            "{e}"
        );
    }
    let affine = with_child(
        "affine.gltf",
        r#""matrix": [0, 1, 0, 0, -1, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]"#,
    );
    check_gltf_scene(&load(&affine).unwrap());
}

#[test]
fn glb_loads_like_gltf() {
    let json = gltf_json(r#"{ "byteLength": 56 }"#, "", "[0, 2]");
    let mut json = json.into_bytes();
    json.resize(json.len().next_multiple_of(4), b' ');
    let bin = gltf_bin();
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut glb = Vec::new();
    glb.extend(b"glTF");
    glb.extend(2u32.to_le_bytes());
    glb.extend((total as u32).to_le_bytes());
    glb.extend((json.len() as u32).to_le_bytes());
    glb.extend(b"JSON");
    glb.extend(&json);
    glb.extend((bin.len() as u32).to_le_bytes());
    glb.extend(b"BIN\0");
    glb.extend(&bin);
    let dir = tempfile::tempdir().unwrap();
    check_gltf_scene(&load(&write(dir.path(), "scene.glb", &glb)).unwrap());
    // A truncated file is an error naming it, not a crash.
    let e = load(&write(dir.path(), "cut.glb", &glb[..40])).unwrap_err();
    assert!(e.to_string().contains("cut.glb"), "{e}");
}

#[test]
fn gltf_mirroring_node_keeps_outward_winding() {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), "data.bin", gltf_bin());
    let mirror = r#", { "name": "mirror", "scale": [1, 1, -1], "mesh": 0 }"#;
    let json = gltf_json(r#"{ "uri": "data.bin", "byteLength": 56 }"#, mirror, "[3]");
    let scene = load(&write(dir.path(), "mirror.gltf", json)).unwrap();
    assert_eq!(scene.triangle_count(), 3);
    for t in 0..3 {
        assert!(
            normal(scene.triangle(t)).z < 0.0,
            "mirrored triangle {t} not reversed"
        );
    }
}

#[test]
fn gltf_errors_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        ("syntax.gltf", "{ \"asset\": ".to_owned()),
        // The .bin file is missing.
        (
            "nobin.gltf",
            gltf_json(r#"{ "uri": "absent.bin", "byteLength": 56 }"#, "", "[0]"),
        ),
        // A buffer too short for its views.
        (
            "short.gltf",
            gltf_json(
                r#"{ "uri": "data:application/octet-stream;base64,AAAA", "byteLength": 3 }"#,
                "",
                "[0]",
            ),
        ),
        // A node hierarchy with a cycle.
        (
            "cycle.gltf",
            gltf_json(r#"{ "uri": "data.bin", "byteLength": 56 }"#, "", "[0]")
                .replace(r#""mesh": 0 },"#, r#""mesh": 0, "children": [0] },"#),
        ),
    ];
    write(dir.path(), "data.bin", gltf_bin());
    common::every_case(cases, |(file, json)| {
        match load(&write(dir.path(), file, json)) {
            Ok(_) => Err(format!("{file}: loaded")),
            Err(e) => common::ensure(e.to_string().contains(file), || format!("{file}: {e}")),
        }
    });
    // A POSITION accessor of the wrong type is reported, not read past.
    let json = gltf_json(r#"{ "uri": "data.bin", "byteLength": 56 }"#, "", "[0]")
        .replace("\"VEC3\"", "\"VEC2\"");
    let e = load(&write(dir.path(), "vec2.gltf", json)).unwrap_err();
    assert!(
        e.to_string().contains("vec2.gltf") && e.to_string().contains("VEC3"),
        "{e}"
    );
    let e = load(&write(dir.path(), "syntax2.gltf", "{\n\n  oops\n}")).unwrap_err();
    assert!(matches!(e, Error::Parse { line: Some(3), .. }), "{e}");
}

#[test]
fn shipped_scene_files_load() {
    let mut loaded = 0;
    for entry in std::fs::read_dir(repo("scenes")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "toml") {
            continue;
        }
        // Benchmark scenes of the shared datasets are not shipped with their meshes.
        let text = std::fs::read_to_string(&path).unwrap();
        if text.contains("shared/datasets/dragon/") && !repo("../shared/datasets/dragon").exists() {
            continue;
        }
        // Loaded with its instances: a scene too large to flatten (dragons-1000.toml) is
        // refused flat by name, and loads in two levels.
        let placed = rbvh::scene::InstancedScene::load(path.to_str().unwrap())
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        assert!(
            placed.camera.is_some() && placed.light.is_some(),
            "{}",
            path.display()
        );
        if placed
            .check_flat_fits(rbvh::scene::available_memory())
            .is_err()
        {
            let e = load(&path).unwrap_err().to_string();
            assert!(e.contains("traced in two levels only"), "{e}");
        } else {
            load(&path).unwrap_or_else(|e| panic!("{} flat: {e}", path.display()));
        }
        loaded += 1;
    }
    assert!(loaded >= 2);

    let scene = load(&repo("scenes/mesh.toml")).unwrap();
    assert_eq!(scene.name, "stepped pyramids");
    assert_eq!(scene.triangle_count(), 128 + 2 * 24);
    assert_eq!(
        scene.light,
        Some(Light::Point {
            position: Vec3::new(2.0, 4.0, 3.0)
        })
    );
    let camera = scene.camera.unwrap();
    assert_eq!((camera.up, camera.vfov_deg), (Vec3::Y, 35.0));
    assert!(scene
        .object_names
        .contains(&"meshes/pyramid.obj/top".to_owned()));
    // The second pyramid: scale [0.5, 1.4, 0.5], then translate [1, 0, -0.7].
    let top = scene
        .object_names
        .iter()
        .rposition(|n| n.ends_with("/top"))
        .unwrap();
    let b = Aabb::from_points(object_triangles(&scene, top).flatten());
    assert_close(b.min, Vec3::new(0.75, 0.7, -0.95), 1e-6);
    assert_close(b.max, Vec3::new(1.25, 1.4, -0.45), 1e-6);

    let showcase = load(&repo("scenes/showcase.toml")).unwrap();
    for object in 1..showcase.object_names.len() {
        let b = Aabb::from_points(object_triangles(&showcase, object).flatten());
        let name = &showcase.object_names[object];
        assert!(
            b.min.y >= -1e-5 && b.min.y < 0.05,
            "{name} floats or sinks: {b:?}"
        );
    }
}

/// `scenes/grove-aerial.toml` is the built-in grove under its own camera, from which every copy
/// is as far as the file says: the level-of-detail view of the README.
#[test]
fn grove_aerial_is_the_grove_seen_from_afar() {
    let aerial = load(&repo("scenes/grove-aerial.toml")).unwrap();
    let grove = Scene::builtin("grove").unwrap();
    assert_eq!(aerial.triangle_count(), grove.triangle_count());
    assert_close(aerial.bounds().min, grove.bounds().min, 1e-5);
    assert_close(aerial.bounds().max, grove.bounds().max, 1e-5);
    let eye = aerial.camera.unwrap().eye;
    let copies =
        (0..aerial.object_names.len()).filter(|&o| aerial.object_names[o].contains("blob"));
    let distances: Vec<f32> = copies
        .map(|o| {
            let b = Aabb::from_points(object_triangles(&aerial, o).flatten());
            b.center().distance(eye)
        })
        .collect();
    assert_eq!(distances.len(), 400);
    let (near, far) = distances
        .iter()
        .fold((f32::INFINITY, 0f32), |(n, f), &d| (n.min(d), f.max(d)));
    assert!(near > 48.0 && far < 155.0, "copies from {near} to {far}");
}

#[test]
fn scene_file_transforms_rotate_about_x_then_y_then_z() {
    let dir = tempfile::tempdir().unwrap();
    let toml = "[[mesh]]\nbuiltin = \"plane\"\n\
                translate = [0, 1, 0]\nrotate = [90, 90, 0]\nscale = [2, 1, 3]\n";
    let scene = load(&write(dir.path(), "t.toml", toml)).unwrap();
    // (x, 0, z) → scale (2x, 0, 3z) → about X (2x, -3z, 0) → about Y (0, -3z, -2x) → +1 y.
    assert_close(scene.bounds().min, Vec3::new(0.0, -2.0, -2.0), 1e-5);
    assert_close(scene.bounds().max, Vec3::new(0.0, 4.0, 2.0), 1e-5);
    assert!(normal(scene.triangle(0)).normalize().x > 0.999);
    assert_eq!(scene.object_names[0], "plane/plane");
    assert_eq!((scene.camera, scene.light), (None, None));

    // A mirroring scale keeps the plane facing up.
    let toml =
        "[light]\ndirection = [0, -2, 0]\n[[mesh]]\nbuiltin = \"plane\"\nscale = [-1, 1, 1]\n";
    let scene = load(&write(dir.path(), "m.toml", toml)).unwrap();
    assert!(normal(scene.triangle(0)).y > 0.0);
    assert_eq!(
        scene.light,
        Some(Light::Directional {
            direction: Vec3::NEG_Y
        })
    );
}

/// Loads `toml` from a file and expects a parse error at `line` whose message mentions `needle`.
/// `Scene::load` and `Scene::check` (which loads no mesh) both refuse `toml` with a parse error at
/// `line` that says `needle`.
fn expect_toml_error(dir: &Path, toml: &str, line: usize, needle: &str) {
    let path = write(dir, "bad.toml", toml);
    let checked = Scene::check(path.to_str().unwrap()).map(|()| None);
    for result in [load(&path).map(Some), checked] {
        match result {
            Err(e @ Error::Parse { line: Some(l), .. }) if l == line => {
                let text = e.to_string();
                assert!(text.contains(&format!("bad.toml:{line}")), "{text}");
                assert!(text.contains(needle), "{needle:?} not in {text:?}");
            }
            other => panic!("{toml:?}: expected a parse error at line {line}, got {other:?}"),
        }
    }
}

/// `Scene::check` takes what `Scene::load` takes without loading meshes: a sound scene file whose
/// mesh is corrupt passes the check and fails the load; missing files and names fail both.
#[test]
fn scenes_are_checked_without_loading_their_meshes() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "broken.obj", "v 0 0 0\nv 1 zero 0\nv 0 1 0\nf 1 2 3\n");
    let file = write(
        d,
        "s.toml",
        "[[mesh]]\npath = \"broken.obj\"\n[[mesh]]\nbuiltin = \"sphere\"\n",
    );
    let spec = file.to_str().unwrap();
    Scene::check(spec).unwrap();
    assert!(Scene::load(spec).is_err());
    Scene::check("sphere").unwrap();
    Scene::check(repo("scenes/meshes/pyramid.obj").to_str().unwrap()).unwrap();
    for bad in ["spere", "/no/such/model.obj", d.to_str().unwrap()] {
        let (checked, loaded) = (Scene::check(bad), Scene::load(bad));
        assert_eq!(
            checked.unwrap_err().to_string(),
            loaded.unwrap_err().to_string(),
            "{bad}"
        );
    }
}

#[test]
fn scene_file_errors_name_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mesh = "[[mesh]]\nbuiltin = \"sphere\"\n";
    expect_toml_error(d, &format!("{mesh}scael = 2\n"), 3, "scael");
    expect_toml_error(d, &format!("name = 1 +\n{mesh}"), 1, "");
    expect_toml_error(d, &format!("{mesh}scale = 0\n"), 3, "scale");
    expect_toml_error(d, &format!("{mesh}scale = [1, nan, 1]\n"), 3, "scale");
    expect_toml_error(d, &format!("{mesh}scale = \"big\"\n"), 3, "number");
    expect_toml_error(d, &format!("{mesh}rotate = [0, inf, 0]\n"), 3, "rotate");
    expect_toml_error(
        d,
        &format!("{mesh}\n[camera]\neye = [0, 0, 1]\ntarget = [0, 0, 0]\nvfov = 180\n"),
        7,
        "vfov",
    );
    expect_toml_error(
        d,
        &format!("{mesh}[camera]\neye = [0, 1, 0]\ntarget = [0, 0, 0]\n"),
        3,
        "up",
    );
    expect_toml_error(
        d,
        &format!("{mesh}[camera]\neye = [1, 1, 1]\ntarget = [1, 1, 1]\n"),
        5,
        "target",
    );
    expect_toml_error(d, &format!("{mesh}[light]\n"), 3, "exactly one");
    expect_toml_error(
        d,
        &format!("{mesh}[light]\ndirection = [0, 0, 0]\n"),
        4,
        "direction",
    );
    expect_toml_error(
        d,
        "[[mesh]]\nbuiltin = \"sphere\"\npath = \"x.obj\"\n",
        1,
        "exactly one",
    );
    expect_toml_error(d, "[[mesh]]\nbuiltin = \"spere\"\n", 2, "torus");
    expect_toml_error(
        d,
        "[[mesh]]\npath = \"gone/missing.obj\"\n",
        2,
        "missing.obj",
    );
    expect_toml_error(d, "[[mesh]]\npath = \"other.toml\"\n", 2, "scene file");
    let e = load(&write(d, "empty.toml", "name = \"nothing\"\n")).unwrap_err();
    assert!(
        e.to_string().contains("empty.toml") && e.to_string().contains("mesh"),
        "{e}"
    );
}

#[test]
fn load_errors_say_what_and_where() {
    match Scene::load("/no/such/dir/model.obj") {
        Err(e @ Error::Io { .. }) => {
            assert!(e.to_string().contains("/no/such/dir/model.obj"), "{e}")
        }
        other => panic!("expected an I/O error, got {other:?}"),
    }
    for spec in ["spherre", "no/such/scene"] {
        let e = Scene::load(spec).unwrap_err();
        assert!(e.to_string().contains(spec), "{e}");
    }
    match Scene::load("spherre") {
        Err(Error::UnknownScene { name, known }) => {
            assert_eq!(name, "spherre");
            for builtin in builtin::NAMES {
                assert!(known.contains(builtin), "{known}");
            }
        }
        other => panic!("expected an unknown scene, got {other:?}"),
    }
    assert!(matches!(
        Scene::builtin("nope"),
        Err(Error::UnknownScene { .. })
    ));
    let dir = tempfile::tempdir().unwrap();
    let e = load(&write(dir.path(), "model.stl", "solid\n")).unwrap_err();
    assert!(
        e.to_string().contains("model.stl")
            && e.to_string().contains(".obj")
            && e.to_string().contains(".ply"),
        "{e}"
    );
    // A point cloud is a scene type of its own: its reader's errors name the file and line.
    let e = load(&write(dir.path(), "model.ply", "ply\n")).unwrap_err();
    assert!(
        e.to_string().contains("model.ply:2") && e.to_string().contains("end_header"),
        "{e}"
    );
}

#[test]
fn framing_is_finite_for_degenerate_boxes_and_fits_the_view() {
    let boxes = [
        Aabb::EMPTY,
        Aabb::from_points([Vec3::new(5.0, -3.0, 2.0)]),
        Aabb::from_points([Vec3::splat(1.0e6)]),
        Aabb::from_points([Vec3::new(-1.0, 0.0, -1.0), Vec3::new(1.0, 0.0, 1.0)]),
    ];
    for b in boxes {
        for aspect in [1.0, 0.25, 4.0, 0.0, f32::NAN] {
            let c = Camera::framing(&b, aspect);
            assert!(
                c.eye.is_finite() && c.target.is_finite(),
                "{b:?} {aspect}: {c:?}"
            );
            assert!(c.eye != c.target, "{b:?}");
            assert!(c
                .primary_rays(4, 3)
                .iter()
                .all(|r| r.is_valid() && r.dir().is_finite()));
        }
    }
    // All corners of a box are in view, for wide and tall images alike.
    let b = Aabb::from_points([Vec3::new(-1.0, 0.0, -2.0), Vec3::new(3.0, 1.0, 2.0)]);
    for aspect in [0.5, 1.0, 2.5] {
        let c = Camera::framing(&b, aspect);
        let forward = (c.target - c.eye).normalize();
        let right = forward.cross(c.up).normalize();
        let up = right.cross(forward);
        let tan_half = (0.5 * c.vfov_deg).to_radians().tan();
        for i in 0..8 {
            let p = Vec3::select(
                glam::BVec3::new(i & 1 != 0, i & 2 != 0, i & 4 != 0),
                b.max,
                b.min,
            ) - c.eye;
            let z = p.dot(forward);
            assert!(
                p.dot(up).abs() / z <= tan_half * (1.0 + 1e-5),
                "corner {i} above or below"
            );
            assert!(
                p.dot(right).abs() / z <= tan_half * aspect * (1.0 + 1e-5),
                "corner {i} beside"
            );
        }
    }
}

#[test]
fn primary_rays_are_unit_row_major_and_centred_on_the_target() {
    let camera = Camera {
        eye: Vec3::new(1.0, 2.0, 5.0),
        target: Vec3::new(0.0, 0.5, 0.0),
        up: Vec3::Y,
        vfov_deg: 50.0,
    };
    let (w, h) = (5, 3);
    let rays = camera.primary_rays(w, h);
    assert_eq!(rays.len(), 15);
    for (i, r) in rays.iter().enumerate() {
        let (x, y) = ((i % 5) as f32 + 0.5, (i / 5) as f32 + 0.5);
        assert_eq!(*r, camera.ray(x, y, w, h));
        assert!((r.dir().length() - 1.0).abs() < 1e-6);
        assert_eq!(
            (r.origin(), r.tmin, r.tmax),
            (camera.eye, 0.0, f32::INFINITY)
        );
    }
    let forward = (camera.target - camera.eye).normalize();
    assert_close(rays[7].dir(), forward, 1e-6);
    assert_close(camera.ray(2.5, 1.5, w, h).dir(), forward, 1e-6);
    // Top row first, left to right.
    assert!(rays[0].dir().y > rays[10].dir().y);
    let right = forward.cross(Vec3::Y);
    assert!(rays[0].dir().dot(right) < rays[4].dir().dot(right));
    // The image's top edge is vfov/2 above the view direction.
    let top = camera.ray(2.5, 0.0, w, h).dir();
    assert!((top.angle_between(forward).to_degrees() - 25.0).abs() < 1e-3);
}

#[test]
fn scenes_without_a_camera_are_framed() {
    let scene = Scene::builtin("sphere").unwrap();
    let c = scene.camera_or_framed(1.5);
    assert_eq!(c, Camera::framing(&scene.bounds(), 1.5));
    assert_close(c.target, Vec3::ZERO, 1e-6);
    let scene = load(&repo("scenes/mesh.toml")).unwrap();
    assert_eq!(scene.camera_or_framed(1.0), scene.camera.unwrap());
}

#[test]
fn scenes_far_from_the_origin_get_a_precision_warning() {
    let sphere = Scene::builtin("sphere").unwrap();
    assert!(sphere.precision_warning().is_none());
    assert!(sphere.coordinate_resolution() < 1e-6);
    for (offset, warned) in [(1.0e3, false), (1.0e6, true), (1.0e7, true)] {
        let mut far = Scene::new("far sphere");
        far.append(
            &sphere,
            glam::Mat4::from_translation(glam::Vec3::splat(offset)),
        );
        let warning = far.precision_warning();
        assert_eq!(warning.is_some(), warned, "offset {offset}: {warning:?}");
        if let Some(w) = warning {
            assert!(w.contains("far sphere") && w.contains("recentre"), "{w}");
        }
    }
}

#[test]
fn devices_and_directories_are_refused_not_read_forever() {
    let dir = tempfile::tempdir().unwrap();
    let folder = dir.path().join("folder.obj");
    std::fs::create_dir(&folder).unwrap();
    let err = Scene::load(folder.to_str().unwrap())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("folder.obj") && err.contains("not a regular file"),
        "{err}"
    );
    let gltf = dir.path().join("zero.gltf");
    std::fs::write(
        &gltf,
        r#"{"asset":{"version":"2.0"},"buffers":[{"uri":"/dev/zero","byteLength":36}],
            "bufferViews":[{"buffer":0,"byteLength":36}],
            "accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[0,0,0]}],
            "meshes":[{"primitives":[{"attributes":{"POSITION":0}}]}],
            "nodes":[{"mesh":0}],"scenes":[{"nodes":[0]}],"scene":0}"#,
    )
    .unwrap();
    let err = Scene::load(gltf.to_str().unwrap()).unwrap_err().to_string();
    assert!(
        err.contains("/dev/zero") && err.contains("not a regular file"),
        "{err}"
    );
}

/// A scene file places point clouds as it places meshes: transformed (normals turned with them,
/// spacing scaled), two copies appended. Mixing point clouds with triangle meshes is refused at
/// the entry that mixes them, since an RBVH is built from one or the other.
#[test]
fn scene_files_place_point_clouds_but_not_beside_meshes() {
    let dir = tempfile::tempdir().unwrap();
    let sphere =
        std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/points/sphere.ply"))
            .unwrap();
    write(dir.path(), "sphere.ply", sphere);
    let single = load(&dir.path().join("sphere.ply")).unwrap();
    let one = single.points.as_ref().unwrap();
    let scan = write(
        dir.path(),
        "scan.toml",
        "[[mesh]]\npath = \"sphere.ply\"\n\n[[mesh]]\npath = \"sphere.ply\"\ntranslate = [3.0, 0.0, 0.0]\nscale = 2.0\nrotate = [0.0, 90.0, 0.0]\n",
    );
    let scene = load(&scan).unwrap();
    assert_eq!(scene.triangle_count(), 0);
    let cloud = scene.points.as_ref().unwrap();
    assert_eq!(cloud.len(), 2 * one.len());
    let n = one.len();
    for i in 0..n {
        // The second copy: still on its sphere (radius 2 about (3, 0, 0)), normals outward.
        let p = cloud.positions[n + i] - Vec3::new(3.0, 0.0, 0.0);
        assert!((p.length() - 2.0).abs() < 1e-3, "{p}");
        assert!(cloud.normals[n + i].dot(p.normalize()) > 0.999);
        assert!(
            (cloud.spacing[n + i] - 2.0 * one.spacing[i]).abs() <= 1e-5 * one.spacing[i].max(1.0)
        );
    }
    let mixed = write(
        dir.path(),
        "mixed.toml",
        "[[mesh]]\nbuiltin = \"plane\"\n\n[[mesh]]\npath = \"sphere.ply\"\n",
    );
    let e = load(&mixed).unwrap_err().to_string();
    assert!(
        e.contains("mixed.toml:4") && e.contains("point cloud"),
        "{e}"
    );
    // A point cloud's [[mesh]] beside a mesh's [[instance]]: each structure used to drop one.
    write(
        dir.path(),
        "tri.obj",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    );
    let beside = write(
        dir.path(),
        "beside.toml",
        "[[mesh]]\npath = \"sphere.ply\"\n\n[[instance]]\npath = \"tri.obj\"\ntranslate = [5.0, 0.0, 0.0]\n",
    );
    for e in [
        load(&beside).unwrap_err().to_string(),
        InstancedScene::load(beside.to_str().unwrap())
            .unwrap_err()
            .to_string(),
    ] {
        assert!(
            e.contains("beside.toml:4") && e.contains("point clouds or meshes, not both"),
            "{e}"
        );
    }
}

/// A `[[mesh]]` whose transform takes its vertices beyond 32-bit floats is refused at its own
/// table (it was reported as "vertex 1" of the merged mesh under the scene's display name), and
/// an `[[instance]]` whose scale overflows is told so (it was called not invertible).
#[test]
fn scene_file_transforms_beyond_floats_are_refused_at_their_entry() {
    let dir = tempfile::tempdir().unwrap();
    write(
        dir.path(),
        "tri.obj",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    );
    let far = "translate = [3e38, 0.0, 0.0]\nscale = 1e38\n";
    let mesh = write(
        dir.path(),
        "far.toml",
        format!("name = \"pretty\"\n\n[[mesh]]\npath = \"tri.obj\"\n\n[[mesh]]\npath = \"tri.obj\"\n{far}"),
    );
    let e = load(&mesh).unwrap_err().to_string();
    assert!(
        e.contains("far.toml:6") && e.contains("vertex 1 of its mesh beyond 32-bit floats"),
        "{e}"
    );
    let instance = write(
        dir.path(),
        "huge.toml",
        format!("[[mesh]]\npath = \"tri.obj\"\n\n[[instance]]\npath = \"tri.obj\"\n{far}"),
    );
    let e = Scene::check(instance.to_str().unwrap())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("huge.toml:4") && e.contains("scale is too large for 32-bit floats"),
        "{e}"
    );
}

/// `Scene::check` refuses an `[[instance]]` transform that loading refuses (not invertible), so
/// that `rbvh bench` finds it before any work, as it finds a bad `[[mesh]]` one.
#[test]
fn scene_file_check_refuses_instances_that_loading_refuses() {
    let dir = tempfile::tempdir().unwrap();
    write(
        dir.path(),
        "tri.obj",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    );
    let flat = write(
        dir.path(),
        "flat.toml",
        "[[instance]]\npath = \"tri.obj\"\n\n[[instance]]\npath = \"tri.obj\"\nscale = [1e-10, 1.0, 1.0]\n",
    );
    let spec = flat.to_str().unwrap();
    for e in [
        Scene::check(spec).unwrap_err().to_string(),
        load(&flat).unwrap_err().to_string(),
    ] {
        assert!(
            e.contains("flat.toml:4") && e.contains("not invertible"),
            "{e}"
        );
    }
}

/// Nodes that draw one mesh are instances of it: the mesh read once in its own space, placed by
/// each node's world transform (a mirroring one too); flattened, the scene the flat loader reads.
#[test]
fn gltf_nodes_sharing_a_mesh_are_its_instances() {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), "data.bin", gltf_bin());
    let mirror = r#", { "name": "mirror", "scale": [1, 1, -1], "mesh": 0 }"#;
    let json = gltf_json(
        r#"{ "uri": "data.bin", "byteLength": 56 }"#,
        mirror,
        "[0, 2, 3]",
    );
    let path = write(dir.path(), "shared.gltf", json);
    let spec = path.to_str().unwrap();
    let placed = rbvh::scene::InstancedScene::load(spec).unwrap();
    assert_eq!(placed.meshes.len(), 1, "the mesh read once");
    assert_eq!(placed.meshes[0].triangle_count(), 3);
    assert_eq!(placed.instances.len(), 3, "drawn by three nodes");
    assert!(placed.instances.iter().all(|i| i.mesh == 0));
    assert!(placed.instances[2].transform.determinant() < 0.0);
    let flat = placed.into_flat();
    let expected = load(&path).unwrap();
    assert_eq!(flat.object_names, expected.object_names);
    assert_eq!(flat.triangles, expected.triangles);
    for (a, b) in flat.positions.iter().zip(&expected.positions) {
        assert_close(*a, *b, 1e-6);
    }
    assert_eq!(flat.positions.len(), expected.positions.len());

    // Told from the nodes alone, before either loader reads the buffers.
    use rbvh::scene::InstancedScene;
    assert_eq!(
        InstancedScene::would_repeat_a_mesh(spec).unwrap(),
        Some(true)
    );
    let once = gltf_json(r#"{ "uri": "data.bin", "byteLength": 56 }"#, "", "[2]");
    let once = write(dir.path(), "once.gltf", once);
    assert_eq!(
        InstancedScene::would_repeat_a_mesh(once.to_str().unwrap()).unwrap(),
        Some(false)
    );
    assert_eq!(
        InstancedScene::would_repeat_a_mesh("grove-instanced").unwrap(),
        None
    );
    let missing = dir.path().join("missing.gltf");
    let e = InstancedScene::would_repeat_a_mesh(missing.to_str().unwrap()).unwrap_err();
    assert!(e.to_string().contains("missing.gltf"), "{e}");
}
