//! What a regression case is — a scene traced by one method — and how it is rendered: the same
//! camera, rays and preview shading as `rbvh render`, so a golden image is what a user of the CLI
//! would see.

use std::fmt;
use std::path::Path;

use crate::geom::Hit;
use crate::gpu::{Query, Tracer};
use crate::lod::{Cones, LodParams, RayCone};
use crate::output::Image;
use crate::preview;
use crate::rbvh::RbvhParams;
use crate::scene::Scene;
pub use crate::structure::Structure;
use crate::structure::{Kind, Recipe};
use crate::{Error, Result};

/// The structure a case traces through: a [`Kind`] of structure and, for the RBVH kinds, the
/// quality preset it is built at (level of detail with its default parameters, every primary
/// ray carrying its pixel's cone).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Method {
    kind: Kind,
    /// `Q0`…`Q4` (0..=4); 0 and unused for the exact BVH.
    level: u32,
}

impl Method {
    /// The exact triangle BVH, the referee.
    pub const EXACT: Method = Method {
        kind: Kind::Exact,
        level: 0,
    };

    /// An RBVH at quality preset `level` (`Q0`…`Q4`, 0..=4).
    pub const fn rbvh(level: u32) -> Method {
        Method {
            kind: Kind::Rbvh,
            level,
        }
    }

    /// The RBVH of preset `level` traced with its levels of detail.
    pub const fn rbvh_lod(level: u32) -> Method {
        Method {
            kind: Kind::RbvhLod,
            level,
        }
    }

    /// Which structure it traces.
    pub fn kind(&self) -> Kind {
        self.kind
    }

    /// `exact`, `rbvh_q<level>` or `rbvh_lod_q<level>`: the method's part of a golden file's name.
    pub fn file_tag(&self) -> String {
        match self.kind {
            Kind::Exact => "exact".into(),
            Kind::ExactInstanced => "exact_instanced".into(),
            Kind::Rbvh => format!("rbvh_q{}", self.level),
            Kind::RbvhLod => format!("rbvh_lod_q{}", self.level),
            Kind::RbvhInstanced => format!("rbvh_instanced_q{}", self.level),
        }
    }

    /// The RBVH preset the method traces, if any.
    pub fn level(&self) -> Option<u32> {
        (!self.kind.is_exact()).then_some(self.level)
    }
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.kind {
            Kind::Exact => f.write_str("exact"),
            Kind::ExactInstanced => f.write_str("exact, two levels"),
            Kind::Rbvh => write!(f, "RBVH Q{}", self.level),
            Kind::RbvhLod => write!(f, "RBVH Q{} with LOD", self.level),
            Kind::RbvhInstanced => write!(f, "RBVH Q{} in two levels", self.level),
        }
    }
}

/// One scene traced by one method: one golden image (and one golden depth).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Case {
    /// What [`Scene::load`] takes: a built-in name or a scene/mesh file.
    pub scene: String,
    /// The structure the scene is traced through.
    pub method: Method,
}

impl Case {
    /// `scene` (a [`Scene::load`] spec) traced by `method`; checked only when the run starts.
    pub fn new(scene: impl Into<String>, method: Method) -> Case {
        Case {
            scene: scene.into(),
            method,
        }
    }

    /// The stem of the case's golden files, `<scene>_<method>` (`default_exact`,
    /// `blob_rbvh_q2`). A scene given as a path contributes its file stem, with anything but
    /// ASCII letters, digits, `-` and `_` replaced by `_`, so that the name is a safe file name on
    /// every system and the golden folder can move between machines.
    pub fn name(&self) -> String {
        let stem = Path::new(&self.scene)
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let stem: String = stem
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                    c
                } else {
                    '_'
                }
            })
            .collect();
        let stem = if stem.is_empty() {
            "scene".into()
        } else {
            stem
        };
        format!("{stem}_{}", self.method.file_tag())
    }
}

/// Every scene traced by every method, scene by scene (so each scene is loaded once).
pub fn cross(scenes: &[String], methods: &[Method]) -> Vec<Case> {
    scenes
        .iter()
        .flat_map(|s| methods.iter().map(move |&m| Case::new(s.clone(), m)))
        .collect()
}

