//! The front door: one string names a scene, whether built in or a file of any supported type.

use std::path::Path;

use super::{builtin, gltf, obj, scene_file, Scene};
use crate::{Error, Result};

/// The file types a scene can be loaded from, by lower-case extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum FileType {
    Obj,
    Gltf,
    SceneFile,
}

impl FileType {
    /// The type `path` names by its extension (case-insensitive), or a parse error naming the
    /// file when it is none of ours.
    pub(super) fn of(path: &Path) -> Result<FileType> {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase());
        match ext.as_deref() {
            Some("obj") => Ok(FileType::Obj),
            Some("gltf" | "glb") => Ok(FileType::Gltf),
            Some("toml") => Ok(FileType::SceneFile),
            _ => Err(Error::parse(
                path,
                None,
                "unsupported file type: expected .obj, .gltf, .glb or .toml",
            )),
        }
    }
}

impl Scene {
    /// Loads `spec`: a built-in name (see [`builtin::NAMES`]) or a path ending in `.obj`,
    /// `.gltf`, `.glb` or `.toml` (a scene file), case-insensitively. Built-in names win, so
    /// a stray file called `sphere` cannot shadow them. A missing path is an I/O error naming
    /// it when `spec` looks like a path (has an extension or a separator), and otherwise an
    /// unknown-scene error listing the built-ins, since it was most likely a mistyped name.
    pub fn load(spec: &str) -> Result<Scene> {
        if builtin::NAMES.contains(&spec) {
            return Scene::builtin(spec);
        }
        let path = Path::new(spec);
        let metadata = std::fs::metadata(path);
        if let Ok(m) = &metadata {
            regular_file(path, m)?;
        }
        if let Err(e) = metadata {
            let looks_like_path = path.extension().is_some() || spec.contains(['/', '\\']);
            return Err(if looks_like_path {
                Error::io(path, e)
            } else {
                Error::UnknownScene {
                    name: spec.to_owned(),
                    known: builtin::NAMES.join(", "),
                }
            });
        }
        match FileType::of(path)? {
            FileType::SceneFile => scene_file::load(path),
            FileType::Obj | FileType::Gltf => load_mesh_file(path),
        }
    }

    /// The built-in scene `name`, or an error listing the built-in names.
    pub fn builtin(name: &str) -> Result<Scene> {
        let scene = builtin::build(name).ok_or_else(|| Error::UnknownScene {
            name: name.to_owned(),
            known: builtin::NAMES.join(", "),
        })?;
        scene.validate()?;
        Ok(scene)
    }
}

/// Loads an OBJ, glTF or GLB file. Scene files refer to meshes through this, which is why it
/// refuses scene files: one level of arrangement keeps them simple and free of cycles. A file
/// with nothing to trace (empty, or only vertices, points or lines) is an error, as an empty
/// scene file is: it is almost certainly the wrong file, and would render a blank image.
pub(super) fn load_mesh_file(path: &Path) -> Result<Scene> {
    let file_type = FileType::of(path)?;
    if file_type == FileType::SceneFile {
        return Err(Error::parse(
            path,
            None,
            "a scene file cannot be used as a mesh: expected .obj, .gltf or .glb",
        ));
    }
    let metadata = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    regular_file(path, &metadata)?;
    let scene = if file_type == FileType::Obj {
        obj::load(path)?
    } else {
        gltf::load(path)?
    };
    if scene.triangle_count() == 0 {
        return Err(Error::parse(
            path,
            None,
            "no triangles: nothing in the file can be traced (no faces, or only points and lines)",
        ));
    }
    Ok(scene)
}

/// Refuses anything but a regular file: a device such as `/dev/zero` or a FIFO would be read
/// forever, and a directory is a mistake. Every file a scene names goes through this.
pub(super) fn regular_file(path: &Path, metadata: &std::fs::Metadata) -> Result<()> {
    if metadata.is_file() {
        Ok(())
    } else {
        Err(Error::parse(
            path,
            None,
            "not a regular file (a directory, device or pipe)",
        ))
    }
}
