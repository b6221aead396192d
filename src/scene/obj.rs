//! Wavefront OBJ meshes, parsed by `tobj`. Each model (`o` or `g` group) becomes an object.
//!
//! Materials give the base colour only: `Kd` (taken as linear, like every renderer that reads
//! MTL) times the `map_Kd` image (sRGB, see `texture.rs`), with texture coordinates from `vt`
//! (whose origin is the image's bottom-left corner, so `v` is flipped). A missing or malformed MTL
//! file does not stop the mesh from loading: it then has no materials, as before materials were
//! read. But an image that a loaded material names must exist and decode: a missing one is
//! [`Error::Io`] and a corrupt one [`Error::Parse`], both naming the image — a silently grey
//! surface would hide the mistake. Relative MTL and image paths resolve against the OBJ's folder.
//! The file is read into memory first so that a parse error can be given the line it happened on,
//! which `tobj` does not report.

use std::collections::HashMap;
use std::io::Cursor;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::{Vec2, Vec3, Vec4};

use super::material::{Material, NO_MATERIAL};
use super::texture::Texture;
use super::{ObjectSurface, Scene};
use crate::{Error, Result};

/// Loads the OBJ file at `path`: polygons are fan-triangulated, points and lines ignored.
pub(super) fn load(path: &Path) -> Result<Scene> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    // A UTF-8 byte order mark (as some Windows editors write) would make the first line's
    // keyword unknown to tobj, which skips such lines: its first vertex would be lost unsaid.
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(&bytes);
    check_face_indices(path, bytes)?;
    let options = tobj::LoadOptions {
        triangulate: true,
        single_index: false,
        ignore_points: true,
        ignore_lines: true,
    };
    let base = match path.parent() {
        Some(dir) if !dir.as_os_str().is_empty() => dir.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let mut cursor = Cursor::new(bytes);
    let (models, materials) = tobj::load_obj_buf(&mut cursor, &options, |mtl| {
        let file = base.join(mtl);
        let regular = std::fs::metadata(&file).is_ok_and(|m| m.is_file());
        if !regular {
            return Err(tobj::LoadError::OpenFileFailed);
        }
        let text = std::fs::read(&file).map_err(|_| tobj::LoadError::OpenFileFailed)?;
        let text = String::from_utf8(text).map_err(|_| tobj::LoadError::ReadError)?;
        if !mtl_is_safe(&text) {
            return Err(tobj::LoadError::MaterialParseError);
        }
        tobj::load_mtl_buf(&mut text.as_bytes())
    })
    .map_err(|e| {
        let line = line_at(bytes, cursor.position() as usize);
        Error::parse(path, Some(line), describe(e))
    })?;

    let mut scene = Scene::new(path.display().to_string());
    let ids = add_materials(&mut scene, &models, &materials.unwrap_or_default(), &base)?;
    for (i, model) in models.iter().enumerate() {
        let mesh = &model.mesh;
        if mesh.indices.is_empty() {
            continue;
        }
        let positions: Vec<Vec3> = mesh
            .positions
            .chunks_exact(3)
            .map(|p| Vec3::new(p[0], p[1], p[2]))
            .collect();
        let triangles: Vec<[u32; 3]> = mesh
            .indices
            .chunks_exact(3)
            .map(|t| [t[0], t[1], t[2]])
            .collect();
        let name = if model.name.is_empty() {
            format!("object{i}")
        } else {
            model.name.clone()
        };
        match (ids.is_empty(), mesh.material_id) {
            (true, _) => scene.push_object(name, &positions, &triangles),
            (false, material) => {
                let id = material
                    .and_then(|m| ids.get(&m).copied())
                    .unwrap_or(NO_MATERIAL);
                let surface = ObjectSurface {
                    material_of_triangle: vec![id; triangles.len()],
                    uv_of_triangle: corner_uvs(mesh, triangles.len()),
                    colour_of_triangle: None,
                };
                scene.push_textured_object(name, &positions, &triangles, surface);
            }
        }
    }
    // `tobj` renumbers vertices per model, so point at the file's own line instead when we can.
    scene
        .validate()
        .map_err(|e| non_finite_vertex(path, bytes).unwrap_or(e))?;
    Ok(scene)
}

