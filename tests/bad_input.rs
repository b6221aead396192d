//! Bad input (issue 6): malformed, truncated, empty, missing and mistyped OBJ / glTF / GLB /
//! scene / ray / RBVH files, unknown scene names and out-of-range CLI values. Each must give an
//! error that names what is wrong and where, exit non-zero from the binary without panicking
//! (exit code 101 or "panicked" on stderr fail the test), and leave no output file — not even a
//! partial or temporary one — behind. Cases already covered by `tests/cli.rs`, `tests/scenes.rs`,
//! `tests/files.rs` and `tests/rbvh_file.rs` are not repeated.
//!
//! The fuzz targets of `fuzz/` (cargo-fuzz) are plain functions in `fuzz/src/lib.rs`, included
//! here: a few thousand deterministic mutations of valid inputs run through each of them, and
//! every input kept under `tests/data/fuzz/<target>/` (crashes found while fuzzing, and a few
//! hand-made regressions) is replayed.

#[path = "../fuzz/src/lib.rs"]
#[allow(dead_code)]
mod fuzz;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use glam::Vec3;
use rbvh::geom::Ray;
use rbvh::rbvh::{Rbvh, RbvhParams};
use rbvh::scene::Scene;
use rbvh::Error;

const PNG_HEAD: &[u8] =
    b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\x00\x00\x00\x10\x00\x00\x00\x10\x08\x06\x00\x00\x00";

fn rbvh(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rbvh"))
        .args(args)
        .current_dir(dir)
        .env("RBVH_VALIDATION", "auto")
        .output()
        .expect("run rbvh")
}

/// Files in `dir`, sorted.
fn listing(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

/// Runs `args` in `dir` and checks a clean failure: non-zero exit that is not a panic, stderr
/// naming every `needle`, and the directory exactly as before (no output, no temporary file).
fn fails_cleanly(dir: &Path, args: &[&str], needles: &[&str]) -> String {
    let before = listing(dir);
    let out = rbvh(dir, args);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success(), "{args:?} succeeded:\n{stderr}");
    assert_ne!(out.status.code(), Some(101), "{args:?} panicked:\n{stderr}");
    assert!(!stderr.contains("panicked"), "{args:?} panicked:\n{stderr}");
    for needle in needles {
        assert!(
            stderr.contains(needle),
            "{args:?}: {needle:?} not in the error:\n{stderr}"
        );
    }
    assert_eq!(listing(dir), before, "{args:?} left files behind");
    stderr
}

fn write(dir: &Path, name: &str, content: impl AsRef<[u8]>) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, content).unwrap();
    path
}

/// A valid ray file with two rays at the unit sphere.
fn good_rays(dir: &Path) -> PathBuf {
    let path = dir.join("good.rays");
    rbvh::io::write_rays(
        &path,
        &[
            Ray::new(Vec3::new(0.0, 0.0, -3.0), Vec3::Z, 0.0, f32::INFINITY),
            Ray::new(Vec3::new(0.0, 5.0, -3.0), Vec3::Z, 0.0, f32::INFINITY),
        ],
    )
    .unwrap();
    path
}

/// A minimal GLB: header, a JSON chunk, a BIN chunk.
fn glb(json: &str, bin: &[u8]) -> Vec<u8> {
    let mut json = json.as_bytes().to_vec();
    json.resize(json.len().next_multiple_of(4), b' ');
    let mut out = Vec::new();
    out.extend(b"glTF");
    out.extend(2u32.to_le_bytes());
    out.extend(((12 + 8 + json.len() + 8 + bin.len()) as u32).to_le_bytes());
    out.extend((json.len() as u32).to_le_bytes());
    out.extend(b"JSON");
    out.extend(&json);
    out.extend((bin.len() as u32).to_le_bytes());
    out.extend(b"BIN\0");
    out.extend(bin);
    out
}

const ONE_TRIANGLE_GLTF: &str = r#"{"asset":{"version":"2.0"},"meshes":[{"primitives":[{"attributes":{"POSITION":0}}]}],"nodes":[{"mesh":0}],"buffers":[{"byteLength":36}],"bufferViews":[{"buffer":0,"byteLength":36}],"accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}]}"#;

