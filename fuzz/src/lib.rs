//! The fuzz targets of `rbvh` as plain functions of the input bytes, so that the cargo-fuzz
//! binaries in `fuzz_targets/` and the deterministic replay in `tests/bad_input.rs` (which
//! includes this file with `#[path]`) run exactly the same code.
//!
//! Every target feeds the bytes to one entry point and then checks what the library promises
//! about whatever comes back: no panic, no hang, and on success a result that is safe to use —
//! loaded scenes validate, built trees validate and fit the stack, loaded RBVHs round-trip
//! byte-identically and trace without overflow, hits are well formed. A failed check panics,
//! which libFuzzer reports as a crash.
//!
//! The loaders take paths, so file inputs go through a per-thread scratch directory.

use std::path::{Path, PathBuf};

use rbvh::bvh::{BuildParams, Bvh, STACK_SIZE};
use rbvh::geom::{Hit, Ray};
use rbvh::rbvh::{Rbvh, RbvhParams, Refinement, Subdivision};
use rbvh::scene::Scene;

/// Scenes loaded from fuzzed files with more triangles than this are not built (a fuzzed scene
/// file can name the 120k-triangle built-ins; loading them is tested, building them is slow).
const MAX_BUILD_TRIANGLES: usize = 5_000;

/// A scratch directory for this process and thread, with `mesh.obj` (one triangle) in it for
/// fuzzed scene files to refer to.
fn scratch() -> PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "rbvh-fuzz-{}-{:?}",
        std::process::id(),
        std::thread::current().id()
    ));
    if !dir.join("mesh.obj").exists() {
        std::fs::create_dir_all(&dir).expect("scratch directory");
        std::fs::write(dir.join("mesh.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
            .expect("scratch mesh");
    }
    dir
}

/// Writes `data` to `name` in the scratch directory and returns its path.
fn scratch_file(name: &str, data: &[u8]) -> PathBuf {
    let path = scratch().join(name);
    std::fs::write(&path, data).expect("scratch file");
    path
}

/// A hit is a miss exactly, or has a finite non-negative `t` inside the ray's interval.
fn check_hit(ray: &Ray, hit: &Hit) {
    if hit.is_hit() {
        assert!(
            hit.t.is_finite() && hit.t >= ray.tmin && hit.t < ray.tmax,
            "{ray:?}: hit at t {}",
            hit.t
        );
        assert!(!hit.normal().is_nan(), "{ray:?}: NaN normal");
    } else {
        assert_eq!(*hit, Hit::MISS, "{ray:?}");
    }
}

/// A few rays through `scene`'s bounds from the six axis directions and the diagonals, plus
/// oddities (a ray starting inside, a tiny direction).
fn probe_rays(bounds: rbvh::geom::Aabb) -> Vec<Ray> {
    let (c, e) = if bounds.is_empty() || !bounds.extent().is_finite() {
        (glam::Vec3::ZERO, 1.0)
    } else {
        (bounds.center(), bounds.extent().max_element().max(1e-30))
    };
    let mut rays = Vec::new();
    for d in [
        glam::Vec3::X,
        glam::Vec3::NEG_X,
        glam::Vec3::Y,
        glam::Vec3::NEG_Y,
        glam::Vec3::Z,
        glam::Vec3::NEG_Z,
        glam::Vec3::ONE.normalize(),
        glam::Vec3::new(-0.3, 0.8, -0.52),
    ] {
        rays.push(Ray::new(c - 2.0 * e * d, d, 0.0, f32::INFINITY));
        rays.push(Ray::new(c + 0.01 * e * d, d, 0.0, f32::INFINITY));
    }
    rays.push(Ray::new(
        c,
        glam::Vec3::new(1e-30, -1e-30, 1e-31),
        0.0,
        1e38,
    ));
    rays
}

/// What every loaded scene must satisfy; builds and traces it when small.
fn check_scene(scene: &Scene) {
    scene
        .validate()
        .expect("a loaded scene validates (the loaders validate before returning)");
    assert!(scene.positions.iter().all(|p| p.is_finite()));
    if scene.triangle_count() <= MAX_BUILD_TRIANGLES {
        check_exact(scene);
    }
}

/// Builds the exact BVH and checks its invariants and its CPU tracer on probe rays.
fn check_exact(scene: &Scene) {
    let bvh = match Bvh::build(scene) {
        Ok(bvh) => bvh,
        Err(e) => panic!("Bvh::build failed on a valid scene: {e}"),
    };
    bvh.validate().expect("a built BVH validates");
    assert!(bvh.depth <= STACK_SIZE);
    for ray in probe_rays(scene.bounds()) {
        for any in [false, true] {
            let (hit, stats) = if any {
                bvh.any_hit(&ray)
            } else {
                bvh.closest_hit(&ray)
            };
            assert!(!stats.overflow, "{ray:?}: stack overflow");
            check_hit(&ray, &hit);
        }
    }
}

/// Fuzz target: an OBJ file.
pub fn obj(data: &[u8]) {
    let path = scratch_file("fuzz.obj", data);
    if let Ok(scene) = Scene::load(path.to_str().expect("utf-8 path")) {
        check_scene(&scene);
    }
}

/// Fuzz target: a glTF (`.gltf`, when the first byte is even) or GLB (odd) file; the rest of
/// the bytes are the file. Buffers may refer to `mesh.obj` or anything in the scratch directory.
pub fn gltf(data: &[u8]) {
    let Some((&selector, body)) = data.split_first() else {
        return;
    };
    // Buffer URIs naming device or process files (or JSON escapes that could spell them) would
    // make the loader read forever; regular files are fair game.
    let forbidden: [&[u8]; 6] = [b"/dev", b"/proc", b"/sys", b"..", b"\\u", b"\\/"];
    if forbidden
        .iter()
        .any(|f| body.windows(f.len()).any(|w| w == *f))
    {
        return;
    }
    let name = if selector % 2 == 0 {
        "fuzz.gltf"
    } else {
        "fuzz.glb"
    };
    let path = scratch_file(name, body);
    if let Ok(scene) = Scene::load(path.to_str().expect("utf-8 path")) {
        check_scene(&scene);
    }
}

/// Fuzz target: a TOML scene file. Mesh paths are relative to the scratch directory, where
/// `mesh.obj` exists.
pub fn scene_file(data: &[u8]) {
    // Absolute paths and parent directories would let the fuzzer read the machine's files
    // (including /dev/zero, which never ends); they add nothing the relative ones do not test.
    if data.windows(2).any(|w| w == b"..")
        || data.contains(&b'/')
        || data.contains(&b'\\')
        || data.windows(2).any(|w| w == b"\\u" || w == b"\\U")
    {
        return;
    }
    let path = scratch_file("fuzz.toml", data);
    if let Ok(scene) = Scene::load(path.to_str().expect("utf-8 path")) {
        check_scene(&scene);
    }
}

/// Fuzz target: the bytes of an RBVH file. A file that loads must round-trip byte for byte and
/// trace on the CPU without overflow and with well-formed hits (the loader promises "safe to
/// trace and to upload").
pub fn rbvh_file(data: &[u8]) {
    let Ok(r) = Rbvh::from_bytes(data, Path::new("fuzz.rbvh")) else {
        return;
    };
    assert_eq!(r.to_bytes(), data, "save(load(file)) differs from the file");
    let bounds = if r.bounds.min.is_finite() && r.bounds.max.is_finite() {
        r.bounds
    } else {
        rbvh::geom::Aabb::EMPTY
    };
    for ray in probe_rays(bounds) {
        for any in [false, true] {
            let (hit, _) = if any {
                r.any_hit(&ray)
            } else {
                r.closest_hit(&ray)
            };
            // Corrupt-but-loadable trees may flag overflow (a cycle); hits must still be sane.
            if hit.is_hit() {
                assert!(
                    !hit.t.is_nan() && hit.t >= ray.tmin && hit.t < ray.tmax,
                    "{ray:?}: {hit:?}"
                );
            } else {
                assert_eq!(hit, Hit::MISS);
            }
        }
    }
}

/// A little-endian reader over the fuzz input that yields zeros once it runs out.
struct Bytes<'a>(&'a [u8]);

