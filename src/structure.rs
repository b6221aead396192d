//! Which structure rays are traced through: the exact BVH, an RBVH, or an RBVH with its levels of
//! detail. One type for the CLI, the image regression, the bench and embedders alike (pbrt-v4 has
//! one `CreateAccelerator` behind one interface), so that "which structure" is decided once: a
//! [`Recipe`] says what to build, [`Structure::build`] builds it, [`Structure::memory`] says what
//! it costs, and every user uploads it ([`crate::gpu::Tracer::new`] takes one), traces it (rays
//! with their footprints, [`Cones`], whatever the structure) and names it the same way. It sits
//! below the GPU side: a structure is data, and the tracer chooses its shader by
//! [`Structure::kind`].

use std::sync::Arc;

use serde::Serialize;

use crate::bvh::{BuildParams, Bvh, InstancedBvh};
use crate::geom::{Hit, Ray};
use crate::lod::{Cones, Lod, LodParams};
use crate::progress::{Progress, Quiet};
use crate::rbvh::InstancedRbvh;
use crate::rbvh::{Rbvh, RbvhParams, RbvhSource};
use crate::scene::{InstancedScene, Scene};
use crate::Result;

/// Which structure, without it: the `method` of benchmark records (`"exact"`, `"rbvh"`,
/// `"rbvh-lod"`, `"exact-instanced"`, `"rbvh-instanced"`) and what [`Structure::kind`] says.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Kind {
    /// The exact triangle BVH ([`crate::bvh`]), the referee.
    Exact,
    /// An RBVH ([`crate::rbvh`]) traced at full resolution.
    Rbvh,
    /// An RBVH traced with its levels of detail ([`crate::lod`]).
    #[serde(rename = "rbvh-lod")]
    RbvhLod,
    /// The exact BVH of a scene with instances, in two levels ([`InstancedBvh`]).
    #[serde(rename = "exact-instanced")]
    ExactInstanced,
    /// The RBVH of a scene with instances, in two levels ([`InstancedRbvh`]).
    #[serde(rename = "rbvh-instanced")]
    RbvhInstanced,
}

impl Kind {
    /// Every kind, in the order the shader statistics list their pipelines.
    pub const ALL: [Kind; 5] = [
        Kind::Exact,
        Kind::ExactInstanced,
        Kind::Rbvh,
        Kind::RbvhLod,
        Kind::RbvhInstanced,
    ];

    /// `"exact"`, `"rbvh"`, `"rbvh-lod"`, `"exact-instanced"` or `"rbvh-instanced"`, as records
    /// and file names write it.
    pub fn name(self) -> &'static str {
        match self {
            Kind::Exact => "exact",
            Kind::Rbvh => "rbvh",
            Kind::RbvhLod => "rbvh-lod",
            Kind::ExactInstanced => "exact-instanced",
            Kind::RbvhInstanced => "rbvh-instanced",
        }
    }

    /// Whether it traces triangles exactly (the exact BVH, flat or in two levels): no march,
    /// no texels, no level of detail.
    pub fn is_exact(self) -> bool {
        matches!(self, Kind::Exact | Kind::ExactInstanced)
    }
}

/// What to build: the kind of structure with its parameters. Building the exact BVH takes none
/// of an RBVH's, and an RBVH's levels of detail are made from the RBVH they belong to, so each
/// kind holds exactly what it is built from.
///
/// A recipe says how a mesh is built, not where it is placed. Rates per object live in the
/// parameters ([`RbvhParams::object_rate`] sizes each object's texel by the object); a scene of
/// instances (one mesh placed many times) takes one recipe for the bottom level of each mesh,
/// with the top level over the placements beside it, so this type needs no variant for them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Recipe {
    /// The exact triangle BVH, built by binned SAH ([`BuildParams::DEFAULT`]).
    Exact,
    /// An RBVH built with these parameters.
    Rbvh(RbvhParams),
    /// An RBVH built with the first parameters, traced with levels of detail built with the
    /// second.
    RbvhLod(RbvhParams, LodParams),
}

impl Recipe {
    /// Which structure it builds.
    pub fn kind(&self) -> Kind {
        match self {
            Recipe::Exact => Kind::Exact,
            Recipe::Rbvh(_) => Kind::Rbvh,
            Recipe::RbvhLod(..) => Kind::RbvhLod,
        }
    }

    /// The RBVH's parameters, for the RBVH kinds.
    pub fn rbvh(&self) -> Option<&RbvhParams> {
        match self {
            Recipe::Exact => None,
            Recipe::Rbvh(params) | Recipe::RbvhLod(params, _) => Some(params),
        }
    }

