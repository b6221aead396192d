//! The front door: one string names a scene, whether built in or a file of any supported type.

use std::path::Path;

use super::mesh_file::{check_mesh_file, load_mesh_file, FileType};
use super::{builtin, gltf, scene_file, InstancedScene, Scene};
use crate::io::input::regular_file;
use crate::progress::{step, Progress, Quiet};
use crate::{Error, Result};

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
            Some((path, FileType::SceneFile)) => {
                scene_file::load(path, progress)?.into_flat_checked()
            }
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

impl InstancedScene {
    /// Loads `spec` as [`Scene::load`] does, keeping a scene file's instances and a glTF file's
    /// nodes that share a mesh ([`InstancedScene`]) and the instances of a built-in scene that
    /// has them ("grove-instanced"); any other mesh file or built-in scene is one mesh placed
    /// once ([`InstancedScene::single`]).
    pub fn load(spec: &str) -> Result<InstancedScene> {
        InstancedScene::load_observed(spec, &Quiet)
    }

    /// [`InstancedScene::load`], reporting to `progress` the meshes of a scene file as they load.
    pub fn load_observed(spec: &str, progress: &dyn Progress) -> Result<InstancedScene> {
        match resolve(spec)? {
            Some((path, FileType::SceneFile)) => scene_file::load(path, progress),
            Some((path, FileType::Gltf)) => {
                step(progress, &format!("loading {}", path.display()), 0, || {
                    check_mesh_file(path)?;
                    gltf::load_instanced(path)
                })
            }
            None => match builtin::build_instanced(spec) {
                Some(placed) => {
                    placed.validate()?;
                    Ok(placed)
                }
                None => Scene::builtin(spec).map(InstancedScene::single),
            },
            _ => Scene::load_observed(spec, progress).map(InstancedScene::single),
        }
    }
}

impl InstancedScene {
    /// Whether [`InstancedScene::load`] of `spec` would place some mesh more than once, told
    /// without loading it where that is cheaper than loading: for a glTF file from its nodes
    /// alone (the file is read, no buffer or image decoded), so that a caller that traces a
    /// scene flat unless it repeats a mesh decodes the meshes once, with the loader it needs; false for any other
    /// mesh file; `None` for a scene file or a built-in scene, which only loading tells. Errors
    /// as loading would give them for a missing or malformed file.
    pub fn would_repeat_a_mesh(spec: &str) -> Result<Option<bool>> {
        match resolve(spec)? {
            Some((path, FileType::Gltf)) => {
                check_mesh_file(path)?;
                gltf::shares_a_mesh(path).map(Some)
            }
            Some((_, FileType::Obj | FileType::Points)) => Ok(Some(false)),
            Some((_, FileType::SceneFile)) | None => Ok(None),
        }
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
