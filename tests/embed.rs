//! `examples/embed.rs` plays an engine that brings its own instance, device and allocator, writes
//! rays with its own shader and records the library's trace into its own command buffer. It must
//! run clean (including under the validation layer when installed) and produce its image.

use std::path::PathBuf;
use std::process::Command;

fn example() -> PathBuf {
    // Integration tests live in target/<profile>/deps; `cargo test` builds examples beside them.
    let deps = std::env::current_exe()
        .unwrap()
        .parent()
        .unwrap()
        .to_path_buf();
    deps.parent().unwrap().join("examples").join("embed")
}

#[test]
fn the_engine_example_runs_and_writes_its_image() {
    let exe = example();
    assert!(
        exe.exists(),
        "{} was not built (cargo test builds examples)",
        exe.display()
    );
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("embed.png");
    let out = Command::new(&exe).arg(&png).arg("sphere").output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}\n{}",
        stdout,
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("rays hit; 0 overflowed"), "{stdout}");
    let img = image::open(&png).unwrap();
    assert_eq!((img.width(), img.height()), (320, 240));
}
