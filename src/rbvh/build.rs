//! The top-down RBVH construction of Novák & Dachsbacher (2012):
//!
//! ```text
//! ConstructRBVH(surfaces):
//!   if surfaces cannot be represented by a single height field:
//!       split surfaces into A and B; ConstructRBVH(A); ConstructRBVH(B)
//!   else:
//!       rasterize surfaces into the atlas
//! ```
//!
//! "Can be represented" means: one connected part (with object split on), a projection axis
//! exists, the refinement criterion holds along it, and the rasterization is single-valued.
//! Beyond the paper, a set of at most `sampled_criterion_texels` texels whose triangles fail the
//! criterion passes if the cells of its rasterized tile meet it: below the sampling rate a scan's
//! noise cannot be represented, and judging it would cut the scan into leaves of a few texels.
//! A representable set larger than `max_tile` samples per side is cut into several tiles (the
//! paper's "subdivide large height fields") that overlap by one cell, so they meet without gaps.
//! A set that is not representable and spans fewer than `min_leaf_texels` texels stays as
//! triangles, traced exactly (the hybrid leaves). So do, beside a height field, the parts of its
//! own triangles that its tiles leave uncovered (`Tile::exposed`: over a cell the ring found no
//! surface for, or rising above or sinking under a cell's surface beyond what it stands in for),
//! so that a ray entering the solid through them cannot pass between the leaves. With
//! `exact_when_cheaper` (on in the presets) triangles that cost fewer bytes traced exactly than
//! sampled stay triangles too: before the recursion every triangle large enough
//! (`Builder::exact_by_size`), and in it every set whose tiles would cost more than its
//! triangles (`sampled_bytes`) — the paper's "triangle leaves where needed", decided by the
//! bytes each way.
//!
//! A scene with points ([`Scene::points`]) is built from them instead, by the same recursion: a
//! point is an element of surface with a normal and the area its spacing gives it, so the
//! criteria, frames and splits read it as they read a triangle, and leaves are splatted
//! (`splat.rs`) instead of rasterized. Points have no exact leaf to fall back on: a set that is
//! still not representable when it is a single point or smaller than `min_leaf_texels` is
//! splatted regardless (a forced leaf), its error bounded by its size.
//!
//! The tree a ray traverses over the leaves is the construction's own or one built again over the
//! leaves' boxes by the exact BVH's SAH, whichever the SAH finds cheaper (`upper_tree`).
//!
//! Parallel with `rayon::join` over subtrees; every per-node computation is sequential and ordered,
//! so the output is byte-identical for any thread count.

use std::collections::HashMap;
use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;

use super::atlas;
use super::frame::{fit, passes, projection_axis, rounding_pad, triangle_elements};
use super::layout::{Texel, HEIGHTFIELD_COUNT};
use super::raster::{rasterize, ring_reach, Frame, Ring, Tile, NO_SOURCE};
use super::splat::{splat, Splat};
use super::split::{split, SplitPrim};
use super::{Rbvh, RbvhParams, RbvhStats, TexelFormat};
use crate::bvh::{join_halves, ChildRef, GpuNode, GpuTriangle, LinearBvh, LEAF_BIT, STACK_SIZE};
use crate::geom::Aabb;
use crate::progress::{step, Progress, Quiet};
use crate::scene::{topology, Scene, Topology};
use crate::{Error, Result};

/// Most triangles in a triangle leaf.
const MAX_TRIANGLE_LEAF: usize = 8;
/// From this depth on, splits are object medians, bounding the construction's tree by 32 +
/// log2(n) (it is traversed where the SAH prefers it to the tree built again over its leaves,
/// `crate::bvh::tree_over`, which bounds its own depth the same way; see `upper_tree`).
const MEDIAN_BELOW_DEPTH: u32 = 32;
/// A set of points whose box is thinner than this fraction of its length is a slab: split by
/// facing when it is not one height field (`Builder::split_by_facing`).
const SLAB: f32 = 0.25;
/// What a triangle traced exactly costs: its 48 bytes ([`GpuTriangle`]) and, alone in its leaf,
/// the 48-byte node above it. A triangle whose area covers at least the texels these bytes buy
/// (24 with normals, 48 height-only) is traced exactly instead of sampled
/// ([`Builder::exact_by_size`]).
const EXACT_TRIANGLE_BYTES: f32 = 96.0;
/// Subtrees smaller than this are built on the calling thread.
const PARALLEL_THRESHOLD: usize = 2048;
/// Upper bound on tile texels before building: beyond it the atlas would not fit 32-bit indices
/// (nor any device), so the build refuses early instead of running out of memory.
const MAX_ESTIMATED_TEXELS: f64 = 2.0e9;

enum Node {
    Inner(Box<[Node; 2]>),
    Heightfield(Box<Tile>),
    Triangles {
        start: u32,
        count: u32,
    },
    /// Parts of triangles, traced exactly (at most [`MAX_TRIANGLE_LEAF`]).
    Pieces(Vec<GpuTriangle>),
    /// A height field's tiles (first) and the exact parts beside them (second), flattened as an
    /// inner node: each part's flags name its tile by its place among them
    /// (`GpuTriangle::part_flags(k, …)`) until flattening numbers the tiles' leaves.
    Surface(Box<[Node; 2]>),
}

/// What the leaves sample: the scene's triangles, or its points.
enum Input<'a> {
    Triangles(&'a [[Vec3; 3]]),
    Points(&'a [Splat]),
}

/// The least longest edge, in texels of its object, of a triangle that
/// [`RbvhParams::exact_crease_deg`] traces exactly: a crease shorter than that is detail the
/// texels average (a scan's noise meets its neighbours at 30° and more in many places, and at 1
/// texel the dragon's Q4 took 8.5% more bytes for the same accuracy; at 2, 1.4%:
/// docs/paper-scale.md, "What the view asks of Q0").
pub const CREASE_EDGE_TEXELS: f32 = 2.0;

/// Leaves of the builder's BVH of the scene, which the ring of samples around each leaf is
/// sampled from by short rays (`raster/ring.rs`): leaves of four keep a ray's triangle tests few
/// (with a median-split tree, 16 cost the dragon's Q4 a tenth more build time).
const SURFACE_LEAF: usize = 4;

struct Builder<'a> {
    input: Input<'a>,
    /// Keep [`Tile::sources`] (as scene triangle or point indices) for the colour channel.
    keep_sources: bool,
    prims: &'a [SplitPrim],
    params: &'a RbvhParams,
    /// Told of every leaf's triangles as the leaf is made.
    progress: &'a dyn Progress,
    /// The scene's texel: its diagonal over `texels_per_diagonal`.
    texel: f32,
    /// Per scene object, its texel ([`object_texels`]); empty when every object takes the
    /// scene's.
    object_texel: Vec<f32>,
    /// Per scene object, its box's diagonal, for [`RbvhParams::exact_edge_fraction`]; empty
    /// when that is 0.
    object_diagonal: Vec<f32>,
    /// Per scene triangle, its object (`Scene::object_of_triangle`); empty for points.
    objects: &'a [u32],
    /// The scene's triangles in a BVH, for the surface around each leaf (its ring of samples).
    surface: Option<&'a LinearBvh<'a>>,
    /// Per scene triangle, whether it touches the open boundary
    /// ([`crate::scene::open_boundary`]); empty for points and for scenes with no open edge.
    open: &'a [bool],
    /// Per scene triangle, the angle at which it meets its neighbours
    /// ([`crate::scene::creases`]); empty for points.
    creases: &'a [f32],
}

