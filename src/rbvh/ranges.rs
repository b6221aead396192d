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

use super::layout::{Atlas, Texel};
use super::params::TexelFormat;
use crate::probe::{Array, Read};

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

impl Atlas {
    /// The atlas as the trace shaders read it in `format`, in words:
    /// 1. the wide texels (before [`Atlas::wide_len`]): one word each (height code in bits 0–15,
    ///    normal in 16–31), or with [`TexelFormat::Height`] their height codes two to a word
    ///    (texel `2k` in the low half of word `k`, `2k + 1` in the high half);
    /// 2. the narrow band's height codes a byte each, four to a word (low byte first): an 8-bit
    ///    code `c` stands for the code `c · 257` ([`Texel::narrow_code_of`]), a hole for 255;
    /// 3. with [`TexelFormat::HeightNormal`], the narrow band's normals two to a word;
    /// 4. [`block_ranges`], from word [`Atlas::texel_words`] on.
    ///
    /// `glsl/atlas.glsl` reads it back.
    pub fn device_words(&self, format: TexelFormat) -> Vec<u32> {
        let (wide, narrow) = self.texels.split_at(self.wide_len());
        let mut words: Vec<u32> = match format {
            TexelFormat::HeightNormal => bytemuck::cast_slice::<Texel, u32>(wide).to_vec(),
            TexelFormat::Height => pack_words(wide, 2, |t| u32::from(t.height_code())),
        };
        words.extend(pack_words(narrow, 4, |t| u32::from(t.height_code() & 0xFF)));
        if format == TexelFormat::HeightNormal {
            words.extend(pack_words(narrow, 2, |t| t.0 >> 16));
        }
        words.extend(block_ranges(self));
        words
    }

    /// Words the texels take in `format`, where the block ranges start.
    pub fn texel_words(&self, format: TexelFormat) -> u64 {
        let wide = self.wide_len() as u64;
        let narrow = self.texels.len() as u64 - wide;
        let normals = match format {
            TexelFormat::HeightNormal => narrow.div_ceil(2),
            TexelFormat::Height => 0,
        };
        let wide_words = match format {
            TexelFormat::HeightNormal => wide,
            TexelFormat::Height => wide.div_ceil(2),
        };
        wide_words + narrow.div_ceil(4) + normals
    }
}

impl Atlas {
    /// The device's read of texel `index`'s height code in `format` ([`Atlas::device_words`]):
    /// the texel's word (its half-word without normals) above the narrow band, the word holding
    /// its byte in it.
    pub(crate) fn code_read(&self, index: usize, format: TexelFormat) -> Read {
        let wide = self.wide_len();
        if index < wide {
            let bytes = format.bytes();
            return Read {
                array: Array::Atlas,
                offset: bytes * index as u64,
                bytes: bytes as u32,
            };
        }
        let wide_words = match format {
            TexelFormat::HeightNormal => wide,
            TexelFormat::Height => wide.div_ceil(2),
        };
        word_read(wide_words + (index - wide) / 4)
    }

    /// The device's reads of texel `index` with its normal (the format with normals): its word
    /// above the narrow band; in it, the word holding its code and the one holding its normal.
    pub(crate) fn normal_reads(&self, index: usize) -> impl Iterator<Item = Read> {
        let wide = self.wide_len();
        let (first, normal) = if index < wide {
            (word_read(index), None)
        } else {
            let k = index - wide;
            let narrow = self.texels.len() - wide;
            let normals = wide + narrow.div_ceil(4);
            (word_read(wide + k / 4), Some(word_read(normals + k / 2)))
        };
        std::iter::once(first).chain(normal)
    }
}

/// A read of atlas word `word`.
fn word_read(word: usize) -> Read {
    Read {
        array: Array::Atlas,
        offset: 4 * word as u64,
        bytes: 4,
    }
}