    /// Checks every parameter ([`RbvhParams::validate`], [`LodParams::validate`]) and that
    /// levels of detail have the texels' normals to read, before anything is built.
    pub fn validate(&self) -> Result<()> {
        match self {
            Recipe::Exact => Ok(()),
            Recipe::Rbvh(params) => params.validate(),
            Recipe::RbvhLod(params, lod) => {
                params.validate()?;
                lod.validate()?;
                crate::lod::no_height_only_texels(params.texels)
            }
        }
    }
}

/// Bytes of one structure, as uploaded.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Memory {
    /// Nodes, plus height-field leaf records for an RBVH and coarse columns for `rbvh-lod`.
    pub tree: u64,
    /// Atlas texels and the blocks' height ranges; 0 for exact.
    pub atlas: u64,
    /// Triangles: all of them for exact, those of hybrid triangle leaves for an RBVH.
    pub triangles: u64,
    /// `tree + atlas + triangles`.
    pub total: u64,
    /// Texels of the height-field tiles (the atlas's unused ones not counted); 0 for exact.
    /// `atlas / texels` is what a texel costs on the device ([`Rbvh::bytes_per_texel`]).
    ///
    /// [`Rbvh::bytes_per_texel`]: crate::rbvh::Rbvh::bytes_per_texel
    pub texels: u64,
    /// Of `texels`, those of tiles with 8-bit heights ([`crate::rbvh::Rbvh::narrow_texels`]).
    pub narrow_texels: u64,
}

/// A built structure, ready to upload ([`crate::gpu::Tracer::new`]) or to trace on the CPU.
pub enum Structure {
    /// The exact triangle BVH, the referee.
    Exact(Bvh),
    /// An RBVH traced at full resolution. Shared, so that one RBVH can be traced both with and
    /// without levels of detail (as the benchmark does) without a copy.
    Rbvh(Arc<Rbvh>),
    /// An RBVH with its levels of detail (built for it), traced with one cone per ray.
    RbvhLod(Arc<Rbvh>, Box<Lod>),
    /// The exact BVH of a scene with instances: a tree per mesh, a top level over the
    /// instances ([`InstancedBvh`]).
    ExactInstanced(InstancedBvh),
    /// The RBVH of a scene with instances: an RBVH per mesh in its own space, a top level over
    /// the instances ([`InstancedRbvh`]).
    RbvhInstanced(Box<InstancedRbvh>),
}

impl From<InstancedRbvh> for Structure {
    fn from(rbvh: InstancedRbvh) -> Self {
        Structure::RbvhInstanced(Box::new(rbvh))
    }
}

impl From<InstancedBvh> for Structure {
    fn from(bvh: InstancedBvh) -> Self {
        Structure::ExactInstanced(bvh)
    }
}

impl From<Bvh> for Structure {
    fn from(bvh: Bvh) -> Self {
        Structure::Exact(bvh)
    }
}

impl From<Rbvh> for Structure {
    fn from(rbvh: Rbvh) -> Self {
        Structure::Rbvh(Arc::new(rbvh))
    }
}

impl From<Arc<Rbvh>> for Structure {
    fn from(rbvh: Arc<Rbvh>) -> Self {
        Structure::Rbvh(rbvh)
    }
}

impl Structure {
    /// Builds what `recipe` says for `scene`.
    pub fn build(scene: &Scene, recipe: &Recipe) -> Result<Structure> {
        Structure::build_observed(scene, recipe, &Quiet)
    }

    /// [`Structure::build`], reporting the build's counted steps to `progress`.
    pub fn build_observed(
        scene: &Scene,
        recipe: &Recipe,
        progress: &dyn Progress,
    ) -> Result<Structure> {
        recipe.validate()?;
        match recipe {
            Recipe::Exact => Ok(Structure::Exact(Bvh::build_observed(
                scene,
                &BuildParams::DEFAULT,
                progress,
            )?)),
            _ => Structure::build_from(&RbvhSource::new(scene)?, recipe, progress),
        }
    }

