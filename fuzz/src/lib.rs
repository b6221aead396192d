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
//! The loaders take paths, so file inputs go through a per-thread scratch directory. A load
//! that fails must fail with an error that names a file ([`check_error`]).

use std::io::Cursor;
use std::path::{Path, PathBuf};

use rbvh::bvh::{BuildParams, Bvh, InstancedBvh, STACK_SIZE};
use rbvh::geom::{Hit, Ray};
use rbvh::ibl::Environment;
use rbvh::rbvh::file::{file_version, section_table, VERSION};
use rbvh::rbvh::{InstancedRbvh, Rbvh, RbvhParams, Refinement, Subdivision};
use rbvh::scene::{Instance, InstancedScene, Scene};
use rbvh::surface::strokes;

#[path = "../../tests/rbvh_files/mod.rs"]
mod rbvh_files;

/// Scenes loaded from fuzzed files with more triangles than this are not built (a fuzzed scene
/// file can name the 120k-triangle built-ins; loading them is tested, building them is slow).
const MAX_BUILD_TRIANGLES: usize = 5_000;

/// Point clouds with more points than this are loaded but not built.
const MAX_BUILD_POINTS: usize = 5_000;

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
    if let Some(cloud) = &scene.points {
        assert!(cloud.normals.iter().all(|n| n.is_normalized()));
        assert!(cloud.spacing.iter().all(|&s| s.is_finite() && s > 0.0));
        if cloud.len() <= MAX_BUILD_POINTS {
            check_rbvh(scene, &RbvhParams::quality(0).expect("Q0"));
        }
    }
    if scene.triangle_count() > 0 && scene.triangle_count() <= MAX_BUILD_TRIANGLES {
        check_exact(scene);
    }
}

