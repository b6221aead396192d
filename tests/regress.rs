//! Image regression (`rbvh::regress`): the shipped goldens pass on this device; a deliberately
//! broken RBVH shader fails with an error picture; a missing golden is a failure that says what
//! to do, and blessing creates it.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use rbvh::gpu::Tracer;
use rbvh::regress::{self, Case, Check, Config, Method, Mode};
use rbvh::structure::Structure;

fn shipped_goldens() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(regress::GOLDEN_DIR)
}

#[test]
fn shipped_goldens_pass() {
    let out = tempfile::tempdir().unwrap();
    let report = regress::run(
        &common::context(),
        &Config::new(shipped_goldens(), out.path()),
    )
    .unwrap();
    assert_eq!(
        report.cases.len(),
        regress::SCENES.len() * regress::METHODS.len()
    );
    assert!(
        report.passed(),
        "renders differ from tests/golden (if the change is intended, run `cargo run --release -- regress --bless`):\n{}",
        report.table()
    );
    assert_eq!(
        std::fs::read_dir(out.path()).unwrap().count(),
        0,
        "passing cases write nothing"
    );
}

/// `glsl/trace_rbvh.comp` compiled as `build.rs` compiles it, with `glsl/rbvh.glsl` replaced by
/// `rbvh_glsl` wherever it is included.
fn compile_trace_rbvh(rbvh_glsl: String) -> Vec<u8> {
    let glsl = Path::new(env!("CARGO_MANIFEST_DIR")).join("glsl");
    let compiler = shaderc::Compiler::new().expect("shaderc");
    let mut options = shaderc::CompileOptions::new().expect("options");
    options.set_target_env(
        shaderc::TargetEnv::Vulkan,
        shaderc::EnvVersion::Vulkan1_1 as u32,
    );
    let dir = glsl.clone();
    options.set_include_callback(move |name, _, _, _| {
        let content = if name == "rbvh.glsl" {
            Ok(rbvh_glsl.clone())
        } else {
            std::fs::read_to_string(dir.join(name)).map_err(|e| e.to_string())
        }?;
        Ok(shaderc::ResolvedInclude {
            resolved_name: name.to_string(),
            content,
        })
    });
    let source = std::fs::read_to_string(glsl.join("trace_rbvh.comp")).unwrap();
    compiler
        .compile_into_spirv(
            &source,
            shaderc::ShaderKind::Compute,
            "trace_rbvh.comp",
            "main",
            Some(&options),
        )
        .unwrap_or_else(|e| panic!("{e}"))
        .as_binary_u8()
        .to_vec()
}

/// Runs the shipped golden of `case` with RBVHs traced by `spirv`.
fn run_with_shader(case: Case, spirv: &[u8], out: &Path) -> regress::Report {
    let config = Config {
        cases: vec![case],
        ..Config::new(shipped_goldens(), out)
    };
    regress::run_with(
        &common::context(),
        &config,
        |ctx, structure| match structure {
            Structure::Rbvh(_) => Tracer::with_shader(ctx, structure, spirv),
            _ => panic!("only plain RBVH cases here"),
        },
    )
    .unwrap()
}

#[test]
fn a_broken_rbvh_shader_fails_with_a_diff_image() {
    let source =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("glsl/rbvh.glsl"))
            .unwrap();
    // A plausible slip: one of a cell's four corners taken at half its height in the cell's
    // triangles.
    let correct = "precise float h = float(code) * leaf.h_scale;";
    assert!(
        source.matches(correct).count() == 1,
        "rbvh.glsl changed; update this test's edit"
    );
    let broken = source.replacen(
        correct,
        "precise float h = float(code) * leaf.h_scale * (q == 3u ? 0.5 : 1.0);",
        1,
    );
    let case = Case::new("blob", Method::rbvh(2));

    // Control: the same compile path with the source unchanged renders the golden.
    let out = tempfile::tempdir().unwrap();
    let report = run_with_shader(case.clone(), &compile_trace_rbvh(source), out.path());
    assert!(report.passed(), "{}", report.table());

    let report = run_with_shader(case, &compile_trace_rbvh(broken), out.path());
    assert!(!report.passed(), "{}", report.table());
    let result = &report.cases[0];
    assert!(
        matches!(result.image, Check::Compared { pass: false, .. }),
        "FLIP alone catches it: {}",
        report.table()
    );
    assert!(
        matches!(result.depth, Check::Compared { pass: false, .. }),
        "{}",
        report.table()
    );
    let diff = out.path().join("blob_rbvh_q2_diff.png");
    assert!(result.written.contains(&diff), "{:?}", result.written);
    let picture = image::open(&diff).unwrap();
    assert_eq!(
        (picture.width(), picture.height()),
        (regress::WIDTH, regress::HEIGHT)
    );
    for name in ["blob_rbvh_q2_render.png", "blob_rbvh_q2_depth_diff.png"] {
        assert!(out.path().join(name).exists(), "{name}");
    }
    // Golden, render and the FLIP picture with its colour bar, side by side: the golden on the
    // left as shipped.
    let compare = image::open(out.path().join("blob_rbvh_q2_compare.png"))
        .unwrap()
        .to_rgb8();
    assert_eq!(compare.width(), 3 * regress::WIDTH + 2 * 4);
    assert!(compare.height() > regress::HEIGHT);
    let golden = image::open(shipped_goldens().join("blob_rbvh_q2.png"))
        .unwrap()
        .to_rgb8();
    for (x, y) in [(0, 0), (80, 60), (159, 119)] {
        assert_eq!(
            compare.get_pixel(x, y),
            golden.get_pixel(x, y),
            "({x}, {y})"
        );
    }
    assert!(report.table().contains("FAIL"), "{}", report.table());
}