/// What every level of an RBVH of one scene shares, made once for all of them: the scene
/// checked, its triangles (or points) gathered with their total area, and, at the first build
/// that needs them, each element's split primitive (box, centroid, area, connected part) and
/// the linear BVH of the scene that the ring samples trace. On the paper-scale scene (21.9M
/// triangles) that is 10 of a Q2 build's 22 seconds, so `rbvh build --quality all` and `rbvh
/// bench` build every level from one source. Its builds are meant to run one after another:
/// two at once would each make the shared part (the same, twice).
pub struct RbvhSource<'s> {
    scene: &'s Scene,
    /// The scene's triangles (none when it has points).
    tris: Vec<[Vec3; 3]>,
    /// The scene's points as splats (none when it has triangles).
    splats: Vec<Splat>,
    /// Per scene object, its surface area, box and element count (one object for points), for
    /// the texel-count estimate that refuses an oversized build early and for each object's
    /// texel.
    objects: Vec<ObjectSize>,
    /// Made by the first build that passes that estimate.
    shared: std::sync::OnceLock<Shared<'s>>,
    /// Milliseconds [`RbvhSource::new`] took. It and [`Shared::ms`] count into each level's
    /// [`RbvhStats::build_ms`]: what building that level alone costs.
    new_ms: f64,
}

/// The costly part of an [`RbvhSource`].
struct Shared<'s> {
    prims: Vec<SplitPrim>,
    /// The scene's triangles in a BVH, for the surface around each leaf (its ring of samples).
    surface: Option<LinearBvh<'s>>,
    /// Per scene triangle, whether it touches the open boundary
    /// ([`crate::scene::open_boundary`]); empty for points and for scenes with no open edge.
    open: Vec<bool>,
    /// Per scene triangle, the angle at which it meets its neighbours
    /// ([`crate::scene::creases`]), for [`RbvhParams::exact_crease_deg`]; empty for points.
    creases: Vec<f32>,
    /// Milliseconds making this took.
    ms: f64,
}

impl<'s> RbvhSource<'s> {
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
    fn input(&self) -> Input<'_> {
        if self.scene.points.is_some() {
            Input::Points(&self.splats)
        } else {
            Input::Triangles(&self.tris)
        }
    }

    /// The split primitives and the surface BVH, made at the first call.
    fn shared(&self, progress: &dyn Progress) -> Result<&Shared<'s>> {
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
                tris.iter()
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
            Input::Triangles(_) => Some(LinearBvh::build(scene, SURFACE_LEAF)?),
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

impl Rbvh {
    /// Builds an RBVH of `scene` with `params` (see [`RbvhParams::quality`] for presets).
    pub fn build(scene: &Scene, params: &RbvhParams) -> Result<Rbvh> {
        Rbvh::build_observed(scene, params, &Quiet)
    }

    /// [`Rbvh::build`], reporting to `progress` the triangles placed in leaves (height fields,
    /// rasterized as they are made, or triangle leaves), then the baking of the colour channel.
    pub fn build_observed(
        scene: &Scene,
        params: &RbvhParams,
        progress: &dyn Progress,
    ) -> Result<Rbvh> {
        params.validate()?;
        Rbvh::build_from(&RbvhSource::new(scene)?, params, progress)
    }

    /// [`Rbvh::build_observed`] from a `source` that other levels of the same scene share: the
    /// same RBVH, byte for byte, without preparing the scene again. Its
    /// [`RbvhStats::build_ms`] counts the preparation as if this level had done it alone.
    pub fn build_from(
        source: &RbvhSource,
        params: &RbvhParams,
        progress: &dyn Progress,
    ) -> Result<Rbvh> {
        params.validate()?;
        let start = Instant::now();
        let scene = source.scene;
        let bounds = scene.bounds();
        let diagonal = bounds.diagonal();
        let texel = if diagonal > 0.0 {
            diagonal / params.texels_per_diagonal
        } else {
            1.0
        };
        let (input, elements) = match source.input() {
            input @ Input::Points(_) => (input, "points"),
            input @ Input::Triangles(_) => (input, "triangles"),
        };
        let object_texel = object_texels(
            &source.objects,
            texel,
            params.object_rate * params.texels_per_diagonal,
        );
        let (area, estimate) =
            source
                .objects
                .iter()
                .enumerate()
                .fold((0.0, 0.0), |(area, estimate), (o, object)| {
                    let t = f64::from(object_texel.get(o).copied().unwrap_or(texel));
                    (area + object.area, estimate + object.area / (t * t))
                });
        if estimate > MAX_ESTIMATED_TEXELS {
            // Named after the rate that asks for more: the objects', where any is finer.
            let (name, what) = if object_texel.iter().any(|&t| t < texel) {
                (
                    "object_rate",
                    format!(" and {} of it along each object's", params.object_rate),
                )
            } else {
                ("texels_per_diagonal", String::new())
            };
            return Err(Error::param(
                name,
                format!(
                    "{} texels along the scene's diagonal{what} would need about {estimate:.3e} texels for {area} of surface (limit {MAX_ESTIMATED_TEXELS:.0e}); lower the sampling rate or the quality level",
                    params.texels_per_diagonal
                ),
            ));
        }
        let made_here = source.shared.get().is_none();
        let shared = source.shared(progress)?;
        // What preparing took before this build started its clock.
        let prepared_ms = source.new_ms + if made_here { 0.0 } else { shared.ms };
        let prims = &shared.prims;
        let keep_sources = match &input {
            Input::Triangles(_) => scene.surface.is_some(),
            Input::Points(_) => scene.points.as_ref().is_some_and(|c| c.colours.is_some()),
        };
        let count = prims.len();
        let surface = shared.surface.as_ref();
        let open = &shared.open;
        let builder = Builder {
            input,
            keep_sources,
            prims,
            params,
            texel,
            object_texel,
            object_diagonal: if params.exact_edge_fraction > 0.0 {
                source.objects.iter().map(|o| o.bounds.diagonal()).collect()
            } else {
                Vec::new()
            },
            objects: match source.input() {
                Input::Triangles(_) => &scene.object_of_triangle,
                Input::Points(_) => &[],
            },
            progress,
            surface,
            open,
            creases: &shared.creases,
        };
        let (mut order, exact) = builder.exact_by_size();
        let root = step(
            progress,
            &format!("building the RBVH ({elements} into leaves)"),
            count as u64,
            || {
                progress.advance(exact.len() as u64);
                let sampled = (!order.is_empty()).then(|| builder.build(&mut order, 0, 0));
                let exact = (!exact.is_empty()).then(|| pieces_subtree(exact, 1));
                match (sampled, exact) {
                    (Some(a), Some(b)) => Some(Node::Inner(Box::new([a, b]))),
                    (a, b) => a.or(b),
                }
            },
        );

        let mut out = Flattened::default();
        let root_children = match &root {
            None => [ChildRef::ABSENT, ChildRef::ABSENT],
            Some(node @ (Node::Inner(children) | Node::Surface(children))) => {
                out.nodes.push(GpuNode::default());
                let refs = out.flatten_children(node, children, &builder, &order);
                out.nodes[0] = GpuNode::new(refs[0], refs[1]);
                refs
            }
            Some(leaf) => [out.flatten(leaf, &builder, &order), ChildRef::ABSENT],
        };
        if out.nodes.is_empty() {
            out.nodes
                .push(GpuNode::new(root_children[0], root_children[1]));
        }
        let (nodes, depth) = step(progress, "building the tree over the leaves", 0, || {
            upper_tree(&mut out, root.as_ref())
        })?;
        let footprints: Vec<atlas::Footprint> =
            out.tiles.iter().map(atlas::Footprint::of).collect();
        let packing = step(progress, "packing the atlas", 0, || {
            atlas::pack(&footprints)
        })?;
        for (leaf, &base) in out.leaves.iter_mut().zip(&packing.bases) {
            leaf.atlas_base = base;
        }
        let mut atlas = atlas::assemble(&out.tiles, &packing);
        let height_only = params.texels == TexelFormat::Height;
        if height_only {
            // Only the height codes are kept (and uploaded, two to a word or, 8-bit, four): a
            // hit's normal comes from the cell triangle it hit.
            for t in &mut atlas.texels {
                *t = Texel(u32::from(t.height_code()));
            }
        }
        let (tiles, bases, pitch, len) = (
            &out.tiles,
            &packing.bases,
            packing.pitch,
            atlas.texels.len(),
        );
        let colours = match (&builder.input, &scene.points, &scene.surface) {
            _ if height_only => None,
            (Input::Points(_), Some(cloud), _) => cloud
                .colours
                .as_ref()
                .map(|colours| super::bake::point_colours(colours, tiles, bases, pitch, len)),
            (Input::Triangles(_), _, Some(surface)) => {
                Some(step(progress, "baking the colour channel", 0, || {
                    super::bake::bake(scene, surface, tiles, bases, pitch, len)
                }))
            }
            _ => None,
        };
        let stats = RbvhStats {
            build_ms: prepared_ms + start.elapsed().as_secs_f64() * 1e3,
            heightfield_leaves: out.leaves.len() as u32,
            triangle_leaves: out.triangle_leaves,
            tile_texels: footprints
                .iter()
                .map(|f| u64::from(f.res_u) * u64::from(f.res_v))
                .sum(),
        };
        let bounds = root_children
            .iter()
            .filter(|c| !c.is_absent())
            .fold(Aabb::EMPTY, |b, c| b.union(c.bounds));
        Ok(Rbvh {
            params: *params,
            nodes,
            triangles: out.triangles,
            leaves: out.leaves,
            atlas,
            bounds,
            depth,
            texel_size: texel,
            stats,
            colours,
        })
    }
}