/// Builds an RBVH of `scene` with `params` (a refusal must name a parameter: the texel estimate
/// or the atlas limit) and checks its depth, file round trip and CPU caster on probe rays.
fn check_rbvh(scene: &Scene, params: &RbvhParams) {
    let r = match Rbvh::build(scene, params) {
        Ok(r) => r,
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

/// What a scene with instances must satisfy (loaded by [`InstancedScene::load`], or placed by
/// [`builders`]): it validates, and where small, both two-level structures build over it (the
/// RBVH with `params`), their CPU tracers
/// trace probe rays without overflow to well-formed hits, and the two-level RBVH's file
/// round-trips.
fn check_instanced(scene: &InstancedScene, params: &RbvhParams) {
    scene
        .validate()
        .expect("a scene loaded with its instances validates");
    if scene.placed_triangle_count() == 0
        || scene.placed_triangle_count() > MAX_BUILD_TRIANGLES
        || scene.stored_triangle_count() > MAX_BUILD_TRIANGLES
        || scene.meshes.iter().any(|m| m.points.is_some())
    {
        return;
    }
    let bvh = InstancedBvh::build(scene).expect("a two-level BVH builds on a valid scene");
    let r = match InstancedRbvh::build(scene, params) {
        Ok(r) => Some(r),
        Err(rbvh::Error::InvalidParameter { .. }) => None,
        Err(e) => panic!("InstancedRbvh::build: {e}"),
    };
    if let Some(r) = &r {
        let bytes = r.to_bytes();
        let back = InstancedRbvh::from_bytes(&bytes, Path::new("fuzz.rbvh"))
            .expect("a built two-level RBVH loads");
        assert_eq!(back.to_bytes(), bytes, "save(load(two-level file)) differs");
    }
    for ray in probe_rays(scene.placed_bounds()) {
        for any in [false, true] {
            let traced = [
                Some(if any {
                    bvh.any_hit(&ray)
                } else {
                    bvh.closest_hit(&ray)
                }),
                r.as_ref().map(|r| {
                    if any {
                        r.any_hit(&ray)
                    } else {
                        r.closest_hit(&ray)
                    }
                }),
            ];
            for (hit, stats) in traced.into_iter().flatten() {
                assert!(!stats.overflow, "{ray:?}: two-level traversal overflow");
                check_hit(&ray, &hit);
            }
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

/// Fuzz target: a point cloud, `.ply` when the first byte is even and `.xyz` when odd (the rest
/// of the bytes are the file). What loads has unit normals and positive spacings, and a small
/// cloud builds an RBVH of its points that traces without overflow; what fails names the file.
pub fn points(data: &[u8]) {
    let Some((&selector, body)) = data.split_first() else {
        return;
    };
    let name = if selector % 2 == 0 {
        "fuzz.ply"
    } else {
        "fuzz.xyz"
    };
    let path = scratch_file(name, body);
    match Scene::load(path.to_str().expect("utf-8 path")) {
        Ok(scene) => check_scene(&scene),
        Err(e) => check_error(&e, Some(&path)),
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
    let spec = path.to_str().expect("utf-8 path");
    if let Ok(scene) = Scene::load(spec) {
        check_scene(&scene);
    }
    // Nodes that share a mesh load as its instances: another reader of the same file.
    match InstancedScene::load(spec) {
        Ok(scene) => check_instanced(&scene, &RbvhParams::quality(0).expect("Q0")),
        Err(e) => check_error(&e, Some(&path)),
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
    let spec = path.to_str().expect("utf-8 path");
    let flat = Scene::load(spec);
    if let Ok(scene) = &flat {
        check_scene(scene);
    }
    // The same file with its instances kept: whatever loads flat loads so too.
    match InstancedScene::load(spec) {
        Ok(scene) => check_instanced(&scene, &RbvhParams::quality(0).expect("Q0")),
        Err(e) => assert!(flat.is_err(), "loads flat but not with its instances: {e}"),
    }
}

/// An RBVH loaded from a file of an older `version` is what the file said: written as version 12
/// (`tests/rbvh_files`, shared with the tests), it is the file with the fields later versions
/// appended at 0, its nodes quantized, its height codes within one of theirs.
fn check_upgrade(r: &Rbvh, data: &[u8], version: u32) {
    let saved = rbvh_files::as_v12(r);
    // From version 7 on, each version appended one 4-byte field to the header of the one
    // before, which an older file loads as 0: (the version that appended it, its name).
    // Versions 4–6 have a 148-byte header; versions 1–3 lack bytes 40..52 of it.
    const V6_HEADER: usize = 148;
    const APPENDED: [(u32, &str); 6] = [
        (7, "object_rate"),
        (8, "narrow_rows"),
        (9, "exact_when_cheaper"),
        (10, "exact_from_texels"),
        (11, "exact_edge_fraction"),
        (12, "exact_crease_deg"),
    ];
    const HEADER: usize = V6_HEADER + 4 * APPENDED.len();
    let old_header = match version {
        1..=3 => 136,
        4..=6 => V6_HEADER,
        v => V6_HEADER + 4 * (v as usize - 6),
    };
    let before_rate = old_header.min(V6_HEADER);
    assert_eq!(saved[12..40], data[12..40], "the upgraded header differs");
    assert_eq!(
        saved[V6_HEADER - (before_rate - 40)..V6_HEADER],
        data[40..before_rate],
        "the upgraded header differs"
    );
    for (k, (since, field)) in APPENDED.into_iter().enumerate() {
        let at = V6_HEADER + 4 * k..V6_HEADER + 4 * (k + 1);
        if version < since {
            assert_eq!(saved[at], [0; 4], "an old file's {field} is not 0");
        } else {
            assert_eq!(saved[at.clone()], data[at], "the upgraded {field} differs");
        }
    }
    let nodes = r.nodes.len();
    let old_node = if version < 5 { 64 } else { 48 };
    let (saved, old) = (
        &saved[HEADER + 48 * nodes..],
        &data[old_header + old_node * nodes..],
    );
    let texels_at = 48 * r.triangles.len() + 64 * r.heightfields.len();
    let texel_bytes = r.params.texels.bytes() as usize;
    let texels_end = texels_at + texel_bytes * r.atlas.texels.len();
    assert_eq!(
        saved.len(),
        old.len(),
        "the upgraded arrays differ in length"
    );
    assert_eq!(
        saved[..texels_at],
        old[..texels_at],
        "the upgraded triangles or leaves differ"
    );
    assert_eq!(
        saved[texels_end..],
        old[texels_end..],
        "the upgraded colours differ"
    );
    let texel = |b: &[u8]| {
        let mut w = [0u8; 4];
        w[..texel_bytes].copy_from_slice(b);
        u32::from_le_bytes(w)
    };
    for (a, b) in saved[texels_at..texels_end]
        .chunks_exact(texel_bytes)
        .zip(old[texels_at..texels_end].chunks_exact(texel_bytes))
    {
        let (a, b) = (texel(a), texel(b));
        assert_eq!(a >> 16, b >> 16, "an upgraded texel's normal differs");
        assert!(
            (a & 0xFFFF).abs_diff(b & 0xFFFF) <= 1,
            "an upgraded height code moved by more than one: {b:#x} → {a:#x}"
        );
    }
}

/// Fuzz target: the bytes of an RBVH file. A file that loads must save to what it was: a current
/// file's every section this build reads byte for byte, and the whole file where its table is
/// the one this build writes; a file of an older version comes back as version 12 would have
/// (the same header, with bytes 40..52 inserted before version 4, its 64-byte nodes quantized to
/// 48 bytes before version 5, its height codes each within one of what they were and its normals
/// kept, and the other arrays unchanged), and what it is saved as loads and saves to the same
/// bytes. It must trace on the CPU without overflow and with well-formed hits (the loader
/// promises "safe to trace and to upload").
pub fn rbvh_file(data: &[u8]) {
    let path = Path::new("fuzz.rbvh");
    two_level_file(data, path);
    let Ok(r) = Rbvh::from_bytes(data, path) else {
        return;
    };
    let saved = r.to_bytes();
    let version = file_version(data, path).expect("a loaded file has a version");
    if version == VERSION {
        let table = section_table(data, path).expect("a loaded file has a table");
        let written = section_table(&saved, path).expect("a saved file has a table");
        for s in &table {
            if let Some(w) = written
                .iter()
                .find(|w| w.tag == s.tag && w.version == s.version)
            {
                assert_eq!(
                    saved[w.bytes()],
                    data[s.bytes()],
                    "section {} differs once saved",
                    s.name()
                );
            }
        }
        if table == written {
            assert_eq!(saved, data, "save(load(file)) differs from the file");
        }
    } else {
        check_upgrade(&r, data, version);
    }
    let again = Rbvh::from_bytes(&saved, path).expect("a saved file loads");
    assert_eq!(again.to_bytes(), saved, "save(load(saved file)) differs");
    check_loaded_hits(r.bounds, |ray, any| {
        if any {
            r.any_hit(ray).0
        } else {
            r.closest_hit(ray).0
        }
    });
}

/// Probe rays through a loaded structure's `bounds` (none where they are not finite), traced
/// closest-hit and any-hit by `trace`: corrupt but loadable trees may flag overflow (a cycle),
/// but every hit is well formed.
fn check_loaded_hits(bounds: rbvh::geom::Aabb, trace: impl Fn(&Ray, bool) -> Hit) {
    let bounds = if bounds.min.is_finite() && bounds.max.is_finite() {
        bounds
    } else {
        rbvh::geom::Aabb::EMPTY
    };
    for ray in probe_rays(bounds) {
        for any in [false, true] {
            let hit = trace(&ray, any);
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

/// The same bytes read as a two-level RBVH's file ([`InstancedRbvh::from_bytes`]): one that
/// loads saves to bytes that load and save to themselves, and traces on the CPU to well-formed
/// hits (a corrupt but loadable tree may flag overflow, as a flat one may).
fn two_level_file(data: &[u8], path: &Path) {
    let Ok(r) = InstancedRbvh::from_bytes(data, path) else {
        return;
    };
    let saved = r.to_bytes();
    let again = InstancedRbvh::from_bytes(&saved, path).expect("a saved two-level file loads");
    assert_eq!(
        again.to_bytes(),
        saved,
        "save(load(saved two-level file)) differs"
    );
    check_loaded_hits(r.bounds(), |ray, any| {
        if any {
            r.any_hit(ray).0
        } else {
            r.closest_hit(ray).0
        }
    });
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
            ..q
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
/// CPU tracers and, for the RBVH, the save/load round trip; then the same geometry as a mesh
/// placed twice, where it is and moved (turned, scaled unevenly or mirrored, as the first byte
/// says), through both two-level structures.
pub fn builders(data: &[u8]) {
    let (scene, params) = decode_geometry(data);
    let extent = scene.bounds().extent().max_element();
    let shift = glam::Vec3::new(
        if extent.is_finite() {
            1.5 * extent
        } else {
            0.0
        },
        0.0,
        0.0,
    );
    let moved = match data.first().map_or(0, |m| m / 3 % 4) {
        0 => glam::Mat4::from_translation(shift),
        1 => glam::Mat4::from_translation(shift) * glam::Mat4::from_rotation_y(0.7),
        2 => glam::Mat4::from_scale(glam::Vec3::new(-0.5, 0.5, 0.5)),
        _ => {
            glam::Mat4::from_rotation_z(0.4)
                * glam::Mat4::from_scale(glam::Vec3::new(2.0, 1.0, 0.25))
        }
    };
    let placed = InstancedScene {
        name: "fuzz".into(),
        meshes: vec![scene.clone()],
        instances: [glam::Mat4::IDENTITY, moved]
            .map(|transform| Instance { mesh: 0, transform })
            .to_vec(),
        ..InstancedScene::default()
    };
    scene.validate().expect("decoded geometry is valid");
    check_exact(&scene);
    let median = BuildParams {
        median_below_depth: 0,
        max_leaf: 1,
        ..BuildParams::DEFAULT
    };
    let bvh = Bvh::build_with(&scene, &median).expect("median build");
    bvh.validate().expect("median BVH validates");
    check_rbvh(&scene, &params);
    if placed.validate().is_ok() {
        check_instanced(&placed, &params);
    }
}

/// A failed load must say what and where: an I/O or parse error naming a file (`file`, when
/// given, is the one it must name), or invalid geometry naming its source.
fn check_error(e: &rbvh::Error, file: Option<&Path>) {
    let named = match e {
        rbvh::Error::Io { path, .. } | rbvh::Error::Parse { path, .. } => {
            file.is_none_or(|f| path == f) && !path.as_os_str().is_empty()
        }
        rbvh::Error::InvalidGeometry { source_name, .. } => !source_name.is_empty(),
        _ => false,
    };
    assert!(named, "the error does not name the file: {e:?}");
}

/// Fuzz target: a strokes file of `rbvh paint`. Loaded dabs are finite with a positive radius.
pub fn strokes(data: &[u8]) {
    let path = scratch_file("fuzz.strokes", data);
    match strokes::load(&path) {
        Ok(dabs) => {
            for d in &dabs {
                assert!(
                    d.screen.is_finite() && d.radius.is_finite() && d.radius > 0.0,
                    "{d:?}"
                );
            }
        }
        Err(e) => check_error(&e, Some(&path)),
    }
}

/// Fuzz target: an OpenEXR environment map. A loaded map has texels and finite, non-negative
/// radiance in every direction.
pub fn environment(data: &[u8]) {
    let path = scratch_file("fuzz.exr", data);
    match Environment::load(&path) {
        Ok(Environment::Map(map)) => {
            assert!(map.width() > 0 && map.height() > 0);
            for dir in [
                glam::Vec3::Y,
                glam::Vec3::NEG_Y,
                glam::Vec3::NEG_Z,
                glam::Vec3::new(0.3, -0.2, 0.9),
                glam::Vec3::NAN,
            ] {
                let l = map.radiance(dir.normalize_or_zero());
                assert!(l.is_finite() && l.min_element() >= 0.0, "{dir}: {l}");
            }
        }
        Ok(other) => panic!("Environment::load gave {other:?}"),
        Err(e) => check_error(&e, Some(&path)),
    }
}

/// Separates the parts of a `textures` input: mesh, MTL, image.
pub const PART_SEPARATOR: &[u8] = b"\0--\0";

/// Fuzz target: a textured mesh. The first byte picks the kind (modulo 3) and the rest is up to
/// three parts separated by [`PART_SEPARATOR`] (the last part may contain it):
///
/// * 0: `tex.obj`, `tex.mtl`, `tex.png` (OBJ with `mtllib tex.mtl` and `map_Kd tex.png`);
/// * 1: `tex.gltf` (its images a data URI or `tex.png`), unused, `tex.png`;
/// * 2: a GLB assembled here from the JSON part and, as its binary chunk, the image part (for
///   images in buffer views).
///
/// Whatever loads must also have usable materials: every texture's texels match its size, and
/// every triangle's colour is finite.
pub fn textures(data: &[u8]) {
    let Some((&selector, body)) = data.split_first() else {
        return;
    };
    let mut parts = split_parts(body);
    let image = parts.pop().unwrap_or_default();
    let mtl = parts.pop().unwrap_or_default();
    let mesh = parts.pop().unwrap_or_default();
    // As in `gltf` and `scene_file`: no paths out of the scratch directory (device files would
    // be read forever). The image part is never a path.
    let forbidden: [&[u8]; 7] = [b"/dev", b"/proc", b"/sys", b"..", b"\\u", b"\\/", b"\\"];
    let absolute = |text: &[u8]| {
        text.split(|&b| b.is_ascii_whitespace())
            .any(|w| w.starts_with(b"/"))
    };
    if [mesh, mtl].iter().any(|text| {
        absolute(text)
            || forbidden
                .iter()
                .any(|f| text.windows(f.len()).any(|w| w == *f))
    }) {
        return;
    }
    scratch_file("tex.png", image);
    scratch_file("tex.mtl", mtl);
    let path = match selector % 3 {
        0 => scratch_file("tex.obj", mesh),
        1 => scratch_file("tex.gltf", mesh),
        _ => scratch_file("tex.glb", &glb(mesh, image)),
    };
    match Scene::load(path.to_str().expect("utf-8 path")) {
        Ok(scene) => {
            check_scene(&scene);
            if let Some(surface) = &scene.surface {
                for m in &surface.materials {
                    if let Some(t) = &m.texture {
                        assert!(t.width > 0 && t.height > 0);
                        assert_eq!(
                            t.texels.len() as u64,
                            u64::from(t.width) * u64::from(t.height)
                        );
                    }
                }
                for t in 0..scene.triangle_count().min(64) {
                    let c = surface.colour(t, glam::Vec3::splat(1.0 / 3.0));
                    assert!(!c.is_nan(), "triangle {t}: colour {c}");
                }
            }
        }
        Err(e) => check_error(&e, None),
    }
}

/// `body` split at the first two [`PART_SEPARATOR`]s.
fn split_parts(body: &[u8]) -> Vec<&[u8]> {
    let mut parts = Vec::new();
    let mut rest = body;
    while parts.len() < 2 {
        let Some(at) = rest
            .windows(PART_SEPARATOR.len())
            .position(|w| w == PART_SEPARATOR)
        else {
            break;
        };
        parts.push(&rest[..at]);
        rest = &rest[at + PART_SEPARATOR.len()..];
    }
    parts.push(rest);
    parts
}

/// A GLB container of `json` and the binary chunk `bin`, each padded to 4 bytes.
fn glb(json: &[u8], bin: &[u8]) -> Vec<u8> {
    let mut json = json.to_vec();
    json.resize(json.len().next_multiple_of(4), b' ');
    let mut bin = bin.to_vec();
    bin.resize(bin.len().next_multiple_of(4), 0);
    let mut glb = b"glTF".to_vec();
    glb.extend(2u32.to_le_bytes());
    glb.extend(((12 + 8 + json.len() + 8 + bin.len()) as u32).to_le_bytes());
    glb.extend((json.len() as u32).to_le_bytes());
    glb.extend(b"JSON");
    glb.extend(&json);
    glb.extend((bin.len() as u32).to_le_bytes());
    glb.extend(b"BIN\0");
    glb.extend(&bin);
    glb
}

/// A tiny PNG: 2×2 RGBA.
fn seed_png() -> Vec<u8> {
    let img = image::RgbaImage::from_fn(2, 2, |x, y| {
        image::Rgba([255 * x as u8, 200, 60 * y as u8, 255 - 100 * y as u8])
    });
    let mut out = Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png)
        .expect("PNG seed");
    out.into_inner()
}

/// A tiny JPEG: 8×8 RGB.
fn seed_jpeg() -> Vec<u8> {
    let img = image::RgbImage::from_fn(8, 8, |x, y| image::Rgb([30 * x as u8, 30 * y as u8, 128]));
    let mut out = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 50)
        .encode_image(&img)
        .expect("JPEG seed");
    out
}

/// A tiny lat-long EXR: `width × height` RGB texels, written with `encoding`, as `f32`
/// (`half` false) or `f16`.
fn seed_exr(width: usize, height: usize, encoding: exr::prelude::Encoding, half: bool) -> Vec<u8> {
    use exr::prelude::{f16, Image, Layer, LayerAttributes, SpecificChannels, WritableImage};
    let value = |x: usize, y: usize| (x as f32 * 0.5, y as f32 + 0.25, 2.0);
    let mut out = Cursor::new(Vec::new());
    if half {
        let channels = SpecificChannels::rgb(|p: exr::math::Vec2<usize>| {
            let (r, g, b) = value(p.0, p.1);
            (f16::from_f32(r), f16::from_f32(g), f16::from_f32(b))
        });
        let layer = Layer::new(
            (width, height),
            LayerAttributes::named("sky"),
            encoding,
            channels,
        );
        Image::from_layer(layer).write().to_buffered(&mut out)
    } else {
        let channels = SpecificChannels::rgb(|p: exr::math::Vec2<usize>| value(p.0, p.1));
        let layer = Layer::new(
            (width, height),
            LayerAttributes::default(),
            encoding,
            channels,
        );
        Image::from_layer(layer).write().to_buffered(&mut out)
    }
    .expect("EXR seed");
    out.into_inner()
}

/// The seeds of `textures`: an OBJ set with a PNG and one with a JPEG, a glTF with a data-URI
/// PNG, and a GLB with the PNG in a buffer view.
fn texture_seeds() -> Vec<Vec<u8>> {
    let png = seed_png();
    let obj = b"mtllib tex.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nusemtl wood\nf 1/1 2/2 3/3\n";
    let mtl = b"newmtl wood\nKd 1 0.5 0.25\nmap_Kd -s 1 1 1 tex.png\n";
    let obj_set = |image: &[u8]| {
        let mut d = vec![0u8];
        for (k, part) in [&obj[..], &mtl[..], image].into_iter().enumerate() {
            if k > 0 {
                d.extend(PART_SEPARATOR);
            }
            d.extend(part);
        }
        d
    };
    // One triangle with texture coordinates: positions (36 bytes), then uvs (24 bytes).
    let mut geometry = Vec::new();
    for v in [0f32, 0., 0., 1., 0., 0., 0., 1., 0., 0., 0., 1., 0., 0., 1.] {
        geometry.extend(v.to_le_bytes());
    }
    let geometry = base64_encode(&geometry);
    let gltf_json = |buffers: &str, image: &str| {
        format!(
            r#"{{"asset":{{"version":"2.0"}},"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0,"TEXCOORD_0":1}},"material":0}}]}}],"nodes":[{{"mesh":0}}],"buffers":[{buffers}],"bufferViews":[{{"buffer":0,"byteLength":36}},{{"buffer":0,"byteOffset":36,"byteLength":24}}],"accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}},{{"bufferView":1,"componentType":5126,"count":3,"type":"VEC2"}}],"materials":[{{"pbrMetallicRoughness":{{"baseColorFactor":[1,1,1,1],"baseColorTexture":{{"index":0}}}}}}],"samplers":[{{"wrapS":33648}}],"textures":[{{"source":0,"sampler":0}}],"images":[{image}]}}"#
        )
    };
    let data_buffer =
        format!(r#"{{"uri":"data:application/octet-stream;base64,{geometry}","byteLength":60}}"#);
    let mut gltf = vec![1u8];
    gltf.extend(
        gltf_json(
            &data_buffer,
            &format!(
                r#"{{"uri":"data:image/png;base64,{}"}}"#,
                base64_encode(&png)
            ),
        )
        .as_bytes(),
    );
    // In the GLB, buffer 0 is the binary chunk (the image) and buffer 1 the geometry.
    let glb_json = gltf_json(
        &format!(r#"{data_buffer},{{"byteLength":{}}}"#, png.len()),
        r#"{"bufferView":2,"mimeType":"image/png"}"#,
    )
    .replace(r#"{"buffer":0,"#, r#"{"buffer":1,"#)
    .replace(
        r#"],"accessors""#,
        &format!(r#",{{"buffer":2,"byteLength":{}}}],"accessors""#, png.len()),
    );
    let mut glb_input = vec![2u8];
    glb_input.extend(glb_json.as_bytes());
    glb_input.extend(PART_SEPARATOR);
    glb_input.extend(PART_SEPARATOR);
    glb_input.extend(&png);
    vec![obj_set(&png), obj_set(&seed_jpeg()), gltf, glb_input]
}

/// Standard base64 with padding (for the seeds' data URIs).
fn base64_encode(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for chunk in bytes.chunks(3) {
        let n = chunk
            .iter()
            .enumerate()
            .fold(0u32, |n, (k, &b)| n | u32::from(b) << (16 - 8 * k));
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(ALPHABET[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
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
        let mut bin = Vec::new();
        for v in [0f32, 0., 0., 1., 0., 0., 0., 1., 0.] {
            bin.extend(v.to_le_bytes());
        }
        let mut out = vec![1u8];
        out.extend(glb(json, &bin));
        out
    };
    let toml = b"name = \"fuzz\"\n[camera]\neye = [0, 1, 3]\ntarget = [0, 0, 0]\nvfov = 50\n\
                 [light]\ndirection = [0, -1, 0]\n[[mesh]]\npath = \"mesh.obj\"\nscale = 2\n\
                 [[mesh]]\nbuiltin = \"plane\"\ntranslate = [0, 1, 0]\nrotate = [10, 20, 30]\n\
                 scale = [1, 2, 3]\n"
        .to_vec();
    // A mesh held once and placed twice, and a glTF mesh drawn by two nodes: both load with
    // their instances.
    let instanced_toml = b"name = \"placed\"\n[[mesh]]\nbuiltin = \"plane\"\n\
                           [[instance]]\npath = \"mesh.obj\"\nscale = 2\n\
                           [[instance]]\npath = \"mesh.obj\"\ntranslate = [0, 0, 1]\n\
                           rotate = [0, 90, 0]\n"
        .to_vec();
    let mut gltf_nodes = vec![0u8];
    gltf_nodes.extend(
        std::str::from_utf8(gltf_json)
            .expect("ASCII")
            .replace(r#""nodes":[0]}]"#, r#""nodes":[0,1]}]"#)
            .replace(
                r#""scale":[2,2,2]}],"#,
                r#""scale":[2,2,2]},{"mesh":0,"rotation":[0,0.7071068,0,0.7071068]}],"#,
            )
            .into_bytes(),
    );
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
        Rbvh::build(&s, &params).expect("seed RBVH")
    };
    let two_level = {
        let mut mesh = Scene::new("");
        mesh.push_object(
            "t",
            &[
                glam::Vec3::ZERO,
                glam::Vec3::X,
                glam::Vec3::Y,
                glam::Vec3::new(0.0, 0.0, 1.0),
            ],
            &[[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]],
        );
        let placed = InstancedScene {
            name: "seed".into(),
            meshes: vec![mesh],
            instances: vec![
                Instance {
                    mesh: 0,
                    transform: glam::Mat4::IDENTITY,
                },
                Instance {
                    mesh: 0,
                    transform: glam::Mat4::from_translation(glam::Vec3::new(2.0, 0.0, 0.0)),
                },
            ],
            ..InstancedScene::default()
        };
        let params = RbvhParams {
            texels_per_diagonal: 16.0,
            ..RbvhParams::quality(0).expect("preset")
        };
        InstancedRbvh::build(&placed, &params).expect("seed two-level RBVH")
    };
    let mut geometry = vec![2, 1, 40, 0, 100, 1, 0, 12, 3, 9];
    for k in 0..120u8 {
        geometry.push(k.wrapping_mul(37).wrapping_add(11));
    }
    let strokes = b"# aim x y, radius, colour\ndab 0.5 0.4 0.02 #ff0000\n\n\
                    line 0.2 0.6 0.21 0.61 0.01 #2060ffcc # a short line\n"
        .to_vec();
    use exr::prelude::{Blocks, Compression, Encoding};
    let tiled_rle = Encoding {
        compression: Compression::RLE,
        blocks: Blocks::Tiles(exr::math::Vec2(2, 2)),
        ..Encoding::UNCOMPRESSED
    };
    let mut seeds = vec![
        ("obj", obj),
        ("gltf", gltf),
        ("gltf", glb),
        ("gltf", gltf_nodes),
        ("scene_file", toml),
        ("scene_file", instanced_toml),
        ("rbvh_file", rbvh.to_bytes()),
        ("rbvh_file", two_level.to_bytes()),
        // The readers of older versions: version 12, which every older one's header prefixes.
        ("rbvh_file", rbvh_files::as_v12(&rbvh)),
        ("builders", geometry),
        ("strokes", strokes),
        ("environment", seed_exr(4, 2, Encoding::UNCOMPRESSED, false)),
        ("environment", seed_exr(3, 3, tiled_rle, true)),
        (
            "environment",
            seed_exr(2, 17, Encoding::SMALL_LOSSLESS, true),
        ),
    ];
    seeds.extend(texture_seeds().into_iter().map(|s| ("textures", s)));
    seeds.extend(point_seeds().into_iter().map(|s| ("points", s)));
    seeds
}

/// Seeds of the `points` target (selector byte first): an ASCII PLY with normals and colours, a
/// binary little-endian PLY with a face element to skip, and an XYZ file with normals.
fn point_seeds() -> Vec<Vec<u8>> {
    let mut ascii =
        b"\0ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\n\
        property float z\nproperty float nx\nproperty float ny\nproperty float nz\n\
        property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n"
            .to_vec();
    for (x, z) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0), (0.5, 0.4)] {
        ascii.extend(format!("{x} 0 {z} 0 1 0 200 100 50\n").into_bytes());
    }
    let mut binary = b"\0ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\n\
        property float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\n\
        end_header\n"
        .to_vec();
    for p in [[0f32, 0., 0.], [1., 0., 0.], [0., 1., 0.], [0.3, 0.3, 0.2]] {
        for c in p {
            binary.extend(c.to_le_bytes());
        }
    }
    binary.push(3);
    for i in [0i32, 1, 2] {
        binary.extend(i.to_le_bytes());
    }
    let xyz =
        b"\x01# x y z nx ny nz\n0 0 0 0 0 1\n1 0 0 0 0 1\n0 1 0 0 0 1\n1 1 0.1 0 0 1\n".to_vec();
    vec![ascii, binary, xyz]
}

/// Runs target `name` on `data`.
pub fn run(name: &str, data: &[u8]) {
    match name {
        "obj" => obj(data),
        "gltf" => gltf(data),
        "scene_file" => scene_file(data),
        "rbvh_file" => rbvh_file(data),
        "builders" => builders(data),
        "strokes" => strokes(data),
        "environment" => environment(data),
        "textures" => textures(data),
        "points" => points(data),
        other => panic!("no fuzz target {other:?}"),
    }
}

/// The target names, as the binaries in `fuzz_targets/` are called.
pub const TARGETS: [&str; 9] = [
    "obj",
    "gltf",
    "scene_file",
    "rbvh_file",
    "builders",
    "strokes",
    "environment",
    "textures",
    "points",
];
