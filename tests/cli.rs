//! The `rbvh` binary end to end: render, trace, and clear errors that leave no output behind.

mod common;

use std::path::Path;
use std::process::Command;

use rbvh::geom::{Hit, Ray};
use rbvh::io;

fn rbvh(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_rbvh"))
        .args(args)
        .env("RBVH_VALIDATION", "auto")
        .output()
        .expect("run rbvh")
}

fn arg(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn render_writes_png_exr_and_heatmap() {
    let dir = tempfile::tempdir().unwrap();
    let (png, exr, heat) = (
        dir.path().join("a.png"),
        dir.path().join("a.exr"),
        dir.path().join("h.png"),
    );
    let out = rbvh(&[
        "render",
        "--scene",
        "default",
        "--width",
        "96",
        "--height",
        "64",
        "--out",
        arg(&png),
        "--exr",
        arg(&exr),
        "--heatmap",
        arg(&heat),
        "--heatmap-max",
        "500",
        "--stats",
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains("MRays/s") && stderr.contains("GPU/CPU"),
        "{stderr}"
    );
    let img = image::open(&png).unwrap();
    assert_eq!((img.width(), img.height()), (96, 64));
    assert!(exr.exists());
    // The heat map: the picture at the fixed scale asked for, with its colour bar below.
    assert!(stderr.contains("0 to 500 on its colour bar"), "{stderr}");
    let map = image::open(&heat).unwrap();
    assert!(
        map.width() == 96 && map.height() > 64,
        "{:?}",
        (map.width(), map.height())
    );
}

#[test]
fn trace_answers_a_ray_file() {
    let dir = tempfile::tempdir().unwrap();
    let (rays_path, hits_path) = (dir.path().join("r.bin"), dir.path().join("h.bin"));
    let rays = vec![
        Ray::new(
            glam::Vec3::new(0.0, 0.0, -3.0),
            glam::Vec3::Z,
            0.0,
            f32::INFINITY,
        ),
        Ray::new(
            glam::Vec3::new(0.0, 5.0, -3.0),
            glam::Vec3::Z,
            0.0,
            f32::INFINITY,
        ),
    ];
    io::write_rays(&rays_path, &rays).unwrap();
    for extra in [&[][..], &["--any-hit"][..], &["--cpu"][..]] {
        let mut args = vec![
            "trace",
            "--scene",
            "sphere",
            "--rays",
            arg(&rays_path),
            "--hits",
            arg(&hits_path),
        ];
        args.extend_from_slice(extra);
        let out = rbvh(&args);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let hits = io::read_hits(&hits_path).unwrap();
        assert_eq!(hits.len(), 2);
        assert!(
            hits[0].is_hit() && (hits[0].t - 2.0).abs() < 0.01,
            "{:?}",
            hits[0]
        );
        assert_eq!(hits[1], Hit::MISS);
    }
}

#[test]
fn errors_name_the_culprit_and_leave_no_output() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("never.png");
    let missing = dir.path().join("missing.obj");
    let out = rbvh(&["render", "--scene", arg(&missing), "--out", arg(&png)]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("missing.obj"));
    let out = rbvh(&["render", "--scene", "no-such-builtin", "--out", arg(&png)]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("no-such-builtin"));
    let out = rbvh(&["render", "--width", "0", "--out", arg(&png)]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--width"));
    let bad_rays = dir.path().join("bad.bin");
    std::fs::write(&bad_rays, [0u8; 33]).unwrap();
    let hits = dir.path().join("hits.bin");
    let out = rbvh(&[
        "trace",
        "--scene",
        "sphere",
        "--rays",
        arg(&bad_rays),
        "--hits",
        arg(&hits),
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("bad.bin"));
    assert!(!png.exists() && !hits.exists());
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        1,
        "only the bad ray file remains"
    );
    // A --plot that is a file is refused before anything is measured, not after every scene.
    let out = rbvh(&["bench", "--quality", "0", "--plot", arg(&bad_rays)]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--plot") && err.contains("bad.bin"), "{err}");
    assert_eq!(std::fs::read(&bad_rays).unwrap(), [0u8; 33]);
}

/// A scene that fails to load after others were measured stops the bench with its error, and
/// loses nothing: what was measured before it is shown and written where asked.
#[test]
fn a_bench_stopped_by_a_later_scene_keeps_the_earlier_ones() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.obj");
    std::fs::write(&bad, "v 0 0 0\nv 1 0 0\nf 1 2 9\n").unwrap();
    let (json, csv) = (dir.path().join("b.json"), dir.path().join("b.csv"));
    let bench = |scenes: String, outputs: &[&str]| {
        let mut args = vec![
            "bench",
            "--scene",
            &scenes,
            "--quality",
            "0",
            "--rays",
            "primary",
            "--width",
            "16",
            "--height",
            "12",
            "--runs",
            "1",
        ];
        args.extend_from_slice(outputs);
        rbvh(&args)
    };
    let out = bench(
        format!("sphere,{}", arg(&bad)),
        &["--json", arg(&json), "--csv", arg(&csv)],
    );
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("bad.obj:3") && err.contains("measured before (sphere: 2 records)"),
        "{err}"
    );
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let results = report["results"].as_array().unwrap();
    assert_eq!(results.len(), 2);
    assert!(results.iter().all(|r| r["scene"] == "sphere"));
    assert_eq!(std::fs::read_to_string(&csv).unwrap().lines().count(), 3);
    // Stopped at the first scene, nothing was measured: the error alone, no file written.
    std::fs::remove_file(&json).unwrap();
    let out = bench(format!("{},sphere", arg(&bad)), &["--json", arg(&json)]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("bad.obj:3"));
    assert!(!json.exists());
}

#[test]
fn rbvh_build_save_render_and_trace() {
    let dir = tempfile::tempdir().unwrap();
    let (file, png, heat) = (
        dir.path().join("s.rbvh"),
        dir.path().join("r.png"),
        dir.path().join("h.png"),
    );
    let out = rbvh(&[
        "build",
        "--scene",
        "sphere",
        "--quality",
        "Q0",
        "--out",
        arg(&file),
        "--stats",
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("Q0") && stdout.contains("vs exact"),
        "{stdout}"
    );
    let out = rbvh(&[
        "render",
        "--scene",
        "sphere",
        "--rbvh",
        arg(&file),
        "--width",
        "64",
        "--height",
        "48",
        "--out",
        arg(&png),
        "--stats",
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains("loaded from") && !stderr.contains(", built in"),
        "{stderr}"
    );
    // The file with a scene it was not built for: an error, before any work.
    let out = rbvh(&[
        "render",
        "--scene",
        "blob",
        "--rbvh",
        arg(&file),
        "--width",
        "8",
        "--height",
        "8",
        "--out",
        arg(&png),
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("built for another scene"),
        "{stderr}"
    );
    let out = rbvh(&[
        "render",
        "--scene",
        "default",
        "--method",
        "rbvh",
        "--quality",
        "1",
        "--width",
        "64",
        "--height",
        "48",
        "--out",
        arg(&png),
        "--heatmap",
        arg(&heat),
        "--stats",
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("RBVH speedup"), "{stderr}");
    assert!(png.exists() && heat.exists());
    let (rays_path, hits_path) = (dir.path().join("r.bin"), dir.path().join("h.bin"));
    io::write_rays(
        &rays_path,
        &[Ray::new(
            glam::Vec3::new(0.0, 0.0, -3.0),
            glam::Vec3::Z,
            0.0,
            f32::INFINITY,
        )],
    )
    .unwrap();
    let out = rbvh(&[
        "trace",
        "--scene",
        "sphere",
        "--method",
        "rbvh",
        "--rays",
        arg(&rays_path),
        "--hits",
        arg(&hits_path),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let hit = io::read_hits(&hits_path).unwrap()[0];
    assert!(
        hit.id & 0x8000_0000 != 0 && (hit.t - 2.0).abs() < 0.01,
        "{hit:?}"
    );
}

/// `rbvh build --scene SCENE --quality QUALITY --out DIR/LABEL-N.rbvh --stats` with `extra`
/// flags: checks that it succeeds and prints a level named `label`, and loads the file.
fn built_level(
    dir: &Path,
    scene: &str,
    quality: &str,
    extra: &[&str],
    label: &str,
) -> rbvh::rbvh::Rbvh {
    let file = dir.join(format!("{label}-{}.rbvh", extra.len()));
    let mut args = vec![
        "build",
        "--scene",
        scene,
        "--quality",
        quality,
        "--out",
        arg(&file),
        "--stats",
    ];
    args.extend(extra);
    let out = rbvh(&args);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout
            .lines()
            .any(|l| l.split_whitespace().next() == Some(label)),
        "{stdout}"
    );
    rbvh::rbvh::Rbvh::load(&file).unwrap()
}

/// The presets trace the cube's large faces exactly; `--sample-all` samples them as the paper
/// does, names the level `Q2s`, and saves that choice in the file.
#[test]
fn sample_all_samples_what_the_presets_trace_exactly() {
    let dir = tempfile::tempdir().unwrap();
    for (extra, label, sampled) in [(&[][..], "Q2", false), (&["--sample-all"][..], "Q2s", true)] {
        let r = built_level(dir.path(), "cube", "2", extra, label);
        assert_eq!(r.params.exact_when_cheaper, !sampled, "{label}");
        assert_eq!(
            !r.heightfields.is_empty(),
            sampled,
            "{label}: {} leaves",
            r.heightfields.len()
        );
    }
}

/// `--view` refines every level asked for where the scene's camera looks closely, at
/// `rbvh::rbvh::VIEW_RATE` without a value: the level is named `Q0v`, the file keeps the rate,
/// and a camera close to the blob makes it larger than the preset (fewer texels, since at the
/// finer texel more of the blob's triangles cost fewer bytes traced exactly, and more exact
/// triangles); a rate out of range, and `--view` on a scene without a camera, are refused
/// naming the flag.
#[test]
fn view_refines_levels_for_the_scenes_camera() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("close.toml");
    std::fs::write(
        &scene,
        "[[mesh]]\nbuiltin = \"blob\"\n[camera]\neye = [0, 0, 1.6]\ntarget = [0, 0, 0]\nvfov = 40\n",
    )
    .unwrap();
    let build =
        |extra: &[&str], label: &str| built_level(dir.path(), arg(&scene), "0", extra, label);
    let preset = build(&[], "Q0");
    let viewed = build(&["--view"], "Q0v");
    assert_eq!(preset.params.view_rate, 0.0);
    assert_eq!(viewed.params.view_rate, rbvh::rbvh::VIEW_RATE);
    assert!(
        viewed.total_bytes() > preset.total_bytes()
            && viewed.triangles.len() > preset.triangles.len(),
        "{} bytes and {} exact triangles against {} and {}",
        viewed.total_bytes(),
        viewed.triangles.len(),
        preset.total_bytes(),
        preset.triangles.len()
    );
    let rate = build(&["--view", "200"], "Q0v");
    assert_eq!(rate.params.view_rate, 200.0);
    assert_ne!(rate.total_bytes(), viewed.total_bytes());
    for (args, needle) in [
        (
            &["--scene", arg(&scene), "--view", "-1"][..],
            "--view: -1 is neither 0",
        ),
        (
            &["--scene", arg(&scene), "--view", "0.5"][..],
            "--view: 0.5 is neither 0",
        ),
        (
            &["--scene", arg(&scene), "--view", "0"][..],
            "--view 0 refines nothing",
        ),
        (&["--scene", "blob", "--view"][..], "\"blob\" has none"),
    ] {
        let out = rbvh(&[&["build"][..], args].concat());
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && stderr.contains(needle),
            "{args:?}: {stderr}"
        );
    }
}

/// What the CLI would otherwise get wrong quietly or refuse obscurely: an output name whose
/// extension says another format, and a negative number (which clap took for a flag).
#[test]
fn formats_follow_the_flag_and_negative_numbers_reach_their_checks() {
    let dir = tempfile::tempdir().unwrap();
    let ok = dir.path().join("ok.png");
    for (flag, name, needle) in [
        ("--out", "r.jpg", "writes PNG, so give it a .png name"),
        ("--heatmap", "h.exr", "writes PNG"),
        ("--exr", "d.png", "writes EXR"),
    ] {
        let path = dir.path().join(name);
        let mut args = vec![
            "render", "--scene", "sphere", "--width", "8", "--height", "8",
        ];
        if flag != "--out" {
            args.extend(["--out", arg(&ok)]);
        }
        args.extend([flag, arg(&path)]);
        let out = rbvh(&args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && stderr.contains(needle),
            "{args:?}: {stderr}"
        );
        assert!(!path.exists(), "{args:?} wrote {}", path.display());
    }
    let out = rbvh(&["build", "--scene", "sphere", "--texels-per-diagonal", "-3"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("--texels-per-diagonal: -3 is outside"),
        "{stderr}"
    );
}

/// A parameter out of range is reported under the flag that set it, not the library's field name.
#[test]
fn parameter_errors_name_their_flag() {
    for (args, needle) in [
        (
            &[
                "render",
                "--scene",
                "sphere",
                "--method",
                "rbvh-lod",
                "--lod-columns",
                "0",
            ][..],
            "--lod-columns: 0 is outside",
        ),
        (
            &[
                "bench",
                "--scene",
                "sphere",
                "--quality",
                "2",
                "--method",
                "rbvh-lod",
                "--lod-bias",
                "20",
            ][..],
            "--lod-bias: 20 is outside",
        ),
        (
            &[
                "build",
                "--scene",
                "sphere",
                "--quality",
                "2",
                "--max-tile",
                "2",
            ][..],
            "--max-tile: 2 is outside",
        ),
        (
            &[
                "build",
                "--scene",
                "sphere",
                "--quality",
                "2",
                "--exact-from-texels=-1",
            ][..],
            "--exact-from-texels: -1 is outside",
        ),
        (
            &[
                "build",
                "--scene",
                "sphere",
                "--quality",
                "2",
                "--exact-from-texels",
                "1.5",
                "--sample-all",
            ][..],
            "--exact-from-texels",
        ),
        (
            &[
                "build",
                "--scene",
                "sphere",
                "--quality",
                "2",
                "--exact-edge-fraction",
                "2",
            ][..],
            "--exact-edge-fraction: 2 is outside",
        ),
        (
            &[
                "build",
                "--scene",
                "sphere",
                "--quality",
                "2",
                "--exact-edge-fraction",
                "0.01",
                "--sample-all",
            ][..],
            "--exact-edge-fraction",
        ),
        (
            &[
                "build",
                "--scene",
                "sphere",
                "--quality",
                "2",
                "--exact-crease",
                "200",
            ][..],
            "--exact-crease: 200 is outside",
        ),
    ] {
        let out = rbvh(args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && stderr.contains(needle),
            "{args:?}: {stderr}"
        );
    }
}

/// `rbvh scenes` lists the built-in scenes, every one of which renders with no file at all.
#[test]
fn the_scenes_command_lists_the_built_in_scenes() {
    let out = rbvh(&["scenes"]);
    assert!(out.status.success());
    let stdout = String::from_utf8_lossy(&out.stdout);
    let names: Vec<&str> = stdout.lines().collect();
    assert_eq!(names, rbvh::scene::builtin::NAMES);
}

#[test]
fn bad_quality_and_parameters_are_clear_errors() {
    for args in [
        &["build", "--scene", "sphere", "--quality", "7"][..],
        &[
            "build",
            "--scene",
            "sphere",
            "--quality",
            "2",
            "--max-angle",
            "95",
        ][..],
        &["render", "--method", "rbvh", "--quality", "1,2"][..],
    ] {
        let out = rbvh(args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?} succeeded");
        assert!(
            stderr.contains("quality") || stderr.contains("--max-angle: 95 is outside"),
            "{args:?}: {stderr}"
        );
    }
}

#[test]
fn a_scene_far_from_the_origin_is_reported() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("far.toml");
    std::fs::write(
        &scene,
        "[[mesh]]\nbuiltin = \"sphere\"\ntranslate = [1.0e6, 0.0, 0.0]\n",
    )
    .unwrap();
    let png = dir.path().join("far.png");
    let out = rbvh(&[
        "render",
        "--scene",
        arg(&scene),
        "--width",
        "16",
        "--height",
        "16",
        "--out",
        arg(&png),
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains("warning") && stderr.contains("recentre"),
        "{stderr}"
    );
}

#[test]
fn render_and_trace_with_level_of_detail() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("lod.png");
    let out = rbvh(&[
        "render",
        "--scene",
        "blob",
        "--method",
        "rbvh-lod",
        "--quality",
        "3",
        "--lod-bias",
        "-0.5",
        "--stats",
        "--width",
        "64",
        "--height",
        "48",
        "--out",
        arg(&png),
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(png.exists());
    assert!(
        err.contains("levels of detail:") && err.contains("LOD speedup"),
        "{err}"
    );

    let (rays_path, hits_path) = (dir.path().join("r.bin"), dir.path().join("h.bin"));
    let rays: Vec<Ray> = (0..50)
        .map(|i| {
            let x = -1.0 + i as f32 * 0.04;
            Ray::new(
                glam::Vec3::new(x, 0.1, 20.0),
                glam::Vec3::NEG_Z,
                0.0,
                f32::INFINITY,
            )
        })
        .collect();
    io::write_rays(&rays_path, &rays).unwrap();
    for cpu in [false, true] {
        let mut args = vec![
            "trace",
            "--scene",
            "blob",
            "--method",
            "rbvh-lod",
            "--lod-spread",
            "0.05",
            "--rays",
            arg(&rays_path),
            "--hits",
            arg(&hits_path),
        ];
        if cpu {
            args.push("--cpu");
        }
        let out = rbvh(&args);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let hits: Vec<Hit> = io::read_hits(&hits_path).unwrap();
        assert!(
            hits.iter()
                .any(|h| h.is_hit() && h.id & rbvh::lod::LOD_BIT != 0),
            "cpu {cpu}"
        );
    }

    let out = rbvh(&[
        "render",
        "--scene",
        "blob",
        "--method",
        "rbvh-lod",
        "--texels",
        "height",
        "--out",
        arg(&png),
    ]);
    assert!(!out.status.success());
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("levels of detail need the texels' normals")
    );
    for (args, needle) in [
        (vec!["--lod-spread", "NaN"], "--lod-spread"),
        (vec!["--lod-spread=-1"], "--lod-spread"),
        (vec!["--lod-columns", "0"], "--lod-columns"),
        (vec!["--lod-min-leaves", "0"], "--lod-min-leaves"),
        (vec!["--lod-bias", "-9"], "--lod-bias"),
        (vec!["--lod-bias", "inf"], "--lod-bias"),
    ] {
        let mut all = vec![
            "trace",
            "--scene",
            "blob",
            "--method",
            "rbvh-lod",
            "--rays",
            arg(&rays_path),
            "--hits",
            arg(&hits_path),
        ];
        all.extend(args);
        let out = rbvh(&all);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && err.contains(needle),
            "{all:?}: {err}"
        );
        assert_ne!(out.status.code(), Some(101), "{all:?} panicked");
    }
}

#[test]
fn render_ibl_writes_png_and_exr_and_compares_with_the_exact_render() {
    let dir = tempfile::tempdir().unwrap();
    let (env, png, exr) = (
        dir.path().join("env.exr"),
        dir.path().join("ibl.png"),
        dir.path().join("ibl.exr"),
    );
    // Bright above the horizon, dark below.
    exr::prelude::write_rgb_file(&env, 32, 16, |_, y| {
        let v = if y < 8 { 1.5f32 } else { 0.1 };
        (v, v, v)
    })
    .unwrap();
    let out = rbvh(&[
        "render",
        "--shading",
        "ibl",
        "--env",
        arg(&env),
        "--samples",
        "2",
        "--seed",
        "9",
        "--method",
        "rbvh",
        "--quality",
        "0",
        "--width",
        "48",
        "--height",
        "32",
        "--out",
        arg(&png),
        "--exr",
        arg(&exr),
        "--stats",
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    for needle in ["IBL exact reference", "FLIP", "PSNR", "wall"] {
        assert!(stderr.contains(needle), "{needle:?} not in:\n{stderr}");
    }
    let img = image::open(&png).unwrap();
    assert_eq!((img.width(), img.height()), (48, 32));
    let layers = exr::prelude::read_all_flat_layers_from_file(&exr).unwrap();
    let names: Vec<String> = layers.layer_data[0]
        .channel_data
        .list
        .iter()
        .map(|c| c.name.to_string())
        .collect();
    for name in ["R", "G", "B", "Z", "N.X", "N.Y", "N.Z"] {
        assert!(names.iter().any(|n| n == name), "{name} not in {names:?}");
    }
}

#[test]
fn render_ibl_refuses_bad_environments_and_samples() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("never.png");
    let bad = dir.path().join("bad.exr");
    std::fs::write(&bad, b"not an exr").unwrap();
    let missing = dir.path().join("missing.exr");
    let cases: [(Vec<&str>, &str); 7] = [
        (
            vec!["--shading", "ibl", "--env", arg(&missing)],
            "missing.exr",
        ),
        (vec!["--shading", "ibl", "--env", arg(&bad)], "bad.exr"),
        (vec!["--shading", "ibl", "--samples", "0"], "--samples"),
        (vec!["--env", arg(&bad)], "--shading ibl"),
        // Flags that only an image-based render uses are refused, not ignored.
        (
            vec!["--samples", "4"],
            "--samples is for an image-based render",
        ),
        (vec!["--seed", "3"], "--seed is for an image-based render"),
        // One structure to trace: both texel formats are for build and bench.
        (
            vec!["--method", "rbvh", "--texels", "normals,height"],
            "--texels names two texel formats: give one to trace",
        ),
    ];
    common::every_case(cases, |(extra, needle)| {
        let mut args = vec![
            "render",
            "--width",
            "16",
            "--height",
            "16",
            "--out",
            arg(&png),
        ];
        args.extend(extra);
        let out = rbvh(&args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        common::ensure(!out.status.success(), || format!("{args:?} succeeded"))?;
        common::ensure(out.status.code() != Some(101), || {
            format!("{args:?} panicked:\n{stderr}")
        })?;
        common::ensure(stderr.contains(needle), || {
            format!("{args:?}: {needle:?} not in:\n{stderr}")
        })?;
        common::ensure(!png.exists(), || {
            format!("{args:?} wrote {}", png.display())
        })
    });
}

#[test]
fn rbvh_addressing_forces_device_addresses_and_refuses_what_it_does_not_know() {
    let dir = tempfile::tempdir().unwrap();
    let render = |value: &str, name: &str| {
        let png = dir.path().join(name);
        let out = Command::new(env!("CARGO_BIN_EXE_rbvh"))
            .args(["render", "--scene", "cube", "--method", "rbvh"])
            .args(["--width", "48", "--height", "32", "--out", arg(&png)])
            .env("RBVH_VALIDATION", "auto")
            .env("RBVH_ADDRESSING", value)
            .output()
            .expect("run rbvh");
        (out, png)
    };
    let (bound, bound_png) = render("bindings", "b.png");
    let (addressed, addressed_png) = render("device", "d.png");
    assert!(bound.status.success() && addressed.status.success());
    assert_eq!(
        std::fs::read(&bound_png).unwrap(),
        std::fs::read(&addressed_png).unwrap(),
        "the same image either way"
    );
    let (bad, bad_png) = render("sideways", "x.png");
    let stderr = String::from_utf8_lossy(&bad.stderr);
    assert!(!bad.status.success());
    assert!(
        stderr.contains("RBVH_ADDRESSING") && stderr.contains("sideways"),
        "{stderr}"
    );
    assert!(!bad_png.exists());
    // A misspelt request for the validation layer is an error, not the layer off.
    let out = Command::new(env!("CARGO_BIN_EXE_rbvh"))
        .args(["render", "--scene", "cube", "--width", "8", "--height", "8"])
        .args(["--out", arg(&bad_png)])
        .env("RBVH_VALIDATION", "requried")
        .output()
        .expect("run rbvh");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("RBVH_VALIDATION"),
        "{stderr}"
    );
    assert!(!bad_png.exists());
}

/// A bench whose hits are wrong fails after reporting, unless told to allow it.
#[test]
fn bench_exits_non_zero_on_an_invalid_measurement() {
    let coarse = [
        "bench",
        "--scene",
        "sphere",
        "--quality",
        "2",
        "--texels-per-diagonal",
        "12",
        "--rays",
        "primary",
        "--width",
        "32",
        "--height",
        "32",
        "--runs",
        "1",
    ];
    let out = rbvh(&coarse);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(stderr.contains("INVALID (--allow-invalid"), "{stderr}");
    // The table is printed all the same.
    assert!(String::from_utf8_lossy(&out.stdout).contains("custom"));
    let out = rbvh(&[&coarse[..], &["--allow-invalid"]].concat());
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Each command shows the flags it uses: `paint` (an RBVH, never level of detail or another
/// structure) shows no --method or level-of-detail flags, and the commands that trace one level
/// say so.
#[test]
fn commands_show_only_the_flags_they_use() {
    let help = |command: &str| {
        let out = rbvh(&[command, "--help"]);
        assert!(out.status.success());
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let paint = help("paint");
    for flag in ["--method", "--lod-bias", "--lod-columns"] {
        assert!(
            !paint.lines().any(|l| l.trim_start().starts_with(flag)),
            "paint shows {flag}:\n{paint}"
        );
    }
    assert!(paint.contains("--strokes") && paint.contains("--quality"));
    for method in ["exact", "rbvh-lod"] {
        let out = rbvh(&[
            "paint",
            "--method",
            method,
            "--strokes",
            "s.txt",
            "--out",
            "o.rbvh",
        ]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && err.contains("takes rbvh alone"),
            "{err}"
        );
    }
    for command in ["render", "trace", "paint"] {
        assert!(help(command).contains("one of 0..4"), "{command}");
    }
    assert!(help("bench").contains("comma-separated"));
}

/// --camera-eye/--camera-target/--vfov place the camera of a scene without one (or replace
/// it), refused with the scene file's reasons when they cannot make rays.
#[test]
fn camera_flags_place_the_camera() {
    let dir = tempfile::tempdir().unwrap();
    let (framed, placed) = (dir.path().join("f.png"), dir.path().join("p.png"));
    let render = |extra: &[&str], out: &Path| {
        let mut args = vec![
            "render", "--scene", "sphere", "--width", "32", "--height", "24",
        ];
        args.extend(extra);
        args.extend(["--out", arg(out)]);
        rbvh(&args)
    };
    assert!(render(&[], &framed).status.success());
    let out = render(
        &[
            "--camera-eye",
            "0,0,4",
            "--camera-target",
            "0,0,0",
            "--vfov",
            "30",
        ],
        &placed,
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (a, b) = (image::open(&framed).unwrap(), image::open(&placed).unwrap());
    assert_ne!(
        a.to_rgb8().into_raw(),
        b.to_rgb8().into_raw(),
        "the camera moved nothing"
    );
    for (extra, needle) in [
        (
            &["--camera-eye", "0,0,4", "--camera-target", "0,0,4"][..],
            "must differ",
        ),
        (
            &["--camera-eye", "0,3,0", "--camera-target", "0,0,0"][..],
            "`up`",
        ),
        (
            &["--camera-eye", "0,0,4", "--camera-target", "0,0"][..],
            "three numbers",
        ),
        (&["--camera-eye", "0,0,4"][..], "--camera-target"),
        (
            &[
                "--camera-eye",
                "0,0,4",
                "--camera-target",
                "0,0,0",
                "--vfov",
                "0",
            ][..],
            "vfov",
        ),
    ] {
        let out = render(extra, &dir.path().join("never.png"));
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && stderr.contains(needle),
            "{extra:?}: {stderr}"
        );
    }
}

/// A point cloud is a scene of its own: rendered and built through an RBVH of its points, refused
/// by the exact BVH with the flag to use; `--points` builds a mesh's RBVH from points sampled on
/// it, and `bench --points` measures them against the exact BVH of the mesh.
#[test]
fn point_clouds_render_build_and_bench() {
    /// Runs `args`, which must succeed; its stdout and stderr.
    fn succeeds(args: &[&str]) -> (String, String) {
        let out = rbvh(args);
        let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
        assert!(out.status.success(), "{args:?}: {stderr}");
        (String::from_utf8_lossy(&out.stdout).into_owned(), stderr)
    }
    /// Runs `args`, which must fail saying each of `says` on stderr.
    fn fails(args: &[&str], says: &[&str]) {
        let out = rbvh(args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && says.iter().all(|s| stderr.contains(s)),
            "{args:?}: {stderr}"
        );
    }
    let dir = tempfile::tempdir().unwrap();
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/points");
    let (ply, xyz) = (data.join("sphere.ply"), data.join("plane.xyz"));
    let png = dir.path().join("points.png");
    let small = ["--width", "32", "--height", "32"];

    let render = [
        &[
            "render",
            "--scene",
            arg(&ply),
            "--method",
            "rbvh",
            "--quality",
            "0",
        ][..],
        &small,
        &["--out", arg(&png), "--stats"],
    ]
    .concat();
    let (_, stderr) = succeeds(&render);
    assert!(stderr.contains("200 points"), "{stderr}");
    assert!(stderr.contains("no exact BVH to compare with"), "{stderr}");
    assert!(png.exists());
    fails(
        &["render", "--scene", arg(&ply), "--out", arg(&png)],
        &["point cloud", "--method rbvh"],
    );

    let (stdout, _) = succeeds(&[
        "build",
        "--scene",
        "sphere",
        "--points",
        "20000",
        "--quality",
        "1",
    ]);
    assert!(stdout.contains("built from 20000 points"), "{stdout}");
    assert!(stdout.contains(" Q1 "), "{stdout}");
    // A scene with instances: its points are sampled over it flattened, and no two-level line
    // of its meshes' triangles stands beside them.
    let (stdout, _) = succeeds(&[
        "build",
        "--scene",
        "grove-instanced",
        "--points",
        "5000",
        "--quality",
        "0",
    ]);
    assert!(stdout.contains("built from 5000 points"), "{stdout}");
    assert!(!stdout.contains("two-level"), "{stdout}");
    let bench = [
        &[
            "bench",
            "--scene",
            "sphere",
            "--points",
            "20000",
            "--quality",
            "0",
        ][..],
        &small,
        &["--rays", "primary", "--runs", "1"],
    ]
    .concat();
    let (stdout, _) = succeeds(&bench);
    assert!(stdout.contains("sphere (20000 points)"), "{stdout}");

    // A point RBVH saved and loaded back with its cloud (its splats reach past the points).
    let saved = dir.path().join("plane.rbvh");
    succeeds(&[
        "build",
        "--scene",
        arg(&xyz),
        "--quality",
        "0",
        "--out",
        arg(&saved),
    ]);
    succeeds(
        &[
            &[
                "render",
                "--scene",
                arg(&xyz),
                "--rbvh",
                arg(&saved),
                "--out",
                arg(&png),
            ][..],
            &small,
        ]
        .concat(),
    );

    // Painting a point RBVH: the dab lands in its colour channel, saved with it.
    let strokes = dir.path().join("s.txt");
    std::fs::write(&strokes, "dab 0.5 0.5 0.1 #ff0000\n").unwrap();
    let painted = dir.path().join("painted.rbvh");
    let paint = [
        &[
            "paint",
            "--scene",
            arg(&ply),
            "--quality",
            "0",
            "--strokes",
            arg(&strokes),
        ][..],
        &["--out", arg(&painted)],
        &small,
    ]
    .concat();
    succeeds(&paint);
    let colours = rbvh::rbvh::Rbvh::load(&painted).unwrap().colours.unwrap();
    assert!(colours.contains(&0xFF00_00FF));

    // A scan of the same object from a file is refereed by the mesh.
    let (stdout, _) = succeeds(&[
        "build",
        "--scene",
        "sphere",
        "--points",
        arg(&ply),
        "--quality",
        "0",
    ]);
    assert!(stdout.contains("built from 200 points"), "{stdout}");

    // What points cannot mean is refused, saying why.
    fails(
        &["build", "--scene", "sphere", "--points", "0"],
        &["--points"],
    );
    fails(
        &[
            "render",
            "--scene",
            "sphere",
            "--points",
            "100",
            "--out",
            arg(&png),
        ],
        &["--method rbvh"],
    );
    fails(
        &["build", "--scene", arg(&ply), "--points", "100"],
        &["points are added to a mesh"],
    );
    fails(
        &[
            "bench",
            "--scene",
            arg(&ply),
            "--rays",
            "primary",
            "--runs",
            "1",
        ],
        &["--points SCAN"],
    );
    fails(
        &["build", "--scene", "plane", "--points", arg(&ply)],
        &["sphere.ply", "must cover the mesh"],
    );
}

/// `rbvh shaders` compiles every pipeline on the default device and writes them, with the host,
/// as JSON; `--wave32` needs `--amd`, and `--amd` refuses a family name that is no name.
#[test]
fn shaders_lists_every_pipeline_with_its_host() {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("shaders.json");
    let out = rbvh(&["shaders", "--json", arg(&json)]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let table = String::from_utf8_lossy(&out.stdout);
    assert!(table.starts_with("host: "), "{table}");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let pipelines = report["pipelines"].as_array().unwrap();
    for p in pipelines {
        assert!(table.contains(p["pipeline"].as_str().unwrap()), "{table}");
    }
    for shader in ["trace_exact", "trace_rbvh", "trace_rbvh_lod", "paint"] {
        assert!(pipelines.iter().any(|p| p["shader"] == shader), "{shader}");
    }
    assert!(report["host"].is_object() && report["date"].is_string());
    assert_eq!(report["compile_only"], false);
    let wave32 = rbvh(&["shaders", "--wave32"]);
    assert!(!wave32.status.success());
    let bad = rbvh(&["shaders", "--amd", "navi 21"]);
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("navi21"));
}

/// `rbvh tables` writes a block's table from its results file; `--check` fails on a table edited
/// by hand, and on a table of figures outside any block.
#[test]
fn tables_are_written_from_results_files_and_checked() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    std::fs::create_dir_all(root.join("docs/results")).unwrap();
    std::fs::write(
        root.join("docs/results/t.json"),
        r#"{"transcribed": {"source": "a test", "commit": "abc1234", "host": "a host",
            "device": "a device"}, "columns": ["level", "MB"], "align": ["l", "r"],
            "rows": [["Q0", "1.5"]]}"#,
    )
    .unwrap();
    let doc = root.join("docs/x.md");
    std::fs::write(
        &doc,
        "# x\n\n<!-- table docs/results/t.json -->\n<!-- /table -->\n",
    )
    .unwrap();
    let check = |root: &Path| rbvh(&["tables", "--check", "--root", arg(root)]);
    assert!(
        !check(root).status.success(),
        "an empty block is not its table"
    );
    let out = rbvh(&["tables", "--root", arg(root)]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let written = std::fs::read_to_string(&doc).unwrap();
    assert!(
        written.contains("| level | MB |\n|---|---:|\n| Q0 | 1.5 |\n"),
        "{written}"
    );
    assert!(
        written.contains("measured at abc1234; host: a host; device: a device"),
        "{written}"
    );
    assert!(written.contains("[results](results/t.json)"), "{written}");
    assert!(check(root).status.success());
    std::fs::write(&doc, written.replace("| Q0 | 1.5 |", "| Q0 | 1.4 |")).unwrap();
    let edited = check(root);
    assert!(!edited.status.success());
    assert!(String::from_utf8_lossy(&edited.stderr).contains("docs/x.md:3"));
    std::fs::write(
        &doc,
        format!("{written}\n| a | b |\n|---|---|\n| 1 | 2 |\n"),
    )
    .unwrap();
    let typed = check(root);
    assert!(!typed.status.success());
    assert!(String::from_utf8_lossy(&typed.stderr).contains("typed by hand"));
}

/// Under `RADV_FORCE_FAMILY` Mesa offers RADV's null device, which compiles but cannot run: a
/// render picks a device that runs instead (it used to pick the null device and crash), and one
/// that names the null device fails with an error saying why.
#[test]
fn a_render_never_runs_on_a_null_device() {
    if !common::radv_or_skip() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("r.png");
    let render = |extra: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_rbvh"))
            .args([
                "render",
                "--width",
                "16",
                "--height",
                "12",
                "--out",
                arg(&png),
            ])
            .args(extra)
            .env("RADV_FORCE_FAMILY", "navi21")
            .env("MESA_SHADER_CACHE_DISABLE", "true")
            .env("RBVH_VALIDATION", "auto")
            .env_remove("RBVH_DEVICE")
            .output()
            .unwrap()
    };
    let out = render(&[]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(png.exists());
    std::fs::remove_file(&png).unwrap();
    let named = render(&["--device", "RADV"]);
    assert_eq!(named.status.code(), Some(1), "an error, not a crash");
    let stderr = String::from_utf8_lossy(&named.stderr);
    assert!(
        stderr.contains("compiles pipelines but cannot run them"),
        "{stderr}"
    );
    assert!(!png.exists(), "nothing written");
}

/// `bench --threads` sets lavapipe's worker threads, which no other driver reads: on RADV's null
/// device (another device, with no GPU needed) it is refused, naming the device, before any work.
#[test]
fn bench_threads_are_refused_where_lavapipe_does_not_run() {
    if !common::radv_or_skip() {
        return;
    }
    let out = Command::new(env!("CARGO_BIN_EXE_rbvh"))
        .args([
            "bench",
            "--threads",
            "2",
            "--device",
            "RADV",
            "--scene",
            "sphere",
        ])
        .args([
            "--quality",
            "0",
            "--rays",
            "primary",
            "--width",
            "8",
            "--height",
            "8",
        ])
        .env("RADV_FORCE_FAMILY", "navi21")
        .env("MESA_SHADER_CACHE_DISABLE", "true")
        .env("RBVH_VALIDATION", "auto")
        .env_remove("RBVH_DEVICE")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1), "an error, not a crash");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("--threads sets lavapipe's worker threads") && stderr.contains("RADV"),
        "{stderr}"
    );
}

/// Every flag does what its help says or is refused, naming itself and why: a flag that would
/// have no effect in a combination (an RBVH's build parameters where none is built, a camera for
/// rays from a file, a tolerance while blessing, ...) is an error there, before any work.
#[test]
fn flags_without_effect_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("never.png");
    let file = dir.path().join("never.rbvh");
    let (rays, hits) = (dir.path().join("r.bin"), dir.path().join("h.bin"));
    let (png, file, rays, hits) = (arg(&png), arg(&file), arg(&rays), arg(&hits));
    let render = |extra: &[&'static str]| -> Vec<String> {
        let mut args = vec!["render", "--width", "8", "--height", "8", "--out", png];
        args.extend(extra);
        args.into_iter().map(String::from).collect()
    };
    let trace = |extra: &[&'static str]| -> Vec<String> {
        let mut args = vec!["trace", "--scene", "sphere", "--rays", rays, "--hits", hits];
        args.extend(extra);
        args.into_iter().map(String::from).collect()
    };
    let paint = |extra: &[&'static str]| -> Vec<String> {
        let mut args = vec!["paint", "--strokes", "s.txt", "--out", file];
        args.extend(extra);
        args.into_iter().map(String::from).collect()
    };
    let with_file = |mut args: Vec<String>, extra: &[&str]| -> Vec<String> {
        args.extend(["--rbvh".to_string(), file.to_string()]);
        args.extend(extra.iter().map(|s| s.to_string()));
        args
    };
    let words = |args: &[&str]| -> Vec<String> { args.iter().map(|s| s.to_string()).collect() };
    let not_given = "required arguments were not provided";
    let cases: Vec<(Vec<String>, Vec<&str>)> = vec![
        // An RBVH's build parameters where the exact BVH is traced.
        (
            render(&["--quality", "3"]),
            vec!["--quality says how to build an RBVH", "--method exact"],
        ),
        (
            render(&["--method", "exact", "--texels-per-diagonal", "64"]),
            vec!["--texels-per-diagonal", "--method rbvh"],
        ),
        (
            render(&["--sample-all"]),
            vec!["--sample-all", "--method exact"],
        ),
        (
            trace(&["--max-tile", "8"]),
            vec!["--max-tile", "--method exact"],
        ),
        (
            trace(&["--texels", "height"]),
            vec!["--texels", "--method exact"],
        ),
        // Level of detail needs normals in the texels.
        (
            words(&[
                "bench",
                "--texels",
                "height",
                "--method",
                "exact,rbvh,rbvh-lod",
                "--quality",
                "0",
            ]),
            vec![
                "--method rbvh-lod measures levels with normals",
                "--texels height",
            ],
        ),
        // Named as the user types it, not as the field it fills.
        (
            render(&["--exact-crease", "20"]),
            vec!["--exact-crease says how to build an RBVH", "--method exact"],
        ),
        // ... and where a saved RBVH is loaded, built already.
        (
            with_file(render(&["--method", "rbvh"]), &["--quality", "1"]),
            vec!["--quality", "--rbvh loads one built already"],
        ),
        (
            with_file(trace(&[]), &["--split", "sah"]),
            vec!["--split", "--rbvh loads one built already"],
        ),
        (
            with_file(paint(&[]), &["--object-rate", "0.5"]),
            vec!["--object-rate", "--rbvh loads one built already"],
        ),
        (
            with_file(render(&["--method", "exact"]), &[]),
            vec!["--method exact", "--rbvh"],
        ),
        // Flags of level of detail and of other outputs, without them.
        (
            render(&["--lod-bias", "0"]),
            vec!["--lod-bias says how levels of detail", "--method rbvh-lod"],
        ),
        (
            trace(&["--method", "rbvh", "--lod-spread", "0.1"]),
            vec!["--lod-spread is the rays' footprint", "--method rbvh-lod"],
        ),
        (
            render(&["--method", "rbvh-lod", "--lod-spread", "0.1"]),
            vec!["unexpected argument '--lod-spread'"],
        ),
        (
            render(&["--method", "exact,rbvh"]),
            vec!["--method: this command traces one structure"],
        ),
        (
            render(&["--heatmap-max", "9"]),
            vec![not_given, "--heatmap"],
        ),
        (render(&["--vfov", "30"]), vec![not_given, "--camera-eye"]),
        // Rays from a file have no camera, and the CPU tracer no device.
        (
            trace(&["--camera-eye", "0,0,4", "--camera-target", "0,0,0"]),
            vec!["unexpected argument '--camera-eye'"],
        ),
        (
            trace(&["--vfov", "30"]),
            vec!["unexpected argument '--vfov'"],
        ),
        (
            trace(&["--cpu", "--device", "llvmpipe"]),
            vec!["'--cpu' cannot be used with '--device"],
        ),
        (
            trace(&["--cpu", "--validate"]),
            vec!["'--cpu' cannot be used with '--validate'"],
        ),
        // Paint samples everything it builds, into a colour channel a height-only RBVH lacks.
        (
            paint(&["--sample-all"]),
            vec!["--sample-all: paint samples"],
        ),
        (
            paint(&["--texels", "height"]),
            vec!["--texels height", "no colours to paint"],
        ),
        (
            paint(&["--method", "exact"]),
            vec!["--method: paint paints an RBVH's texels"],
        ),
        // build prints its table anyway without --out.
        (
            words(&["build", "--scene", "sphere", "--stats"]),
            vec![not_given, "--out"],
        ),
        // bench: the AO radius without AO rays, a seed with nothing random to draw.
        (
            words(&["bench", "--rays", "primary,shadow", "--ao-radius", "0.1"]),
            vec!["--ao-radius", "add ao to --rays"],
        ),
        (
            words(&[
                "bench",
                "--rays",
                "primary",
                "--seam-rays",
                "0",
                "--seed",
                "3",
            ]),
            vec!["--seed draws", "has none of them"],
        ),
        // paint samples every triangle: the rules for tracing some exactly have none to choose.
        (
            paint(&["--exact-crease", "45"]),
            vec!["--exact-crease: paint samples every triangle"],
        ),
        (
            paint(&["--exact-from-texels", "2"]),
            vec!["--exact-from-texels: paint samples every triangle"],
        ),
        (
            paint(&["--exact-edge-fraction", "0.01"]),
            vec!["--exact-edge-fraction: paint samples every triangle"],
        ),
        // build: a comparison of flat RBVHs where the scene is saved in two levels.
        (
            words(&[
                "build",
                "--scene",
                "grove-instanced",
                "--out",
                file,
                "--compare-splits",
            ]),
            vec!["--compare-splits compares flat RBVHs", "--instances flat"],
        ),
        (
            words(&[
                "build",
                "--scene",
                "grove-instanced",
                "--out",
                file,
                "--timings",
            ]),
            vec!["--timings times flat builds", "--instances flat"],
        ),
        // bench: steps are counted for flat structures; levels of detail are built over one.
        (
            words(&["bench", "--instances", "two-level", "--steps"]),
            vec!["--steps: where steps go", "--instances auto or flat"],
        ),
        (
            words(&[
                "bench",
                "--method",
                "rbvh,rbvh-lod",
                "--instances",
                "two-level",
            ]),
            vec![
                "--method rbvh-lod: levels of detail",
                "measure rbvh instead",
            ],
        ),
        // bench: RBVHs beside the exact BVH, seams and height-only levels of the plain levels.
        (
            words(&["bench", "--method", "exact"]),
            vec!["--method exact: bench measures RBVHs beside the exact BVH"],
        ),
        (
            words(&["bench", "--method", "exact,rbvh-lod", "--seam-rays", "5"]),
            vec!["--seam-rays aims at the seams", "add rbvh to --method"],
        ),
        (
            words(&[
                "bench",
                "--method",
                "rbvh-lod",
                "--texels",
                "normals,height",
            ]),
            vec!["--texels height builds levels only --method rbvh measures"],
        ),
        (
            words(&[
                "bench",
                "--method",
                "exact,rbvh-lod",
                "--rays",
                "primary",
                "--seed",
                "3",
            ]),
            vec!["--seed draws", "has none of them"],
        ),
        (
            words(&["bench", "--lod-columns", "8"]),
            vec![
                "--lod-columns says how levels of detail",
                "--method rbvh-lod",
            ],
        ),
        // regress: levels without an RBVH method, tolerances while blessing.
        (
            words(&["regress", "--method", "exact", "--quality", "2"]),
            vec!["--quality says how to build an RBVH", "--method rbvh"],
        ),
        (
            words(&["regress", "--texels-per-diagonal", "300"]),
            vec!["--texels-per-diagonal: regress compares the presets"],
        ),
        (
            words(&["regress", "--lod-bias", "0"]),
            vec!["--lod-bias: regress compares the presets"],
        ),
        (
            words(&["regress", "--bless", "--max-flip-mean", "0.1"]),
            vec!["'--bless' cannot be used with '--max-flip-mean"],
        ),
        (
            words(&["regress", "--bless", "--depth-tolerance", "0.1"]),
            vec!["'--bless' cannot be used with '--depth-tolerance"],
        ),
        (
            words(&["regress", "--bless", "--out", "elsewhere"]),
            vec!["'--bless' cannot be used with '--out"],
        ),
        // shaders: wave32 is AMD's, and --amd picks the device.
        (words(&["shaders", "--wave32"]), vec![not_given, "--amd"]),
        (
            words(&["shaders", "--amd", "navi21", "--device", "x"]),
            vec!["cannot be used with"],
        ),
        // compare: its RBVH's parameters are the file's; never the exact BVH beside itself.
        (
            words(&["compare", "--rbvh", file, "--max-angle", "30"]),
            vec!["--max-angle", "--rbvh loads one built already"],
        ),
        (
            words(&["compare", "--method", "exact"]),
            vec!["--method exact: compare sets an RBVH beside the exact BVH"],
        ),
    ];
    common::every_case(cases, |(args, needles)| {
        let out = rbvh(&args.iter().map(String::as_str).collect::<Vec<_>>());
        let stderr = String::from_utf8_lossy(&out.stderr);
        common::ensure(!out.status.success(), || format!("{args:?} succeeded"))?;
        common::ensure(out.status.code() != Some(101), || {
            format!("{args:?} panicked:\n{stderr}")
        })?;
        for needle in needles {
            common::ensure(stderr.contains(needle), || {
                format!("{args:?}: {needle:?} not in:\n{stderr}")
            })?;
        }
        common::ensure(
            std::fs::read_dir(dir.path()).unwrap().next().is_none(),
            || format!("{args:?} wrote a file"),
        )
    });
}

/// The help of each command says what it takes: the commands that trace one RBVH offer one
/// texel format (build and bench both), paint's mentions no --method, and trace's no camera.
#[test]
fn help_says_what_each_command_takes() {
    let help = |command: &str| {
        let out = rbvh(&[command, "--help"]);
        assert!(out.status.success(), "{command}");
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    for command in ["render", "trace", "paint", "compare"] {
        let text = help(command);
        assert!(!text.contains("comma-separate both"), "{command}:\n{text}");
        let shows = |flag: &str| text.lines().any(|l| l.trim_start().starts_with(flag));
        assert_eq!(shows("--lod-spread"), command == "trace", "{command}");
    }
    for command in ["build", "bench"] {
        assert!(help(command).contains("comma-separate both"), "{command}");
    }
    let paint = help("paint");
    assert!(!paint.contains("--method"), "{paint}");
    for flag in [
        "--sample-all",
        "--exact-from-texels",
        "--exact-edge-fraction",
        "--exact-crease",
    ] {
        assert!(
            !paint.lines().any(|l| l.trim_start().starts_with(flag)),
            "{flag}: {paint}"
        );
    }
    assert!(paint.contains("`auto` and `flat` alike"), "{paint}");
    let trace = help("trace");
    for flag in ["--camera-eye", "--camera-target", "--vfov"] {
        assert!(!trace.contains(flag), "{trace}");
    }
}

/// A ray file in `dir` of `n` rays at the built-in sphere from 3 units away, and where its hits
/// go.
fn rays_at_the_sphere(dir: &Path, n: usize) -> (std::path::PathBuf, std::path::PathBuf) {
    let (rays, hits) = (dir.join("r.bin"), dir.join("h.bin"));
    let ray = Ray::new(
        glam::Vec3::new(0.0, 0.0, -3.0),
        glam::Vec3::Z,
        0.0,
        f32::INFINITY,
    );
    io::write_rays(&rays, &vec![ray; n]).unwrap();
    (rays, hits)
}

/// `trace --cpu --stats` reports the CPU tracer's time and rate (it used to print nothing).
#[test]
fn trace_cpu_stats_reports_the_cpu_trace() {
    let dir = tempfile::tempdir().unwrap();
    let (rays_path, hits_path) = rays_at_the_sphere(dir.path(), 64);
    let out = rbvh(&[
        "trace",
        "--scene",
        "sphere",
        "--cpu",
        "--stats",
        "--rays",
        arg(&rays_path),
        "--hits",
        arg(&hits_path),
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains("trace (CPU reference, exact BVH): 64 rays") && stderr.contains("MRays/s"),
        "{stderr}"
    );
    assert_eq!(io::read_hits(&hits_path).unwrap().len(), 64);
}

/// `trace --cpu` opens no Vulkan device: it traces where the loader finds no driver at all, where
/// the GPU trace says it could not create the device.
#[test]
fn trace_cpu_needs_no_vulkan_driver() {
    let dir = tempfile::tempdir().unwrap();
    let (rays_path, hits_path) = rays_at_the_sphere(dir.path(), 8);
    let no_driver = dir.path().join("no-driver.json");
    let run = |extra: &[&str]| {
        let mut args = vec![
            "trace",
            "--scene",
            "sphere",
            "--method",
            "rbvh",
            "--quality",
            "0",
            "--stats",
            "--rays",
            arg(&rays_path),
            "--hits",
            arg(&hits_path),
        ];
        args.extend(extra);
        Command::new(env!("CARGO_BIN_EXE_rbvh"))
            .args(&args)
            .env("VK_ICD_FILENAMES", &no_driver)
            .env("VK_DRIVER_FILES", &no_driver)
            .env("RBVH_VALIDATION", "off")
            .output()
            .expect("run rbvh")
    };
    let out = run(&["--cpu"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("trace (CPU reference, RBVH"), "{stderr}");
    let hits = io::read_hits(&hits_path).unwrap();
    assert!(
        hits.len() == 8 && hits.iter().all(|h| h.is_hit()),
        "{hits:?}"
    );
    let out = run(&[]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("creating the Vulkan device"),
        "{stderr}"
    );
}

/// `rbvh compare` renders the scene through the exact BVH and an RBVH into one PNG, side by side,
/// and prints each one's memory, speed and error.
#[test]
fn compare_puts_the_exact_bvh_and_an_rbvh_side_by_side() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("c.png");
    let out = rbvh(&[
        "compare",
        "--scene",
        "blob",
        "--quality",
        "1",
        "--width",
        "40",
        "--height",
        "30",
        "--samples",
        "2",
        "--out",
        arg(&png),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let img = image::open(&png).unwrap();
    assert_eq!((img.width(), img.height()), (80, 30));
    for name in ["exact BVH", "RBVH Q1"] {
        let line = stdout
            .lines()
            .find(|l| l.starts_with(name))
            .unwrap_or_else(|| panic!("no {name} line in:\n{stdout}"));
        for needle in ["memory", " MB", "speed", "MRays/s", "FLIP"] {
            assert!(line.contains(needle), "{needle:?} not in {line:?}");
        }
    }
    assert!(
        stdout.contains("x smaller") && stdout.contains("PSNR") && stdout.contains("hit/miss"),
        "{stdout}"
    );
    // The same with level of detail, its coarse columns counted with the RBVH's memory.
    let out = rbvh(&[
        "compare",
        "--scene",
        "blob",
        "--method",
        "rbvh-lod",
        "--quality",
        "1",
        "--width",
        "40",
        "--height",
        "30",
        "--samples",
        "2",
        "--out",
        arg(&png),
    ]);
    let lod_stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        lod_stdout
            .lines()
            .any(|l| l.starts_with("RBVH Q1 with LOD") && l.contains("FLIP")),
        "{lod_stdout}"
    );
    // The flags of a render that compare takes are checked as render checks them.
    for (args, needle) in [
        (&["--samples", "0"][..], "--samples"),
        (&["--width", "9000"][..], "--width"),
        (&["--out", "c.jpg"][..], "writes PNG"),
    ] {
        let out = rbvh(&[&["compare"], args].concat());
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && stderr.contains(needle),
            "{args:?}: {stderr}"
        );
    }
}

/// A scene that places a mesh more than once is traced in two levels by default, and renders as
/// its flat copy does (the exact path bit for bit); `--instances` chooses, and what only a flat
/// scene has (levels of detail, painting) refuses two levels by name.
#[test]
fn scenes_of_instances_render_in_two_levels() {
    let dir = tempfile::tempdir().unwrap();
    let png = |name: &str| dir.path().join(name);
    let render = |out: &Path, extra: &[&str]| {
        let mut args = vec![
            "render",
            "--scene",
            "grove-instanced",
            "--width",
            "64",
            "--height",
            "48",
            "--stats",
            "--out",
            arg(out),
        ];
        args.extend_from_slice(extra);
        let out = rbvh(&args);
        let stderr = String::from_utf8_lossy(&out.stderr).to_string();
        assert!(out.status.success(), "{extra:?}: {stderr}");
        stderr
    };
    let two = render(&png("two.png"), &[]);
    assert!(
        two.contains("401 instances of 2 meshes") && two.contains("two-level exact BVH:"),
        "{two}"
    );
    let flat = render(&png("flat.png"), &["--instances", "flat"]);
    assert!(!flat.contains("two-level"), "{flat}");
    assert_eq!(
        image::open(png("two.png")).unwrap().to_rgba8(),
        image::open(png("flat.png")).unwrap().to_rgba8()
    );
    let rbvh_two = render(&png("rbvh.png"), &["--method", "rbvh"]);
    assert!(
        rbvh_two.contains("two-level RBVH:")
            && rbvh_two.contains("two-level exact BVH on the same rays"),
        "{rbvh_two}"
    );
    // Saved, the two-level RBVH (every mesh once, and its placements) renders as built; a flat
    // scene refuses it.
    let file = dir.path().join("grove.rbvh");
    let out = rbvh(&["build", "--scene", "grove-instanced", "--out", arg(&file)]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success() && stderr.contains("a two-level RBVH: 2 meshes, 401 instances"),
        "{stderr}"
    );
    let loaded = render(&png("loaded.png"), &["--rbvh", arg(&file)]);
    assert!(loaded.contains("two-level RBVH:"), "{loaded}");
    assert_eq!(
        image::open(png("loaded.png")).unwrap().to_rgba8(),
        image::open(png("rbvh.png")).unwrap().to_rgba8()
    );
    let out = rbvh(&["render", "--scene", "grove", "--rbvh", arg(&file)]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("built for another scene"),
        "{stderr}"
    );
    // Levels of detail are flat: auto gives them the flat scene, two-level is refused.
    render(&png("lod.png"), &["--method", "rbvh-lod"]);
    for (args, refused) in [
        (&["render", "--method", "rbvh-lod"][..], png("refused.png")),
        (
            &["paint", "--method", "rbvh", "--strokes", "none.json"][..],
            png("refused.rbvh"),
        ),
    ] {
        let mut args = args.to_vec();
        args.extend(["--scene", "grove-instanced", "--instances", "two-level"]);
        args.extend(["--out", arg(&refused)]);
        let out = rbvh(&args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?}");
        assert!(
            stderr.contains("--instances two-level"),
            "{args:?}: {stderr}"
        );
        assert!(!refused.exists());
    }
}

/// `rbvh build --timings` names each step of each build with its wall time, in order, each once:
/// the shared steps at the first level only; and the steps' times add up to the build's.
#[test]
fn build_timings_name_each_step_within_the_build() {
    let out = rbvh(&[
        "build",
        "--scene",
        "sphere",
        "--quality",
        "0,2",
        "--timings",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    let took: Vec<&str> = stdout.lines().filter(|l| l.contains(" took ")).collect();
    assert_eq!(took.len(), 3, "the exact BVH and two levels:\n{stdout}");
    let level = [
        "building the RBVH (triangles into leaves)",
        "building the tree over the leaves",
        "packing the atlas",
    ];
    let first: Vec<&str> = [
        "finding the scene's connected parts",
        "building the BVH the rings are sampled by",
        "finding the scene's open edges and creases",
    ]
    .into_iter()
    .chain(level)
    .collect();
    for (line, label, steps) in [
        (
            took[0],
            "exact BVH",
            vec!["building the exact BVH (triangles)"],
        ),
        (took[1], "Q0", first),
        (took[2], "Q2", level.to_vec()),
    ] {
        let (head, listed) = line.split_once(": ").unwrap();
        assert_eq!(
            head.trim_start().split(" took ").next(),
            Some(label),
            "{line}"
        );
        let ms = |s: &str| -> f64 { s.split(' ').next().unwrap().parse().unwrap() };
        let parts: Vec<&str> = listed.split("; ").collect();
        let names: Vec<&str> = parts
            .iter()
            .map(|p| p.split_once(" ms ").unwrap().1)
            .collect();
        let mut expected = steps.clone();
        expected.push("between them");
        assert_eq!(names, expected, "{line}");
        // Each printed figure is rounded to the millisecond.
        let total = ms(head.rsplit(" took ").next().unwrap());
        let sum: f64 = parts.iter().map(|p| ms(p)).sum();
        assert!((sum - total).abs() <= parts.len() as f64, "{line}");
    }
}

/// **Misuse the tool once answered with an abort, a panic or a field's name**: an AMD family
/// that RADV does not know (RADV aborted the process), the library's limits on bench and regress
/// parameters (told as `min_run_ms`, `flip_mean`), and a reader of the output that goes away
/// (`| head`: `println!` panicked).
#[test]
fn misuse_is_told_by_its_flag_and_never_aborts() {
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&[&str], &str); 4] = [
        (
            &["shaders", "--amd", "navi99"],
            "--amd \"navi99\": not a family RADV knows",
        ),
        (
            &["bench", "--scene", "sphere", "--min-run-ms", "-1"],
            "--min-run-ms: -1 is outside",
        ),
        (
            &["bench", "--scene", "sphere", "--ao-radius", "0"],
            "--ao-radius: 0 is not",
        ),
        (
            &["regress", "--out", arg(dir.path()), "--max-flip-mean", "2"],
            "--max-flip-mean: 2 is outside",
        ),
    ];
    for (args, needle) in cases {
        let out = rbvh(args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}:\n{stderr}");
        assert!(
            stderr.contains(needle),
            "{args:?}: {needle:?} not in\n{stderr}"
        );
    }
    // Its reader gone before it writes a line: ended by SIGPIPE, as Unix tools are, not by a
    // panic (exit 101).
    let write_end = {
        use std::os::fd::FromRawFd;
        let mut fds = [0; 2];
        // SAFETY: `fds` has room for the two descriptors the call makes.
        assert_eq!(unsafe { libc::pipe(fds.as_mut_ptr()) }, 0);
        // SAFETY: both descriptors were just made, and each is owned by one File alone.
        let (read_end, write_end) = unsafe {
            (
                std::fs::File::from_raw_fd(fds[0]),
                std::fs::File::from_raw_fd(fds[1]),
            )
        };
        drop(read_end);
        write_end
    };
    let out = Command::new(env!("CARGO_BIN_EXE_rbvh"))
        .arg("scenes")
        .stdout(write_end)
        .output()
        .expect("run rbvh");
    let stderr = String::from_utf8_lossy(&out.stderr);
    use std::os::unix::process::ExitStatusExt;
    assert_eq!(out.status.signal(), Some(libc::SIGPIPE), "{stderr}");
}

/// A level named twice (`--quality 0,0`, `all,2`) is built once, as a texel format named twice is.
#[test]
fn a_level_named_twice_is_built_once() {
    let out = rbvh(&["build", "--scene", "sphere", "--quality", "0,q0"]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let rows = stdout
        .lines()
        .filter(|l| l.trim_start().starts_with("Q0 "))
        .count();
    assert_eq!(rows, 1, "{stdout}");
    assert!(stdout.contains("peak host memory so far "), "{stdout}");
    assert!(
        stdout.lines().next().unwrap_or("").ends_with(" MB"),
        "{stdout}"
    );
}

/// A view straight down needs an up other than +y: `--camera-up` gives it, and without it the
/// error names the flag.
#[test]
fn a_view_straight_down_takes_its_up_from_camera_up() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("down.png");
    let down = [
        "render", "--scene", "plane", "--width", "8", "--height", "8",
    ];
    let looking = ["--camera-eye", "0,5,0", "--camera-target", "0,0,0"];
    let out = rbvh(&[&down[..], &looking, &["--out", arg(&png)]].concat());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("--camera-up"),
        "{stderr}"
    );
    let out = rbvh(
        &[
            &down[..],
            &looking,
            &["--camera-up", "0,0,-1", "--out", arg(&png)],
        ]
        .concat(),
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(png.exists());
}

/// A command that traces one structure and is given several says which flag named them.
#[test]
fn one_structure_to_trace_is_asked_of_the_flag_that_named_more() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("never.png");
    for (extra, needle) in [
        (&["--quality", "0,2"][..], "--quality names 2 levels"),
        (
            &["--texels", "normals,height"][..],
            "--texels names two texel formats",
        ),
        (
            &["--heatmap", "h.png", "--heatmap-max", "0"][..],
            "--heatmap-max",
        ),
    ] {
        let mut args = vec!["render", "--method", "rbvh", "--out", arg(&png)];
        args.extend(extra);
        let out = rbvh(&args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && stderr.contains(needle),
            "{args:?}: {stderr}"
        );
        assert!(!png.exists());
    }
}