/// Adds the materials that some model uses to `scene` (none when no model uses one, so that a
/// mesh without materials gets no surface table), loading each image once; returns the scene's
/// id of each used `tobj` material index.
fn add_materials(
    scene: &mut Scene,
    models: &[tobj::Model],
    materials: &[tobj::Material],
    base: &Path,
) -> Result<HashMap<usize, u32>> {
    let mut used: Vec<usize> = models
        .iter()
        .filter_map(|m| m.mesh.material_id)
        .filter(|&m| m < materials.len())
        .collect();
    used.sort_unstable();
    used.dedup();
    let mut images: HashMap<PathBuf, Arc<Texture>> = HashMap::new();
    let mut ids = HashMap::new();
    for m in used {
        let mtl = &materials[m];
        let kd = mtl.diffuse.unwrap_or([1.0; 3]);
        let texture = match mtl.diffuse_texture.as_deref().and_then(texture_file) {
            Some(file) => {
                let file = base.join(file);
                let t = match images.get(&file) {
                    Some(t) => t.clone(),
                    None => Arc::new(Texture::load(&file)?),
                };
                images.insert(file, t.clone());
                Some(t)
            }
            None => None,
        };
        let material = Material {
            texture,
            ..Material::constant(mtl.name.clone(), Vec4::new(kd[0], kd[1], kd[2], 1.0))
        };
        ids.insert(m, scene.add_material(material));
    }
    Ok(ids)
}

/// Whether `tobj` 4 parses the MTL `text` without panicking: it unwraps the colour of a `Ka`,
/// `Kd`, `Ks` or `Ke` statement as three numbers without checking that there are three, and
/// slices a `newmtl` line at byte 6 whatever whitespace precedes the keyword. A file it would
/// panic on is malformed, like one it refuses (the mesh then loads without materials).
fn mtl_is_safe(text: &str) -> bool {
    text.lines().all(|line| {
        let mut words = line.split_whitespace();
        match words.next() {
            Some("Ka" | "Kd" | "Ks" | "Ke") => words.count() >= 3,
            Some("newmtl") => line.is_char_boundary(6),
            _ => true,
        }
    })
}

/// The file name of a `map_Kd` statement: the whole argument, or its last word when it starts
/// with options (`-s 1 1 1 wood.png`).
fn texture_file(argument: &str) -> Option<&str> {
    let argument = argument.trim();
    let file = if argument.starts_with('-') {
        argument.split_whitespace().last()?
    } else {
        argument
    };
    (!file.is_empty()).then_some(file)
}

/// Per triangle of `mesh`, its corners' texture coordinates with `v` flipped to the image's
/// top-left origin; zero where the mesh has none.
fn corner_uvs(mesh: &tobj::Mesh, triangles: usize) -> Vec<[Vec2; 3]> {
    let uv = |corner: usize| {
        mesh.texcoord_indices
            .get(corner)
            .and_then(|&i| mesh.texcoords.get(2 * i as usize..2 * i as usize + 2))
            .map_or(Vec2::ZERO, |t| Vec2::new(t[0], 1.0 - t[1]))
    };
    (0..triangles)
        .map(|t| [uv(3 * t), uv(3 * t + 1), uv(3 * t + 2)])
        .collect()
}