    /// [`Structure::build_observed`] of an RBVH kind from `source`, what every level of a scene
    /// shares (its parts, and the BVH its rings are sampled by), so that several levels are built
    /// from one; the exact BVH is built from the source's scene.
    pub fn build_from(
        source: &RbvhSource,
        recipe: &Recipe,
        progress: &dyn Progress,
    ) -> Result<Structure> {
        recipe.validate()?;
        match recipe {
            Recipe::Exact => Structure::build_observed(source.scene(), recipe, progress),
            Recipe::Rbvh(params) => Ok(Rbvh::build_from(source, params, progress)?.into()),
            Recipe::RbvhLod(params, lod) => {
                Structure::from(Rbvh::build_from(source, params, progress)?).with_levels(lod)
            }
        }
    }

    /// Builds what `recipe` says in two levels for a scene of instances: one bottom level per
    /// mesh and a top level over the placements ([`InstancedBvh`], [`InstancedRbvh`]), the
    /// meshes never copied. Levels of detail are refused, as [`Structure::with_levels`] refuses
    /// them over instances.
    pub fn build_instanced(
        scene: &InstancedScene,
        recipe: &Recipe,
        progress: &dyn Progress,
    ) -> Result<Structure> {
        recipe.validate()?;
        match recipe {
            Recipe::Exact => Ok(InstancedBvh::build(scene)?.into()),
            Recipe::Rbvh(params) => {
                Ok(InstancedRbvh::build_observed(scene, params, progress)?.into())
            }
            Recipe::RbvhLod(..) => Err(no_levels_over_instances()),
        }
    }

    /// The same RBVH (shared, not copied) traced with levels of detail built by `params`: what a
    /// measurement of both needs. Fails for the exact BVH, which has none.
    pub fn with_levels(&self, params: &LodParams) -> Result<Structure> {
        let rbvh = match self {
            Structure::Exact(_) | Structure::ExactInstanced(_) => {
                return Err(crate::Error::param(
                    "lod",
                    "levels of detail are built for an RBVH, not the exact BVH".to_string(),
                ))
            }
            Structure::RbvhInstanced(_) => return Err(no_levels_over_instances()),
            Structure::Rbvh(rbvh) | Structure::RbvhLod(rbvh, _) => rbvh,
        };
        let lod = Lod::build(rbvh, params)?;
        Ok(Structure::RbvhLod(Arc::clone(rbvh), Box::new(lod)))
    }

    /// What it costs on the device, by array. Levels of detail count with the tree: their
    /// columns are traversal data.
    pub fn memory(&self) -> Memory {
        match self {
            Structure::Exact(bvh) => Memory {
                tree: bvh.tree_bytes(),
                triangles: bvh.triangle_bytes(),
                total: bvh.tree_bytes() + bvh.triangle_bytes(),
                ..Memory::default()
            },
            // The instances' records are traversal data: they count with the tree.
            Structure::ExactInstanced(bvh) => {
                let tree = bvh.tree_bytes() + bvh.instance_bytes();
                Memory {
                    tree,
                    triangles: bvh.triangle_bytes(),
                    total: tree + bvh.triangle_bytes(),
                    ..Memory::default()
                }
            }
            Structure::RbvhInstanced(two) => {
                let rbvh = two.parts();
                let tree = rbvh.tree_bytes() + two.instance_bytes();
                Memory {
                    tree,
                    atlas: rbvh.atlas_bytes(),
                    triangles: rbvh.triangle_bytes(),
                    total: tree + rbvh.atlas_bytes() + rbvh.triangle_bytes(),
                    texels: rbvh.stats.tile_texels,
                    narrow_texels: rbvh.narrow_texels(),
                }
            }
            Structure::Rbvh(rbvh) | Structure::RbvhLod(rbvh, _) => {
                let lod = self.lod().map_or(0, Lod::bytes);
                Memory {
                    tree: rbvh.tree_bytes() + lod,
                    atlas: rbvh.atlas_bytes(),
                    triangles: rbvh.triangle_bytes(),
                    total: rbvh.total_bytes() + lod,
                    texels: rbvh.stats.tile_texels,
                    narrow_texels: rbvh.narrow_texels(),
                }
            }
        }
    }

    /// How long it took to build, in milliseconds (an RBVH's and its levels of detail's
    /// together).
    pub fn build_ms(&self) -> f64 {
        match self {
            Structure::Exact(bvh) => bvh.build_ms,
            Structure::ExactInstanced(bvh) => bvh.build_ms,
            Structure::RbvhInstanced(two) => two.stats().build_ms,
            Structure::Rbvh(rbvh) => rbvh.stats.build_ms,
            Structure::RbvhLod(rbvh, lod) => rbvh.stats.build_ms + lod.stats.build_ms,
        }
    }

