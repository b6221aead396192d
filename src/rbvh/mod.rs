//! The Rasterized BVH (Novák & Dachsbacher, Eurographics 2012): a BVH whose leaves are height
//! fields in a texel atlas, mixed with ordinary triangle leaves where height fields do not fit.
//!
//! * [`params`]: quality presets and free parameters;
//! * `build`: the top-down recursion — refinement criteria, subdivision, leaf frames — and the
//!   tree traversed over its leaves (its own, or an SAH tree over them, whichever is cheaper);
//! * `raster`: rasterizing a leaf's triangles into its tile, dilation, quantization;
//! * `splat`: splatting a leaf's points (a scan's samples) into its tile, for RBVHs of point clouds;
//! * `atlas`: packing tiles into one atlas;
//! * `bake`: the scene's base colour into the per-texel colour channel (packed as [`crate::rgba`]);
//! * [`layout`]: the packed data the GPU reads;
//! * [`child`]: what a node's child is (inner, absent, triangles, height field): the one decoder of
//!   its encoding, where a new kind of leaf starts;
//! * [`ranges`]: height ranges of the atlas's 8 × 8 blocks, for the device march's jumps;
//! * [`words`]: the atlas as the device holds it (codes, block ranges, normals where there are
//!   samples and their rank directory), and the reads the device makes of it;
//! * `instanced`: the RBVH of a scene with instances, in two levels ([`InstancedRbvh`]);
//! * `march`: the CPU reference caster on exactly that packed data, and its [`DeviceTwin`];
//! * [`file`](mod@file): save and load, and the file format's tables (its older versions in
//!   `file::legacy`).

mod atlas;
mod bake;
mod build;
pub mod child;
pub mod file;
mod frame;
mod instanced;
pub mod layout;
pub(crate) mod march;
pub mod params;
pub mod ranges;
pub(crate) mod raster;
mod splat;
mod split;
pub mod triangles;
pub mod words;

pub use build::{RbvhSource, CREASE_EDGE_TEXELS};
pub use child::{Child, HEIGHTFIELD_COUNT};
pub use instanced::InstancedRbvh;
pub use layout::{Atlas, GpuHeightfield, Texel, PACKED_BITS};
pub use march::DeviceTwin;
pub use params::{
    level_name, RbvhParams, Refinement, Subdivision, TexelFormat, QUALITY_NAMES, SAMPLED_SUFFIX,
    VIEWED_SUFFIX, VIEW_RATE,
};
pub use raster::CREST_TEXELS;
pub use triangles::{ExactTriangles, GpuIndexedTriangle, GpuVertex};

use crate::bvh::GpuNode;
use crate::geom::Aabb;
use crate::scene::Scene;
use crate::{Error, Result};

/// A built RBVH in its packed (GPU) form.
#[derive(Clone, Debug, PartialEq)]
pub struct Rbvh {
    /// The parameters it was built with (stored in the file, too).
    pub params: RbvhParams,
    /// Node 0 is the root.
    pub nodes: Vec<GpuNode>,
    /// Triangles of the triangle leaves (hybrid leaves and exact parts), in leaf order: gathered
    /// for the host, indexed for the device ([`ExactTriangles`]).
    pub triangles: ExactTriangles,
    /// The height-field leaves' records, which a node's [`Child::Heightfield`] indexes (named
    /// apart from the tree's leaves, which are triangle leaves too).
    pub heightfields: Vec<GpuHeightfield>,
    /// Texels of all height-field tiles, addressed by [`GpuHeightfield::atlas_base`].
    pub atlas: Atlas,
    /// World box of the root's children: the leaves' boxes, dilated rims included, so it may
    /// differ from the scene's by up to [`SCENE_MATCH_TEXELS`] texels.
    pub bounds: Aabb,
    /// Inner nodes on the longest root-to-leaf path, at least 1.
    pub depth: u32,
    /// World-space size of one texel (scene diagonal / texels_per_diagonal).
    pub texel_size: f32,
    /// What the build made and how long it took.
    pub stats: RbvhStats,
    /// Optional per-texel surface colour, parallel to `atlas.texels` (same index): RGBA8 packed
    /// as in [`crate::rgba`] (red in the low byte, RGB sRGB-encoded, alpha linear), 0 at
    /// holes. Baked at build time when the scene has materials, created on first paint otherwise;
    /// `None` costs nothing. See `crate::surface`.
    pub colours: Option<Vec<u32>>,
}

