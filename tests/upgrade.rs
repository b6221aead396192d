//! `rbvh upgrade` end to end: a file of every earlier version is rewritten as the current one,
//! holding what loading the old one gives (painted colours included), in place or beside it;
//! optional sections this build does not know are dropped and said so; a bad file fails
//! cleanly, leaving nothing behind. No Vulkan device is needed.

mod rbvh_files;

use std::path::Path;
use std::process::{Command, Output};

use rbvh::rbvh::{Rbvh, RbvhParams, TexelFormat};
use rbvh::scene::Scene;
use rbvh_files::{as_v12, as_v12_loads, as_version, assemble, parts};

fn upgrade(input: &Path, out: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rbvh"))
        .args(["upgrade", arg(input), "--out", arg(out)])
        .output()
        .expect("run rbvh")
}

fn arg(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A small RBVH of the sphere with a colour channel; with `height`, height-only (and without).
fn sphere(height: bool) -> Rbvh {
    let params = RbvhParams {
        texels_per_diagonal: 32.0,
        texels: if height {
            TexelFormat::Height
        } else {
            TexelFormat::HeightNormal
        },
        ..RbvhParams::quality(0).unwrap()
    };
    let mut r = Rbvh::build(&Scene::builtin("sphere").unwrap(), &params).unwrap();
    r.colours = (!height).then(|| {
        (0..r.atlas.texels.len() as u32)
            .map(|k| k.wrapping_mul(0x0103_0507))
            .collect()
    });
    r
}

#[test]
fn every_earlier_version_is_rewritten_as_the_current_one() {
    let dir = tempfile::tempdir().unwrap();
    let (painted, height) = (sphere(false), sphere(true));
    for version in 1..=12 {
        // Version 1 kept no colours, version 3 only heights; the others keep the paint.
        let mut r = if version == 3 {
            height.clone()
        } else {
            painted.clone()
        };
        if version == 1 {
            r.colours = None;
        }
        let old = dir.path().join(format!("v{version}.rbvh"));
        std::fs::write(&old, as_version(&r, version)).unwrap();
        let new = dir.path().join(format!("v{version}-new.rbvh"));
        let out = upgrade(&old, &new);
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success(),
            "{stdout}{}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(
            stdout.contains(&format!("v{version}.rbvh (version {version}) → "))
                && stdout.contains("-new.rbvh (version 13)")
                && stdout.contains("sections PARM v8, HEAD v2, NODE v1"),
            "{stdout}"
        );
        assert_eq!(stdout.contains("and their colours"), r.colours.is_some());
        let loaded = Rbvh::load(&old).unwrap();
        let bytes = std::fs::read(&new).unwrap();
        assert_eq!(bytes, loaded.to_bytes(), "version {version}");
        assert_eq!(Rbvh::load(&new).unwrap(), loaded);
        assert_eq!(loaded.colours, r.colours, "version {version}");
    }
}

#[test]
fn a_file_is_upgraded_in_place_and_unknown_optional_sections_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("painted.rbvh");
    let r = sphere(false);
    std::fs::write(&file, as_v12(&r)).unwrap();
    let out = upgrade(&file, &file);
    assert!(out.status.success(), "{out:?}");
    assert_eq!(std::fs::read(&file).unwrap(), as_v12_loads(&r).to_bytes());
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);

    // A current file keeps what this build reads, and drops (saying so) what it skips.
    let mut p = parts(&r.to_bytes());
    p.push((*b"XTRA", 3, 0, vec![7; 5]));
    std::fs::write(&file, assemble(&p)).unwrap();
    let out = upgrade(&file, &file);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{out:?}");
    assert!(
        stdout.contains("(version 13) → ")
            && stdout.contains(
                "dropped: optional section XTRA (version 3, 5 bytes), which this build does not \
                 know"
            ),
        "{stdout}"
    );
    assert_eq!(std::fs::read(&file).unwrap(), r.to_bytes());
}

#[test]
fn a_bad_file_fails_cleanly_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let bytes = as_v12(&sphere(false));
    let cut = dir.path().join("cut.rbvh");
    std::fs::write(&cut, &bytes[..bytes.len() - 1]).unwrap();
    let new = dir.path().join("new.rbvh");
    for input in [cut, dir.path().join("missing.rbvh")] {
        let out = upgrade(&input, &new);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{stderr}");
        assert!(
            stderr.starts_with("error: ") && stderr.contains(arg(&input)),
            "{stderr}"
        );
        assert!(!new.exists());
    }
    // --out is required: the command never picks a file to write by itself.
    let out = Command::new(env!("CARGO_BIN_EXE_rbvh"))
        .args(["upgrade", "any.rbvh"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--out"));
}