fn triangle_bin() -> Vec<u8> {
    [0f32, 0., 0., 1., 0., 0., 0., 1., 0.]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect()
}

/// **Every bad mesh or scene file fails `render`, `build` and `trace` cleanly, naming the file**
/// (and the line, where there is one): empty files, vertices without faces, truncated text,
/// binary garbage and a PNG renamed to each extension, out-of-range and zero face indices, a
/// face of two vertices, a glTF triangle list whose count is no multiple of 3, a GLB whose BIN
/// chunk is shorter than its buffer, glTF that is
/// valid JSON but no glTF, glTF without meshes, data URIs that are not base64,
/// accessors whose counts overflow, GLB with a wrong version, a length beyond the file or a
/// chunk beyond the file, scene files that are empty, truncated, refer to a bad mesh, to
/// themselves, or scale the geometry beyond f32, a directory named like a mesh, and missing
/// `.gltf`/`.glb`/`.toml` files.
#[test]
fn bad_mesh_and_scene_files_fail_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    good_rays(d);
    let tri_bin = triangle_bin();
    let cases: Vec<(&str, Vec<u8>, Vec<&str>)> = vec![
        ("empty.obj", vec![], vec!["empty.obj", "no triangles"]),
        (
            "points.obj",
            b"v 0 0 0\nv 1 0 0\nv 0 1 0\np 1 2 3\nl 1 2\n".to_vec(),
            vec!["points.obj", "no triangles"],
        ),
        (
            "cut.obj",
            b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nv 0.5 0.".to_vec(),
            vec!["cut.obj:5", "vertex"],
        ),
        ("png.obj", PNG_HEAD.to_vec(), vec!["png.obj:1"]),
        (
            "latin1.obj",
            b"o caf\xe9\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n".to_vec(),
            vec!["latin1.obj:1", "UTF-8"],
        ),
        (
            "zero.obj",
            b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n".to_vec(),
            vec!["zero.obj:4"],
        ),
        (
            "negative.obj",
            b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -9\n".to_vec(),
            vec!["negative.obj:4"],
        ),
        (
            "huge.obj",
            b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999999999999\n".to_vec(),
            vec!["huge.obj:4"],
        ),
        (
            "twoface.obj",
            b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2\n".to_vec(),
            vec!["twoface.obj:5", "a face needs at least 3"],
        ),
        (
            "shortbin.glb",
            glb(ONE_TRIANGLE_GLTF, &triangle_bin()[..32]),
            vec!["shortbin.glb", "the BIN chunk holds 32"],
        ),
        (
            "fourth.glb",
            {
                let json = ONE_TRIANGLE_GLTF
                    .replace("\"count\":3", "\"count\":4")
                    .replace("36", "48");
                let mut bin = triangle_bin();
                bin.extend([1f32, 1., 0.].iter().flat_map(|v| v.to_le_bytes()));
                glb(&json, &bin)
            },
            vec!["fourth.glb", "not a multiple of 3"],
        ),
        ("empty.gltf", vec![], vec!["empty.gltf"]),
        ("png.gltf", PNG_HEAD.to_vec(), vec!["png.gltf"]),
        ("array.gltf", b"[1, 2, 3]".to_vec(), vec!["array.gltf"]),
        (
            "nomesh.gltf",
            br#"{"asset":{"version":"2.0"}}"#.to_vec(),
            vec!["nomesh.gltf", "no triangles"],
        ),
        (
            "cut.gltf",
            ONE_TRIANGLE_GLTF.as_bytes()[..120].to_vec(),
            vec!["cut.gltf:1"],
        ),
        (
            "base64.gltf",
            ONE_TRIANGLE_GLTF
                .replace(
                    r#"{"byteLength":36}"#,
                    r#"{"uri":"data:application/octet-stream;base64,!!not base64!!","byteLength":36}"#,
                )
                .into_bytes(),
            vec!["base64.gltf"],
        ),
        (
            "count.gltf",
            ONE_TRIANGLE_GLTF
                .replace(r#"{"byteLength":36}"#, r#"{"uri":"data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA","byteLength":36}"#)
                .replace(r#""count":3"#, r#""count":4294967295000"#)
                .into_bytes(),
            vec!["count.gltf"],
        ),
        ("empty.glb", vec![], vec!["empty.glb"]),
        ("png.glb", PNG_HEAD.to_vec(), vec!["png.glb"]),
        (
            "version.glb",
            {
                let mut g = glb(ONE_TRIANGLE_GLTF, &tri_bin);
                g[4] = 1;
                g
            },
            vec!["version.glb"],
        ),
        (
            "length.glb",
            {
                let mut g = glb(ONE_TRIANGLE_GLTF, &tri_bin);
                g[8..12].copy_from_slice(&u32::MAX.to_le_bytes());
                g
            },
            vec!["length.glb"],
        ),
        (
            "chunk.glb",
            {
                let mut g = glb(ONE_TRIANGLE_GLTF, &tri_bin);
                g[12..16].copy_from_slice(&0xFFFF_FFF0u32.to_le_bytes());
                g
            },
            vec!["chunk.glb"],
        ),
        (
            "half.glb",
            glb(ONE_TRIANGLE_GLTF, &tri_bin)[..60].to_vec(),
            vec!["half.glb"],
        ),
        ("empty.toml", vec![], vec!["empty.toml", "mesh"]),
        ("png.toml", PNG_HEAD.to_vec(), vec!["png.toml"]),
        (
            "cut.toml",
            b"[[mesh]]\nbuiltin = \"sphere\"\n[camera]\neye = [0, 1,".to_vec(),
            vec!["cut.toml:4"],
        ),
        (
            "refers.toml",
            b"[[mesh]]\nbuiltin = \"sphere\"\n[[mesh]]\npath = \"png.obj\"\n".to_vec(),
            vec!["png.obj"],
        ),
        (
            "refers_empty.toml",
            b"[[mesh]]\npath = \"empty.obj\"\n".to_vec(),
            vec!["empty.obj", "no triangles"],
        ),
        (
            "self.toml",
            b"[[mesh]]\npath = \"self.toml\"\n".to_vec(),
            vec!["self.toml:2", "scene file"],
        ),
        (
            "overflow.toml",
            b"[[mesh]]\nbuiltin = \"sphere\"\nscale = 2e38\ntranslate = [2e38, 0, 0]\n".to_vec(),
            vec!["overflow.toml", "not finite"],
        ),
        (
            "four.toml",
            b"[[mesh]]\nbuiltin = \"sphere\"\ntranslate = [1, 2, 3, 4]\n".to_vec(),
            vec!["four.toml:3", "invalid length 4, expected three numbers"],
        ),
    ];
    for (name, content, _) in &cases {
        write(d, name, content);
    }
    std::fs::create_dir(d.join("folder.obj")).unwrap();
    let mut all: Vec<(&str, Vec<&str>)> = cases
        .iter()
        .map(|(n, _, needles)| (*n, needles.clone()))
        .collect();
    all.push(("folder.obj", vec!["folder.obj"]));
    for missing in ["gone.gltf", "gone.glb", "gone.toml", "sub/gone.obj"] {
        all.push((missing, vec![missing, "No such file"]));
    }
    for (name, needles) in &all {
        fails_cleanly(
            d,
            &[
                "render",
                "--scene",
                name,
                "--out",
                "o.png",
                "--exr",
                "o.exr",
                "--heatmap",
                "h.png",
                "--width",
                "8",
                "--height",
                "8",
            ],
            needles,
        );
    }
    // The other commands share the loader: a sample of the cases through each.
    for (name, needles) in all.iter().step_by(3) {
        fails_cleanly(d, &["build", "--scene", name, "--out", "s.rbvh"], needles);
        fails_cleanly(
            d,
            &[
                "trace",
                "--scene",
                name,
                "--rays",
                "good.rays",
                "--hits",
                "h.bin",
            ],
            needles,
        );
    }
}

/// **Bad ray files fail `trace` cleanly, naming the file**, on both methods and with `--cpu`:
/// empty, one byte, 31 and 33 bytes (not whole records), missing, a directory, and a PNG whose
/// length is not a multiple of 32. A *well-framed* file of garbage floats is not an error: its
/// rays are answered (invalid ones as misses; see `tests/stability/invalid_rays.rs`).
#[test]
fn bad_ray_files_fail_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "empty.rays", []);
    write(d, "one.rays", [0u8]);
    write(d, "short.rays", [0u8; 31]);
    write(d, "long.rays", [0u8; 33]);
    write(d, "png.rays", PNG_HEAD);
    std::fs::create_dir(d.join("folder.rays")).unwrap();
    for (file, needle) in [
        ("empty.rays", "empty"),
        ("one.rays", "one.rays"),
        ("short.rays", "short.rays"),
        ("long.rays", "long.rays"),
        ("png.rays", "png.rays"),
        ("missing.rays", "No such file"),
        ("folder.rays", "folder.rays"),
    ] {
        for extra in [
            &[][..],
            &["--cpu"][..],
            &["--method", "rbvh", "--quality", "0"][..],
        ] {
            let mut args = vec![
                "trace", "--scene", "sphere", "--rays", file, "--hits", "h.bin",
            ];
            args.extend_from_slice(extra);
            fails_cleanly(d, &args, &[file, needle]);
        }
    }
    // Garbage floats in whole records are rays, answered one hit per ray.
    let garbage: Vec<u8> = (0..32 * 40).map(|i| (i * 97 % 251) as u8).collect();
    write(d, "garbage.rays", &garbage);
    let out = rbvh(
        d,
        &[
            "trace",
            "--scene",
            "sphere",
            "--rays",
            "garbage.rays",
            "--hits",
            "g.hits",
        ],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(rbvh::io::read_hits(&d.join("g.hits")).unwrap().len(), 40);
}