    /// `rbvh` traced with its levels of detail `lod` (built for it by [`Lod::build`]).
    pub fn with_lod(rbvh: impl Into<Arc<Rbvh>>, lod: Lod) -> Self {
        Structure::RbvhLod(rbvh.into(), Box::new(lod))
    }

    /// The exact BVH, if that is what is traced.
    pub fn bvh(&self) -> Option<&Bvh> {
        match self {
            Structure::Exact(bvh) => Some(bvh),
            _ => None,
        }
    }

    /// The RBVH traced, if any (for the colour of its hits, its texel size): not one over
    /// instances, whose arrays are no RBVH to trace alone.
    pub fn rbvh(&self) -> Option<&Rbvh> {
        match self {
            Structure::Exact(_) | Structure::ExactInstanced(_) | Structure::RbvhInstanced(_) => {
                None
            }
            Structure::Rbvh(rbvh) | Structure::RbvhLod(rbvh, _) => Some(rbvh),
        }
    }

    /// The parameters of the RBVH traced, flat or in two levels; none for the exact BVH.
    pub fn rbvh_params(&self) -> Option<&RbvhParams> {
        match self {
            Structure::RbvhInstanced(two) => Some(two.params()),
            _ => self.rbvh().map(|r| &r.params),
        }
    }

    /// The world texel of the RBVH traced, flat or in two levels (there the flat scene's, which
    /// no instance's texel exceeds: `crate::rbvh::InstancedRbvh`'s rate rule): how far a
    /// secondary ray leaves its surface, since an RBVH surface may lie a fraction of a texel off
    /// the exact one. None for the exact BVH.
    pub fn texel_size(&self) -> Option<f32> {
        match self {
            Structure::RbvhInstanced(two) => Some(two.texel_size()),
            _ => self.rbvh().map(|r| r.texel_size),
        }
    }

    /// How far a secondary ray leaving `hit` starts off its surface beyond the rounding offset
    /// ([`crate::rays::offset_origin`]): one texel of the RBVH's surface there, which may lie a
    /// fraction of a texel off the exact one; for a two-level RBVH the hit instance's own texel
    /// ([`InstancedRbvh::instance_texel`]), so that it scales with each instance; 0 for the
    /// exact BVH.
    pub fn surface_offset(&self, hit: &Hit) -> f32 {
        match self {
            Structure::RbvhInstanced(two) => two.instance_texel(hit.instance),
            _ => self.texel_size().unwrap_or(0.0),
        }
    }

    /// The RBVH traced, if any, to change (painting its colour channel, say); a copy of it
    /// when it is shared with another structure.
    pub fn rbvh_mut(&mut self) -> Option<&mut Rbvh> {
        match self {
            Structure::Exact(_) | Structure::ExactInstanced(_) | Structure::RbvhInstanced(_) => {
                None
            }
            Structure::Rbvh(rbvh) | Structure::RbvhLod(rbvh, _) => Some(Arc::make_mut(rbvh)),
        }
    }

    /// The levels of detail, when traced with them.
    pub fn lod(&self) -> Option<&Lod> {
        match self {
            Structure::RbvhLod(_, lod) => Some(lod),
            _ => None,
        }
    }

    /// Which of the four it is.
    pub fn kind(&self) -> Kind {
        match self {
            Structure::Exact(_) => Kind::Exact,
            Structure::Rbvh(_) => Kind::Rbvh,
            Structure::RbvhLod(..) => Kind::RbvhLod,
            Structure::ExactInstanced(_) => Kind::ExactInstanced,
            Structure::RbvhInstanced(_) => Kind::RbvhInstanced,
        }
    }

    /// "exact BVH", "RBVH", "RBVH with levels of detail", "two-level exact BVH" or "two-level
    /// RBVH": for messages.
    pub fn label(&self) -> &'static str {
        match self {
            Structure::Exact(_) => "exact BVH",
            Structure::Rbvh(_) => "RBVH",
            Structure::RbvhLod(..) => "RBVH with levels of detail",
            Structure::ExactInstanced(_) => "two-level exact BVH",
            Structure::RbvhInstanced(_) => "two-level RBVH",
        }
    }

    /// The CPU reference of a trace of `rays`: closest hits, or with `any_hit` any hits. `cones`,
    /// the rays' footprints, are read only with levels of detail, which fail without them; as
    /// [`crate::gpu::Tracer::trace_with`].
    pub fn trace_cpu<'c>(
        &self,
        rays: &[Ray],
        cones: impl Into<Cones<'c>>,
        any_hit: bool,
    ) -> Result<Vec<Hit>> {
        Ok(match self {
            Structure::Exact(bvh) => bvh.trace_cpu(rays, any_hit),
            Structure::ExactInstanced(bvh) => bvh.trace_cpu(rays, any_hit),
            Structure::RbvhInstanced(two) => two.trace_cpu(rays, any_hit),
            Structure::Rbvh(rbvh) => rbvh.trace_cpu(rays, any_hit),
            Structure::RbvhLod(rbvh, lod) => rbvh.trace_cpu_lod(lod, rays, cones, any_hit)?,
        })
    }
}

