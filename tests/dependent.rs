//! rbvh as an engine takes it: a crate of its own, outside this repository (so this repository's
//! `.cargo/config.toml` is not read), depending on rbvh by path with default features off and only
//! `loaded` on. It must build with nothing but what the README's set-up installs, pull in none of
//! the measuring or CLI crates, and trace the built-in sphere to the analytic answer.
//!
//! The dependent crate builds in a target folder kept under Cargo's test scratch space, so only the
//! first run compiles its dependencies (about a minute on 2 cores, in the dev profile).

use std::path::Path;
use std::process::Command;

/// The dependent's own code: build a Q2 RBVH of the built-in sphere, trace a camera's rays on
/// the standalone context, and compare every hit with the exact sphere.
const MAIN_RS: &str = r#"
use rbvh::scene::builtin::{analytic, Analytic};
use rbvh::{Context, ContextOptions, Query, Rbvh, RbvhParams, Scene, Structure, Tracer};

fn main() -> Result<(), rbvh::Error> {
    let scene = Scene::load("sphere")?;
    let Some(Analytic::Sphere { center, radius, max_chord_error }) = analytic("sphere") else {
        panic!("the built-in sphere has no analytic twin");
    };
    let rays = scene.camera_or_framed(1.0).primary_rays(48, 48);
    let context = Context::new(&ContextOptions::default())?;
    let params = RbvhParams::quality(2)?;
    let rbvh = Rbvh::build(&scene, &params)?;
    let hits = Tracer::new(&context, &Structure::from(rbvh))?.trace(&rays, Query::Closest)?.hits;

    // A hit lies within a texel of the tessellated sphere.
    let tolerance = max_chord_error + scene.bounds().diagonal() / params.texels_per_diagonal;
    let (mut hit_count, mut worst) = (0, 0.0f32);
    for (ray, hit) in rays.iter().zip(&hits) {
        let d = ray.dir().normalize();
        let oc = ray.origin() - center;
        let b = oc.dot(d);
        let disc = b * b - (oc.length_squared() - radius * radius);
        // Rays that graze the silhouette may go either way in an approximation.
        if disc.abs() < 0.05 * radius * radius {
            continue;
        }
        assert_eq!(hit.is_hit(), disc > 0.0, "ray {ray:?}: {hit:?}");
        if disc > 0.0 {
            let t = (-b - disc.sqrt()) / ray.dir().length();
            worst = worst.max((hit.t - t).abs() * ray.dir().length());
            hit_count += 1;
        }
    }
    assert!(hit_count > 500, "only {hit_count} hits");
    assert!(worst <= tolerance, "|Δt| {worst} over {tolerance}");
    println!("dependent: {hit_count} hits, max |Δt| {worst:.5} (bound {tolerance:.5})");
    Ok(())
}
"#;

/// Crates that only the `exr`, `measure` and `cli` features may bring in.
const HEAVY: [&str; 6] = ["nv-flip", "plotters", "exr", "clap", "indicatif", "anyhow"];

fn cargo(dir: &Path, target: &Path, args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO"))
        .args(args)
        .current_dir(dir)
        .env("CARGO_TARGET_DIR", target)
        // Inherited from the `cargo test` that runs us, these would steer the inner build.
        .env_remove("RUSTFLAGS")
        .env_remove("CARGO_ENCODED_RUSTFLAGS")
        .env_remove("CARGO_BUILD_RUSTFLAGS")
        .output()
        .expect("cargo runs")
}

#[test]
fn a_crate_outside_the_repository_depends_on_rbvh_without_default_features() {
    let manifest_dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    assert!(
        !dir.path().starts_with(manifest_dir),
        "the dependent must live outside the repository so that its .cargo/config.toml is not read"
    );
    std::fs::create_dir(dir.path().join("src")).unwrap();
    std::fs::write(dir.path().join("src/main.rs"), MAIN_RS).unwrap();
    std::fs::write(
        dir.path().join("Cargo.toml"),
        format!(
            "[package]\nname = \"engine\"\nversion = \"0.0.0\"\nedition = \"2021\"\n\n\
             [dependencies]\nrbvh = {{ path = {:?}, default-features = false, features = [\"loaded\"] }}\n",
            manifest_dir.display().to_string()
        ),
    )
    .unwrap();
    // The versions this repository was tested with, and no registry access needed.
    std::fs::copy(
        manifest_dir.join("Cargo.lock"),
        dir.path().join("Cargo.lock"),
    )
    .unwrap();
    let target = Path::new(env!("CARGO_TARGET_TMPDIR")).join("dependent-target");

    let tree = cargo(
        dir.path(),
        &target,
        &[
            "tree",
            "--offline",
            "--edges",
            "normal,build",
            "--prefix",
            "none",
        ],
    );
    let tree_text = String::from_utf8_lossy(&tree.stdout);
    assert!(
        tree.status.success(),
        "cargo tree: {}",
        String::from_utf8_lossy(&tree.stderr)
    );
    for heavy in HEAVY {
        assert!(
            !tree_text
                .lines()
                .any(|l| l.starts_with(&format!("{heavy} v"))),
            "{heavy} is in a build without default features:\n{tree_text}"
        );
    }

    let run = cargo(dir.path(), &target, &["run", "--offline", "--quiet"]);
    let stdout = String::from_utf8_lossy(&run.stdout);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(
        run.status.success(),
        "the dependent failed:\n{stdout}\n{stderr}"
    );
    assert!(stdout.contains("dependent: "), "{stdout}");
    eprintln!("{}", stdout.trim_end());
}