impl Builder<'_> {
    /// The scene's triangles split into those to sample (their indices, the construction's
    /// `order`) and, with `exact_when_cheaper`, those traced exactly because that costs fewer
    /// bytes: a triangle whose area covers at least [`EXACT_TRIANGLE_BYTES`] worth of texels of
    /// its object ([`Builder::texel_of`]), at the texel format's full bytes a texel. Such a triangle has no detail between its corners for
    /// texels to sample: a wall, a floor, a column's face, a cube's side. Sampled, it would also
    /// be widened at its silhouette by the dilated rim, the largest error on architecture (the
    /// columns and arches of the paper-scale scene's Sponza). With
    /// [`RbvhParams::exact_edge_fraction`], so is every triangle whose longest edge is at least
    /// that fraction of its object's diagonal, and with [`RbvhParams::exact_crease_deg`] every
    /// triangle on a crease that spans [`CREASE_EDGE_TEXELS`] texels. Points have no such
    /// triangles.
    fn exact_by_size(&self) -> (Vec<u32>, Vec<GpuTriangle>) {
        let all = match self.input {
            Input::Triangles(all) if self.params.exact_when_cheaper => all,
            _ => return ((0..self.prims.len() as u32).collect(), Vec::new()),
        };
        let texels = if self.params.exact_from_texels > 0.0 {
            self.params.exact_from_texels
        } else {
            EXACT_TRIANGLE_BYTES / self.params.texels.bytes() as f32
        };
        let (mut sampled, mut exact) = (Vec::new(), Vec::new());
        for (i, &[a, b, c]) in (0u32..).zip(all.iter()) {
            let texel = self.texel_of(&[i]);
            let area = 0.5 * (b - a).cross(c - a).length();
            let longest = (b - a).length().max((c - b).length()).max((a - c).length());
            if area >= texels * texel * texel
                || self.long_edge(i, longest)
                || self.on_crease(i, longest, texel)
            {
                exact.push(GpuTriangle::new([a, b, c], i));
            } else {
                sampled.push(i);
            }
        }
        (sampled, exact)
    }

    /// Whether triangle `i`, whose longest edge is `longest`, has an edge of at least
    /// [`RbvhParams::exact_edge_fraction`] of its object's diagonal (never where that is 0).
    fn long_edge(&self, i: u32, longest: f32) -> bool {
        let Some(&diagonal) = self
            .objects
            .get(i as usize)
            .and_then(|&o| self.object_diagonal.get(o as usize))
        else {
            return false;
        };
        longest >= self.params.exact_edge_fraction * diagonal
    }

    /// Whether triangle `i`, whose longest edge is `longest`, meets a neighbour at a crease of at
    /// least [`RbvhParams::exact_crease_deg`] (never where that is 0) with an edge of at least
    /// [`CREASE_EDGE_TEXELS`] of its object's `texel`.
    fn on_crease(&self, i: u32, longest: f32, texel: f32) -> bool {
        let angle = self.params.exact_crease_deg;
        let on = self.creases.get(i as usize).is_some_and(|&c| c >= angle);
        angle > 0.0 && on && longest >= CREASE_EDGE_TEXELS * texel
    }

    /// The texel of the set `order`: its objects' finest ([`RbvhParams::object_rate`]),
    /// or the scene's. With object split on, a set that becomes a leaf lies in one object.
    fn texel_of(&self, order: &[u32]) -> f32 {
        if self.objects.is_empty() {
            // Points: the cloud is one object.
            return self.object_texel.first().copied().unwrap_or(self.texel);
        }
        if self.object_texel.is_empty() {
            return self.texel;
        }
        order.iter().fold(self.texel, |t, &i| {
            t.min(self.object_texel[self.objects[i as usize] as usize])
        })
    }

    fn build(&self, order: &mut [u32], offset: u32, depth: u32) -> Node {
        let n = order.len();
        // The box of the surface the set samples: its triangles, or its points (whose splits
        // see them with their reach, but whose size is that of the samples).
        let bounds = match self.input {
            Input::Triangles(_) => order
                .iter()
                .fold(Aabb::EMPTY, |b, &i| b.union(self.prims[i as usize].bounds)),
            Input::Points(_) => order
                .iter()
                .fold(Aabb::EMPTY, |b, &i| b.grow(self.prims[i as usize].centroid)),
        };
        let texel = self.texel_of(order);
        let first = &self.prims[order[0] as usize];
        let one_part = !self.params.object_split
            || order
                .iter()
                .all(|&i| self.prims[i as usize].component == first.component);
        if one_part {
            if let Some(tiles) = self.heightfield(order, bounds.diagonal(), texel) {
                self.progress.advance(n as u64);
                let parts = self.parts(&tiles, order);
                if let (Input::Triangles(all), true) = (&self.input, self.params.exact_when_cheaper)
                {
                    if sampled_bytes(&tiles, parts.len(), self.params.texels)
                        > n as f32 * EXACT_TRIANGLE_BYTES
                    {
                        let exact = order.iter().map(|&i| GpuTriangle::new(all[i as usize], i));
                        return pieces_subtree(exact.collect(), 1);
                    }
                }
                return self.surface_subtree(tiles, parts, order);
            }
        }
        let small = bounds.diagonal() < self.params.min_leaf_texels * texel;
        // A slab (thinner than that, or than a quarter of its length: two sides of a thin sheet,
        // scanned from both): space splits along its length and never between its sides, only
        // their facing does.
        let extent = bounds.extent();
        let thin = extent.min_element()
            < (self.params.min_leaf_texels * texel).max(SLAB * extent.max_element());
        match self.input {
            Input::Triangles(_) if n == 1 || (n <= MAX_TRIANGLE_LEAF && small) => {
                self.progress.advance(n as u64);
                return Node::Triangles {
                    start: offset,
                    count: n as u32,
                };
            }
            Input::Points(points) if n > 1 && (small || thin) => {
                let classes = facing_classes(points, order);
                let two_sided = (0..3).any(|axis| classes >> (2 * axis) & 0b11 == 0b11);
                if (small && classes.count_ones() > 1) || (thin && two_sided) {
                    return self.split_by_facing(points, order, offset, depth);
                }
                if n == 1 || small {
                    return self.forced(points, order, offset, texel);
                }
            }
            Input::Points(points) if n == 1 => return self.forced(points, order, offset, texel),
            _ => {}
        }
        let mid = split(
            self.prims,
            order,
            self.params.subdivision,
            self.params.object_split,
            depth >= MEDIAN_BELOW_DEPTH,
        );
        let (left, right) = order.split_at_mut(mid);
        let (a, b) = join_halves(
            n >= PARALLEL_THRESHOLD,
            || self.build(left, offset, depth + 1),
            || self.build(right, offset + mid as u32, depth + 1),
        );
        Node::Inner(Box::new([a, b]))
    }

    /// The subtree of the set `order` made one height field of `tiles`: the tiles, and beside
    /// them, when they leave some of the set's triangles uncovered ([`Tile::exposed`]: over a
    /// cell the ring found no surface for, or rising above or sinking under a cell's surface
    /// beyond what it stands in for), those triangles' parts there as triangle leaves,
    /// traced exactly, so that a ray entering the solid through them meets them where the
    /// height field, and its neighbours', may leave a gap.
    fn surface_subtree(&self, tiles: Vec<Tile>, pieces: Vec<GpuTriangle>, order: &[u32]) -> Node {
        let surface = tiles_subtree(self.scene_sources(tiles, order));
        if pieces.is_empty() {
            return surface;
        }
        Node::Surface(Box::new([
            surface,
            pieces_subtree(pieces, MAX_TRIANGLE_LEAF),
        ]))
    }

    /// The exact parts of the set `order`'s triangles beside its `tiles` (see
    /// [`Builder::surface_subtree`]), each naming its tile.
    fn parts(&self, tiles: &[Tile], order: &[u32]) -> Vec<GpuTriangle> {
        match self.input {
            Input::Triangles(all) => tiles
                .iter()
                .enumerate()
                .flat_map(|(k, tile)| {
                    tile.exposed.iter().flat_map(move |e| {
                        let prim = order[e.input as usize];
                        e.part(&tile.frame, &all[prim as usize])
                            .into_iter()
                            .map(move |t| GpuTriangle {
                                flags: GpuTriangle::part_flags(k as u32, e.bare),
                                ..GpuTriangle::new(t, prim)
                            })
                    })
                })
                .collect(),
            Input::Points(_) => Vec::new(),
        }
    }

    /// The forced leaf of the points `order` (see [`Builder::forced_heightfield`]).
    fn forced(&self, points: &[Splat], order: &[u32], offset: u32, texel: f32) -> Node {
        self.progress.advance(order.len() as u64);
        let tiles = self.forced_heightfield(points, order, texel);
        if tiles.is_empty() {
            // Unreachable for finite points (each marks the sample nearest to it); an empty
            // leaf keeps the tree whole if it were not.
            return Node::Triangles {
                start: offset,
                count: 0,
            };
        }
        tiles_subtree(self.scene_sources(tiles, order))
    }

    /// A small or thin set of points that is not one height field, split by which of the six
    /// axis directions each normal is nearest (at most 54.7° away): where space can no longer be
    /// split usefully (a closed speck: a claw, a horn's tip) or never between the sides (a thin
    /// sheet scanned from both), the sides a set shows each way are split apart, each a better
    /// candidate for a height field than the whole, instead of being cut into leaves of a few
    /// points or squashed into one forced leaf. Triangles need no such split: they fall back to
    /// exact leaves.
    fn split_by_facing(&self, all: &[Splat], order: &mut [u32], offset: u32, depth: u32) -> Node {
        order.sort_by_key(|&i| facing_class(all[i as usize].normal));
        let mut children = Vec::new();
        let (mut rest, mut start) = (order, 0usize);
        while !rest.is_empty() {
            let class = facing_class(all[rest[0] as usize].normal);
            let len = rest
                .iter()
                .position(|&i| facing_class(all[i as usize].normal) != class)
                .unwrap_or(rest.len());
            let (group, tail) = rest.split_at_mut(len);
            children.push(self.build(group, offset + start as u32, depth + 1));
            start += len;
            rest = tail;
        }
        balanced(children)
    }

    /// `tiles` of the set `order` with their sources turned from indices into the set to scene
    /// triangle or point indices, or dropped when no colour channel needs them.
    fn scene_sources(&self, mut tiles: Vec<Tile>, order: &[u32]) -> Vec<Tile> {
        for tile in &mut tiles {
            tile.sources = if self.keep_sources {
                let scene_index = |s: u32| order.get(s as usize).copied();
                tile.sources
                    .iter()
                    .map(|&s| scene_index(s).unwrap_or(NO_SOURCE))
                    .collect()
            } else {
                Vec::new()
            };
        }
        tiles
    }

    /// The tiles of the set `order` (whose box diagonal is `diagonal`) as one height field of
    /// texels `texel` wide, or None when it is not representable.
    fn heightfield(&self, order: &[u32], diagonal: f32, texel: f32) -> Option<Vec<Tile>> {
        match self.input {
            Input::Triangles(all) => {
                let tris: Vec<[Vec3; 3]> = order.iter().map(|&i| all[i as usize]).collect();
                let open: Vec<bool> = if self.open.is_empty() {
                    Vec::new()
                } else {
                    order.iter().map(|&i| self.open[i as usize]).collect()
                };
                let elements = triangle_elements(&tris);
                let (frame, judge) =
                    self.judged_frame(&elements, tris.as_flattened(), 0.0, diagonal, texel)?;
                let ring = self.surface.map(|surface| Ring {
                    surface,
                    reach: ring_reach(self.params.refinement),
                });
                // Layers closer than a texel are one surface at this sampling rate.
                self.tiles(&frame, |window| {
                    rasterize(&tris, window, texel, judge, ring, &open)
                })
            }
            Input::Points(all) => {
                let (points, positions, reach) = gather(all, order);
                let elements = point_elements(&points);
                let (frame, judge) =
                    self.judged_frame(&elements, &positions, reach, diagonal, texel)?;
                self.tiles(&frame, |window| splat(&points, window, texel, judge, false))
            }
        }
    }

    /// The frame of a set of surface `elements` (see `frame::triangle_elements`) with corner or
    /// point `positions` reaching `margin` beyond them, and the criterion its samples must pass
    /// (None: its elements passed already); None when it is not representable as one height field
    /// at any sampling: no projection axis, or failing the criterion while larger than
    /// `sampled_criterion_texels`.
    fn judged_frame(
        &self,
        elements: &[Vec3],
        positions: &[Vec3],
        margin: f32,
        diagonal: f32,
        texel: f32,
    ) -> Option<(Frame, Option<super::Refinement>)> {
        let w = projection_axis(elements)?;
        let elements_pass = passes(self.params.refinement, elements, w);
        if !elements_pass && diagonal > self.params.sampled_criterion_texels * texel {
            return None;
        }
        // Elements that fail the criterion get a second hearing on their surface as sampled.
        let judge = (!elements_pass).then_some(self.params.refinement);
        Some((fit(positions, w, texel, margin), judge))
    }

    /// The covered tiles of `frame`'s windows (at most `max_tile` samples a side), each sampled
    /// by `sample`; None when any window is not a height field, or none is covered.
    fn tiles(&self, frame: &Frame, sample: impl Fn(&Frame) -> Option<Tile>) -> Option<Vec<Tile>> {
        let mut tiles = Vec::new();
        for window in windows(frame, self.params.max_tile) {
            let tile = sample(&window)?;
            if tile.covered > 0 {
                tiles.push(tile);
            }
        }
        (!tiles.is_empty()).then_some(tiles)
    }

    /// A forced leaf of the points `order` (see `splat.rs`): splatted along their area-weighted
    /// normal (or the first point's, when their normals cancel), the nearest point winning where
    /// they overlap.
    fn forced_heightfield(&self, all: &[Splat], order: &[u32], texel: f32) -> Vec<Tile> {
        let (points, positions, reach) = gather(all, order);
        let w = projection_axis(&point_elements(&points))
            .or_else(|| points.first().map(|p| p.normal))
            .unwrap_or(Vec3::Z);
        let frame = fit(&positions, w, texel, reach);
        self.tiles(&frame, |window| splat(&points, window, texel, None, true))
            .unwrap_or_default()
    }
}

