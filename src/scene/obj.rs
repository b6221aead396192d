//! Wavefront OBJ meshes, parsed by `tobj`. Each model (`o` or `g` group) becomes an object.
//!
//! Only positions and faces matter to a ray caster, so materials are never read: a missing or
//! malformed MTL file must not stop a mesh from loading. The file is read into memory first so
//! that a parse error can be given the line it happened on, which `tobj` does not report.

use std::io::Cursor;
use std::path::Path;

use glam::Vec3;

use super::Scene;
use crate::{Error, Result};

/// Loads the OBJ file at `path`: polygons are fan-triangulated, points and lines ignored.
pub(super) fn load(path: &Path) -> Result<Scene> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    check_face_indices(path, &bytes)?;
    let options = tobj::LoadOptions {
        triangulate: true,
        single_index: false,
        ignore_points: true,
        ignore_lines: true,
    };
    let mut cursor = Cursor::new(bytes.as_slice());
    let (models, _materials) = tobj::load_obj_buf(&mut cursor, &options, |_| {
        Err(tobj::LoadError::GenericFailure)
    })
    .map_err(|e| {
        let line = line_at(&bytes, cursor.position() as usize);
        Error::parse(path, Some(line), describe(e))
    })?;

    let mut scene = Scene::new(path.display().to_string());
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
        scene.push_object(name, &positions, &triangles);
    }
    // `tobj` renumbers vertices per model, so point at the file's own line instead when we can.
    scene
        .validate()
        .map_err(|e| non_finite_vertex(path, &bytes).unwrap_or(e))?;
    Ok(scene)
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

    #[test]
    fn line_at_counts_the_line_being_parsed() {
        let text = b"v 0 0 0\nv 1 x 0\nf 1 2 3";
        assert_eq!(line_at(text, 0), 1);
        assert_eq!(line_at(text, 16), 2);
        assert_eq!(line_at(text, text.len()), 3);
    }
}