/// **Bad RBVH files fail `render --rbvh` and `trace --rbvh` cleanly, naming the file**: missing,
/// empty, a PNG, a real file cut at several points (in the section table, in the sections), with
/// a byte of the node section's length flipped, with trailing bytes, and with an unknown version. No image or hit
/// file is left behind. (`tests/rbvh_file.rs` checks the library's messages one by one.)
#[test]
fn bad_rbvh_files_fail_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    good_rays(d);
    let scene = Scene::builtin("sphere").unwrap();
    let params = RbvhParams {
        texels_per_diagonal: 32.0,
        ..RbvhParams::quality(0).unwrap()
    };
    let bytes = Rbvh::build(&scene, &params).unwrap().to_bytes();
    let mut flipped = bytes.clone();
    // Table entry 2 (bytes 72..100) is the nodes'; its last 8 bytes their length.
    flipped[92] ^= 0x40;
    let mut trailing = bytes.clone();
    trailing.extend([0u8; 7]);
    let mut version = bytes.clone();
    version[8] = 14;
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("empty.rbvh", vec![], "truncated"),
        ("png.rbvh", PNG_HEAD.to_vec(), "not an RBVH file"),
        ("header.rbvh", bytes[..70].to_vec(), "truncated"),
        (
            "arrays.rbvh",
            bytes[..bytes.len() / 2].to_vec(),
            "truncated",
        ),
        ("last.rbvh", bytes[..bytes.len() - 1].to_vec(), "truncated"),
        ("flipped.rbvh", flipped, "rbvh"),
        ("trailing.rbvh", trailing, "trailing"),
        ("version.rbvh", version, "version"),
    ];
    for (name, content, _) in &cases {
        write(d, name, content);
    }
    let mut all: Vec<(&str, &str)> = cases.iter().map(|(n, _, w)| (*n, *w)).collect();
    all.push(("missing.rbvh", "No such file"));
    for (name, what) in all {
        fails_cleanly(
            d,
            &[
                "render", "--scene", "sphere", "--rbvh", name, "--out", "o.png", "--width", "8",
                "--height", "8",
            ],
            &[name, what],
        );
        fails_cleanly(
            d,
            &[
                "trace",
                "--scene",
                "sphere",
                "--rbvh",
                name,
                "--rays",
                "good.rays",
                "--hits",
                "h.bin",
            ],
            &[name, what],
        );
    }
}