/// Why levels of detail are not built over instances: a coarse node would stand for one
/// placement of a mesh, with world-sized columns (`crate::rbvh::InstancedRbvh`'s module).
fn no_levels_over_instances() -> crate::Error {
    crate::Error::param(
        "lod",
        "levels of detail are built for a flat RBVH, not over instances (trace the flat scene \
         for them)"
            .to_string(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each recipe builds its kind, and its memory is the sum of its arrays: the exact BVH's
    /// nodes and triangles, the RBVH's tree, atlas and triangles, and the levels of detail with
    /// the tree.
    #[test]
    fn a_recipe_builds_its_kind_and_counts_its_bytes() {
        let scene = Scene::builtin("sphere").unwrap();
        let params = RbvhParams::quality(1).unwrap();
        let lod = LodParams::default();
        let exact = Structure::build(&scene, &Recipe::Exact).unwrap();
        let rbvh = Structure::build(&scene, &Recipe::Rbvh(params)).unwrap();
        let with_lod = Structure::build(&scene, &Recipe::RbvhLod(params, lod)).unwrap();
        for (structure, kind) in [
            (&exact, Kind::Exact),
            (&rbvh, Kind::Rbvh),
            (&with_lod, Kind::RbvhLod),
        ] {
            assert_eq!(structure.kind(), kind);
            let m = structure.memory();
            assert_eq!(m.total, m.tree + m.atlas + m.triangles, "{kind:?}");
            assert!(m.total > 0 && structure.build_ms() > 0.0, "{kind:?}");
        }
        let bvh = exact.bvh().unwrap();
        assert_eq!(
            exact.memory().total,
            bvh.tree_bytes() + bvh.triangle_bytes()
        );
        let r = rbvh.rbvh().unwrap();
        assert_eq!(rbvh.memory().total, r.total_bytes());
        assert_eq!(rbvh.memory().texels, r.stats.tile_texels);
        // The same RBVH, built twice from one recipe, and its levels of detail on top.
        assert_eq!(with_lod.rbvh().unwrap().nodes, r.nodes);
        let lod_bytes = with_lod.lod().unwrap().bytes();
        assert_eq!(with_lod.memory().tree, rbvh.memory().tree + lod_bytes);
        assert_eq!(with_lod.memory().atlas, rbvh.memory().atlas);
        // Levels added to a built RBVH share it rather than copy it.
        let shared = rbvh.with_levels(&lod).unwrap();
        assert!(std::ptr::eq(shared.rbvh().unwrap(), r));
        assert!(exact.with_levels(&lod).is_err());
    }

    /// A recipe is checked before anything is built, its errors naming the parameter.
    #[test]
    fn a_bad_recipe_is_refused_by_name() {
        let scene = Scene::builtin("sphere").unwrap();
        let bad = RbvhParams {
            texels_per_diagonal: -1.0,
            ..RbvhParams::quality(1).unwrap()
        };
        let err = Structure::build(&scene, &Recipe::Rbvh(bad)).err().unwrap();
        assert!(err.to_string().contains("texels_per_diagonal"), "{err}");
        let lod = LodParams {
            columns: 0,
            ..LodParams::default()
        };
        let good = RbvhParams::quality(1).unwrap();
        let err = Structure::build(&scene, &Recipe::RbvhLod(good, lod))
            .err()
            .unwrap();
        assert!(err.to_string().contains("columns"), "{err}");
        assert_eq!(Recipe::RbvhLod(good, lod).kind(), Kind::RbvhLod);
        let height_only = RbvhParams {
            texels: crate::rbvh::TexelFormat::Height,
            ..good
        };
        let lod = LodParams::default();
        let err = Recipe::RbvhLod(height_only, lod).validate().unwrap_err();
        assert!(err.to_string().contains("normals"), "{err}");
        assert!(Recipe::Rbvh(height_only).validate().is_ok());
        assert_eq!(Recipe::Exact.rbvh(), None);
    }
}