/// Which of the six axis directions (+x, −x, +y, −y, +z, −z: 0…5) `normal` is nearest.
fn facing_class(normal: Vec3) -> u8 {
    let a = normal.abs();
    let axis = if a.x >= a.y && a.x >= a.z {
        0
    } else if a.y >= a.z {
        1
    } else {
        2
    };
    2 * axis + u8::from(normal[axis as usize] < 0.0)
}

/// The facing classes the points `order` fall into, as a mask (bit `c` for class `c`).
fn facing_classes(all: &[Splat], order: &[u32]) -> u8 {
    order
        .iter()
        .fold(0u8, |m, &i| m | 1 << facing_class(all[i as usize].normal))
}

/// A balanced subtree over `nodes` (at least one), in their order.
fn balanced(mut nodes: Vec<Node>) -> Node {
    if nodes.len() == 1 {
        return nodes.pop().expect("one node");
    }
    let right = nodes.split_off(nodes.len() / 2);
    Node::Inner(Box::new([balanced(nodes), balanced(right)]))
}

/// The points `order` of `all`, their positions, and the farthest any of their splats reaches.
fn gather(all: &[Splat], order: &[u32]) -> (Vec<Splat>, Vec<Vec3>, f32) {
    let points: Vec<Splat> = order.iter().map(|&i| all[i as usize]).collect();
    let positions = points.iter().map(|p| p.position).collect();
    let reach = points.iter().map(Splat::reach).fold(0.0, f32::max);
    (points, positions, reach)
}

