//! Surface data end to end, on inputs generated here: a textured OBJ (MTL + PNG) and glTF, a
//! Kd-only OBJ, colours baked into the RBVH and read back at hits of both structures, the
//! `rbvh paint` command, and typed errors for bad textures and strokes.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use glam::{Vec3, Vec4};
use rbvh::bvh::Bvh;
use rbvh::geom::Ray;
use rbvh::gpu::{Query, Tracer};
use rbvh::rbvh::{Rbvh, RbvhParams};
use rbvh::scene::Scene;
use rbvh::structure::{Recipe, Structure};
use rbvh::surface::hit_albedo;
use rbvh::Error;
use std::sync::Arc;

/// The checker's texels, top-left, top-right, bottom-left, bottom-right (sRGB codes); chosen so
/// that each is 0 or 255 per channel and so exact in linear light.
const CHECKER: [[u8; 3]; 4] = [[255, 0, 0], [0, 255, 0], [0, 0, 255], [255, 255, 0]];

/// World points at the centres of the quad's quadrants, in the order of [`CHECKER`] (the quad is
/// `[-1, 1]²` at z = 0, seen from +z with +y up).
const QUADRANTS: [(f32, f32); 4] = [(-0.5, 0.5), (0.5, 0.5), (-0.5, -0.5), (0.5, -0.5)];

fn write_checker(path: &Path) {
    let mut img = image::RgbaImage::new(2, 2);
    for (k, c) in CHECKER.iter().enumerate() {
        img.put_pixel(
            k as u32 % 2,
            k as u32 / 2,
            image::Rgba([c[0], c[1], c[2], 255]),
        );
    }
    img.save(path).unwrap();
}

fn write(dir: &Path, name: &str, content: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, content).unwrap();
    path
}

/// A quad whose `vt` put the image's top-left texel at the top-left quadrant (OBJ's `v` points up).
fn textured_obj(dir: &Path, texture_line: &str) -> PathBuf {
    write(
        dir,
        "quad.mtl",
        &format!("newmtl checker\nKd 1 1 1\n{texture_line}\n"),
    );
    write(
        dir,
        "quad.obj",
        "mtllib quad.mtl\nv -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\n\
         vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl checker\nf 1/1 2/2 3/3 4/4\n",
    )
}

fn down_ray(x: f32, y: f32) -> Ray {
    Ray::new(Vec3::new(x, y, 5.0), -Vec3::Z, 0.0, f32::INFINITY)
}

/// The base colour at each quadrant centre, through the exact BVH and an RBVH (both traced on the
/// device), checked against `expect` (linear RGB).
fn check_quadrants(scene: &Scene, expect: [Vec3; 4]) {
    let ctx = common::context();
    let rays: Vec<Ray> = QUADRANTS.iter().map(|&(x, y)| down_ray(x, y)).collect();
    let exact_structure = Structure::from(Bvh::build(scene).unwrap());
    let exact = Tracer::new(&ctx, &exact_structure)
        .unwrap()
        .trace(&rays, Query::Closest)
        .unwrap()
        .hits;
    // The preset traces the quad's two large triangles exactly (its colour is the surface's at
    // the hit); with every triangle sampled it is a height field whose texels hold the colour.
    let preset = RbvhParams::quality(4).unwrap();
    let sampled = common::sampled_preset(4);
    let mut structures = vec![("exact", exact_structure, exact)];
    for (name, params) in [("rbvh Q4", preset), ("rbvh Q4s", sampled)] {
        let rbvh = Arc::new(Rbvh::build(scene, &params).unwrap());
        assert!(rbvh.colours.is_some());
        assert_eq!(
            rbvh.stats.heightfield_leaves > 0,
            !params.exact_when_cheaper,
            "{name}"
        );
        let structure = Structure::from(rbvh);
        let hits = Tracer::new(&ctx, &structure)
            .unwrap()
            .trace(&rays, Query::Closest)
            .unwrap()
            .hits;
        structures.push((name, structure, hits));
    }
    for (name, structure, hits) in &structures {
        let albedo = hit_albedo(scene, structure, &rays, hits).unwrap();
        for (k, (&got, want)) in albedo.iter().zip(expect).enumerate() {
            assert!(
                (got - want).abs().max_element() < 0.05,
                "{name}, quadrant {k}: {got} instead of {want}"
            );
        }
    }
}

