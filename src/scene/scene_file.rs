//! TOML scene files: meshes (built-in or from files) placed by transforms, plus an optional
//! camera and light, so that a reproducible view of a model is one small text file. A `[[mesh]]`
//! is copied into the scene where it is placed; an `[[instance]]` places a mesh held once
//! ([`InstancedScene`]), which a two-level structure traces without copying it.
//!
//! Unknown keys are errors (a typo must not be silently ignored), and every error names the
//! file and the line of the offending value; the format is described in `scenes/README.md`.

use std::collections::hash_map::{Entry, HashMap};
use std::ops::Range;
use std::path::Path;

use glam::{Mat4, Vec3};
use serde::Deserialize;
use toml::Spanned;

use super::camera::DEFAULT_VFOV_DEG;
use super::instances::{transform_fault, Instance, InstancedScene};
use super::mesh_file::{check_mesh_file, load_mesh_file};
use super::{Camera, CameraFault, Light, Scene};
use crate::progress::{step, Progress};
use crate::{Error, Result};

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SceneFile {
    name: Option<String>,
    camera: Option<Spanned<CameraEntry>>,
    light: Option<Spanned<LightEntry>>,
    #[serde(default)]
    mesh: Vec<Spanned<MeshEntry>>,
    #[serde(default)]
    instance: Vec<Spanned<MeshEntry>>,
}

/// Three numbers, exactly: an `[f32; 3]` would take the first three of a longer array and drop
/// the rest unsaid.
struct Triple([f32; 3]);

