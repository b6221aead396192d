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
//! leaves' boxes by a full-sweep SAH (the exact BVH's builder), whichever the SAH finds cheaper
//! (`upper_tree`).
//!
//! Parallel with `rayon::join` over subtrees; every per-node computation is sequential and ordered,
//! so the output is byte-identical for any thread count.
//!
//! ## Files
//! Here: the build's steps in order ([`Rbvh::build_from`]) and the tree's nodes. [`source`]: what
//! the levels of one scene share; [`parts`]: connected parts, for the object split; [`exact`]:
//! which triangles are traced exactly for their bytes; [`recursion`]: the top-down recursion;
//! [`leaf`]: making leaves (tiles, exact parts, forced leaves); [`flatten`]: the packed tree and
//! the tree traversed over the leaves.

mod exact;
mod flatten;
mod leaf;
mod parts;
mod recursion;
mod scale;
mod source;
mod view;

use std::time::Instant;

use glam::Vec3;

pub use exact::CREASE_EDGE_TEXELS;
pub use source::RbvhSource;

use super::atlas;
use super::layout::Texel;
use super::raster::Tile;
use super::splat::Splat;
use super::split::SplitPrim;
use super::{ExactTriangles, Rbvh, RbvhParams, RbvhStats, TexelFormat};
use crate::bvh::{ChildRef, GpuNode, GpuTriangle, LinearBvh};
use crate::geom::Aabb;
use crate::progress::{step, Progress, Quiet};
use crate::scene::{Camera, Scene};
use crate::{Error, Result};
use flatten::{upper_tree, Flattened};
use leaf::pieces_subtree;
use source::object_texels;

/// Most triangles in a triangle leaf.
const MAX_TRIANGLE_LEAF: usize = 8;

/// From this depth on, splits are object medians, bounding the construction's tree by 32 +
/// log2(n) (it is traversed where the SAH prefers it to the tree built again over its leaves,
/// `crate::bvh::tree_over`, which bounds its own depth the same way; see `upper_tree`).
const MEDIAN_BELOW_DEPTH: u32 = 32;

/// A set of points whose box is thinner than this fraction of its length is a slab: split by
/// facing when it is not one height field (`Builder::split_by_facing`).
const SLAB: f32 = 0.25;

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
    /// Per scene triangle, the texel the scene's view asks of it where finer than its object's
    /// ([`RbvhParams::view_rate`], [`view::view_texels`]), `f32::INFINITY` elsewhere; empty
    /// without a view.
    view_texel: Vec<f32>,
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
    /// The build's estimated texels (the refusal's estimate): four times it bounds any one set's
    /// frame (`Builder::frame_samples`).
    estimate: f64,
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
        let diagonal = source.scene.bounds().diagonal();
        let texel = if diagonal > 0.0 {
            diagonal / params.texels_per_diagonal
        } else {
            1.0
        };
        Rbvh::build_at(source, params, texel, progress)
    }

    /// [`Rbvh::build_from`] with the scene's texel given rather than taken from its diagonal: a
    /// mesh of a scene with instances is built in its own space at the texel its placements ask
    /// for ([`crate::rbvh::InstancedRbvh`]). Objects' own rates
    /// ([`RbvhParams::object_rate`]) are relative to their own boxes, so they are the same in
    /// any space. `params` must be valid. A scene too large or too small for float32's squares
    /// is built scaled by a power of two and scaled back (`scale.rs`).
    pub(crate) fn build_at(
        source: &RbvhSource,
        params: &RbvhParams,
        texel: f32,
        progress: &dyn Progress,
    ) -> Result<Rbvh> {
        match crate::geom::scale::rescale_exponent(source.scene.bounds().diagonal(), texel) {
            Some(k) => scale::build_scaled(source, params, texel, k, progress),
            None => Rbvh::build_native(source, params, texel, progress),
        }
    }

    /// [`Rbvh::build_at`] of a scene as it is.
    fn build_native(
        source: &RbvhSource,
        params: &RbvhParams,
        texel: f32,
        progress: &dyn Progress,
    ) -> Result<Rbvh> {
        let start = Instant::now();
        let scene = source.scene;
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
        let (view_texel, viewed) = match (&input, scene.camera) {
            (Input::Triangles(tris), Some(camera)) if params.view_rate > 0.0 => {
                // The view's texels need a view: a camera `Camera::look_at` would make.
                Camera::look_at(camera.eye, camera.target, camera.up, camera.vfov_deg).map_err(
                    |fault| {
                        Error::param(
                            "view_rate",
                            format!("refines for the scene's camera, which is not one: {fault}"),
                        )
                    },
                )?;
                view::view_texels(&camera, tris, params.view_rate, texel, |i| {
                    object_texel
                        .get(scene.object_of_triangle[i] as usize)
                        .copied()
                        .unwrap_or(texel)
                })
            }
            _ => (Vec::new(), 0.0),
        };
        let alone = estimate;
        let estimate = estimate + viewed;
        // An estimate that overflowed to NaN is refused too.
        if estimate.is_nan() || estimate > MAX_ESTIMATED_TEXELS {
            // Named after the rate that asks for more: the view's, where the build fits
            // without it, else the objects', where any is finer.
            let (name, what) = if alone <= MAX_ESTIMATED_TEXELS {
                (
                    "view_rate",
                    format!(
                        " and {} across the view's field at each distance",
                        params.view_rate
                    ),
                )
            } else if object_texel.iter().any(|&t| t < texel) {
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
            view_texel,
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
            estimate,
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
            atlas::pack(&footprints, params.texels)
        })?;
        for (leaf, &base) in out.heightfields.iter_mut().zip(&packing.bases) {
            leaf.atlas_base = base;
        }
        let mut atlas = atlas::assemble(&out.tiles, &packing);
        let height_only = params.texels == TexelFormat::Height;
        if height_only {
            // Only the height codes are kept (and uploaded, two to a word, or packed 12, 10 or 8
            // bits each): a hit's normal comes from the cell triangle it hit.
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
            heightfield_leaves: out.heightfields.len() as u32,
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
            triangles: ExactTriangles::new(out.triangles),
            heightfields: out.heightfields,
            atlas,
            bounds,
            depth,
            texel_size: texel,
            stats,
            colours,
        })
    }
}
