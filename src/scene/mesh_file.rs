//! One mesh file — OBJ, glTF/GLB, or a point cloud — by its type: what a scene named by a single
//! file and each mesh of a scene file are loaded through.

use std::path::Path;

use super::{gltf, obj, Scene};
use crate::io::input::regular_file;
use crate::points::PointCloud;
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