/// The surface elements of points (see `frame::triangle_elements`): each normal times the area
/// its spacing stands for.
fn point_elements(points: &[Splat]) -> Vec<Vec3> {
    points
        .iter()
        .map(|p| p.normal * (p.spacing * p.spacing))
        .collect()
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
struct ObjectSize {
    /// Surface area of its triangles (or its points' splats).
    area: f64,
    /// Box of its triangles (or the scene's, for points).
    bounds: Aabb,
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
fn object_texels(objects: &[ObjectSize], texel: f32, rate: f32) -> Vec<f32> {
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

/// Cuts `frame` into windows of at most `max` samples per side. Neighbouring windows overlap by
/// one cell (window k starts at sample k·(max − 2)): each window's origin is rounded to f32 on its
/// own, so samples that two windows would share in exact arithmetic lie up to an ulp apart, and a
/// ray aimed exactly at a seam of shared samples could slip between the two tiles. Far from the
/// world origin, where rounding moves grids by a noticeable part of a texel, the overlap grows
/// by [`rounding_pad`] cells (at most `(max − 2) / 2`).
fn windows(frame: &Frame, max: u32) -> Vec<Frame> {
    let reach =
        frame.origin.abs().max_element() + (frame.res_u as f32 + frame.res_v as f32) * frame.texel;
    let overlap = rounding_pad(2.0 * reach, frame.texel)
        .max(1)
        .min((max - 2) / 2);
    let starts = |res: u32| -> Vec<(u32, u32)> {
        if res <= max {
            return vec![(0, res)];
        }
        let step = max - 1 - overlap;
        let mut out = Vec::new();
        let mut s = 0;
        loop {
            let n = max.min(res - s);
            out.push((s, n));
            if s + n >= res {
                break;
            }
            s += step;
        }
        out
    };
    let mut out = Vec::new();
    for &(sv, nv) in &starts(frame.res_v) {
        for &(su, nu) in &starts(frame.res_u) {
            out.push(Frame {
                origin: (frame.origin.as_dvec3()
                    + (su as f64 * frame.texel as f64) * frame.u.as_dvec3()
                    + (sv as f64 * frame.texel as f64) * frame.v.as_dvec3())
                .as_vec3(),
                res_u: nu,
                res_v: nv,
                ..*frame
            });
        }
    }
    out
}

/// The device bytes of a height field of `tiles` beside `parts` exact parts: each tile's texels
/// (one byte less for 8-bit heights), its 64-byte leaf record and a 48-byte node over it, and
/// each part's 48-byte triangle.
fn sampled_bytes(tiles: &[Tile], parts: usize, format: TexelFormat) -> f32 {
    let tiles: u64 = tiles
        .iter()
        .map(|tile| {
            let texel = format.bytes() - u64::from(tile.narrow);
            tile.texels.len() as u64 * texel + 64 + 48
        })
        .sum();
    (tiles + parts as u64 * 48) as f32
}

/// A balanced subtree over the tiles of one subdivided height field (in window order, so halves
/// are spatially coherent).
fn tiles_subtree(tiles: Vec<Tile>) -> Node {
    balanced(
        tiles
            .into_iter()
            .map(|tile| Node::Heightfield(Box::new(tile)))
            .collect(),
    )
}

/// A subtree of [`Node::Pieces`] leaves over `pieces`: halved at the median of their centroids
/// along the longest side of the centroids' box until a leaf holds at most `max_leaf` pieces
/// lying together, its box at most twice as long as its longest piece's. Exact parts take
/// [`MAX_TRIANGLE_LEAF`]; triangles traced exactly for their size one each, since their long
/// boxes overlap, and rays entering a leaf of eight of them tested most for nothing (28
/// triangles per primary ray on the paper-scale scene at Q2, against the exact BVH's 5.3).
/// Pieces from places apart in one leaf (two rims of one surface) would give it a box
/// that rays between them enter for nothing: on the default scene at Q2–Q4, 0.11–0.14
/// triangles tested per primary ray instead of 0.00–0.01. Ties keep their order (a stable
/// sort), so it is deterministic.
fn pieces_subtree(mut pieces: Vec<GpuTriangle>, max_leaf: usize) -> Node {
    let bounds = |t: &GpuTriangle| Aabb::from_points(t.vertices());
    let union = pieces.iter().fold(Aabb::EMPTY, |b, t| b.union(bounds(t)));
    let longest = pieces
        .iter()
        .map(|t| bounds(t).extent().max_element())
        .fold(0.0, f32::max);
    let together = union.extent().max_element() <= 2.0 * longest;
    if pieces.len() == 1 || (pieces.len() <= max_leaf && together) {
        return Node::Pieces(pieces);
    }
    let centroid = |t: &GpuTriangle| t.vertices().into_iter().sum::<Vec3>();
    let axis = pieces
        .iter()
        .fold(Aabb::EMPTY, |b, t| b.grow(centroid(t)))
        .largest_axis();
    pieces.sort_by(|a, b| centroid(a)[axis].total_cmp(&centroid(b)[axis]));
    let right = pieces.split_off(pieces.len() / 2);
    Node::Inner(Box::new([
        pieces_subtree(pieces, max_leaf),
        pieces_subtree(right, max_leaf),
    ]))
}

/// The tree traversal runs over the leaves of `out`: the construction's own (`out.nodes`, of
/// depth `root`'s), or one built again over the leaves' boxes by the exact BVH's SAH
/// ([`crate::bvh::tree_over`]), whichever the SAH finds cheaper ([`crate::bvh::sah_cost`]),
/// the construction's on a tie.
///
/// The construction splits until a set is one height field: its splits serve the refinement
/// criterion and the object split, not traversal. Over many objects that tree is poor: on the
/// paper-scale scene at Q2 a primary ray visited 108 inner nodes against the exact BVH's 63, and
/// the SAH tree over the same leaves costs 62.4 against 107.9 (inner nodes' areas over the root's)
/// and takes rays through 59 nodes. Within one detailed object the construction's tree can be
/// the better one: on the dragon close-up it costs 24.0 against 24.7 at Q2, and rays visit 5%
/// fewer nodes through it than through the SAH tree. The cost decides, so each scene gets the
/// cheaper of the two.
fn upper_tree(out: &mut Flattened, root: Option<&Node>) -> Result<(Vec<GpuNode>, u32)> {
    let (rebuilt, rebuilt_depth) = crate::bvh::tree_over(&out.refs)?;
    if crate::bvh::sah_cost(&rebuilt) < crate::bvh::sah_cost(&out.nodes) {
        return Ok((rebuilt, rebuilt_depth));
    }
    crate::bvh::check_node_count(out.nodes.len())?;
    let depth = root.map_or(0, depth_of).max(1);
    if depth > STACK_SIZE {
        return Err(Error::param(
            "scene",
            format!("RBVH depth {depth} exceeds the {STACK_SIZE}-entry stack"),
        ));
    }
    Ok((std::mem::take(&mut out.nodes), depth))
}

fn depth_of(node: &Node) -> u32 {
    match node {
        Node::Inner(c) | Node::Surface(c) => 1 + depth_of(&c[0]).max(depth_of(&c[1])),
        _ => 0,
    }
}

/// The construction's tree packed depth-first, with its leaves' references and everything they
/// refer to.
#[derive(Default)]
struct Flattened {
    nodes: Vec<GpuNode>,
    /// Each leaf's reference and box, in depth-first order, for the tree built again over them
    /// ([`crate::bvh::tree_over`]).
    refs: Vec<ChildRef>,
    triangles: Vec<GpuTriangle>,
    leaves: Vec<super::GpuHeightfield>,
    tiles: Vec<Tile>,
    triangle_leaves: u32,
    /// The leaf of the first tile of the [`Node::Surface`] being flattened, which its parts'
    /// flags count from.
    surface_leaves: u32,
}

impl Flattened {
    /// The two children of `node` (inner or [`Node::Surface`]), flattened in order; a
    /// surface's parts name their tiles' leaves, which its first child has just numbered.
    fn flatten_children(
        &mut self,
        node: &Node,
        children: &[Node; 2],
        b: &Builder,
        order: &[u32],
    ) -> [ChildRef; 2] {
        let first_leaf = self.leaves.len() as u32;
        let l = self.flatten(&children[0], b, order);
        if matches!(node, Node::Surface(_)) {
            self.surface_leaves = first_leaf;
        }
        [l, self.flatten(&children[1], b, order)]
    }

    /// Depth-first packing; inner boxes are the union of their children's boxes: a height-field
    /// leaf's is the box of its samples, dilated rim included (`Tile::surface_bounds`).
    fn flatten(&mut self, node: &Node, b: &Builder, order: &[u32]) -> ChildRef {
        let leaf = match node {
            Node::Inner(children) | Node::Surface(children) => {
                let index = self.nodes.len() as u32;
                self.nodes.push(GpuNode::default());
                let [l, r] = self.flatten_children(node, children, b, order);
                self.nodes[index as usize] = GpuNode::new(l, r);
                return ChildRef {
                    bounds: l.bounds.union(r.bounds),
                    child: index,
                    count: 0,
                };
            }
            Node::Heightfield(tile) => {
                let index = self.leaves.len() as u32;
                self.leaves.push(tile.heightfield(0));
                self.tiles.push((**tile).clone());
                ChildRef {
                    bounds: tile.surface_bounds(),
                    child: LEAF_BIT | index,
                    count: HEIGHTFIELD_COUNT,
                }
            }
            Node::Pieces(pieces) => {
                let first = self.triangles.len() as u32;
                let bounds = pieces
                    .iter()
                    .fold(Aabb::EMPTY, |b, t| b.union(Aabb::from_points(t.vertices())));
                let base = self.surface_leaves;
                self.triangles
                    .extend(pieces.iter().map(|&t| match t.part_leaf() {
                        None => t,
                        Some(k) => GpuTriangle {
                            flags: GpuTriangle::part_flags(
                                base + k,
                                t.flags & GpuTriangle::BARE != 0,
                            ),
                            ..t
                        },
                    }));
                self.triangle_leaves += 1;
                ChildRef {
                    bounds,
                    child: LEAF_BIT | first,
                    count: pieces.len() as u32,
                }
            }
            Node::Triangles { start, count } => {
                let first = self.triangles.len() as u32;
                let mut bounds = Aabb::EMPTY;
                let Input::Triangles(tris) = b.input else {
                    // A point set's empty leaf (see `Builder::build`).
                    return ChildRef::ABSENT;
                };
                for &i in &order[*start as usize..(*start + *count) as usize] {
                    let t = tris[i as usize];
                    bounds = bounds.union(Aabb::from_points(t));
                    self.triangles.push(GpuTriangle::new(t, i));
                }
                self.triangle_leaves += 1;
                ChildRef {
                    bounds,
                    child: LEAF_BIT | first,
                    count: *count,
                }
            }
        };
        self.refs.push(leaf);
        leaf
    }
}

/// Per triangle, a dense id of its connected part: vertices are welded by position within each
/// scene object (loaders often duplicate vertices along UV or normal seams), then joined by the
/// triangles that share them. Ids are numbered in order of first appearance, so they are
/// deterministic.
///
/// Parts never span objects, so when each object's triangles are one run (as [`Scene::append`]
/// makes them) the objects are found in parallel and numbered one after the other, which is the
/// same numbering; otherwise the whole scene is one run.
fn connected_parts(scene: &Scene) -> Vec<u32> {
    let object = |t: usize| scene.object_of_triangle.get(t).copied().unwrap_or(0);
    let mut runs: Vec<std::ops::Range<usize>> = Vec::new();
    for t in 0..scene.triangle_count() {
        match runs.last_mut() {
            Some(run) if object(run.start) == object(t) => run.end = t + 1,
            _ => runs.push(t..t + 1),
        }
    }
    if runs
        .windows(2)
        .any(|w| object(w[0].start) >= object(w[1].start))
    {
        runs.clear();
        runs.push(0..scene.triangle_count());
    }
    let parts: Vec<(Vec<u32>, u32)> = runs
        .par_iter()
        .map(|run| parts_of_run(scene, run.clone()))
        .collect();
    let mut offset = 0;
    let mut ids = Vec::with_capacity(scene.triangle_count());
    for (local, count) in parts {
        ids.extend(local.into_iter().map(|id| id + offset));
        offset += count;
    }
    ids
}

/// [`connected_parts`] of triangles `run`, numbered from 0, and how many parts there are.
///
/// A vertex index remembers its (object, welded vertex) once looked up, so the position map is
/// consulted once per vertex rather than once per corner: a sixth of the lookups on a closed
/// mesh, which take most of the time on a scene of millions of triangles.
fn parts_of_run(scene: &Scene, run: std::ops::Range<usize>) -> (Vec<u32>, u32) {
    const UNSEEN: (u32, u32) = (u32::MAX, u32::MAX);
    let triangles = &scene.triangles[run.clone()];
    let first_vertex = triangles.iter().flatten().copied().min().unwrap_or(0);
    let last_vertex = triangles.iter().flatten().copied().max().unwrap_or(0);
    let mut welded_of_vertex = vec![UNSEEN; (last_vertex - first_vertex) as usize + 1];
    let mut key_of: HashMap<(u32, [u32; 3]), u32> = HashMap::new();
    let mut parent: Vec<u32> = Vec::new();
    let mut corners = Vec::with_capacity(triangles.len());
    for (t, tri) in run.zip(triangles) {
        let object = scene.object_of_triangle.get(t).copied().unwrap_or(0);
        let ids = tri.map(|v| {
            let slot = &mut welded_of_vertex[(v - first_vertex) as usize];
            if slot.0 == object && slot.1 != u32::MAX {
                return slot.1;
            }
            let p = scene.positions[v as usize] + Vec3::ZERO;
            let key = (object, [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()]);
            let welded = *key_of.entry(key).or_insert_with(|| {
                parent.push(parent.len() as u32);
                parent.len() as u32 - 1
            });
            *slot = (object, welded);
            welded
        });
        union(&mut parent, ids[0], ids[1]);
        union(&mut parent, ids[0], ids[2]);
        corners.push(ids[0]);
    }
    let mut dense = vec![u32::MAX; parent.len()];
    let mut count = 0;
    let ids = corners
        .into_iter()
        .map(|v| {
            let root = find(&mut parent, v) as usize;
            if dense[root] == u32::MAX {
                dense[root] = count;
                count += 1;
            }
            dense[root]
        })
        .collect();
    (ids, count)
}

fn find(parent: &mut [u32], mut x: u32) -> u32 {
    while parent[x as usize] != x {
        parent[x as usize] = parent[parent[x as usize] as usize];
        x = parent[x as usize];
    }
    x
}

fn union(parent: &mut [u32], a: u32, b: u32) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    if ra != rb {
        parent[ra.max(rb) as usize] = ra.min(rb);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Whether `point` lies over `leaf`'s tile or the ring of cells around it, where its exact
    /// parts are cut (a cell and a half past its outer samples).
    fn over_tile(leaf: &super::super::GpuHeightfield, point: Vec3) -> bool {
        let f = leaf.to_frame(point);
        let (lo, hi) = (-1.5, [leaf.res_u as f32 + 1.5, leaf.res_v as f32 + 1.5]);
        f.x >= lo && f.y >= lo && f.x <= hi[0] && f.y <= hi[1]
    }

    /// Preset `level` with every triangle sampled: the parts these tests check stand beside the
    /// default scene's cube and cone, which the presets trace exactly.
    fn sampled(level: u32) -> RbvhParams {
        RbvhParams {
            exact_when_cheaper: false,
            ..RbvhParams::quality(level).unwrap()
        }
    }

    /// Every exact part names the height-field leaf it stands beside: it lies over that leaf's
    /// tile (the cells it was cut to and their ring), and no other leaf's index is named.
    #[test]
    fn exact_parts_name_the_leaf_they_stand_beside() {
        let scene = Scene::builtin("default").unwrap();
        let r = Rbvh::build(&scene, &sampled(2)).unwrap();
        let mut parts = 0;
        for t in &r.triangles {
            let Some(leaf) = t.part_leaf() else { continue };
            parts += 1;
            let leaf = r.leaves[leaf as usize];
            for q in t.vertices() {
                assert!(over_tile(&leaf, q), "{q} beside {leaf:?}");
            }
        }
        assert!(parts > 50, "{parts} parts");
    }

    /// A hit on an exact part lands on the leaf it stands beside, also where its scene triangle
    /// left parts beside several leaves (a triangle crossing tiles of one surface: the default
    /// scene at Q4 has such), not on the first leaf found for that triangle.
    #[test]
    fn a_hit_on_an_exact_part_lands_on_its_own_leaf() {
        use crate::geom::{Hit, Ray};
        let scene = Scene::builtin("default").unwrap();
        let r = Rbvh::build(&scene, &sampled(4)).unwrap();
        let shared = r.part_leaves().values().filter(|l| l.len() > 1).count();
        assert!(shared > 0, "no triangle with parts beside several leaves");
        for t in r.triangles.iter().filter(|t| t.part_leaf().is_some()) {
            let [a, b, c] = t.vertices();
            let centre = (a + b + c) / 3.0;
            let ray = Ray::new(centre + t.normal(), -t.normal(), 0.0, f32::INFINITY);
            let hit = Hit {
                t: 1.0,
                normal: t.normal().to_array(),
                id: t.prim,
                reserved: [0; 3],
            };
            let loc = r.locate(&ray, &hit).expect("a part's hit has a texel");
            assert!(
                over_tile(&r.leaves[loc.leaf as usize], centre),
                "part of {} at {centre}: leaf {}",
                t.prim,
                loc.leaf
            );
        }
    }

    /// The default scene's ground triangles cover 27 texels each at Q2: at 4 bytes a texel (108)
    /// more than a triangle traced exactly costs (96), at 2 (54) less. So with normals every
    /// ground triangle is traced exactly, whole (not an exact part), and height-only none is;
    /// the sphere's triangles (under 2 texels each) are sampled in both.
    #[test]
    fn triangles_that_cost_more_as_texels_are_traced_exactly() {
        let scene = Scene::builtin("default").unwrap();
        let objects = &scene.object_of_triangle;
        let object = |name: &str| {
            let o = scene.object_names.iter().position(|n| n == name).unwrap() as u32;
            let of = move |prim: u32| objects[prim as usize] == o;
            (of, objects.iter().filter(|&&x| x == o).count())
        };
        let (ground, ground_count) = object("ground");
        let (sphere, _) = object("sphere");
        let whole = |r: &Rbvh, of: &dyn Fn(u32) -> bool| {
            r.triangles
                .iter()
                .filter(|t| t.part_leaf().is_none() && of(t.prim))
                .count()
        };
        let mut params = super::super::RbvhParams {
            exact_when_cheaper: true,
            ..super::super::RbvhParams::quality(2).unwrap()
        };
        let r = Rbvh::build(&scene, &params).unwrap();
        assert_eq!(whole(&r, &ground), ground_count);
        assert_eq!(whole(&r, &sphere), 0);
        params.texels = TexelFormat::Height;
        let r = Rbvh::build(&scene, &params).unwrap();
        assert_eq!(whole(&r, &ground), 0);
        assert_eq!(whole(&r, &sphere), 0);
    }

    /// A unit square in one object, cut into `cells` × `cells` cells of two triangles each.
    fn square(cells: u32) -> Scene {
        let n = cells + 1;
        let positions: Vec<Vec3> = (0..n * n)
            .map(|k| Vec3::new((k % n) as f32, (k / n) as f32, 0.0) / cells as f32)
            .collect();
        let mut triangles = Vec::new();
        for j in 0..cells {
            for i in 0..cells {
                let k = j * n + i;
                triangles.push([k, k + 1, k + n + 1]);
                triangles.push([k, k + n + 1, k + n]);
            }
        }
        let mut scene = Scene::new("square");
        scene.push_object("square", &positions, &triangles);
        scene
    }

    /// At 9 texels along its diagonal a unit square's two triangles cover 20.25 texels each,
    /// under what a triangle alone must cover to be traced exactly (24 with normals), but its
    /// tile, with the ring of samples around it, costs more than the two triangles do (192
    /// bytes): the set is traced exactly, in either texel format. Cut into 16 × 16 cells, its
    /// 512 triangles cost more than that tile: it is sampled.
    #[test]
    fn a_set_whose_tiles_cost_more_than_its_triangles_is_traced_exactly() {
        for format in [TexelFormat::HeightNormal, TexelFormat::Height] {
            let params = super::super::RbvhParams {
                texels_per_diagonal: 9.0,
                texels: format,
                exact_when_cheaper: true,
                ..super::super::RbvhParams::quality(2).unwrap()
            };
            let r = Rbvh::build(&square(1), &params).unwrap();
            assert!(r.leaves.is_empty(), "{format:?}: {} leaves", r.leaves.len());
            assert_eq!(r.triangles.len(), 2);
            assert!(r.triangles.iter().all(|t| t.part_leaf().is_none()));
            let r = Rbvh::build(&square(16), &params).unwrap();
            assert!(!r.leaves.is_empty(), "{format:?}");
            assert!(r.triangles.is_empty(), "{format:?}: {}", r.triangles.len());
        }
    }

    /// Two triangles welded along a duplicated edge, and one apart, in one object.
    fn object(scene: &mut Scene, x: f32) {
        let p = |a: f32, b: f32| Vec3::new(x + a, b, 0.0);
        scene.push_object(
            "o",
            &[
                p(0.0, 0.0),
                p(1.0, 0.0),
                p(0.0, 1.0),
                // The shared edge again, as a loader splits vertices along a UV seam.
                p(1.0, 0.0),
                p(0.0, 1.0),
                p(1.0, 1.0),
                p(5.0, 5.0),
                p(6.0, 5.0),
                p(5.0, 6.0),
            ],
            &[[0, 1, 2], [3, 5, 4], [6, 7, 8]],
        );
    }

    #[test]
    fn parts_weld_within_an_object_never_across_and_number_by_first_appearance() {
        let mut scene = Scene::new("parts");
        object(&mut scene, 0.0);
        // The same positions in another object: touching, but a part of its own.
        object(&mut scene, 0.0);
        assert_eq!(connected_parts(&scene), [0, 0, 1, 2, 2, 3]);

        // Objects interleaved (public fields allow it): found as one run. The second triangle
        // now belongs to the other object and welds with the fourth; the fifth, in the first
        // object, with the first.
        let mut interleaved = scene.clone();
        interleaved.object_of_triangle = vec![0, 1, 0, 1, 0, 1];
        assert_eq!(connected_parts(&interleaved), [0, 1, 2, 1, 0, 3]);
    }
}
