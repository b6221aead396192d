//! The device march's block jumps (step 3 of [`super`], with [`super::Walk::blocks`]): the
//! atlas-aligned 8×8 blocks a leaf's tile lies in and their height ranges
//! ([`crate::rbvh::ranges`]), addressed as `rbvh_march` in `glsl/rbvh.glsl` addresses them, and
//! the jump over a block the ray passes wholly above or below.

use crate::geom::grid::{height_at, GridWalk};
use crate::probe::{Array, Probe, Read};
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
    count: u64,
    /// Where the ranges start in the device's atlas buffer, in words: after the height codes.
    first_word: u64,
}

/// What a ray must clear to pass a block: its height in the leaf's frame (`o_h + d_h·t`), the
/// height quantum, and the margins beyond the block's range: the march's height `slack` both
/// ways, and below also the skirt's depth `skirt_h` (a block the ray passes below by less may
/// hold a skirt hit).
pub(super) struct Clearance {
    pub(super) o_h: f32,
    pub(super) d_h: f32,
    pub(super) h_scale: f32,
    pub(super) slack: f32,
    pub(super) skirt_h: f32,
}

impl Clearance {
    /// Whether the ray, from `t_a` to `t_b`, passes wholly above or below the block of height
    /// code range `range` (low code in the low half-word) by more than the margins: then none of
    /// its cells can be hit. An empty block (no texel: the range is inverted) is passed by every
    /// ray. `rbvh_block_clear` in `glsl/rbvh.glsl` is its twin.
    fn clears(&self, range: u32, t_a: f32, t_b: f32) -> bool {
        let (code_lo, code_hi) = (range & 0xFFFF, range >> 16);
        let lo = code_lo as f32 * self.h_scale - self.slack - self.skirt_h;
        let hi = code_hi as f32 * self.h_scale + self.slack;
        let h_a = height_at(self.o_h, self.d_h, t_a);
        let h_b = height_at(self.o_h, self.d_h, t_b);
        code_lo > code_hi || h_a.max(h_b) < lo || h_a.min(h_b) > hi
    }
}

/// What checking the block the walk is in did.
pub(super) enum Jump {
    /// Nothing: the block was checked already, or the ray may hit in it.
    Stay,
    /// The walk jumped to the block's exit cell; the axis its last step crossed, if it took any.
    Jumped(Option<usize>),
    /// The ray leaves the tile's box before it leaves the block: the march ends.
    Ended,
}

impl<'a> Blocks<'a> {
    /// The blocks of `leaf`'s tile, with the atlas's block `ranges`, which the device reads
    /// after its `code_words` words of height codes.
    pub(super) fn of(
        atlas: &Atlas,
        leaf: &GpuHeightfield,
        ranges: &'a [u32],
        code_words: u64,
    ) -> Blocks<'a> {
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
            first_word: code_words,
        }
    }

    /// The block holding `cell` (both ≥ 0: the walk never leaves the tile).
    fn index(&self, cell: [i64; 2]) -> u64 {
        let block = u64::from(BLOCK);
        let (ax, ay) = (self.tile_u + cell[0] as u64, self.tile_v + cell[1] as u64);
        (ay / block) * self.pitch + ax / block
    }

    /// The last cell of the block holding `w`'s cell that the walk reaches (clamped to the
    /// tile): along each axis the block's far side in the direction the ray steps.
    fn exit_cell(&self, w: &GridWalk) -> [i64; 2] {
        let block = u64::from(BLOCK);
        let tile = [self.tile_u, self.tile_v];
        [0, 1].map(|a| {
            let at = tile[a] + w.cell[a] as u64;
            // The tile cell at the block's first atlas column (row); negative before the tile.
            let first = (at / block * block) as i64 - tile[a] as i64;
            if w.ray.step[a] > 0 {
                (first + i64::from(BLOCK) - 1).min(w.ray.last[a])
            } else {
                first.max(0)
            }
        })
    }

    /// The block's height-code range word; a block without one (only in data the loader
    /// refuses) gets the full range, which never jumps.
    fn range(&self, block: u64) -> u32 {
        usize::try_from(block)
            .ok()
            .and_then(|b| self.ranges.get(b))
            .copied()
            .unwrap_or(0xFFFF_0000)
    }

    /// On entering a block (one other than `checked`, which it then becomes) whose height range
    /// the ray passes wholly above or below, by more than `clear`'s margins, from the walk's
    /// entry until it leaves the block or the tile's box at `t1`: moves the walk straight to the
    /// block's exit cell, as it would reach it cell by cell ([`GridWalk::jump`]).
    pub(super) fn jump<P: Probe>(
        &self,
        w: &mut GridWalk,
        checked: &mut Option<u64>,
        clear: &Clearance,
        t1: f32,
        probe: &mut P,
    ) -> Jump {
        let block = self.index(w.cell);
        if *checked == Some(block) || block >= self.count {
            return Jump::Stay;
        }
        *checked = Some(block);
        let edge = self.exit_cell(w);
        let leave = [0, 1].map(|a| w.ray.boundary_t(a, edge[a]));
        probe.read(Read {
            array: Array::Atlas,
            offset: 4 * (self.first_word + block),
            bytes: 4,
        });
        let t_b = leave[0].min(leave[1]).min(t1);
        let clears = clear.clears(self.range(block), w.t_in, t_b);
        if !clears {
            Jump::Stay
        } else if t1 < leave[0].min(leave[1]) {
            Jump::Ended
        } else {
            Jump::Jumped(w.jump(edge, leave))
        }
    }
}