impl<'de> Deserialize<'de> for Triple {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        let numbers = Vec::<f32>::deserialize(d)?;
        <[f32; 3]>::try_from(numbers.as_slice())
            .map(Triple)
            .map_err(|_| serde::de::Error::invalid_length(numbers.len(), &"three numbers"))
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraEntry {
    eye: Spanned<Triple>,
    target: Spanned<Triple>,
    up: Option<Spanned<Triple>>,
    vfov: Option<Spanned<f32>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct LightEntry {
    direction: Option<Spanned<Triple>>,
    position: Option<Spanned<Triple>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct MeshEntry {
    builtin: Option<Spanned<String>>,
    path: Option<Spanned<String>>,
    translate: Option<Spanned<Triple>>,
    rotate: Option<Spanned<Triple>>,
    scale: Option<Spanned<ScaleEntry>>,
}

#[derive(Deserialize)]
#[serde(untagged, expecting = "a number or an array of three numbers")]
enum ScaleEntry {
    Uniform(f32),
    PerAxis(Triple),
}

/// The text of the scene file at `path`, and the file parsed from it (with at least one mesh or
/// instance).
fn parse(path: &Path) -> Result<(String, SceneFile)> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let file: SceneFile = toml::from_str(&text).map_err(|e| {
        let line = e.span().map(|s| line_of(&text, s.start));
        Error::parse(path, line, e.message())
    })?;
    if file.mesh.is_empty() && file.instance.is_empty() {
        return Err(Error::parse(
            path,
            None,
            "no meshes: a scene file needs at least one [[mesh]] or [[instance]] table",
        ));
    }
    Ok((text, file))
}

/// Checks the scene file at `path` as [`load`] would, short of loading its meshes: its syntax,
/// camera, light and transforms, and that each mesh is a built-in name or an existing file.
pub(super) fn check(path: &Path) -> Result<()> {
    let (text, file) = parse(path)?;
    let source = Source { path, text: &text };
    file.camera.map(|c| source.camera(&c)).transpose()?;
    file.light.map(|l| source.light(&l)).transpose()?;
    let dir = path.parent().unwrap_or(Path::new(""));
    for entry in &file.mesh {
        source.transform(entry.get_ref())?;
        source.mesh_exists(entry, dir)?;
    }
    for entry in &file.instance {
        source.instance_transform(entry)?;
        source.mesh_exists(entry, dir)?;
    }
    Ok(())
}

/// Loads the scene file at `path`. Mesh paths are relative to the file's directory.
///
/// A mesh named by several entries (the same built-in name, or the same path as written) is
/// read once: a scene of 25 copies of a dragon parses one. The `[[mesh]]` entries are copied
/// into one mesh placed where it is (mesh 0, unnamed, so that its objects keep their names'
/// prefixes as written), and each `[[instance]]` places the mesh it names, held once; flattened
/// ([`InstancedScene::into_flat`]), the scene has the `[[mesh]]` entries' triangles first, then each
/// instance's in the file's order.
pub(super) fn load(path: &Path, progress: &dyn Progress) -> Result<InstancedScene> {
    let (text, file) = parse(path)?;
    let source = Source { path, text: &text };
    let mut scene = InstancedScene {
        name: file
            .name
            .clone()
            .unwrap_or_else(|| path.display().to_string()),
        camera: file.camera.map(|c| source.camera(&c)).transpose()?,
        light: file.light.map(|l| source.light(&l)).transpose()?,
        ..InstancedScene::default()
    };
    let dir = path.parent().unwrap_or(Path::new(""));
    let what = format!("loading the meshes of {}", path.display());
    let entries = (file.mesh.len() + file.instance.len()) as u64;
    step(progress, &what, entries, || {
        let mut loaded: HashMap<(bool, &str), Scene> = HashMap::new();
        let mut copied = Scene::new("");
        for entry in &file.mesh {
            let transform = source.transform(entry.get_ref())?;
            let named = source.mesh_ref(entry)?;
            let mesh = match loaded.entry(named.key()) {
                Entry::Occupied(known) => known.into_mut(),
                Entry::Vacant(new) => new.insert(source.mesh(named, dir)?),
            };
            if (copied.points.is_some() && mesh.triangle_count() > 0)
                || (copied.triangle_count() > 0 && mesh.points.is_some())
            {
                return Err(source.error(
                    entry.span(),
                    "this entry mixes a point cloud with triangle meshes: an RBVH is built from one \
                     or the other, so a scene file places point clouds or meshes, not both",
                ));
            }
            let placed = copied.positions.len();
            let points = copied.points.as_ref().map_or(0, |p| p.positions.len());
            copied.append(mesh, transform);
            let out_of_range = copied.positions[placed..]
                .iter()
                .position(|p| !p.is_finite());
            let out_of_range = out_of_range.or_else(|| {
                let cloud = &copied.points.as_ref()?.positions;
                cloud[points..].iter().position(|p| !p.is_finite())
            });
            if let Some(k) = out_of_range {
                return Err(source.error(
                    entry.span(),
                    format!(
                        "this entry's transform takes vertex {k} of its mesh beyond 32-bit \
                         floats (not finite): place it nearer or smaller"
                    ),
                ));
            }
            progress.advance(1);
        }
        if let (Some(_), Some(first)) = (&copied.points, file.instance.first()) {
            return Err(source.error(
                first.span(),
                "this [[instance]] places a triangle mesh beside the point clouds of the [[mesh]] \
                 entries: an RBVH is built from one or the other, so a scene file places point \
                 clouds or meshes, not both",
            ));
        }
        if !file.mesh.is_empty() {
            scene.meshes.push(copied);
            scene.instances.push(Instance {
                mesh: 0,
                transform: Mat4::IDENTITY,
            });
        }
        let mut mesh_of: HashMap<(bool, &str), u32> = HashMap::new();
        for entry in &file.instance {
            let transform = source.instance_transform(entry)?;
            let named = source.mesh_ref(entry)?;
            let mesh = match mesh_of.entry(named.key()) {
                Entry::Occupied(known) => *known.get(),
                Entry::Vacant(new) => {
                    let mesh = match loaded.remove(&named.key()) {
                        Some(mesh) => mesh,
                        None => source.mesh(named, dir)?,
                    };
                    if mesh.points.is_some() {
                        return Err(source.error(
                            entry.span(),
                            "an [[instance]] places a triangle mesh, and this is a point cloud: \
                             place it with [[mesh]]",
                        ));
                    }
                    scene.meshes.push(mesh);
                    *new.insert((scene.meshes.len() - 1) as u32)
                }
            };
            scene.instances.push(Instance { mesh, transform });
            progress.advance(1);
        }
        Ok::<(), Error>(())
    })?;
    scene.validate()?;
    Ok(scene)
}

/// The 1-based line of byte `offset` in `text`.
fn line_of(text: &str, offset: usize) -> usize {
    let before = &text.as_bytes()[..offset.min(text.len())];
    before.iter().filter(|&&b| b == b'\n').count() + 1
}

/// What a `[[mesh]]` names: a built-in scene or a file, with its place in the scene file.
#[derive(Clone, Copy)]
enum MeshRef<'e> {
    Builtin(&'e Spanned<String>),
    File(&'e Spanned<String>),
}

impl<'e> MeshRef<'e> {
    /// What the mesh is known by while loading: entries with equal keys name one mesh.
    fn key(self) -> (bool, &'e str) {
        match self {
            MeshRef::Builtin(name) => (true, name.get_ref()),
            MeshRef::File(file) => (false, file.get_ref()),
        }
    }
}

/// The file being read, for errors that point into it.
struct Source<'a> {
    path: &'a Path,
    text: &'a str,
}

impl Source<'_> {
    fn error(&self, span: Range<usize>, message: impl Into<String>) -> Error {
        Error::parse(self.path, Some(line_of(self.text, span.start)), message)
    }

    /// `value` as a vector, or an error naming `key` when a component is not finite.
    fn vec3(&self, key: &str, value: &Spanned<Triple>) -> Result<Vec3> {
        let v = Vec3::from_array(value.get_ref().0);
        if v.is_finite() {
            Ok(v)
        } else {
            Err(self.error(value.span(), format!("`{key}` must be finite, got {v}")))
        }
    }

    fn camera(&self, entry: &Spanned<CameraEntry>) -> Result<Camera> {
        let c = entry.get_ref();
        let eye = self.vec3("eye", &c.eye)?;
        let target = self.vec3("target", &c.target)?;
        let up =
            c.up.as_ref()
                .map_or(Ok(Vec3::Y), |up| self.vec3("up", up))?;
        let vfov_deg = c.vfov.as_ref().map_or(DEFAULT_VFOV_DEG, |v| *v.get_ref());
        Camera::look_at(eye, target, up, vfov_deg).map_err(|fault| {
            // The line of the entry at fault.
            let span = match fault {
                CameraFault::SameEyeAndTarget => c.target.span(),
                CameraFault::BadUp => c.up.as_ref().map_or(entry.span(), Spanned::span),
                CameraFault::BadVfov(_) => c.vfov.as_ref().map_or(entry.span(), Spanned::span),
                CameraFault::NotFinite => entry.span(),
            };
            self.error(span, fault.to_string())
        })
    }

    fn light(&self, entry: &Spanned<LightEntry>) -> Result<Light> {
        match (&entry.get_ref().direction, &entry.get_ref().position) {
            (Some(direction), None) => {
                let d = self.vec3("direction", direction)?;
                let Some(direction) = super::camera::direction(d) else {
                    return Err(self.error(direction.span(), "light `direction` must be non-zero"));
                };
                Ok(Light::Directional { direction })
            }
            (None, Some(position)) => Ok(Light::Point {
                position: self.vec3("position", position)?,
            }),
            _ => Err(self.error(
                entry.span(),
                "[light] needs exactly one of `direction` or `position`",
            )),
        }
    }

    /// An `[[instance]]`'s [`Source::transform`], refused where no instance can have it
    /// ([`transform_fault`]: it must be affine and invertible), by [`check`] as by [`load`].
    fn instance_transform(&self, entry: &Spanned<MeshEntry>) -> Result<Mat4> {
        let transform = self.transform(entry.get_ref())?;
        match transform_fault(&transform) {
            Some(fault) => Err(self.error(entry.span(), fault)),
            None => Ok(transform),
        }
    }

    /// `translate · rotate · scale`; rotations are in degrees about the X axis first, then Y,
    /// then Z (fixed axes).
    fn transform(&self, entry: &MeshEntry) -> Result<Mat4> {
        let translate = entry
            .translate
            .as_ref()
            .map_or(Ok(Vec3::ZERO), |t| self.vec3("translate", t))?;
        let rotate = entry
            .rotate
            .as_ref()
            .map_or(Ok(Vec3::ZERO), |r| self.vec3("rotate", r))?;
        let scale = match &entry.scale {
            None => Vec3::ONE,
            Some(s) => {
                let v = match s.get_ref() {
                    ScaleEntry::Uniform(k) => Vec3::splat(*k),
                    ScaleEntry::PerAxis(v) => Vec3::from_array(v.0),
                };
                if !v.is_finite() || v.cmpeq(Vec3::ZERO).any() {
                    return Err(self.error(
                        s.span(),
                        format!("`scale` must be finite and non-zero, got {v}"),
                    ));
                }
                v
            }
        };
        let r = rotate * std::f32::consts::PI / 180.0;
        let rotation =
            Mat4::from_rotation_z(r.z) * Mat4::from_rotation_y(r.y) * Mat4::from_rotation_x(r.x);
        Ok(Mat4::from_translation(translate) * rotation * Mat4::from_scale(scale))
    }

    /// The mesh an entry names, or an error when it names none or both.
    fn mesh_ref<'e>(&self, entry: &'e Spanned<MeshEntry>) -> Result<MeshRef<'e>> {
        match (&entry.get_ref().builtin, &entry.get_ref().path) {
            (Some(name), None) => Ok(MeshRef::Builtin(name)),
            (None, Some(file)) => Ok(MeshRef::File(file)),
            _ => Err(self.error(
                entry.span(),
                "[[mesh]] needs exactly one of `builtin` or `path`",
            )),
        }
    }

    /// Whether the mesh an entry names is there: a built-in name, or a regular file of a mesh
    /// type, without loading it.
    fn mesh_exists(&self, entry: &Spanned<MeshEntry>, dir: &Path) -> Result<()> {
        match self.mesh_ref(entry)? {
            MeshRef::Builtin(name) if super::builtin::NAMES.contains(&name.get_ref().as_str()) => {
                Ok(())
            }
            MeshRef::Builtin(name) => Err(self.error(
                name.span(),
                format!(
                    "unknown built-in scene {:?} (built-ins: {})",
                    name.get_ref(),
                    super::builtin::NAMES.join(", ")
                ),
            )),
            MeshRef::File(file) => {
                let path = dir.join(file.get_ref());
                check_mesh_file(&path)
                    .map(|_| ())
                    .map_err(|e| self.error(file.span(), format!("cannot load mesh: {e}")))
            }
        }
    }

    /// Loads the mesh `named`. Its objects are later prefixed with the name it is given here:
    /// the built-in name or the path as written, shorter than the resolved path.
    fn mesh(&self, named: MeshRef<'_>, dir: &Path) -> Result<Scene> {
        match named {
            MeshRef::Builtin(name) => {
                Scene::builtin(name.get_ref()).map_err(|e| self.error(name.span(), e.to_string()))
            }
            MeshRef::File(file) => {
                let mut mesh = load_mesh_file(&dir.join(file.get_ref()))
                    .map_err(|e| self.error(file.span(), format!("cannot load mesh: {e}")))?;
                mesh.name = file.get_ref().clone();
                Ok(mesh)
            }
        }
    }
}