/// Refuses face indices that `tobj` cannot take safely, naming their line. `tobj` 4 turns an
/// index into a `usize` without checking and multiplies texture-coordinate and normal indices
/// unchecked: a zero, a relative index reaching before the first element, or an index beyond the
/// elements of its kind overflows (a panic in debug builds, a wrapped index in release builds).
/// So every `f` index is checked against the `v`, `vt` and `vn` lines: a positive one against
/// those in the whole file, a negative (relative) one against those before its line. Malformed
/// numbers are left to `tobj`, which reports them.
fn check_face_indices(path: &Path, bytes: &[u8]) -> Result<()> {
    const KINDS: [&str; 3] = ["v", "vt", "vn"];
    const NAMES: [&str; 3] = ["vertex", "texture coordinate", "normal"];
    let text = String::from_utf8_lossy(bytes);
    let kind = |line: &str| {
        let first = line.split_whitespace().next()?;
        KINDS.iter().position(|&k| k == first)
    };
    let mut total = [0i64; 3];
    for line in text.lines() {
        if let Some(k) = kind(line) {
            total[k] += 1;
        }
    }
    let mut seen = [0i64; 3];
    for (n, line) in text.lines().enumerate() {
        if let Some(k) = kind(line) {
            seen[k] += 1;
            continue;
        }
        let mut words = line.split_whitespace();
        if words.next() != Some("f") {
            continue;
        }
        // tobj drops a face of one or two vertices unsaid.
        let corners = words.clone().count();
        if corners < 3 {
            return Err(Error::parse(
                path,
                Some(n + 1),
                format!("a face has {corners} vertices; a face needs at least 3"),
            ));
        }
        for word in words {
            for (k, part) in word.split('/').take(3).enumerate() {
                let Ok(x) = part.parse::<i64>() else {
                    continue;
                };
                let fine = if x < 0 {
                    seen[k] + x >= 0
                } else {
                    x >= 1 && x <= total[k]
                };
                if !fine {
                    return Err(Error::parse(
                        path,
                        Some(n + 1),
                        format!(
                            "face index {part} refers to no {}: the file has {} ({} before this line)",
                            NAMES[k], total[k], seen[k]
                        ),
                    ));
                }
            }
        }
    }
    Ok(())
}

/// The 1-based line that a parser stopped in after consuming `pos` bytes: `tobj` reads line by
/// line, so the failing line is the last one consumed.
fn line_at(bytes: &[u8], pos: usize) -> usize {
    let consumed = &bytes[..pos.min(bytes.len())];
    let newlines = consumed.iter().filter(|&&b| b == b'\n').count();
    let unterminated = consumed.last().is_some_and(|&b| b != b'\n');
    (newlines + usize::from(unterminated)).max(1)
}

/// A message for a `tobj` error that says what is wrong in the user's terms.
fn describe(e: tobj::LoadError) -> String {
    use tobj::LoadError as E;
    match e {
        E::ReadError => "cannot read this line; is the file UTF-8 text?".to_owned(),
        E::PositionParseError => "malformed vertex: expected `v x y z [w]`".to_owned(),
        E::FaceParseError => {
            "malformed face: expected `f` followed by vertex indices that exist".to_owned()
        }
        E::FaceVertexOutOfBounds
        | E::FaceTexCoordOutOfBounds
        | E::FaceNormalOutOfBounds
        | E::FaceColorOutOfBounds => {
            format!("{e}: a face of the object or group ending here refers to data the file lacks")
        }
        other => other.to_string(),
    }
}

/// The first `v` line with a non-finite coordinate, as an error naming its line and its
/// 1-based OBJ vertex number; `None` when every `v` line is finite as written (the non-finite
/// value then came from arithmetic, and [`Scene::validate`]'s message is the best we have).
fn non_finite_vertex(path: &Path, bytes: &[u8]) -> Option<Error> {
    let text = String::from_utf8_lossy(bytes);
    let mut vertex = 0;
    for (line, content) in text.lines().enumerate() {
        let mut words = content.split_whitespace();
        if words.next() != Some("v") {
            continue;
        }
        vertex += 1;
        let finite = words
            .take(3)
            .all(|w| w.parse::<f32>().is_ok_and(f32::is_finite));
        if !finite {
            return Some(Error::InvalidGeometry {
                source_name: format!("{}:{}", path.display(), line + 1),
                message: format!("vertex {vertex} is not finite: `{}`", content.trim()),
            });
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A byte order mark before the first line leaves that line's vertex where it is.
    #[test]
    fn a_byte_order_mark_keeps_the_first_line() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bom.obj");
        std::fs::write(&path, b"\xEF\xBB\xBFv 5 5 5\nv 0 0 0\nv 1 0 0\nf 1 2 3\n").unwrap();
        let scene = load(&path).unwrap();
        assert_eq!(scene.triangle(0)[0], Vec3::splat(5.0));
    }

    #[test]
    fn line_at_counts_the_line_being_parsed() {
        let text = b"v 0 0 0\nv 1 x 0\nf 1 2 3";
        assert_eq!(line_at(text, 0), 1);
        assert_eq!(line_at(text, 16), 2);
        assert_eq!(line_at(text, text.len()), 3);
    }
}
