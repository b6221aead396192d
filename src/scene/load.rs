//! The front door: one string names a scene, whether built in or a file of any supported type.

use std::path::Path;

use super::{builtin, gltf, obj, scene_file, Scene};
use crate::points::PointCloud;
use crate::progress::{step, Progress, Quiet};
use crate::{Error, Result};

/// The file types a scene can be loaded from, by lower-case extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum FileType {
    Obj,
    Gltf,
    /// A point cloud: `.ply` or `.xyz` (see [`crate::points`]).
    Points,
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
            Some("ply" | "xyz") => Ok(FileType::Points),
            Some("toml") => Ok(FileType::SceneFile),
            _ => Err(Error::parse(
                path,
                None,
                "unsupported file type: expected .obj, .gltf, .glb, .ply, .xyz or .toml",
            )),
        }
    }
}

impl Scene {
    /// Loads `spec`: a built-in name (see [`builtin::NAMES`]) or a path ending in `.obj`,
    /// `.gltf`, `.glb`, `.ply` or `.xyz` (a point cloud, see [`Scene::points`]) or `.toml` (a
    /// scene file), case-insensitively. Built-in names win, so
    /// a stray file called `sphere` cannot shadow them. A missing path is an I/O error naming
    /// it when `spec` looks like a path (has an extension or a separator), and otherwise an
    /// unknown-scene error listing the built-ins, since it was most likely a mistyped name.
    pub fn load(spec: &str) -> Result<Scene> {
        Scene::load_observed(spec, &Quiet)
    }

    /// [`Scene::load`], reporting to `progress` the meshes of a scene file as they load (a
    /// single mesh file or built-in scene is one step with nothing to count).
    pub fn load_observed(spec: &str, progress: &dyn Progress) -> Result<Scene> {
        match resolve(spec)? {
            None => Scene::builtin(spec),
            Some((path, FileType::SceneFile)) => scene_file::load(path, progress),
            Some((path, FileType::Obj | FileType::Gltf | FileType::Points)) => {
                step(progress, &format!("loading {}", path.display()), 0, || {
                    load_mesh_file(path)
                })
            }
        }
    }

    /// Checks `spec` as [`Scene::load`] would take it, without loading any mesh: a built-in name,
    /// or an existing mesh file of a known type, or a scene file whose syntax, camera, light,
    /// transforms and meshes (each a built-in name or an existing file) are sound. A caller with
    /// several scenes to load (`rbvh bench`) checks them all before any work.
    pub fn check(spec: &str) -> Result<()> {
        match resolve(spec)? {
            Some((path, FileType::SceneFile)) => scene_file::check(path),
            _ => Ok(()),
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

/// What `spec` names: None for a built-in scene, else an existing regular file and its type; an
/// error for a missing file (or an unknown name that does not look like a path), a directory, or
/// an unknown extension.
fn resolve(spec: &str) -> Result<Option<(&Path, FileType)>> {
    if builtin::NAMES.contains(&spec) {
        return Ok(None);
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
    Ok(Some((path, FileType::of(path)?)))
}

/// The type of the mesh file at `path` (OBJ or glTF), after checking that it is one and is there:
/// what [`load_mesh_file`] checks before reading it, in the same order.
pub(super) fn check_mesh_file(path: &Path) -> Result<FileType> {
    let file_type = FileType::of(path)?;
    if file_type == FileType::SceneFile {
        return Err(Error::parse(
            path,
            None,
            "a scene file cannot be used as a mesh: expected .obj, .gltf, .glb, .ply or .xyz",
        ));
    }
    let metadata = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    regular_file(path, &metadata)?;
    Ok(file_type)
}

/// Loads an OBJ, glTF or GLB file, or a point cloud (a scene of points alone, named by its
/// file). Scene files refer to meshes through this, which is why it refuses scene files: one
/// level of arrangement keeps them simple and free of cycles. A mesh file with nothing to trace
/// (empty, or only vertices, points or lines) is an error, as an empty scene file is: it is
/// almost certainly the wrong file, and would render a blank image.
pub(super) fn load_mesh_file(path: &Path) -> Result<Scene> {
    let file_type = check_mesh_file(path)?;
    let scene = match file_type {
        FileType::Obj => obj::load(path)?,
        FileType::Points => {
            let mut scene = Scene::new(path.display().to_string());
            scene.points = Some(PointCloud::load(path)?);
            return Ok(scene);
        }
        _ => gltf::load(path)?,
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