fn checker_linear() -> [Vec3; 4] {
    CHECKER.map(|c| Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32) / 255.0)
}

#[test]
fn obj_with_mtl_and_png_texture_colours_both_structures() {
    let dir = tempfile::tempdir().unwrap();
    write_checker(&dir.path().join("checker.png"));
    let scene = Scene::load(
        textured_obj(dir.path(), "map_Kd checker.png")
            .to_str()
            .unwrap(),
    )
    .unwrap();
    let surface = scene.surface.as_ref().unwrap();
    assert_eq!(surface.materials.len(), 1);
    assert!(surface.materials[0].texture.is_some());
    check_quadrants(&scene, checker_linear());
}

#[test]
fn kd_only_obj_colours_objects_and_leaves_plain_meshes_without_materials() {
    let dir = tempfile::tempdir().unwrap();
    write(
        dir.path(),
        "kd.mtl",
        "newmtl a\nKd 1 0 0\nnewmtl b\nKd 0 0.5 1\n",
    );
    let obj = write(
        dir.path(),
        "kd.obj",
        "mtllib kd.mtl\nv -1 -1 0\nv 0 -1 0\nv 0 1 0\nv -1 1 0\nv 1 -1 0\nv 1 1 0\n\
         o left\nusemtl a\nf 1 2 3 4\no right\nusemtl b\nf 2 5 6 3\n",
    );
    let scene = Scene::load(obj.to_str().unwrap()).unwrap();
    let red = Vec3::X;
    let blue = Vec3::new(0.0, 0.5, 1.0);
    check_quadrants(&scene, [red, blue, red, blue]);

    // No materials: no surface table, no colour channel, no albedo (renders stay grey).
    let plain = Scene::load("cube").unwrap();
    assert!(plain.surface.is_none());
    // Every triangle sampled: the preset traces the cube's faces exactly, with no texels.
    let r = Rbvh::build(&plain, &common::sampled_preset(1)).unwrap();
    assert!(r.stats.heightfield_leaves > 0);
    assert!(r.colours.is_none() && r.colour_bytes() == 0);
    let rays = [down_ray(0.0, 0.0)];
    let hits = r.trace_cpu(&rays, false);
    assert!(hit_albedo(&plain, &Structure::from(r), &rays, &hits).is_none());
}

/// A glTF quad with its buffer as a data URI, its base colour texture `image` (a JSON image
/// object) and `factor`; `uv` put the image's top-left texel at the top-left quadrant.
fn gltf_quad(image: &str, factor: [f32; 4]) -> String {
    use base64::encode;
    let positions: [[f32; 3]; 4] = [
        [-1.0, 1.0, 0.0],
        [1.0, 1.0, 0.0],
        [1.0, -1.0, 0.0],
        [-1.0, -1.0, 0.0],
    ];
    let uvs: [[f32; 2]; 4] = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
    let indices: [u16; 6] = [3, 2, 1, 3, 1, 0];
    let mut bytes: Vec<u8> = bytemuck::cast_slice(&positions).to_vec();
    bytes.extend_from_slice(bytemuck::cast_slice(&uvs));
    bytes.extend_from_slice(bytemuck::cast_slice(&indices));
    format!(
        r#"{{
  "asset": {{"version": "2.0"}},
  "scene": 0, "scenes": [{{"nodes": [0]}}], "nodes": [{{"mesh": 0}}],
  "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0, "TEXCOORD_0": 1}}, "indices": 2, "material": 0}}]}}],
  "materials": [{{"pbrMetallicRoughness": {{"baseColorFactor": {factor:?}, "baseColorTexture": {{"index": 0}}}}}}],
  "textures": [{{"source": 0, "sampler": 0}}],
  "samplers": [{{"wrapS": 33071, "wrapT": 33071}}],
  "images": [{image}],
  "buffers": [{{"byteLength": {len}, "uri": "data:application/octet-stream;base64,{data}"}}],
  "bufferViews": [
    {{"buffer": 0, "byteOffset": 0, "byteLength": 48}},
    {{"buffer": 0, "byteOffset": 48, "byteLength": 32}},
    {{"buffer": 0, "byteOffset": 80, "byteLength": 12}}],
  "accessors": [
    {{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [-1, -1, 0], "max": [1, 1, 0]}},
    {{"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"}},
    {{"bufferView": 2, "componentType": 5123, "count": 6, "type": "SCALAR"}}]
}}"#,
        len = bytes.len(),
        data = encode(&bytes),
    )
}