impl Method {
    /// What this method builds: the preset's RBVH, with default levels of detail for
    /// `rbvh-lod`.
    pub fn recipe(self) -> Result<Recipe> {
        Ok(match self.kind {
            // A two-level structure takes its flat twin's recipe for each mesh's tree (the image
            // regression traces scenes flattened: no case names a two-level method).
            Kind::Exact | Kind::ExactInstanced => Recipe::Exact,
            Kind::Rbvh | Kind::RbvhInstanced => Recipe::Rbvh(RbvhParams::quality(self.level)?),
            Kind::RbvhLod => {
                Recipe::RbvhLod(RbvhParams::quality(self.level)?, LodParams::default())
            }
        })
    }

    /// Builds the structure this method traces through, for `scene`.
    pub fn build(self, scene: &Scene) -> Result<Structure> {
        Structure::build(scene, &self.recipe()?)
    }
}

/// A case rendered: the shaded image and the primary hits it was shaded from.
pub struct Render {
    pub image: Image,
    pub hits: Vec<Hit>,
}

/// Renders `scene` through `tracer` (made for `structure`) as `rbvh render` does: the scene's
/// camera (or the framing one) at `width` × `height`, one primary ray per pixel centre (with its
/// pixel's cone for level of detail), shaded by [`preview::shade`] as `rbvh render` shades. Nothing here is random, so a render depends only
/// on the scene, the structure and the device's arithmetic.
pub fn render(
    tracer: &Tracer,
    structure: &Structure,
    scene: &Scene,
    width: u32,
    height: u32,
) -> Result<Render> {
    let camera = scene.camera_or_framed(width as f32 / height as f32);
    let rays = camera.primary_rays(width, height);
    let cones = Cones::Same(RayCone::pixel(&camera, height));
    let hits = tracer.trace_with(&rays, cones, Query::Closest, false)?.hits;
    let image = preview::shade(scene, structure, &rays, &hits, width, height)?;
    Ok(Render { image, hits })
}

/// Checks that no two cases share a golden file: two scene files with the same stem (or the same
/// case given twice) would otherwise silently compare against, or bless, each other's goldens.
/// Names are compared without case, since macOS's and Windows' file systems do not tell
/// `Bunny_exact.png` from `bunny_exact.png`, and a golden folder moves between systems.
pub fn check_unique_names(cases: &[Case]) -> Result<()> {
    let mut seen = std::collections::HashMap::new();
    for case in cases {
        let name = case.name();
        if let Some(other) = seen.insert(name.to_ascii_lowercase(), case) {
            let why = if other.scene == case.scene && other.method == case.method {
                format!("{:?} ({}) is given twice", case.scene, case.method)
            } else {
                format!(
                    "{:?} ({}) and {:?} ({}) would share the golden files {}.* (names are \
                     compared without case, as macOS and Windows file systems do); rename one \
                     of the files",
                    other.scene,
                    other.method,
                    case.scene,
                    case.method,
                    other.name()
                )
            };
            return Err(Error::param("scene", why));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_safe_file_stems() {
        assert_eq!(Case::new("default", Method::EXACT).name(), "default_exact");
        assert_eq!(Case::new("blob", Method::rbvh(2)).name(), "blob_rbvh_q2");
        assert_eq!(
            Case::new("../data/my dragon.v2.obj", Method::rbvh(4)).name(),
            "my_dragon_v2_rbvh_q4"
        );
    }

    #[test]
    fn clashing_names_are_an_error_naming_both() {
        let cases = cross(&["a/x.obj".into(), "b/x.obj".into()], &[Method::EXACT]);
        let err = check_unique_names(&cases).unwrap_err().to_string();
        assert!(err.contains("a/x.obj") && err.contains("b/x.obj"), "{err}");
        // One file on macOS and Windows.
        let cases = cross(
            &["a/Bunny.obj".into(), "b/bunny.obj".into()],
            &[Method::EXACT],
        );
        let err = check_unique_names(&cases).unwrap_err().to_string();
        assert!(
            err.contains("a/Bunny.obj") && err.contains("b/bunny.obj"),
            "{err}"
        );
        // A scene given twice has no file to rename.
        let cases = cross(&["sphere".into(), "sphere".into()], &[Method::EXACT]);
        let err = check_unique_names(&cases).unwrap_err().to_string();
        assert!(
            err.contains("given twice") && !err.contains("rename"),
            "{err}"
        );
        check_unique_names(&cross(
            &["sphere".into()],
            &[Method::EXACT, Method::rbvh(0)],
        ))
        .unwrap();
    }
}