impl Bytes<'_> {
    fn u8(&mut self) -> u8 {
        match self.0.split_first() {
            Some((&b, rest)) => {
                self.0 = rest;
                b
            }
            None => 0,
        }
    }

    fn u32(&mut self) -> u32 {
        u32::from_le_bytes([self.u8(), self.u8(), self.u8(), self.u8()])
    }
}

/// Decodes a small scene and RBVH parameters from fuzz bytes: a header choosing the parameters
/// and how coordinates are made (small integers on a grid, raw f32 bits, or a mix — raw bits
/// reach huge, tiny, denormal and signed-zero values), then vertices and index triples.
pub fn decode_geometry(data: &[u8]) -> (Scene, RbvhParams) {
    let mut b = Bytes(data);
    let mode = b.u8();
    let params = {
        let q = RbvhParams::quality(u32::from(b.u8() % 5)).expect("preset");
        let rate = 1.0 + f32::from(b.u8() % 64);
        let refinement = match b.u8() % 4 {
            0 => Refinement::NormalCone {
                max_angle_deg: 0.5 + f32::from(b.u8()) * (89.0 / 255.0),
            },
            1 => Refinement::ProjectedArea {
                min_ratio: (f32::from(b.u8()) + 1.0) / 256.0,
            },
            _ => q.refinement,
        };
        let subdivision = if b.u8() % 2 == 0 {
            Subdivision::SpatialMedian
        } else {
            Subdivision::AreaSah
        };
        RbvhParams {
            texels_per_diagonal: rate,
            refinement,
            subdivision,
            object_split: b.u8() % 2 == 0,
            max_tile: 4 + u32::from(b.u8() % 61),
            min_leaf_texels: f32::from(b.u8() % 8),
        }
    };
    let vertex_count = 3 + usize::from(b.u8() % 30);
    let coordinate = |b: &mut Bytes| -> f32 {
        match mode % 3 {
            0 => f32::from(b.u8() as i8) / 16.0,
            1 => f32::from_bits(b.u32()),
            _ => {
                if b.u8() % 4 == 0 {
                    f32::from_bits(b.u32())
                } else {
                    f32::from(b.u8() as i8) * 0.37
                }
            }
        }
    };
    let positions: Vec<glam::Vec3> = (0..vertex_count)
        .map(|_| {
            let p = glam::Vec3::new(coordinate(&mut b), coordinate(&mut b), coordinate(&mut b));
            // Non-finite vertices are a load-time error; the builders are fed finite ones.
            if p.is_finite() {
                p
            } else {
                glam::Vec3::ZERO
            }
        })
        .collect();
    let mut triangles = Vec::new();
    while !b.0.is_empty() && triangles.len() < 64 {
        let n = vertex_count as u8;
        triangles.push([b.u8() % n, b.u8() % n, b.u8() % n].map(u32::from));
    }
    let mut scene = Scene::new("fuzz");
    let split = triangles.len() / 2;
    scene.push_object("a", &positions, &triangles[..split]);
    scene.push_object("b", &positions, &triangles[split..]);
    (scene, params)
}

