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

/// Where the device keeps one band's height codes ([`Atlas::device_words`]).
struct DeviceBand {
    /// Bits of a texel's field: 32 for the 16-bit band with normals (its word holds both), else
    /// the band's bits.
    field: u32,
    /// The band's texels.
    texels: std::ops::Range<usize>,
    /// Its first word.
    word: usize,
}

impl DeviceBand {
    /// The word holding texel `index`'s field (its first bits where the field crosses into the
    /// next word) and the field's shift in it.
    fn word_of(&self, index: usize) -> (usize, u32) {
        let bit = (index - self.texels.start) as u64 * u64::from(self.field);
        (self.word + (bit / 32) as usize, (bit % 32) as u32)
    }
}

impl Atlas {
    /// Where the device keeps each band's codes in `format`, then the first word of the packed
    /// bands' normals and the words the texels take in all.
    fn device_layout(&self, format: TexelFormat) -> ([DeviceBand; 4], usize, usize) {
        let mut word = 0;
        let bands = self.bands().map(|(bits, texels)| {
            let field = match (bits, format) {
                (16, TexelFormat::HeightNormal) => 32,
                _ => bits,
            };
            let band = DeviceBand {
                field,
                word,
                texels,
            };
            word += (band.texels.len() * field as usize).div_ceil(32);
            band
        });
        let normal_words = match format {
            TexelFormat::HeightNormal => (self.texels.len() - self.wide_len()).div_ceil(2),
            TexelFormat::Height => 0,
        };
        (bands, word, word + normal_words)
    }

    /// The atlas as the trace shaders read it in `format`, in words:
    /// 1. the 16-bit texels (before [`Atlas::wide_len`]): one word each (height code in bits
    ///    0–15, normal in 16–31), or with [`TexelFormat::Height`] their height codes two to a word
    ///    (texel `2k` in the low half of word `k`, `2k + 1` in the high half);
    /// 2. each band of packed heights ([`Atlas::packed_rows`]), 12-, 10- then 8-bit: its fields
    ///    `bits` wide, one after another from the lowest bit of its first word (a field may cross
    ///    into the next word), the field `c` standing for the code `c · step(bits)`, all ones
    ///    for a hole ([`Texel::expand`]);
    /// 3. with [`TexelFormat::HeightNormal`], the packed bands' normals two to a word;
    /// 4. [`block_ranges`], from word [`Atlas::texel_words`] on.
    ///
    /// Each part starts on a word, its last word padded with ones. `glsl/atlas.glsl` reads it back.
    pub fn device_words(&self, format: TexelFormat) -> Vec<u32> {
        let (bands, _, _) = self.device_layout(format);
        let mut words = Vec::new();
        for band in &bands {
            let texels = &self.texels[band.texels.clone()];
            words.extend(match band.field {
                32 => bytemuck::cast_slice::<Texel, u32>(texels).to_vec(),
                16 => pack_bits(texels, 16, |t| u32::from(t.height_code())),
                bits => pack_bits(texels, bits, |t| match t.is_hole() {
                    true => u32::MAX,
                    false => u32::from(t.height_code()) / Texel::step(bits),
                }),
            });
        }
        if format == TexelFormat::HeightNormal {
            words.extend(pack_bits(&self.texels[self.wide_len()..], 16, |t| {
                t.0 >> 16
            }));
        }
        words.extend(block_ranges(self));
        words
    }

    /// Words the texels take in `format`, where the block ranges start.
    pub fn texel_words(&self, format: TexelFormat) -> u64 {
        self.device_layout(format).2 as u64
    }
}

impl Atlas {
    /// The band that holds texel `index` as the device keeps it in `format` (the last one for an
    /// index past the atlas).
    fn device_band(&self, index: usize, format: TexelFormat) -> DeviceBand {
        let [wide, b12, b10, b8] = self.device_layout(format).0;
        [wide, b12, b10]
            .into_iter()
            .find(|b| b.texels.contains(&index))
            .unwrap_or(b8)
    }

    /// The device's read of texel `index`'s height code in `format` ([`Atlas::device_words`]):
    /// in the 16-bit band its word (its half-word without normals); in a packed band the word
    /// holding its field, and the next with it (8 bytes) where the field crosses into it.
    pub(crate) fn code_read(&self, index: usize, format: TexelFormat) -> Read {
        let band = self.device_band(index, format);
        match band.field {
            // The 16-bit band (32 bits with normals).
            16 | 32 => Read {
                array: Array::Atlas,
                offset: u64::from(band.field / 8) * index as u64,
                bytes: band.field / 8,
            },
            field => {
                let (word, shift) = band.word_of(index);
                Read {
                    bytes: if shift + field > 32 { 8 } else { 4 },
                    ..word_read(word)
                }
            }
        }
    }

    /// The device's read of a cell's row in `format`: texel `index` and the next, whose fields lie
    /// in the two words from the first's (`rbvh_atlas_tile_pair` in `glsl/atlas.glsl`), read
    /// together.
    pub(crate) fn pair_read(&self, index: usize, format: TexelFormat) -> Read {
        Read {
            bytes: 8,
            ..word_read(self.device_band(index, format).word_of(index).0)
        }
    }