/// `texels` as words of `per_word` fields of `32 / per_word` bits, the first texel in the lowest
/// bits, each field `field(texel)`; a last word's missing fields are all ones (holes).
fn pack_words(texels: &[Texel], per_word: usize, field: impl Fn(Texel) -> u32) -> Vec<u32> {
    let bits = 32 / per_word;
    texels
        .chunks(per_word)
        .map(|chunk| {
            (0..per_word).fold(0u32, |word, k| {
                let value = chunk.get(k).map_or(u32::MAX, |&t| field(t));
                word | (value & (u32::MAX >> (32 - bits))) << (k * bits)
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn atlas(pitch: u32, rows: u32, f: impl Fn(u32, u32) -> Texel) -> Atlas {
        let texels = (0..rows)
            .flat_map(|y| (0..pitch).map(move |x| (x, y)))
            .map(|(x, y)| f(x, y))
            .collect();
        Atlas {
            pitch,
            rows,
            narrow_rows: 0,
            texels,
        }
    }

    /// Texel `index` as `glsl/atlas.glsl` reads it from `words` (its code, and with normals its
    /// normal in the high half).
    fn device_texel(a: &Atlas, words: &[u32], format: TexelFormat, index: usize) -> u32 {
        let wide = a.wide_len();
        let height_only = format == TexelFormat::Height;
        if index < wide {
            return if height_only {
                (words[index / 2] >> (16 * (index % 2))) & 0xFFFF
            } else {
                words[index]
            };
        }
        let k = index - wide;
        let codes = if height_only { wide.div_ceil(2) } else { wide };
        let code = ((words[codes + k / 4] >> (8 * (k % 4))) & 0xFF) * Texel::NARROW_STEP;
        if height_only {
            return code;
        }
        let normals = codes + (a.texels.len() - wide).div_ceil(4);
        code | ((words[normals + k / 2] >> (16 * (k % 2))) & 0xFFFF) << 16
    }

    #[test]
    fn narrow_rows_are_stored_a_byte_a_height_and_read_back() {
        // 5 × 7 texels, the last 2 rows narrow (codes c · 257), some holes: 25 wide texels and 10
        // narrow ones, so that the last word of each band is part padding in every format.
        let mut a = atlas(5, 7, |x, y| {
            let n = glam::Vec3::new(x as f32 - 2.5, y as f32 - 3.0, 2.0).normalize();
            match (x + 2 * y) % 4 {
                0 => Texel::HOLE,
                _ if y >= 5 => Texel::new(((x * 31 + y) % 255) as u16 * 257, n),
                _ => Texel::new((x * 4001 + y * 13) as u16, n),
            }
        });
        a.narrow_rows = 2;
        assert_eq!(a.wide_len(), 25);
        for format in [TexelFormat::HeightNormal, TexelFormat::Height] {
            let words = a.device_words(format);
            let k = a.texel_words(format) as usize;
            assert_eq!(&words[k..], &block_ranges(&a)[..], "{format:?}");
            for (i, t) in a.texels.iter().enumerate() {
                let want = match format {
                    TexelFormat::HeightNormal => t.0,
                    TexelFormat::Height => u32::from(t.height_code()),
                };
                assert_eq!(
                    device_texel(&a, &words, format, i),
                    want,
                    "{format:?} texel {i}"
                );
            }
        }
        // Words: 25 wide texels at one (a half), 10 narrow codes at a quarter, their normals at a
        // half, each band rounded up.
        assert_eq!(a.texel_words(TexelFormat::HeightNormal), 25 + 3 + 5);
        assert_eq!(a.texel_words(TexelFormat::Height), 13 + 3);
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
        let words = a.device_words(TexelFormat::HeightNormal);
        assert_eq!(words.len(), a.texels.len() + r.len());
        assert_eq!(&words[a.texels.len()..], &r[..]);
        // Height-only: two codes a word, then the same ranges from `texel_words` on.
        let half = a.device_words(TexelFormat::Height);
        let k = a.texel_words(TexelFormat::Height) as usize;
        assert_eq!(k, a.texels.len().div_ceil(2));
        assert_eq!(&half[k..], &r[..]);
        for (i, t) in a.texels.iter().enumerate() {
            let code = (half[i / 2] >> (16 * (i % 2))) & 0xFFFF;
            assert_eq!(code, u32::from(t.height_code()), "texel {i}");
        }
    }

    #[test]
    fn an_odd_texel_count_pads_its_last_word_with_a_hole() {
        let a = Atlas {
            pitch: 1,
            rows: 3,
            narrow_rows: 0,
            texels: vec![Texel::new(5, glam::Vec3::Z); 3],
        };
        let words = a.device_words(TexelFormat::Height);
        assert_eq!(
            words[..2],
            [5 | 5 << 16, 5 | u32::from(Texel::HOLE_CODE) << 16]
        );
    }
}