#[test]
fn gltf_base_colour_texture_times_factor_from_a_file_and_a_data_uri() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("checker.png");
    write_checker(&png);
    let factor = [1.0, 0.5, 1.0, 1.0];
    let expect = checker_linear().map(|c| c * Vec3::new(1.0, 0.5, 1.0));

    let external = write(
        dir.path(),
        "file.gltf",
        &gltf_quad(r#"{"uri": "checker.png"}"#, factor),
    );
    let scene = Scene::load(external.to_str().unwrap()).unwrap();
    check_quadrants(&scene, expect);

    let uri = format!(
        r#"{{"uri": "data:image/png;base64,{}"}}"#,
        base64::encode(std::fs::read(&png).unwrap())
    );
    let embedded = write(dir.path(), "embedded.gltf", &gltf_quad(&uri, factor));
    let scene = Scene::load(embedded.to_str().unwrap()).unwrap();
    assert_eq!(
        scene.surface.as_ref().unwrap().materials[0].factor,
        Vec4::from(factor)
    );
    check_quadrants(&scene, expect);
}

/// `KHR_texture_transform` on the base colour texture: a quarter turn (u, v) → (v, −u) and an
/// offset of one along v map each quadrant centre onto another texel's centre, and a `texCoord`
/// override names the set the primitive must have.
#[test]
fn gltf_texture_transform_moves_the_texture_and_may_pick_another_set() {
    let dir = tempfile::tempdir().unwrap();
    write_checker(&dir.path().join("checker.png"));
    let with_transform = |transform: &str| {
        gltf_quad(r#"{"uri": "checker.png"}"#, [1.0; 4])
            .replace(
                r#""baseColorTexture": {"index": 0}"#,
                &format!(
                    r#""baseColorTexture": {{"index": 0, "extensions": {{"KHR_texture_transform": {transform}}}}}"#
                ),
            )
            .replace(
                r#""asset": {"version": "2.0"},"#,
                r#""asset": {"version": "2.0"}, "extensionsUsed": ["KHR_texture_transform"],"#,
            )
    };
    let turned = write(
        dir.path(),
        "turned.gltf",
        &with_transform(r#"{"rotation": 1.5707964, "offset": [0, 1], "scale": [1, 1]}"#),
    );
    let scene = Scene::load(turned.to_str().unwrap()).unwrap();
    let c = checker_linear();
    // Quadrant centres (u, v) → (v, 1 − u): top-left → bottom-left texel, top-right → top-left,
    // bottom-left → bottom-right, bottom-right → top-right.
    check_quadrants(&scene, [c[2], c[0], c[3], c[1]]);

    // Scale before offset: (u, v) → (u/2 + 1/2, v) puts the left quadrants' centres a quarter
    // texel right of the left texels' centres (sampled between the two texels of their row) and
    // the right quadrants' beyond the right texels' (clamped to them). Offset first would give
    // (u/2 + 1/4, v) instead.
    let scaled = write(
        dir.path(),
        "scaled.gltf",
        &with_transform(r#"{"offset": [0.5, 0], "scale": [0.5, 1]}"#),
    );
    let scene = Scene::load(scaled.to_str().unwrap()).unwrap();
    let mix = |a: Vec3, b: Vec3| a * 0.25 + b * 0.75;
    check_quadrants(&scene, [mix(c[0], c[1]), c[1], mix(c[2], c[3]), c[3]]);

    let other_set = write(
        dir.path(),
        "set1.gltf",
        &with_transform(r#"{"texCoord": 1}"#),
    );
    let e = Scene::load(other_set.to_str().unwrap()).unwrap_err();
    assert!(e.to_string().contains("TEXCOORD_1"), "{e}");
}

/// `quad` (a [`gltf_quad`] document) with a `COLOR_0` accessor of `kind` (`"VEC3"`, `"VEC4"`) and
/// `component_type` (normalized unless float) whose every element is `element`, and without its
/// material when `material` is false.
fn with_vertex_colours(
    quad: &str,
    element: &[u8],
    component_type: u32,
    kind: &str,
    material: bool,
) -> String {
    let mut json: serde_json::Value = serde_json::from_str(quad).unwrap();
    let uri = json["buffers"][0]["uri"].as_str().unwrap().to_owned();
    let mut bytes = base64::decode(uri.split_once(";base64,").unwrap().1).unwrap();
    let offset = bytes.len();
    for _ in 0..4 {
        bytes.extend_from_slice(element);
    }
    json["buffers"][0]["byteLength"] = bytes.len().into();
    json["buffers"][0]["uri"] = format!(
        "data:application/octet-stream;base64,{}",
        base64::encode(&bytes)
    )
    .into();
    let views = json["bufferViews"].as_array_mut().unwrap();
    views.push(serde_json::json!(
        {"buffer": 0, "byteOffset": offset, "byteLength": 4 * element.len()}
    ));
    let view = views.len() - 1;
    let accessors = json["accessors"].as_array_mut().unwrap();
    accessors.push(serde_json::json!({
        "bufferView": view, "componentType": component_type, "count": 4, "type": kind,
        "normalized": component_type != 5126
    }));
    let accessor = accessors.len() - 1;
    let primitive = &mut json["meshes"][0]["primitives"][0];
    primitive["attributes"]["COLOR_0"] = accessor.into();
    if !material {
        primitive.as_object_mut().unwrap().remove("material");
    }
    json.to_string()
}

/// glTF `COLOR_0` multiplies the base colour, and colours a primitive without a material, in
/// each component type glTF allows.
#[test]
fn gltf_vertex_colours_multiply_the_base_colour() {
    let dir = tempfile::tempdir().unwrap();
    write_checker(&dir.path().join("checker.png"));
    let quad = gltf_quad(r#"{"uri": "checker.png"}"#, [1.0; 4]);
    let colour = [0.5f32, 0.25, 1.0];
    let tint = Vec3::from(colour);
    let float = bytemuck::cast_slice::<f32, u8>(&colour).to_vec();

    let tinted = write(
        dir.path(),
        "tinted.gltf",
        &with_vertex_colours(&quad, &float, 5126, "VEC3", true),
    );
    let scene = Scene::load(tinted.to_str().unwrap()).unwrap();
    check_quadrants(&scene, checker_linear().map(|c| c * tint));

    let shorts: Vec<u8> = [32768u16, 16384, 65535, 65535]
        .iter()
        .flat_map(|c| c.to_le_bytes())
        .collect();
    for (name, element, component_type, kind) in [
        ("float.gltf", float, 5126, "VEC3"),
        ("bytes.gltf", vec![128, 64, 255, 255], 5121, "VEC4"),
        ("shorts.gltf", shorts, 5123, "VEC4"),
    ] {
        let bare = write(
            dir.path(),
            name,
            &with_vertex_colours(&quad, &element, component_type, kind, false),
        );
        let scene = Scene::load(bare.to_str().unwrap()).unwrap();
        assert!(scene.surface.as_ref().unwrap().materials.is_empty());
        check_quadrants(&scene, [tint; 4]);
    }
}

#[test]
fn missing_and_corrupt_textures_are_typed_errors_naming_the_image() {
    let dir = tempfile::tempdir().unwrap();
    let obj = textured_obj(dir.path(), "map_Kd nowhere.png");
    match Scene::load(obj.to_str().unwrap()) {
        Err(e @ Error::Io { .. }) => assert!(e.to_string().contains("nowhere.png"), "{e}"),
        other => panic!("expected an I/O error, got {other:?}"),
    }
    std::fs::write(
        dir.path().join("broken.png"),
        b"\x89PNG\r\n\x1a\nnot really",
    )
    .unwrap();
    let obj = textured_obj(dir.path(), "map_Kd broken.png");
    match Scene::load(obj.to_str().unwrap()) {
        Err(e @ Error::Parse { .. }) => assert!(e.to_string().contains("broken.png"), "{e}"),
        other => panic!("expected a parse error, got {other:?}"),
    }
    let gltf = write(
        dir.path(),
        "lost.gltf",
        &gltf_quad(r#"{"uri": "lost.png"}"#, [1.0; 4]),
    );
    match Scene::load(gltf.to_str().unwrap()) {
        Err(e @ Error::Io { .. }) => assert!(e.to_string().contains("lost.png"), "{e}"),
        other => panic!("expected an I/O error, got {other:?}"),
    }
    let gltf = write(
        dir.path(),
        "garbage.gltf",
        &gltf_quad(r#"{"uri": "data:image/png;base64,AAAA"}"#, [1.0; 4]),
    );
    match Scene::load(gltf.to_str().unwrap()) {
        Err(e @ Error::Parse { .. }) => {
            let s = e.to_string();
            assert!(s.contains("garbage.gltf") && s.contains("image 0"), "{s}");
        }
        other => panic!("expected a parse error, got {other:?}"),
    }
}

fn rbvh_cli(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_rbvh"))
        .args(args)
        .env("RBVH_VALIDATION", "auto")
        .output()
        .expect("run rbvh")
}

#[test]
fn paint_command_saves_colours_that_render_shows() {
    let dir = tempfile::tempdir().unwrap();
    let p = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    std::fs::write(
        p("s.txt"),
        "# centre of the view\ndab 0.5 0.5 0.05 #ff0000\n",
    )
    .unwrap();
    let out = rbvh_cli(&[
        "paint",
        "--scene",
        "cube",
        "--quality",
        "2",
        "--strokes",
        &p("s.txt"),
        "--out",
        &p("painted.rbvh"),
        "--before",
        &p("before.png"),
        "--after",
        &p("after.png"),
        "--width",
        "64",
        "--height",
        "48",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let painted = Rbvh::load(Path::new(&p("painted.rbvh"))).unwrap();
    assert!(
        !painted.params.exact_when_cheaper,
        "paint samples every triangle: the preset's cube would have no texels"
    );
    assert!(painted.colours.unwrap().contains(&0xFF00_00FF));
    let out = rbvh_cli(&[
        "render",
        "--scene",
        "cube",
        "--rbvh",
        &p("painted.rbvh"),
        "--out",
        &p("again.png"),
        "--width",
        "64",
        "--height",
        "48",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let pixel = |name: &str| *image::open(p(name)).unwrap().to_rgb8().get_pixel(32, 24);
    let (before, after) = (pixel("before.png"), pixel("after.png"));
    assert_eq!(after, pixel("again.png"));
    assert!(
        before[0] == before[1] && before[1] == before[2],
        "{before:?} is grey"
    );
    assert!(
        after[0] > 100 && after[1] < 10 && after[2] < 10,
        "{after:?} is red"
    );

    // A bad strokes file: the error names file and line, and nothing is written.
    std::fs::write(p("bad.txt"), "dab 0.5 0.5 0.05 #ff0000\ndab 0.5 0.5\n").unwrap();
    let out = rbvh_cli(&[
        "paint",
        "--scene",
        "cube",
        "--strokes",
        &p("bad.txt"),
        "--out",
        &p("bad.rbvh"),
    ]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("bad.txt:2"), "{stderr}");
    assert!(!Path::new(&p("bad.rbvh")).exists());
}

#[test]
fn gltf_uris_are_percent_decoded_and_file_uris_to_special_files_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("tex base.png");
    image::RgbaImage::from_pixel(2, 2, image::Rgba([0, 255, 0, 255]))
        .save(&png)
        .unwrap();
    let quad = |uri: &str| gltf_quad(&format!(r#"{{"uri": "{uri}"}}"#), [1.0; 4]);
    let ok = dir.path().join("encoded.gltf");
    std::fs::write(&ok, quad("tex%20base.png")).unwrap();
    let scene = Scene::load(ok.to_str().unwrap()).unwrap();
    assert!(scene.surface.is_some());
    let bad = dir.path().join("scheme.gltf");
    std::fs::write(&bad, quad("http://example.com/tex.png")).unwrap();
    let e = Scene::load(bad.to_str().unwrap()).unwrap_err().to_string();
    assert!(
        e.contains("scheme.gltf") && e.contains("unsupported URI scheme"),
        "{e}"
    );
    let dev = dir.path().join("device.gltf");
    std::fs::write(&dev, quad("file:///dev/zero")).unwrap();
    let e = Scene::load(dev.to_str().unwrap()).unwrap_err().to_string();
    assert!(e.contains("/dev/zero"), "{e}");
}

#[test]
fn height_field_colours_are_filtered_between_samples() {
    use rbvh::rgba;
    let scene = Scene::load("plane").unwrap();
    // Every triangle sampled: the preset traces the plane's two triangles exactly.
    let mut r = Rbvh::build(&scene, &common::sampled_preset(0)).unwrap();
    let (red, blue) = (
        rgba::from_bytes([255, 0, 0, 255]),
        rgba::from_bytes([0, 0, 255, 255]),
    );
    // Columns of samples alternate red and blue.
    let pitch = r.atlas.pitch as usize;
    r.colours = Some(
        (0..r.atlas.texels.len())
            .map(|k| if (k % pitch) % 2 == 0 { red } else { blue })
            .collect(),
    );
    let (l, leaf) = r
        .heightfields
        .iter()
        .enumerate()
        .find(|(_, l)| l.res_u > 4 && l.res_v > 4)
        .unwrap();
    let (i, j) = (2u32, 2u32);
    let texel = |i: u32, j: u32| r.atlas.texels[(leaf.atlas_base + j * r.atlas.pitch + i) as usize];
    let grid = leaf.grid();
    let a = grid.point(i, j, texel(i, j).height_code());
    let b = grid.point(i + 1, j, texel(i + 1, j).height_code());
    let mid = (a + b) * 0.5;
    let ray = Ray::new(mid + Vec3::Y, Vec3::NEG_Y, 0.0, f32::INFINITY);
    let (hit, _) = r.closest_hit(&ray);
    assert_eq!(hit.id, rbvh::bvh::LEAF_BIT | l as u32, "{hit:?}");
    let c = r.filtered_colour(&ray, &hit).unwrap();
    let expect = (rgba::unpack(red) + rgba::unpack(blue)) * 0.5;
    assert!((c - expect).abs().max_element() < 0.02, "{c} vs {expect}");
    // At a sample itself, its own colour.
    let ray = Ray::new(a + Vec3::Y, Vec3::NEG_Y, 0.0, f32::INFINITY);
    let (hit, _) = r.closest_hit(&ray);
    let own = rgba::unpack(
        r.colours.as_ref().unwrap()[(leaf.atlas_base + j * r.atlas.pitch + i) as usize],
    );
    assert!(
        (r.filtered_colour(&ray, &hit).unwrap() - own)
            .abs()
            .max_element()
            < 0.02
    );
}

/// A texture far finer than the atlas: the bake gives each texel the mean colour of the texture
/// over the surface patch it stands for (a mip chain sampled at the patch's size), so a checker
/// of single texels bakes to an even grey at Q0, where point samples would give a noise of black
/// and white texels.
#[test]
fn baked_colours_average_a_texture_finer_than_the_atlas() {
    use rbvh::rgba;
    let dir = tempfile::tempdir().unwrap();
    let side = 512;
    let checker = image::RgbaImage::from_fn(side, side, |x, y| {
        let c = if (x + y) % 2 == 0 { 255 } else { 0 };
        image::Rgba([c, c, c, 255])
    });
    checker.save(dir.path().join("fine.png")).unwrap();
    let scene = Scene::load(
        textured_obj(dir.path(), "map_Kd fine.png")
            .to_str()
            .unwrap(),
    )
    .unwrap();
    // On many threads, as on a 16-core machine: the chain is built on first need while other
    // workers wait for it, which once deadlocked there (the build nested parallel work).
    let (send, receive) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(16)
            .build()
            .unwrap();
        for _ in 0..3 {
            // Every triangle sampled: the preset traces the quad exactly, with no texels to bake.
            let rbvh = pool.install(|| Rbvh::build(&scene, &common::sampled_preset(0)));
            send.send(rbvh.unwrap()).unwrap();
        }
    });
    let timeout = std::time::Duration::from_secs(120);
    let builds: Vec<Rbvh> = (0..3)
        .map(|k| {
            receive
                .recv_timeout(timeout)
                .unwrap_or_else(|e| panic!("build {k}: {e}"))
        })
        .collect();
    assert!(builds.windows(2).all(|w| w[0].colours == w[1].colours));
    let rbvh = &builds[0];
    // The quad is 2 units wide: the texture has several texels per atlas texel.
    let per_texel = side as f32 * rbvh.texel_size / 2.0;
    assert!(
        per_texel > 2.0,
        "{per_texel} texture texels per atlas texel"
    );
    let greys: Vec<f32> = rbvh
        .colours
        .as_ref()
        .unwrap()
        .iter()
        .filter(|&&c| c != 0)
        .map(|&c| rgba::unpack(c).x)
        .collect();
    assert!(greys.len() > 10_000, "{} coloured texels", greys.len());
    let mean = greys.iter().sum::<f32>() / greys.len() as f32;
    let worst = greys.iter().map(|g| (g - 0.5).abs()).fold(0.0, f32::max);
    assert!((mean - 0.5).abs() < 0.01, "mean {mean}");
    assert!(worst < 0.05, "a texel {worst} away from mid grey");
}

/// A textured mesh placed three times (moved, turned and shrunk, mirrored) colours hits of both
/// two-level structures as its flat copy colours the flat structures' hits: each hit's colour is
/// looked up in its instance's mesh, in the mesh's own space (`SceneView::hit_mesh`).
#[test]
fn instances_colour_their_hits_as_the_flat_copy_does() {
    use rbvh::scene::{InstancedScene, SceneView};
    let dir = tempfile::tempdir().unwrap();
    write_checker(&dir.path().join("checker.png"));
    let obj = textured_obj(dir.path(), "map_Kd checker.png");
    let toml = write(
        dir.path(),
        "placed.toml",
        &format!(
            "[[instance]]\npath = {obj:?}\ntranslate = [-3.0, 0.0, 0.0]\n\n\
             [[instance]]\npath = {obj:?}\nrotate = [0.0, 0.0, 90.0]\nscale = 0.75\n\n\
             [[instance]]\npath = {obj:?}\ntranslate = [3.0, 0.0, 0.0]\nscale = [-1.0, 1.0, 1.0]\n"
        ),
    );
    let placed = InstancedScene::load(toml.to_str().unwrap()).unwrap();
    assert!(placed.repeats_a_mesh());
    let flat = placed.clone().into_flat();
    let mut rays = Vec::new();
    for i in 0..48 {
        for j in 0..12 {
            rays.push(down_ray(-4.2 + i as f32 * 0.175, -1.1 + j as f32 * 0.2));
        }
    }
    let flat_of = |recipe: &Recipe| Structure::build(&flat, recipe).unwrap();
    let two_of = |recipe: &Recipe| {
        Structure::build_instanced(&placed, recipe, &rbvh::progress::Quiet).unwrap()
    };
    for recipe in [
        Recipe::Exact,
        Recipe::Rbvh(RbvhParams::quality(4).unwrap()),
        Recipe::Rbvh(common::sampled_preset(4)),
    ] {
        let (flat_structure, two) = (flat_of(&recipe), two_of(&recipe));
        let flat_hits = flat_structure
            .trace_cpu(&rays, rbvh::lod::Cones::None, false)
            .unwrap();
        let two_hits = two.trace_cpu(&rays, rbvh::lod::Cones::None, false).unwrap();
        let want = hit_albedo(&flat, &flat_structure, &rays, &flat_hits).unwrap();
        let got = hit_albedo(SceneView::from(&placed), &two, &rays, &two_hits).unwrap();
        let mut coloured = 0;
        for (k, (g, w)) in got.iter().zip(&want).enumerate() {
            if flat_hits[k].is_hit() != two_hits[k].is_hit() {
                continue;
            }
            coloured += usize::from(flat_hits[k].is_hit());
            assert!(
                (*g - *w).abs().max_element() < 0.05,
                "{}, ray {k}: {g} in two levels, {w} flat",
                two.label()
            );
        }
        assert!(coloured > 100, "{}: {coloured} rays hit", two.label());
    }
}