/// **Unknown scene names fail every command cleanly and list the built-ins**: a typo, the empty
/// string, a trailing space, the wrong case, and "-".
#[test]
fn unknown_scene_names_fail_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    good_rays(d);
    for name in ["spherre", "", "sphere ", "SPHERE", "-"] {
        let needles = ["unknown scene", "bumpy-sphere"];
        fails_cleanly(d, &["render", "--scene", name, "--out", "o.png"], &needles);
        fails_cleanly(d, &["build", "--scene", name, "--out", "s.rbvh"], &needles);
        fails_cleanly(
            d,
            &[
                "trace",
                "--scene",
                name,
                "--rays",
                "good.rays",
                "--hits",
                "h.bin",
            ],
            &needles,
        );
    }
}

/// **Out-of-range and malformed CLI values fail cleanly, naming the option or parameter and its
/// range**: image sizes, every RBVH free parameter at and beyond both ends (including NaN,
/// infinity and negatives, given as `--opt=value`), a sampling rate whose atlas would be too
/// large (refused before building), conflicting options, several levels with free parameters,
/// an unknown device, an unknown method, and values that are not numbers.
#[test]
fn out_of_range_cli_values_fail_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let build = |extra: &[&'static str]| {
        let mut a = vec!["build", "--scene", "sphere", "--out", "s.rbvh"];
        a.extend_from_slice(extra);
        a
    };
    let cases: Vec<(Vec<&str>, Vec<&str>)> = vec![
        (
            vec!["render", "--height", "16385", "--out", "o.png"],
            vec!["--height", "16384"],
        ),
        (
            vec!["render", "--width=-3", "--out", "o.png"],
            vec!["--width"],
        ),
        (
            vec!["render", "--width", "many", "--out", "o.png"],
            vec!["--width"],
        ),
        (
            vec!["render", "--width", "4294967296", "--out", "o.png"],
            vec!["--width"],
        ),
        (
            build(&["--texels-per-diagonal=0.5"]),
            vec!["--texels-per-diagonal", "1..=1e6"],
        ),
        (
            build(&["--texels-per-diagonal=-5"]),
            vec!["--texels-per-diagonal"],
        ),
        (
            build(&["--texels-per-diagonal=inf"]),
            vec!["--texels-per-diagonal"],
        ),
        (
            build(&["--texels-per-diagonal", "2e6"]),
            vec!["--texels-per-diagonal", "1..=1e6"],
        ),
        (
            build(&["--texels-per-diagonal", "100000"]),
            vec!["--texels-per-diagonal", "lower the sampling rate"],
        ),
        (build(&["--max-angle", "0"]), vec!["--max-angle", "(0, 90)"]),
        (build(&["--max-angle", "90"]), vec!["--max-angle"]),
        (build(&["--max-angle=-10"]), vec!["--max-angle"]),
        (
            build(&["--min-area-ratio", "0"]),
            vec!["--min-area-ratio", "(0, 1]"],
        ),
        (
            build(&["--min-area-ratio", "1.5"]),
            vec!["--min-area-ratio"],
        ),
        (
            build(&["--min-area-ratio", "NaN"]),
            vec!["--min-area-ratio"],
        ),
        (
            build(&["--max-angle", "30", "--min-area-ratio", "0.5"]),
            vec!["--max-angle", "--min-area-ratio"],
        ),
        (build(&["--max-tile", "3"]), vec!["--max-tile", "4..=4096"]),
        (build(&["--max-tile", "4097"]), vec!["--max-tile"]),
        (build(&["--max-tile=-1"]), vec!["--max-tile"]),
        (
            build(&["--min-leaf-texels=-1"]),
            vec!["--min-leaf-texels", "0..=1e4"],
        ),
        (
            build(&["--min-leaf-texels", "1e5"]),
            vec!["--min-leaf-texels"],
        ),
        (build(&["--split", "random"]), vec!["--split"]),
        (build(&["--quality", "Q5"]), vec!["--quality", "Q5"]),
        (build(&["--quality=-1"]), vec!["--quality"]),
        (
            build(&["--quality", "0,1"]),
            vec!["--out", "single --quality"],
        ),
        (
            vec![
                "build",
                "--scene",
                "sphere",
                "--quality",
                "all",
                "--max-tile",
                "8",
            ],
            vec!["single --quality"],
        ),
        (
            vec!["render", "--method", "bvh4", "--out", "o.png"],
            vec!["--method"],
        ),
        (
            vec![
                "render",
                "--scene",
                "sphere",
                "--device",
                "no-such-gpu",
                "--out",
                "o.png",
                "--width",
                "8",
                "--height",
                "8",
            ],
            vec!["no-such-gpu"],
        ),
        (vec!["render", "--shading", "phong"], vec!["--shading"]),
        (vec!["frobnicate"], vec!["frobnicate"]),
    ];
    for (args, needles) in &cases {
        fails_cleanly(d, args, needles);
    }
}

