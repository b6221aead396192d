//! The files a command writes, checked before it does any work.
//!
//! Every output is written atomically (`rbvh::io::write_atomically`), so one write that fails
//! loses nothing; but a command whose second output fails after its first was written, or which
//! writes over a file it names, still would: a render's picture over the mesh it was made from,
//! a bench's records lost at the end of its run to a JSON path in a missing folder. So each
//! command names its outputs and the files its flags name first, and [`check`] refuses, before
//! any work, an output whose folder is missing or cannot be read, one that is a folder, two
//! outputs that are one file, and an output that is one of those inputs (`upgrade` and `paint`
//! may write the RBVH file they read: it is read whole before the new one replaces it). What a
//! scene file names in turn (its meshes, their textures) is not checked, nor whether a folder
//! can be written: a write that fails there still fails after the work.

use std::path::{Path, PathBuf};

use anyhow::{bail, Result};
use rbvh::scene::PointSource;

use crate::prepare::Source;

/// An input: a flag and the path it names, if given.
pub type Named<'a> = (&'static str, Option<&'a Path>);

/// An output: its flag, the path it names if given, and the extension its format takes (`None`:
/// any name, as the headerless ray and hit files).
pub struct Output<'a> {
    pub flag: &'static str,
    pub path: Option<&'a Path>,
    pub ext: Option<&'static str>,
}

/// An output of the format whose files end in `.ext`.
pub fn output<'a>(flag: &'static str, path: Option<&'a Path>, ext: &'static str) -> Output<'a> {
    Output {
        flag,
        path,
        ext: Some(ext),
    }
}

/// Refuses the outputs as the module says, and a name whose extension is not its format's (the
/// format is the flag's, not the name's). A device or FIFO (`/dev/null`) is written through
/// rather than replaced, so it takes any name and may be named by several outputs.
pub fn check(outputs: &[Output], inputs: &[Named]) -> Result<()> {
    let inputs: Vec<(&str, PathBuf)> = inputs
        .iter()
        .filter_map(|&(flag, path)| path.filter(|p| p.exists()).map(|p| (flag, identity(p))))
        .collect();
    let mut written: Vec<(&str, PathBuf)> = Vec::new();
    for out in outputs {
        let (flag, Some(path)) = (out.flag, out.path) else {
            continue;
        };
        let folder = match path.parent() {
            Some(folder) if !folder.as_os_str().is_empty() => folder,
            _ => Path::new("."),
        };
        match std::fs::metadata(folder) {
            Ok(m) if m.is_dir() => {}
            Ok(_) => bail!(
                "{flag} {}: {} is not a folder",
                path.display(),
                folder.display()
            ),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => bail!(
                "{flag} {}: the folder {} does not exist",
                path.display(),
                folder.display()
            ),
            Err(e) => bail!(
                "{flag} {}: the folder {}: {e}",
                path.display(),
                folder.display()
            ),
        }
        // Replaced by a file of its own, or written through (a device, FIFO or descriptor).
        let replaced = match rbvh::io::rename_target(path) {
            Ok(target) => target.is_some(),
            Err(e) => bail!("{flag} {}: {e}", path.display()),
        };
        if let (Some(ext), true) = (out.ext, replaced) {
            if !path
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case(ext))
            {
                bail!(
                    "{flag} {}: writes {}, so give it a .{ext} name",
                    path.display(),
                    ext.to_uppercase()
                );
            }
        }
        let file = identity(path);
        if let Some((input, _)) = inputs.iter().find(|(_, p)| *p == file) {
            bail!(
                "{flag} {} is the file {input} reads: writing it would replace it; name another \
                 file",
                path.display()
            );
        }
        if let Some((other, _)) = written.iter().find(|(_, p)| *p == file) {
            if replaced {
                bail!(
                    "{flag} and {other} both name {}: one would replace the other",
                    path.display()
                );
            }
        }
        written.push((flag, file));
    }
    Ok(())
}

/// The inputs of a command's `--scene` (where it names a file rather than a built-in scene,
/// which the loader prefers) and `--points` (where it names one).
pub fn scene_inputs<'a>(scene: &'a str, points: Option<&'a PointSource>) -> [Named<'a>; 2] {
    let points = match points {
        Some(PointSource::File(path)) => Some(path.as_path()),
        _ => None,
    };
    let file = (!rbvh::scene::builtin::NAMES.contains(&scene)).then(|| Path::new(scene));
    [("--scene", file), ("--points", points)]
}

/// The inputs of a command that traces one structure: its scene, points and RBVH file.
pub fn source_inputs(source: &Source) -> Vec<Named<'_>> {
    let mut inputs = scene_inputs(&source.scene, source.points.points.as_ref()).to_vec();
    inputs.push(("--rbvh", source.rbvh.as_deref()));
    inputs
}

/// What names one file: its path with every link followed where it exists, else its folder's
/// so, with its name.
fn identity(path: &Path) -> PathBuf {
    if let Ok(file) = std::fs::canonicalize(path) {
        return file;
    }
    let folder = match path.parent() {
        Some(folder) if !folder.as_os_str().is_empty() => folder,
        _ => Path::new("."),
    };
    match (std::fs::canonicalize(folder), path.file_name()) {
        (Ok(folder), Some(name)) => folder.join(name),
        _ => path.to_path_buf(),
    }
}
