//! One leaf's march as every step sees it (see [`super`]): the ray in the leaf's frame, made by
//! the walk's first step, and the leaf's texels with what the cell test and the normal need
//! besides the cell. Its own file so that the steps that read it (walk, cell test, skirts,
//! normal) depend on it and not on each other in a circle.

use glam::Vec3;

use crate::geom::{Ray, RayShear};
use crate::rbvh::layout::{Atlas, GpuHeightfield, Texel};
use crate::rbvh::TexelFormat;

/// A ray in a leaf's frame `(s, t, h)` with its interval `[tmin, t_closest)`, its shear for the
/// watertight test, and its height `slack` (see [`crate::rbvh::layout::MARCH_SLACK`]); computed once per leaf.
pub(super) struct FrameRay {
    pub(super) ray: Ray,
    pub(super) shear: RayShear,
    pub(super) slack: f32,
}

/// Texel `(i, j)` of the leaf's tile and its index in the atlas, or a hole (and no index) when
/// the index leaves the atlas. The march only asks for `(i, j)` inside a tile that
/// [`crate::rbvh::layout::tile_fits`], so the index cannot overflow; the checked read is the last line of defence.
pub(super) fn texel(
    atlas: &Atlas,
    leaf: &GpuHeightfield,
    i: i64,
    j: i64,
) -> (Texel, Option<usize>) {
    let index = i64::from(leaf.atlas_base) + j * i64::from(atlas.pitch) + i;
    let Ok(index) = usize::try_from(index) else {
        return (Texel::HOLE, None);
    };
    match atlas.texels.get(index) {
        Some(&t) => (t, Some(index)),
        None => (Texel::HOLE, None),
    }
}

/// The cells of one leaf's march: what [`Cells::hit`] needs besides the cell.
pub(super) struct Cells<'a> {
    pub(super) atlas: &'a Atlas,
    pub(super) leaf: &'a GpuHeightfield,
    /// Which leaf `leaf` is (for the reads again that a height-only hit's normal costs).
    pub(super) leaf_index: u32,
    pub(super) fr: &'a FrameRay,
    /// The world ray's direction, which a hit's normal should face.
    pub(super) dir: Vec3,
    /// What the texels hold: the normal of a hit comes from its sample or from its facet.
    pub(super) format: TexelFormat,
    /// `|axis_u|²`: one over the texel's size squared, in the frame's height units (for the
    /// skirt's depth without a square root).
    pub(super) uu: f32,
}