/// Fuzz target: both builders on small fuzzed geometry with fuzzed RBVH parameters, then their
/// CPU tracers and, for the RBVH, the save/load round trip.
pub fn builders(data: &[u8]) {
    let (scene, params) = decode_geometry(data);
    scene.validate().expect("decoded geometry is valid");
    check_exact(&scene);
    let median = BuildParams {
        median_below_depth: 0,
        max_leaf: 1,
        ..BuildParams::DEFAULT
    };
    let bvh = Bvh::build_with(&scene, &median).expect("median build");
    bvh.validate().expect("median BVH validates");
    let r = match Rbvh::build(&scene, &params) {
        Ok(r) => r,
        // Only a refusal that names a parameter: the estimate or the atlas limit.
        Err(rbvh::Error::InvalidParameter { .. }) => return,
        Err(e) => panic!("Rbvh::build: {e}"),
    };
    assert!(r.depth <= STACK_SIZE, "RBVH depth {}", r.depth);
    let bytes = r.to_bytes();
    let back = Rbvh::from_bytes(&bytes, Path::new("fuzz.rbvh")).expect("a built RBVH loads");
    assert_eq!(back.to_bytes(), bytes);
    for ray in probe_rays(scene.bounds()) {
        for any in [false, true] {
            let (hit, stats) = if any {
                r.any_hit(&ray)
            } else {
                r.closest_hit(&ray)
            };
            assert!(!stats.overflow, "{ray:?}: RBVH traversal overflow");
            check_hit(&ray, &hit);
        }
    }
}

