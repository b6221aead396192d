//! What every level of an RBVH of one scene shares ([`RbvhSource`]): the scene checked, its
//! triangles or points gathered with each object's size, and, made once for all levels, the
//! split primitives (with their connected parts, [`super::parts`]), the scene's open boundary
//! and creases, and the linear BVH of the scene that the ring samples trace. Also each object's
//! texel ([`object_texels`]), from those sizes.

use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;

use super::parts::connected_parts;
use super::Input;
use crate::bvh::{LinearBvh, LEAF_BIT};
use crate::geom::Aabb;
use crate::progress::{step, Progress};
use crate::rbvh::splat::Splat;
use crate::rbvh::split::SplitPrim;
use crate::scene::{topology, Scene, Topology};
use crate::{Error, Result};

/// Leaves of the builder's BVH of the scene, which the ring of samples around each leaf is
/// sampled from by short rays (`raster/ring.rs`). Eight: at the paper's scale the linear BVH of
/// leaves of four took 6.6–7.7 s of a level's 25, half of it packing its nodes (one thread), and
/// leaves of eight take 4.0–4.7 s while the rings' rays, testing more triangles a leaf, take no
/// measurably longer; sixteen made the dragon close-up's Q4 recursion 17% slower
/// (docs/paper-scale.md, "The ring's BVH with leaves of eight").
const SURFACE_LEAF: usize = 8;

/// What every level of an RBVH of one scene shares, made once for all of them: the scene
/// checked, its triangles (or points) gathered with their total area, and, at the first build
/// that needs them, each element's split primitive (box, centroid, area, connected part) and
/// the linear BVH of the scene that the ring samples trace. On the paper-scale scene (21.9M
/// triangles) that is about 12 of a Q2 build's 27 seconds (docs/paper-scale.md, "Build time at
/// 55b4840"), so `rbvh build --quality all` and `rbvh
/// bench` build every level from one source. Its builds are meant to run one after another:
/// two at once would each make the shared part (the same, twice).
pub struct RbvhSource<'s> {
    pub(super) scene: &'s Scene,
    /// The scene's triangles (none when it has points).
    tris: Vec<[Vec3; 3]>,
    /// The scene's points as splats (none when it has triangles).
    splats: Vec<Splat>,
    /// Per scene object, its surface area, box and element count (one object for points), for
    /// the texel-count estimate that refuses an oversized build early and for each object's
    /// texel.
    pub(super) objects: Vec<ObjectSize>,
    /// Made by the first build that passes that estimate.
    pub(super) shared: std::sync::OnceLock<Shared<'s>>,
    /// Milliseconds [`RbvhSource::new`] took. It and [`Shared::ms`] count into each level's
    /// [`RbvhStats::build_ms`]: what building that level alone costs.
    pub(super) new_ms: f64,
}

/// The costly part of an [`RbvhSource`].
pub(super) struct Shared<'s> {
    pub(super) prims: Vec<SplitPrim>,
    /// The scene's triangles in a BVH, for the surface around each leaf (its ring of samples).
    pub(super) surface: Option<LinearBvh<'s>>,
    /// Per scene triangle, whether it touches the open boundary
    /// ([`crate::scene::open_boundary`]); empty for points and for scenes with no open edge.
    pub(super) open: Vec<bool>,
    /// Per scene triangle, the angle at which it meets its neighbours
    /// ([`crate::scene::creases`]), for [`RbvhParams::exact_crease_deg`]; empty for points.
    pub(super) creases: Vec<f32>,
    /// Milliseconds making this took.
    pub(super) ms: f64,
}

