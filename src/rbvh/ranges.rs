//! Height ranges of the atlas's blocks, which let the device's march jump over the cells of a block
//! that a ray passes wholly above or below (Tevs, Ihrke & Seidel, "Maximum Mipmaps for Fast,
//! Accurate, and Scalable Dynamic Height Field Rendering", I3D 2008, one level of it, with minima
//! too because a ray may come from either side of an RBVH surface).
//!
//! Blocks are aligned to the atlas, not to tiles: block `(X, Y)` holds the cells whose texel
//! `(0, 0)` corner lies in atlas columns `8X…8X+7` and rows `8Y…8Y+7`, so its range covers the
//! corner samples in columns `8X…8X+8` and rows `8Y…8Y+8`. A block shared by neighbouring tiles
//! takes the codes of all of them: that only widens the range, which stays conservative for each
//! (a code range read with any one leaf's scale contains that leaf's own heights). Holes do not
//! count; a block of holes only gets the empty range `min > max`.
//!
//! Why blocks pay: camera rays cross only a few cells in all, but most of those are in the long
//! marches of rays grazing a surface near a silhouette (on the default scene at Q2, rays of more
//! than 16 cells hold 78% of the primary rays' cells and 77% of the shadow rays'), and a SIMD
//! group waits for its longest march. The walk reads a block's range once, on entering it, and
//! when the ray's height over the block lies outside it (with the cell test's slack), it moves
//! straight to the block's exit cell. The main cells it skips could not be hit (their own test
//! reads and rounds heights the same way and would reject them), so the hits are those of the
//! plain walk (the CPU caster in `march/` walks every cell, and the agreement tests compare). One
//! gap remains in principle: an "extra" cell, the neighbour the walk also tests where a ray passes
//! a grid vertex within rounding, lies outside the block when that vertex is on the block's edge;
//! it is skipped too, and could only have been hit within rounding times the surface's slope of
//! the vertex, which the block's range (holding that vertex's sample) excludes. In
//! `tests/rbvh_agreement.rs`, 60,000 rays aimed at the grid vertices and surfaces of terraced and
//! swelling tiles with holes, not aligned to blocks, find no difference (while the device visits
//! a quarter fewer steps); a review's stress test of 360,000 such rays found none either.

use rayon::prelude::*;

use super::layout::Atlas;

/// Cells along a block's side.
pub const BLOCK: u32 = 8;

/// Blocks along an atlas row: `⌈pitch / 8⌉`.
pub fn block_pitch(atlas: &Atlas) -> u32 {
    atlas.pitch.div_ceil(BLOCK)
}

/// Blocks in the atlas: [`block_pitch`] × `⌈rows / 8⌉`.
pub fn block_count(atlas: &Atlas) -> u64 {
    u64::from(block_pitch(atlas)) * u64::from(atlas.rows.div_ceil(BLOCK))
}

/// One word per block, row by row (`⌈rows / 8⌉` rows of [`block_pitch`] blocks): the smallest
/// height code of its samples in bits 0–15 and the largest in bits 16–31, or `0x0000_FFFF`
/// (min > max) when all of them are holes.
pub fn block_ranges(atlas: &Atlas) -> Vec<u32> {
    let (pitch, rows) = (atlas.pitch as usize, atlas.rows as usize);
    let (bp, brows) = (
        pitch.div_ceil(BLOCK as usize),
        rows.div_ceil(BLOCK as usize),
    );
    let b = BLOCK as usize;
    (0..brows)
        .into_par_iter()
        .flat_map_iter(|by| {
            (0..bp).map(move |bx| {
                let (mut lo, mut hi) = (u16::MAX, 0u16);
                for y in by * b..((by + 1) * b + 1).min(rows) {
                    let row = &atlas.texels[y * pitch..(y + 1) * pitch];
                    for t in &row[bx * b..((bx + 1) * b + 1).min(pitch)] {
                        if !t.is_hole() {
                            lo = lo.min(t.height_code());
                            hi = hi.max(t.height_code());
                        }
                    }
                }
                u32::from(lo) | (u32::from(hi) << 16)
            })
        })
        .collect()
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::rbvh::layout::Texel;

    /// A `pitch` × `rows` atlas of texels `f(x, y)`, without packed bands.
    pub(crate) fn atlas(pitch: u32, rows: u32, f: impl Fn(u32, u32) -> Texel) -> Atlas {
        let texels = (0..rows)
            .flat_map(|y| (0..pitch).map(move |x| (x, y)))
            .map(|(x, y)| f(x, y))
            .collect();
        Atlas {
            pitch,
            rows,
            packed_rows: [0; 3],
            texels,
        }
    }

    #[test]
    fn ranges_cover_each_block_and_its_far_edge_samples() {
        // Height code x + 100·y on a 20 × 12 atlas: block (X, Y) spans columns 8X..=8X+8 and rows
        // 8Y..=8Y+8, clamped to the atlas.
        let a = atlas(20, 12, |x, y| {
            Texel::new((x + 100 * y) as u16, glam::Vec3::Z)
        });
        let r = block_ranges(&a);
        assert_eq!(block_pitch(&a), 3);
        assert_eq!(r.len() as u64, block_count(&a));
        assert_eq!(r.len(), 3 * 2);
        let range = |w: u32| (w & 0xFFFF, w >> 16);
        assert_eq!(range(r[0]), (0, 8 + 800));
        assert_eq!(range(r[1]), (8, 16 + 800));
        assert_eq!(range(r[2]), (16, 19 + 800));
        assert_eq!(range(r[3]), (800, 8 + 1100));
        assert_eq!(range(r[5]), (816, 19 + 1100));
    }

    #[test]
    fn holes_do_not_count_and_an_all_hole_block_is_empty() {
        let a = atlas(16, 8, |x, _| {
            if x < 9 {
                Texel::HOLE
            } else {
                Texel::new(x as u16, glam::Vec3::Z)
            }
        });
        let r = block_ranges(&a);
        assert_eq!(
            r[0] & 0xFFFF,
            u32::from(u16::MAX),
            "block 0 sees only holes"
        );
        assert!(r[0] & 0xFFFF > r[0] >> 16);
        assert_eq!((r[1] & 0xFFFF, r[1] >> 16), (9, 15));
    }
}