#[test]
fn a_missing_golden_fails_with_advice_and_bless_creates_it() {
    let ctx = common::context();
    let dir = tempfile::tempdir().unwrap();
    let (golden, out) = (dir.path().join("golden"), dir.path().join("out"));
    // The folder is there; the case's golden files are not.
    std::fs::create_dir(&golden).unwrap();
    let mut config = Config {
        cases: vec![Case::new("sphere", Method::EXACT)],
        width: 48,
        height: 32,
        ..Config::new(&golden, &out)
    };

    let report = regress::run(&ctx, &config).unwrap();
    assert!(!report.passed());
    let Check::Unusable(message) = &report.cases[0].image else {
        panic!("{}", report.table())
    };
    assert!(
        message.contains("no golden")
            && message.contains("sphere_exact.png")
            && message.contains("--bless"),
        "{message}"
    );
    assert!(out.join("sphere_exact_render.png").exists());

    config.mode = Mode::Bless;
    let report = regress::run(&ctx, &config).unwrap();
    assert!(report.passed(), "{}", report.table());
    assert!(
        golden.join("sphere_exact.png").exists() && golden.join("sphere_exact_depth.exr").exists()
    );

    config.mode = Mode::Compare;
    let report = regress::run(&ctx, &config).unwrap();
    assert!(report.passed(), "{}", report.table());
    // The first run's render of the failing case is not left beside this run's results.
    assert!(!out.join("sphere_exact_render.png").exists());

    // Another size than blessed is a failure naming both sizes, not a crash.
    config.width = 40;
    let report = regress::run(&ctx, &config).unwrap();
    let Check::Unusable(message) = &report.cases[0].image else {
        panic!("{}", report.table())
    };
    assert!(
        message.contains("48×32") && message.contains("40×32"),
        "{message}"
    );
}

fn rbvh(args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_rbvh"))
        .args(args)
        .env("RBVH_VALIDATION", "auto")
        .output()
        .expect("run rbvh");
    let text =
        String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr);
    (out.status.success(), text)
}

#[test]
fn cli_fails_on_a_missing_golden_and_an_unknown_scene() {
    let dir = tempfile::tempdir().unwrap();
    let golden = dir.path().join("g");
    let out = dir.path().join("o");
    // Without the folder the run stops at once (a_missing_golden_folder_is_one_clear_error).
    let (ok, text) = rbvh(&[
        "regress",
        "--scene",
        "plane",
        "--method",
        "exact",
        "--golden",
        golden.to_str().unwrap(),
    ]);
    assert!(!ok && text.contains("no golden folder"), "{text}");
    assert!(!text.contains("plane_exact"), "{text}");
    std::fs::create_dir(&golden).unwrap();
    // --bless writes no renders, so it takes no --out.
    let blessing = [
        "--golden",
        golden.to_str().unwrap(),
        "--width",
        "32",
        "--height",
        "24",
    ];
    let common = [&blessing[..], &["--out", out.to_str().unwrap()]].concat();
    let (ok, text) = rbvh(
        &[
            &["regress", "--scene", "plane", "--method", "exact"],
            &common[..],
        ]
        .concat(),
    );
    assert!(!ok, "{text}");
    assert!(
        text.contains("plane_exact") && text.contains("FAIL") && text.contains("--bless"),
        "{text}"
    );

    let (ok, text) = rbvh(
        &[
            &[
                "regress",
                "--scene",
                "plane",
                "--method",
                "rbvh",
                "--quality",
                "0",
                "--bless",
            ],
            &blessing[..],
        ]
        .concat(),
    );
    assert!(ok, "{text}");
    assert!(golden.join("plane_rbvh_q0.png").exists(), "{text}");

    let (ok, text) = rbvh(&[&["regress", "--scene", "no-such-scene"], &common[..]].concat());
    assert!(
        !ok && text.contains("no-such-scene") && !text.contains("panicked"),
        "{text}"
    );
}

/// Comparing against a golden folder that is not there is one clear error before any render, not
/// a failure per case; blessing into it is fine (it is made).
#[test]
fn a_missing_golden_folder_is_one_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("no-goldens");
    let config = Config::new(&missing, dir.path().join("out"));
    let e = config.validate().unwrap_err().to_string();
    assert!(
        e.contains("no golden folder") && e.contains("no-goldens") && e.contains("--bless"),
        "{e}"
    );
    let bless = Config {
        mode: Mode::Bless,
        ..config
    };
    bless.validate().unwrap();

    // An output folder that is a file is refused before any case runs, not at the first failure.
    let golden = dir.path().join("golden");
    std::fs::create_dir(&golden).unwrap();
    let file = dir.path().join("notes.txt");
    std::fs::write(&file, "kept").unwrap();
    let e = Config::new(&golden, &file)
        .validate()
        .unwrap_err()
        .to_string();
    assert!(e.contains("notes.txt") && e.contains("not a folder"), "{e}");
    assert_eq!(std::fs::read_to_string(&file).unwrap(), "kept");
}