impl<'s> RbvhSource<'s> {
    /// The scene it gathers.
    pub fn scene(&self) -> &'s Scene {
        self.scene
    }

    /// Checks `scene` (finite, and fewer than 2^31 triangles and points) and gathers its
    /// triangles or points.
    pub fn new(scene: &'s Scene) -> Result<RbvhSource<'s>> {
        scene.validate()?;
        let points = scene.points.as_ref().map_or(0, |c| c.len());
        if scene.triangle_count() >= LEAF_BIT as usize || points >= LEAF_BIT as usize {
            return Err(Error::param(
                "scene",
                format!(
                    "{} triangles and {points} points: each must stay below 2^31",
                    scene.triangle_count()
                ),
            ));
        }
        let start = Instant::now();
        let (tris, splats, objects): (Vec<[Vec3; 3]>, Vec<Splat>, Vec<ObjectSize>) =
            match &scene.points {
                Some(cloud) => {
                    let splats: Vec<Splat> = (0..cloud.len())
                        .map(|i| Splat {
                            position: cloud.positions[i],
                            normal: cloud.normals[i],
                            spacing: cloud.spacing[i],
                        })
                        .collect();
                    let area = splats.iter().map(|p| f64::from(p.spacing).powi(2)).sum();
                    let cloud = ObjectSize {
                        area,
                        bounds: scene.bounds(),
                        elements: splats.len(),
                    };
                    (Vec::new(), splats, vec![cloud])
                }
                None => {
                    let tris: Vec<[Vec3; 3]> = (0..scene.triangle_count())
                        .into_par_iter()
                        .map(|i| scene.triangle(i))
                        .collect();
                    let mut objects: Vec<ObjectSize> = scene
                        .object_bounds()
                        .into_iter()
                        .map(|bounds| ObjectSize {
                            area: 0.0,
                            bounds,
                            elements: 0,
                        })
                        .collect();
                    for (t, &o) in tris.iter().zip(&scene.object_of_triangle) {
                        let [a, b, c] = *t;
                        let object = &mut objects[o as usize];
                        object.area += 0.5 * (b - a).cross(c - a).length() as f64;
                        object.elements += 1;
                    }
                    (tris, Vec::new(), objects)
                }
            };
        Ok(RbvhSource {
            scene,
            tris,
            splats,
            objects,
            shared: std::sync::OnceLock::new(),
            new_ms: start.elapsed().as_secs_f64() * 1e3,
        })
    }

    /// What the leaves sample.
    pub(super) fn input(&self) -> Input<'_> {
        if self.scene.points.is_some() {
            Input::Points(&self.splats)
        } else {
            Input::Triangles(&self.tris)
        }
    }

    /// The split primitives and the surface BVH, made at the first call.
    pub(super) fn shared(&self, progress: &dyn Progress) -> Result<&Shared<'s>> {
        if let Some(shared) = self.shared.get() {
            return Ok(shared);
        }
        let start = Instant::now();
        let scene = self.scene;
        let prims: Vec<SplitPrim> = match self.input() {
            Input::Triangles(tris) => {
                let components = step(progress, "finding the scene's connected parts", 0, || {
                    connected_parts(scene)
                });
                tris.par_iter()
                    .zip(&components)
                    .map(|(t, &component)| {
                        let bounds = Aabb::from_points(*t);
                        SplitPrim {
                            bounds,
                            centroid: bounds.center(),
                            area: 0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length(),
                            component,
                        }
                    })
                    .collect()
            }
            // Points are not connected: a scan is one part, split by space alone.
            Input::Points(points) => points
                .iter()
                .map(|p| SplitPrim {
                    bounds: Aabb {
                        min: p.position - p.reach(),
                        max: p.position + p.reach(),
                    },
                    centroid: p.position,
                    area: p.spacing * p.spacing,
                    component: 0,
                })
                .collect(),
        };
        let surface = match self.input() {
            // Only traced by rays a few texels long: a linear BVH serves, in a fraction of the
            // exact BVH's time.
            Input::Triangles(_) => Some(step(
                progress,
                "building the BVH the rings are sampled by",
                0,
                || LinearBvh::build(scene, SURFACE_LEAF),
            )?),
            Input::Points(_) => None,
        };
        let Topology { open, creases } = match self.input() {
            Input::Triangles(_) => step(
                progress,
                "finding the scene's open edges and creases",
                0,
                || topology(scene),
            ),
            Input::Points(_) => Topology {
                open: Vec::new(),
                creases: Vec::new(),
            },
        };
        // Kept only where some triangle touches the open boundary: a closed scene has none to fill.
        let open = if open.contains(&true) {
            open
        } else {
            Vec::new()
        };
        let ms = start.elapsed().as_secs_f64() * 1e3;
        Ok(self.shared.get_or_init(|| Shared {
            prims,
            surface,
            open,
            creases,
            ms,
        }))
    }
}

/// How many times its box diagonal squared an object's area may be before the object counts as a
/// crowd rather than a surface ([`object_texels`]): a closed surface has about one time (a
/// sphere 1.05, the Stanford dragon about 1), a crowd of overlapping triangles thousands (200,000
/// triangles in a speck, `tests/stability`: 25,000). No height field represents a crowd, and
/// sampled for its own size it is no longer below a texel: every split tried to rasterize it and
/// traced its ring through the crowd, minutes where the scene's texel took a second. A crowd
/// takes the scene's texel.
const CROWD_LAYERS: f64 = 64.0;

/// What sizes one scene object's texel ([`object_texels`]).
#[derive(Clone, Copy, Debug)]
pub(super) struct ObjectSize {
    /// Surface area of its triangles (or its points' splats).
    pub(super) area: f64,
    /// Box of its triangles (or the scene's, for points).
    pub(super) bounds: Aabb,
    /// How many triangles (or points) it has.
    elements: usize,
}

/// Per object, its texel: the scene's `texel`, or finer where the object's own rate asks for it
/// (its box diagonal over `rate` texels), but never finer than the object's mean triangle
/// (the side of a square of its area over its triangle count): an object is not given more
/// texels than it has triangles, since it has no detail between them to sample (the grove's
/// blobs of 1,280 triangles, a fifty-fifth of their scene's diagonal, took 21.8M texels at Q4
/// without that bound, 4 times the scene's exact BVH). Empty when `rate` is 0 (every object
/// takes the scene's). An object without extent, or a crowd ([`CROWD_LAYERS`]), takes the
/// scene's.
pub(super) fn object_texels(objects: &[ObjectSize], texel: f32, rate: f32) -> Vec<f32> {
    if rate <= 0.0 {
        return Vec::new();
    }
    objects
        .iter()
        .map(|o| {
            let mean = (o.area / o.elements.max(1) as f64).sqrt() as f32;
            let diagonal = o.bounds.diagonal();
            let own = (diagonal / rate).max(mean);
            let crowd = o.area > CROWD_LAYERS * f64::from(diagonal) * f64::from(diagonal);
            if own.is_finite() && own > 0.0 && !crowd {
                texel.min(own)
            } else {
                texel
            }
        })
        .collect()
}
