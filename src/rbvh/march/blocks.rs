//! The device march's block jumps (step 3 of [`super`], with [`super::Walk::Blocks`]): the
//! atlas-aligned 8×8 blocks a leaf's tile lies in and their height ranges
//! ([`crate::rbvh::ranges`]), addressed as `rbvh_march` in `glsl/rbvh.glsl` addresses them.

use crate::rbvh::layout::{Atlas, GpuHeightfield};
use crate::rbvh::ranges::BLOCK;

/// The atlas-aligned 8×8 blocks a leaf's tile lies in (`src/rbvh/ranges.rs`), addressed as
/// `rbvh_march` does.
pub(super) struct Blocks<'a> {
    ranges: &'a [u32],
    /// The tile's corner in the atlas.
    tile_u: u64,
    tile_v: u64,
    pitch: u64,
    pub(super) count: u64,
}

impl<'a> Blocks<'a> {
    pub(super) fn of(atlas: &Atlas, leaf: &GpuHeightfield, ranges: &'a [u32]) -> Blocks<'a> {
        let pitch = u64::from(atlas.pitch.max(1));
        // Rows as the device counts them: from the texel count (the loader makes it a whole
        // number of rows).
        let rows = atlas.texels.len() as u64 / pitch;
        let block = u64::from(BLOCK);
        Blocks {
            ranges,
            tile_u: u64::from(leaf.atlas_base) % pitch,
            tile_v: u64::from(leaf.atlas_base) / pitch,
            pitch: pitch.div_ceil(block),
            count: rows.div_ceil(block) * pitch.div_ceil(block),
        }
    }

    /// The block holding cell `(ci, cj)` (both ≥ 0: the walk never leaves the tile).
    pub(super) fn index(&self, ci: i64, cj: i64) -> u64 {
        let block = u64::from(BLOCK);
        let (ax, ay) = (self.tile_u + ci as u64, self.tile_v + cj as u64);
        (ay / block) * self.pitch + ax / block
    }

    /// The tile cell at the block's first atlas column and row (negative before the tile).
    pub(super) fn first_cell(&self, ci: i64, cj: i64) -> (i64, i64) {
        let block = u64::from(BLOCK);
        let (ax, ay) = (self.tile_u + ci as u64, self.tile_v + cj as u64);
        (
            (ax / block * block) as i64 - self.tile_u as i64,
            (ay / block * block) as i64 - self.tile_v as i64,
        )
    }

    /// The block's height-code range word; a block without one (only in data the loader
    /// refuses) gets the full range, which never jumps.
    pub(super) fn range(&self, block: u64) -> u32 {
        usize::try_from(block)
            .ok()
            .and_then(|b| self.ranges.get(b))
            .copied()
            .unwrap_or(0xFFFF_0000)
    }
}