/// **Outputs that cannot be written fail cleanly, naming the path, and leave nothing behind**:
/// into a directory that does not exist, onto an existing directory, for `render` (PNG, EXR,
/// heat map), `build --out` and `trace --hits`; every output is checked before any is written,
/// so a render whose second output cannot be written does not write its first.
#[test]
fn unwritable_outputs_fail_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    good_rays(d);
    std::fs::create_dir(d.join("taken")).unwrap();
    let render = |extra: &[&'static str]| {
        let mut a = vec![
            "render", "--scene", "sphere", "--width", "8", "--height", "8",
        ];
        a.extend_from_slice(extra);
        a
    };
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (render(&["--out", "nowhere/o.png"]), "nowhere/o.png"),
        (render(&["--out", "taken"]), "taken"),
        (
            render(&["--out", "o.png", "--exr", "nowhere/o.exr"]),
            "nowhere/o.exr",
        ),
        (render(&["--out", "o.png", "--heatmap", "taken"]), "taken"),
        (
            vec![
                "build",
                "--scene",
                "sphere",
                "--quality",
                "0",
                "--out",
                "nowhere/s.rbvh",
            ],
            "nowhere/s.rbvh",
        ),
        (
            vec![
                "trace",
                "--scene",
                "sphere",
                "--rays",
                "good.rays",
                "--hits",
                "nowhere/h.bin",
            ],
            "nowhere/h.bin",
        ),
        (
            vec![
                "trace",
                "--scene",
                "sphere",
                "--rays",
                "good.rays",
                "--hits",
                "taken",
            ],
            "taken",
        ),
    ];
    for (args, path) in &cases {
        let before = listing(d);
        let out = rbvh(d, args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?} succeeded");
        assert_ne!(out.status.code(), Some(101), "{args:?} panicked: {stderr}");
        assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
        assert!(stderr.contains(path), "{args:?}: {path} not in {stderr}");
        assert_eq!(listing(d), before, "{args:?} left files behind");
        assert!(
            listing(&d.join("taken")).is_empty(),
            "{args:?} wrote into the directory"
        );
    }
}