/// Accounting of one build.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RbvhStats {
    /// Wall time of [`Rbvh::build`] in milliseconds (as recorded at build time for a loaded file).
    pub build_ms: f64,
    /// Leaves that became height fields (= `heightfields.len()`).
    pub heightfield_leaves: u32,
    /// Leaves of triangles, traced exactly: sets kept as triangles (hybrid leaves), and beside
    /// height fields the triangles their tiles leave uncovered (`raster/exposed.rs`).
    pub triangle_leaves: u32,
    /// Texels of all tiles (the atlas has `atlas.pitch × atlas.rows`, the difference is waste).
    pub tile_texels: u64,
}

/// How far, in texels of its level, an RBVH's box may lie from its scene's on any side
/// ([`Rbvh::check_built_from`]): a one-texel dilated rim whose heights are extrapolated along
/// slopes of up to a few texels per texel, and the tile's edge.
pub const SCENE_MATCH_TEXELS: f32 = 16.0;

impl Rbvh {
    /// Bytes of the node array and the height-field leaf records.
    pub fn tree_bytes(&self) -> u64 {
        (std::mem::size_of_val(self.nodes.as_slice())
            + std::mem::size_of_val(self.heightfields.as_slice())) as u64
    }

    /// The atlas as the device holds it ([`Atlas::device_words`]): the height codes, the blocks'
    /// height ranges ([`ranges::block_ranges`], 1/64 as many words) and, with normals, a rank
    /// directory and the normals of the texels that are not holes.
    pub fn atlas_bytes(&self) -> u64 {
        4 * self.atlas.device_parts(self.params.texels).end as u64
    }

    /// The atlas as the trace shaders read it, in this RBVH's texel format
    /// ([`Atlas::device_words`]).
    pub fn atlas_words(&self) -> Vec<u32> {
        self.atlas.device_words(self.params.texels)
    }

    /// Device bytes of the triangle-leaf triangles, indexed ([`ExactTriangles::device_bytes`]):
    /// hybrid leaves' and exact parts' together.
    pub fn triangle_bytes(&self) -> u64 {
        self.triangles.device_bytes()
    }

    /// Of [`Rbvh::triangle_bytes`], those of the exact parts beside height fields
    /// ([`GpuTriangle::PART`](crate::bvh::GpuTriangle::PART); [`ExactTriangles::part_bytes`]): the rest are hybrid leaves, sets
    /// too small to be height fields.
    pub fn part_bytes(&self) -> u64 {
        self.triangles.part_bytes()
    }

    /// Bytes of the optional colour channel (0 without one). Not part of [`Rbvh::total_bytes`],
    /// which is the geometry that the exact BVH is compared with.
    pub fn colour_bytes(&self) -> u64 {
        self.colours
            .as_ref()
            .map_or(0, |c| std::mem::size_of_val(c.as_slice()) as u64)
    }

    /// Device bytes of the geometry: tree, atlas (with block ranges) and triangles, the figure
    /// compared with [`Bvh`](crate::bvh::Bvh)'s nodes and triangles.
    pub fn total_bytes(&self) -> u64 {
        self.tree_bytes() + self.atlas_bytes() + self.triangle_bytes()
    }

