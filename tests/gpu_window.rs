//! The scripts of a GPU window (docs/measuring.md) end to end, on lavapipe: `scripts/gpu-bundle.sh`
//! packs the binary, the window's script and scene files, and `run.sh` runs the window from the
//! bundle alone. GPU windows are short and rare, so a script that broke since the last one would
//! cost one; this finds it first.

use std::path::Path;
use std::process::Command;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn a_bundle_runs_the_window_from_itself() {
    let dir = tempfile::tempdir().unwrap();
    let bundle = dir.path().join("bundle");
    // No datasets (the steps that need them are skipped, saying so) and no loader package: the
    // test machine has a loader, and fetching one needs the network.
    let pack = Command::new("bash")
        .arg(root().join("scripts/gpu-bundle.sh"))
        .arg(&bundle)
        .arg(dir.path().join("no-datasets"))
        .env("RBVH", env!("CARGO_BIN_EXE_rbvh"))
        .env("RBVH_COMMIT", "0123456789abcdef0123456789abcdef01234567")
        .env("LOADER_DEB", "none")
        .output()
        .expect("run gpu-bundle.sh");
    let said =
        String::from_utf8_lossy(&pack.stderr).to_string() + &String::from_utf8_lossy(&pack.stdout);
    assert!(pack.status.success(), "{said}");
    assert!(
        said.contains("left out:") && said.contains("dragon_vrip.obj is missing"),
        "{said}"
    );
    for file in [
        "rbvh",
        "run.sh",
        "scripts/gpu-window.sh",
        "scenes/dragon-closeup.toml",
        "scenes/paper-scale.toml",
    ] {
        assert!(
            bundle.join(file).exists(),
            "{file} is not in the bundle:\n{said}"
        );
    }

    // The budget lets the registers' step run (it needs 20 s; it takes a few here) and no bench
    // (the default scene's needs 40): the window then ends cleanly, each step saying what it did.
    let results = dir.path().join("results");
    let run = Command::new("bash")
        .arg(bundle.join("run.sh"))
        .arg("38")
        .arg(&results)
        .env("DEVICE", "llvmpipe")
        .output()
        .expect("run the bundle's run.sh");
    let log = std::fs::read_to_string(results.join("log.txt")).unwrap_or_default();
    assert!(
        run.status.success(),
        "{}\n{log}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(log.contains("shaders: done"), "{log}");
    assert!(
        log.contains("dragon-closeup primary: skipped") && log.contains("all steps ended"),
        "{log}"
    );
    let shaders: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(results.join("shaders-gpu.json")).unwrap())
            .unwrap();
    assert_eq!(
        shaders["git"], "0123456789abcdef0123456789abcdef01234567",
        "the results name the bundle's commit"
    );
}