/// **An output never replaces one of the command's inputs, nor another of its outputs, and a
/// name must be its format's**: each refused before any work, naming the flags, with every file
/// as it was. The RBVH file that `upgrade` rewrites in place is the documented exception
/// (`tests/cli.rs`).
#[test]
fn outputs_never_replace_inputs_or_each_other() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    good_rays(d);
    std::fs::write(d.join("tri.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    std::fs::write(d.join("kept.png"), b"an earlier picture").unwrap();
    let cases: Vec<(Vec<&str>, Vec<&str>)> = vec![
        (
            vec![
                "trace",
                "--scene",
                "sphere",
                "--rays",
                "good.rays",
                "--hits",
                "good.rays",
            ],
            vec!["--hits good.rays is the file --rays reads"],
        ),
        (
            vec!["render", "--scene", "tri.obj", "--out", "tri.obj"],
            vec!["--out tri.obj", "writes PNG"],
        ),
        (
            vec![
                "build",
                "--scene",
                "tri.obj",
                "--quality",
                "0",
                "--out",
                "tri.obj",
            ],
            vec!["--out tri.obj", "writes RBVH, so give it a .rbvh name"],
        ),
        (
            vec![
                "render",
                "--scene",
                "sphere",
                "--width",
                "8",
                "--height",
                "8",
                "--out",
                "same.png",
                "--heatmap",
                "same.png",
            ],
            vec!["--heatmap and --out both name same.png"],
        ),
        (
            vec![
                "render",
                "--scene",
                "sphere",
                "--width",
                "8",
                "--height",
                "8",
                "--out",
                "kept.png",
                "--exr",
                "nowhere/x.exr",
            ],
            vec!["--exr nowhere/x.exr: the folder nowhere does not exist"],
        ),
        (
            vec!["bench", "--scene", "sphere", "--json", "nowhere/b.json"],
            vec!["--json nowhere/b.json: the folder nowhere does not exist"],
        ),
        (
            vec!["bench", "--scene", "sphere", "--csv", "b.json"],
            vec!["--csv b.json: writes CSV"],
        ),
    ];
    let contents = |d: &Path| -> Vec<Vec<u8>> {
        ["good.rays", "tri.obj", "kept.png"]
            .map(|f| std::fs::read(d.join(f)).unwrap())
            .to_vec()
    };
    let before = contents(d);
    for (args, needles) in &cases {
        fails_cleanly(d, args, needles);
        assert_eq!(contents(d), before, "{args:?} changed an input");
    }
}

/// **The library's loaders give typed errors naming the file**, without the binary: every bad
/// file of `bad_mesh_and_scene_files_fail_cleanly` that is reachable this way is a `Parse`,
/// `Io` or `InvalidGeometry` error whose message names it, and an empty mesh file is refused
/// rather than loaded as an empty scene.
#[test]
fn loaders_refuse_empty_mesh_files() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (name, content) in [
        ("empty.obj", &b""[..]),
        ("vertices.obj", b"v 0 0 0\nv 1 0 0\n"),
        ("lines.obj", b"v 0 0 0\nv 1 0 0\nl 1 2\n"),
        ("nomesh.gltf", br#"{"asset":{"version":"2.0"}}"#),
    ] {
        let path = write(d, name, content);
        match Scene::load(path.to_str().unwrap()) {
            Err(e @ Error::Parse { .. }) => {
                let text = e.to_string();
                assert!(
                    text.contains(name) && text.contains("no triangles"),
                    "{text}"
                );
            }
            other => panic!("{name}: expected a parse error, got {other:?}"),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// The fuzz targets, deterministically

/// The library's SplitMix64, drawing indices.
struct Rng(rbvh::random::SplitMix64);

impl Rng {
    fn below(&mut self, n: usize) -> usize {
        (self.0.next_u64() % n.max(1) as u64) as usize
    }
}

/// Byte strings that matter to the parsers: numbers at the edges, keywords, separators.
const TOKENS: [&[u8]; 24] = [
    b"nan",
    b"-inf",
    b"1e39",
    b"-0",
    b"4294967295",
    b"-2147483648",
    b"0",
    b"\n",
    b" ",
    b"/",
    b"f ",
    b"v ",
    b"\"count\":",
    b"\"byteLength\":",
    b"\"uri\":",
    b"[[mesh]]",
    b"scale = ",
    b"builtin = \"plane\"",
    b"path = \"mesh.obj\"",
    b"\xff\xff\xff\xff",
    b"\x00\x00\x00\x00",
    b"\x7f\x7f\xff\xff",
    b"\x00\x00\x80\x7f",
    b"glTF",
];

/// One random mutation of `data`: flip, set, insert or delete bytes, splice a token, overwrite
/// a 4-byte word with an extreme value, truncate, or duplicate a chunk.
fn mutate(rng: &mut Rng, data: &mut Vec<u8>) {
    let len = data.len();
    match rng.below(9) {
        0 if len > 0 => {
            let i = rng.below(len);
            data[i] ^= 1 << rng.below(8);
        }
        1 if len > 0 => {
            let i = rng.below(len);
            data[i] = rng.0.next_u64() as u8;
        }
        2 => {
            let i = rng.below(len + 1);
            data.insert(i, rng.0.next_u64() as u8);
        }
        3 if len > 0 => {
            let i = rng.below(len);
            let n = rng.below(8.min(len - i)) + 1;
            data.drain(i..i + n);
        }
        4 => {
            let i = rng.below(len + 1);
            let t = TOKENS[rng.below(TOKENS.len())];
            data.splice(i..i, t.iter().copied());
        }
        5 if len >= 4 => {
            let i = rng.below(len - 3) & !3;
            let word = [0u32, u32::MAX, 0x7F80_0000, 0x7FC0_0000, 1, 0x8000_0000][rng.below(6)];
            data[i..i + 4].copy_from_slice(&word.to_le_bytes());
        }
        6 if len > 0 => {
            let n = rng.below(len);
            data.truncate(n);
        }
        7 if len > 1 => {
            let i = rng.below(len);
            let n = rng.below(32.min(len - i)) + 1;
            let chunk: Vec<u8> = data[i..i + n].to_vec();
            let j = rng.below(len + 1);
            data.splice(j..j, chunk);
        }
        _ => {
            let i = rng.below(len + 1);
            data.insert(i, b"0123456789.-e"[rng.below(13)]);
        }
    }
}

/// Every fuzz target survives ~6000 deterministic mutations of valid inputs (1–8 stacked
/// mutations each): no panic, and whatever loads or builds passes the target's checks (see
/// `fuzz/src/lib.rs`). The same functions are the cargo-fuzz targets.
#[test]
fn fuzz_targets_survive_mutated_inputs() {
    let seeds = fuzz::seeds();
    let per_seed = 1000;
    let mut rng = Rng(rbvh::random::SplitMix64::new(0x5EED));
    for (target, seed) in &seeds {
        fuzz::run(target, seed);
        for _ in 0..per_seed {
            let mut data = seed.clone();
            for _ in 0..rng.below(8) + 1 {
                mutate(&mut rng, &mut data);
            }
            let outcome = std::panic::catch_unwind(|| fuzz::run(target, &data));
            if outcome.is_err() {
                let keep = std::env::temp_dir().join(format!("rbvh-fuzz-crash-{target}"));
                std::fs::write(&keep, &data).unwrap();
                panic!(
                    "fuzz target {target} panicked on a mutated input, saved to {}",
                    keep.display()
                );
            }
        }
    }
}

/// Every input under `tests/data/fuzz/<target>/` — crashes found by cargo-fuzz and hand-made
/// regressions — runs through its target without a panic.
#[test]
fn fuzz_regressions_replay() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/fuzz");
    let mut replayed = 0;
    for target in fuzz::TARGETS {
        let dir = root.join(target);
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        let mut files: Vec<PathBuf> = entries.map(|e| e.unwrap().path()).collect();
        files.sort();
        for file in files {
            let data = std::fs::read(&file).unwrap();
            let outcome = std::panic::catch_unwind(|| fuzz::run(target, &data));
            assert!(outcome.is_ok(), "{} panicked", file.display());
            replayed += 1;
        }
    }
    println!("replayed {replayed} fuzz regression inputs");
    assert!(
        replayed > 0,
        "no regression inputs under {}",
        root.display()
    );
}

/// Writes the seeds of `fuzz/src/lib.rs` into cargo-fuzz's corpus folders
/// (`fuzz/corpus/<target>/seed-<n>`), so that a fuzzing run starts from valid inputs; run it with
/// `cargo test --release --test bad_input -- --ignored write_fuzz_seeds`.
#[test]
#[ignore = "writes into fuzz/corpus; run by hand before fuzzing"]
fn write_fuzz_seeds() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/corpus");
    for (n, (target, seed)) in fuzz::seeds().into_iter().enumerate() {
        let dir = root.join(target);
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join(format!("seed-{n}")), seed).unwrap();
    }
}