/// Inputs that the deterministic replay mutates: one valid example per target.
pub fn seeds() -> Vec<(&'static str, Vec<u8>)> {
    let obj = b"# a quad and a triangle\no quad\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n\
                g tri\nv 0 0 1\nv 1 0 1\nv 0 1 1.5\nf -3 -2 -1\nvt 0 0\nvn 0 0 1\nf 5/1/1 6/1/1 7/1/1\n"
        .to_vec();
    let gltf_json = br#"{"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[0]}],
"nodes":[{"mesh":0,"translation":[1,0,0],"scale":[2,2,2]}],
"meshes":[{"primitives":[{"attributes":{"POSITION":0},"indices":1}]}],
"buffers":[{"uri":"data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAAAAABAAIAAAA=","byteLength":44}],
"bufferViews":[{"buffer":0,"byteOffset":0,"byteLength":36},{"buffer":0,"byteOffset":36,"byteLength":6}],
"accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]},
{"bufferView":1,"componentType":5123,"count":3,"type":"SCALAR"}]}"#;
    let mut gltf = vec![0u8];
    gltf.extend_from_slice(gltf_json);
    let glb = {
        let json = br#"{"asset":{"version":"2.0"},"meshes":[{"primitives":[{"attributes":{"POSITION":0}}]}],"nodes":[{"mesh":0}],"buffers":[{"byteLength":36}],"bufferViews":[{"buffer":0,"byteLength":36}],"accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}]}"#;
        let mut json = json.to_vec();
        json.resize(json.len().next_multiple_of(4), b' ');
        let mut bin = Vec::new();
        for v in [0f32, 0., 0., 1., 0., 0., 0., 1., 0.] {
            bin.extend(v.to_le_bytes());
        }
        let mut glb = vec![1u8];
        glb.extend(b"glTF");
        glb.extend(2u32.to_le_bytes());
        glb.extend(((12 + 8 + json.len() + 8 + bin.len()) as u32).to_le_bytes());
        glb.extend((json.len() as u32).to_le_bytes());
        glb.extend(b"JSON");
        glb.extend(&json);
        glb.extend((bin.len() as u32).to_le_bytes());
        glb.extend(b"BIN\0");
        glb.extend(&bin);
        glb
    };
    let toml = b"name = \"fuzz\"\n[camera]\neye = [0, 1, 3]\ntarget = [0, 0, 0]\nvfov = 50\n\
                 [light]\ndirection = [0, -1, 0]\n[[mesh]]\npath = \"mesh.obj\"\nscale = 2\n\
                 [[mesh]]\nbuiltin = \"plane\"\ntranslate = [0, 1, 0]\nrotate = [10, 20, 30]\n\
                 scale = [1, 2, 3]\n"
        .to_vec();
    let rbvh = {
        let mut s = Scene::new("seed");
        s.push_object(
            "t",
            &[
                glam::Vec3::ZERO,
                glam::Vec3::X,
                glam::Vec3::Y,
                glam::Vec3::new(1.0, 1.0, 0.3),
                glam::Vec3::new(0.0, 0.0, 1.0),
            ],
            &[[0, 1, 2], [1, 3, 2], [0, 4, 1], [0, 2, 4]],
        );
        let params = RbvhParams {
            texels_per_diagonal: 8.0,
            ..RbvhParams::quality(0).expect("preset")
        };
        Rbvh::build(&s, &params).expect("seed RBVH").to_bytes()
    };
    let mut geometry = vec![2, 1, 40, 0, 100, 1, 0, 12, 3, 9];
    for k in 0..120u8 {
        geometry.push(k.wrapping_mul(37).wrapping_add(11));
    }
    vec![
        ("obj", obj),
        ("gltf", gltf),
        ("gltf", glb),
        ("scene_file", toml),
        ("rbvh_file", rbvh),
        ("builders", geometry),
    ]
}

/// Runs target `name` on `data`.
pub fn run(name: &str, data: &[u8]) {
    match name {
        "obj" => obj(data),
        "gltf" => gltf(data),
        "scene_file" => scene_file(data),
        "rbvh_file" => rbvh_file(data),
        "builders" => builders(data),
        other => panic!("no fuzz target {other:?}"),
    }
}

/// The target names, as the binaries in `fuzz_targets/` are called.
pub const TARGETS: [&str; 5] = ["obj", "gltf", "scene_file", "rbvh_file", "builders"];