    /// The device's reads of texel `index` with its normal (the format with normals): its word
    /// in the 16-bit band; in a packed band, the reads of its code and the word holding its
    /// normal.
    pub(crate) fn normal_reads(&self, index: usize) -> impl Iterator<Item = Read> {
        let wide = self.wide_len();
        let normals = self.device_layout(TexelFormat::HeightNormal).1;
        std::iter::once(self.code_read(index, TexelFormat::HeightNormal))
            .chain((index >= wide).then(|| word_read(normals + (index - wide) / 2)))
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

/// `texels` as fields of `bits` bits (at most 32) each, `field(texel)`, one after another from
/// the lowest bit of the first word; the last word's missing bits are all ones (holes).
fn pack_bits(texels: &[Texel], bits: u32, field: impl Fn(Texel) -> u32) -> Vec<u32> {
    let mask = u64::from(u32::MAX >> (32 - bits));
    let mut words = Vec::with_capacity((texels.len() * bits as usize).div_ceil(32));
    let (mut acc, mut filled) = (0u64, 0u32);
    for &t in texels {
        acc |= (u64::from(field(t)) & mask) << filled;
        filled += bits;
        if filled >= 32 {
            words.push(acc as u32);
            (acc, filled) = (acc >> 32, filled - 32);
        }
    }
    if filled > 0 {
        words.push((acc | u64::MAX << filled) as u32);
    }
    words
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
            packed_rows: [0; 3],
            texels,
        }
    }

    /// Texel `index` as `glsl/atlas.glsl` reads it from `words` (its code, and with normals its
    /// normal in the high half): the band it lies in, that band's first word after the words of
    /// those before it (each rounded up), its field (a 32-bit word with normals in the 16-bit
    /// band) from one word or two, expanded to a code, and a packed texel's normal after the
    /// codes.
    fn device_texel(a: &Atlas, words: &[u32], format: TexelFormat, index: usize) -> u32 {
        let height_only = format == TexelFormat::Height;
        let (mut word, mut found) = (0, None);
        for (n, (bits, range)) in a.bands().into_iter().enumerate() {
            let field = match n {
                0 if !height_only => 32,
                _ => bits,
            };
            if range.contains(&index) {
                found = Some((field, bits, range.start, word));
            }
            word += (range.len() * field as usize).div_ceil(32);
        }
        let normals = word;
        let (field, bits, start, first) = found.expect("a texel of the atlas");
        let bit = (index - start) * field as usize;
        let (w, shift) = (first + bit / 32, (bit % 32) as u32);
        let lo = u64::from(words[w]) >> shift;
        let hi = if shift + field > 32 {
            u64::from(words[w + 1]) << (32 - shift)
        } else {
            0
        };
        let raw = ((lo | hi) & u64::from(u32::MAX >> (32 - field))) as u32;
        if field == 32 {
            return raw;
        }
        let code = u32::from(Texel::expand(raw, bits));
        if height_only || bits == 16 {
            return code;
        }
        let k = index - a.wide_len();
        code | ((words[normals + k / 2] >> (16 * (k % 2))) & 0xFFFF) << 16
    }

    #[test]
    fn packed_rows_are_stored_their_bits_a_height_and_read_back() {
        // 5 × 9 texels: 3 rows of 16-bit codes, then 2 rows each of 12-, 10- and 8-bit codes
        // (`step · c`), some holes; 10 texels a packed band, so that fields cross words and the
        // last word of each band is part padding in every format.
        let mut a = atlas(5, 9, |x, y| {
            let n = glam::Vec3::new(x as f32 - 2.5, y as f32 - 3.0, 2.0).normalize();
            let bits = match y {
                0..=2 => 16,
                3..=4 => 12,
                5..=6 => 10,
                _ => 8,
            };
            let c = (x * 4001 + y * 13 + 7) % ((1 << bits) - 1);
            match (x + 2 * y) % 4 {
                0 => Texel::HOLE,
                _ => Texel::new((c * Texel::step(bits)) as u16, n),
            }
        });
        a.packed_rows = [2, 2, 2];
        assert_eq!(a.wide_len(), 15);
        assert_eq!(a.first_code_off_its_band(), None);
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
                let crossing = i >= 15 && {
                    let (k, bits) = ((i - 15) % 10, [12, 10, 8][(i - 15) / 10]);
                    k * bits % 32 + bits > 32
                };
                let bytes = match (i < 15, format) {
                    (true, TexelFormat::Height) => 2,
                    (false, _) if crossing => 8,
                    _ => 4,
                };
                assert_eq!(a.code_read(i, format).bytes, bytes, "{format:?} texel {i}");
                // A row's two codes: the two words from the one holding the first's field.
                let pair = a.pair_read(i, format);
                assert_eq!(pair.bytes, 8, "{format:?} texel {i}");
                assert_eq!(
                    pair.offset,
                    a.code_read(i, format).offset / 4 * 4,
                    "texel {i}"
                );
            }
        }
        // Words: 15 wide texels at one (a half); 10 codes of 12, 10 and 8 bits (120, 100 and 80
        // bits); the 30 packed texels' normals at a half; each part rounded up.
        assert_eq!(
            a.texel_words(TexelFormat::HeightNormal),
            15 + 4 + 4 + 3 + 15
        );
        assert_eq!(a.texel_words(TexelFormat::Height), 8 + 4 + 4 + 3);
        // A code its band cannot hold is found.
        a.texels[40] = Texel::new(1000, glam::Vec3::Z);
        assert_eq!(a.first_code_off_its_band(), Some((40, 1000, 8)));
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
            packed_rows: [0; 3],
            texels: vec![Texel::new(5, glam::Vec3::Z); 3],
        };
        let words = a.device_words(TexelFormat::Height);
        assert_eq!(
            words[..2],
            [5 | 5 << 16, 5 | u32::from(Texel::HOLE_CODE) << 16]
        );
    }
}