    /// Checks that this RBVH (one loaded from a file, say) was built from `scene`, which a file
    /// cannot know by itself: traced with another scene's camera and materials it would show the
    /// wrong geometry without a word. Its box must be the scene's to within
    /// [`SCENE_MATCH_TEXELS`] texels on every side: leaves reach past the triangles by their
    /// dilated rims (extrapolated along steep slopes) and may fall short by a sliver that no
    /// sample met. A scene of points widens that by the farthest a splat reaches past its point
    /// (`splat::REACH_SPACINGS` spacings along its plane, up to 1/`splat::MIN_FACING` times that
    /// across it). The error names both boxes. A box can match another scene's, so each exact
    /// triangle must then be the scene's triangle it names, or a piece of it, in that triangle's
    /// box. (A two-level RBVH's file,
    /// [`InstancedRbvh::check_built_from`], is checked by its meshes' boxes alone.)
    pub fn check_built_from(&self, scene: &Scene) -> Result<()> {
        let expected = scene.bounds();
        if expected.is_empty() && self.bounds.is_empty() {
            return Ok(());
        }
        let splat_reach = scene.points.as_ref().map_or(0.0, |cloud| {
            let widest = cloud.spacing.iter().copied().fold(0.0f32, f32::max);
            widest * splat::REACH_SPACINGS * (1.0 + 1.0 / splat::MIN_FACING as f32)
        });
        let tolerance = SCENE_MATCH_TEXELS * self.texel_size.max(0.0)
            + splat_reach
            + 1e-5 * expected.diagonal();
        let apart = (self.bounds.min - expected.min)
            .abs()
            .max((self.bounds.max - expected.max).abs())
            .max_element();
        // NaN (an empty box on one side only) fails too.
        if apart <= tolerance {
            // A vertex written by another build of the same scene may differ by a few ulps of
            // the coordinates (a transform rounded otherwise), however small the scene is.
            let magnitude = expected.min.abs().max(expected.max.abs()).max_element();
            let slack = 1e-5 * expected.diagonal() + 4.0 * f32::EPSILON * magnitude;
            return self.check_triangles_of(scene, slack);
        }
        Err(Error::param(
            "rbvh",
            format!(
                "built for another scene: its box is {:?}..{:?}, scene {:?}'s is {:?}..{:?} \
                 ({apart} apart, more than {SCENE_MATCH_TEXELS} texels of {}); rebuild it from \
                 this scene (rbvh build --scene ... --out ...)",
                self.bounds.min.to_array(),
                self.bounds.max.to_array(),
                scene.name,
                expected.min.to_array(),
                expected.max.to_array(),
                self.texel_size
            ),
        ))
    }

    /// The rest of [`Rbvh::check_built_from`], for two scenes of one box: each exact triangle
    /// names a triangle of `scene` (its `prim`) and lies in that triangle's box, within `slack`
    /// (an exact part is the triangle or a piece of it). A scene of points has none.
    fn check_triangles_of(&self, scene: &Scene, slack: f32) -> Result<()> {
        if scene.points.is_some() {
            return Ok(());
        }
        let count = scene.triangle_count();
        for (slot, t) in self.triangles.gathered().iter().enumerate() {
            let prim = t.prim as usize;
            let fits = prim < count && {
                let b = crate::geom::Aabb::from_points(scene.triangle(prim));
                [t.v0, t.v1, t.v2].iter().all(|&v| {
                    let v = glam::Vec3::from_array(v);
                    v.cmpge(b.min - slack).all() && v.cmple(b.max + slack).all()
                })
            };
            if !fits {
                return Err(Error::param(
                    "rbvh",
                    format!(
                        "built for another scene: its exact triangle {slot} is scene triangle \
                         {prim}, which scene {:?} ({count} triangles) does not have there; \
                         rebuild it from this scene (rbvh build --scene ... --out ...)",
                        scene.name
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Texels of the tiles stored with 8-bit heights: those in the atlas's 8-bit band
    /// ([`Atlas::packed_rows`]). A tile whose codes are 8-bit ones but whose band would cost more
    /// than it saves is stored with 16-bit codes (`atlas::pack`) and does not count.
    pub fn narrow_texels(&self) -> u64 {
        self.heightfields
            .iter()
            .filter(|l| self.atlas.bits_at(l.atlas_base as usize) == 8)
            .map(|l| u64::from(l.res_u) * u64::from(l.res_v))
            .sum()
    }

    /// What a texel costs on the device: [`Rbvh::atlas_bytes`] (the texels in this RBVH's format,
    /// the atlas's unused texels and the blocks' height ranges) over the tiles' texels; 0 without
    /// any.
    pub fn bytes_per_texel(&self) -> f64 {
        match self.stats.tile_texels {
            0 => 0.0,
            n => self.atlas_bytes() as f64 / n as f64,
        }
    }

    /// Used tile texels over atlas texels.
    pub fn fill_ratio(&self) -> f64 {
        let total = self.atlas.texels.len() as f64;
        if total == 0.0 {
            1.0
        } else {
            self.stats.tile_texels as f64 / total
        }
    }
}
