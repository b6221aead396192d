//! The atlas as the device holds it, in 32-bit words ([`Atlas::device_words`]), and the reads the
//! device makes of it, which the CPU twin reports (`Atlas::pair_read`, `Atlas::normal_reads`).
//! `glsl/atlas.glsl` reads the same words back.
//!
//! **Normals where there are samples.** A texel with normals was its height code and a 16-bit
//! normal, holes and the packing's unused texels included: 12–25% of the presets' tile texels are
//! holes and 2–12% of the atlas unused, and their normals were a tenth to a fifth of the atlas's
//! bytes
//! (issue "Small and valid at every scale": at most 3 bytes a texel with normals at Q2). The
//! device now keeps one normal per texel that is not a hole, in atlas order, and finds texel
//! `k`'s by its *rank*, the number of such texels before it: a succinct rank directory
//! (Jacobson, "Space-efficient static trees and graphs", FOCS 1989, two levels of counts), with
//! the holes' all-ones codes themselves as the bit vector, so that nothing but the counts is
//! added. Each [`RANK_SPAN`] texels have the texels before them counted in one word and each
//! [`RANK_GROUP`] of them the texels before it within the span in a byte; the rest is counted
//! from the group's codes, at most 16 (from the group's start or back from its end, whichever is
//! nearer), once a ray is done (a hit reads a normal, never a march).
//! The heights are laid out alike in both formats (the 16-bit band's codes two to a word), so a
//! format with normals is the height-only atlas plus its normals and their counts.

use super::layout::{Atlas, Texel};
use super::params::TexelFormat;
use super::ranges::{block_count, block_ranges};
use crate::probe::{Array, Read};

/// Texels whose non-holes are counted from their codes by the device: a byte of the rank
/// directory a group.
pub const RANK_GROUP: usize = 32;

/// Texels a word of the rank directory counts the non-holes before: [`RANK_SPAN`] /
/// [`RANK_GROUP`] groups, whose bytes in two more words say how many lie in the span before
/// each group (at most 224, a byte; a group past the atlas's end, the span's whole count).
pub const RANK_SPAN: usize = 256;

/// Words of the rank directory a span: its count, and a byte for each of its 8 groups. After
/// the last span, one word more: the count of them all, where the last group counts back from.
pub const RANK_SPAN_WORDS: usize = 3;

/// Where the device keeps one band's height codes ([`Atlas::device_words`]).
struct DeviceBand {
    /// Bits of a texel's field: the band's.
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

/// Where each part of the device's atlas starts, in words ([`Atlas::device_words`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DeviceParts {
    /// The blocks' height ranges, after the height codes.
    pub ranges: usize,
    /// The rank directory of the normals (the format with normals), after the ranges.
    pub ranks: usize,
    /// The normals, after the rank directory.
    pub normals: usize,
    /// Words in all.
    pub end: usize,
}

impl Atlas {
    /// Where the device keeps each band's codes.
    fn device_bands(&self) -> [DeviceBand; 4] {
        let mut word = 0;
        self.bands().map(|(bits, texels)| {
            let band = DeviceBand {
                field: bits,
                word,
                texels,
            };
            word += (band.texels.len() * bits as usize).div_ceil(32);
            band
        })
    }

    /// Words the height codes take: where the blocks' height ranges start, in either format.
    pub fn code_words(&self) -> u64 {
        let last = &self.device_bands()[3];
        (last.word + (last.texels.len() * last.field as usize).div_ceil(32)) as u64
    }

    /// Texels that are not holes: those whose normals the format with normals keeps.
    pub fn samples(&self) -> usize {
        self.texels.iter().filter(|t| !t.is_hole()).count()
    }

    /// Where the device's parts start in `format` ([`Atlas::device_words`]); `end` counts the
    /// texels that are not holes.
    pub fn device_parts(&self, format: TexelFormat) -> DeviceParts {
        let ranges = self.code_words() as usize;
        let ranks = self.rank_word();
        let (normals, end) = match format {
            TexelFormat::HeightNormal => {
                let normals = ranks + rank_words(self.texels.len());
                (normals, normals + self.samples().div_ceil(2))
            }
            TexelFormat::Height => (ranks, ranks),
        };
        DeviceParts {
            ranges,
            ranks,
            normals,
            end,
        }
    }

    /// Where the rank directory starts (with normals; the end of the words height-only): after
    /// the codes and the blocks' height ranges.
    fn rank_word(&self) -> usize {
        self.code_words() as usize + block_count(self) as usize
    }

    /// The atlas as the trace shaders read it in `format`, in words, each part starting on a
    /// word, its last word padded with ones:
    /// 1. the 16-bit texels' height codes (before [`Atlas::wide_len`]) two to a word (texel
    ///    `2k` in the low half of word `k`, `2k + 1` in the high half);
    /// 2. each band of packed heights ([`Atlas::packed_rows`]), 12-, 10- then 8-bit: its fields
    ///    `bits` wide, one after another from the lowest bit of its first word (a field may cross
    ///    into the next word), the field `c` standing for the code `c · step(bits)`, all ones
    ///    for a hole ([`Texel::expand`]);
    /// 3. [`block_ranges`], from word [`Atlas::code_words`] on;
    /// 4. with [`TexelFormat::HeightNormal`], the rank directory ([`rank_directory`]) and then
    ///    the normals of the texels that are not holes, in atlas order, two to a word.
    ///
    /// `glsl/atlas.glsl` reads it back.
    pub fn device_words(&self, format: TexelFormat) -> Vec<u32> {
        let mut words = Vec::with_capacity(self.device_parts(format).end);
        for band in &self.device_bands() {
            let texels = &self.texels[band.texels.clone()];
            words.extend(match band.field {
                16 => pack_bits(texels, 16, |t| u32::from(t.height_code())),
                bits => pack_bits(texels, bits, |t| match t.is_hole() {
                    true => u32::MAX,
                    false => u32::from(t.height_code()) / Texel::step(bits),
                }),
            });
        }
        words.extend(block_ranges(self));
        if format == TexelFormat::HeightNormal {
            words.extend(rank_directory(&self.texels));
            let sampled: Vec<Texel> = self
                .texels
                .iter()
                .filter(|t| !t.is_hole())
                .copied()
                .collect();
            words.extend(pack_bits(&sampled, 16, |t| t.0 >> 16));
        }
        words
    }

    /// The band that holds texel `index` (the last one for an index past the atlas).
    fn device_band(&self, index: usize) -> DeviceBand {
        let [wide, b12, b10, b8] = self.device_bands();
        [wide, b12, b10]
            .into_iter()
            .find(|b| b.texels.contains(&index))
            .unwrap_or(b8)
    }

    /// The device's read of a cell's row: texel `index` and the next, whose fields lie in the two
    /// words from the first's (`rbvh_atlas_tile_pair` in `glsl/atlas.glsl`), read together.
    pub(crate) fn pair_read(&self, index: usize) -> Read {
        Read {
            bytes: 8,
            ..word_read(self.device_band(index).word_of(index).0)
        }
    }

    /// The device's reads for the normal of texel `index`, not a hole (the format with normals;
    /// `rbvh_atlas_normal` in `glsl/atlas.glsl`): the rank directory's words that count the
    /// texels before its group (its span's count and the word of its group's byte), or, in the
    /// group's second half, before the next group (the next span's count where that begins a
    /// span); the codes of the group's texels before it, or of those from it to the group's
    /// end, a row of two at a time (a part in each band they span); and the word holding its
    /// normal. `ranks` is the atlas's [`rank_directory`], made once by the twin.
    pub(crate) fn normal_reads(&self, index: usize, ranks: &[u32]) -> Vec<Read> {
        let ranks_word = self.rank_word();
        let normals = ranks_word + rank_words(self.texels.len());
        let counted = RankCount::of(index, self.texels.len());
        let span = ranks_word + RANK_SPAN_WORDS * (index / RANK_SPAN);
        let mut reads = match counted.group {
            8 => vec![word_read(span + RANK_SPAN_WORDS)],
            g => vec![word_read(span), word_read(span + 1 + g / 4)],
        };
        let mut at = counted.texels.start;
        while at < counted.texels.end {
            let end = counted.texels.end.min(self.device_band(at).texels.end);
            reads.extend((at..end).step_by(2).map(|k| self.pair_read(k)));
            at = end;
        }
        let rank = counted.rank(ranks, index, |k| !self.texels[k].is_hole());
        reads.push(word_read(normals + rank / 2));
        reads
    }
}

/// How the device counts a texel's rank from the rank directory: the texels that are not holes
/// before group `group` of its span (8: the next span), plus those in `texels` (the group's
/// texels before it) or minus those (from it to the group's end), whichever are fewer.
struct RankCount {
    group: usize,
    texels: std::ops::Range<usize>,
    forward: bool,
}

impl RankCount {
    /// The count for texel `index` of an atlas of `len` texels.
    fn of(index: usize, len: usize) -> RankCount {
        let first = index / RANK_GROUP * RANK_GROUP;
        let group = index / RANK_GROUP % (RANK_SPAN / RANK_GROUP);
        match index - first < RANK_GROUP / 2 {
            true => RankCount {
                group,
                texels: first..index,
                forward: true,
            },
            false => RankCount {
                group: group + 1,
                texels: index..(first + RANK_GROUP).min(len),
                forward: false,
            },
        }
    }

    /// Texel `index`'s rank from the directory `ranks`, `sampled(k)` telling the texels that
    /// are not holes.
    fn rank(&self, ranks: &[u32], index: usize, sampled: impl Fn(usize) -> bool) -> usize {
        let span = RANK_SPAN_WORDS * (index / RANK_SPAN);
        let before = match self.group {
            8 => ranks[span + RANK_SPAN_WORDS],
            g => ranks[span] + (ranks[span + 1 + g / 4] >> (8 * (g % 4)) & 0xFF),
        } as usize;
        let n = self.texels.clone().filter(|&k| sampled(k)).count();
        match self.forward {
            true => before + n,
            false => before - n,
        }
    }
}

/// Words of the rank directory of `texels` texels: [`RANK_SPAN_WORDS`] a span of
/// [`RANK_SPAN`], the last one partial, and the count of them all.
pub fn rank_words(texels: usize) -> usize {
    texels.div_ceil(RANK_SPAN) * RANK_SPAN_WORDS + 1
}

/// The rank directory of `texels` ([`Atlas::device_words`]): for each span of [`RANK_SPAN`]
/// texels, the texels before it that are not holes, then in two words a byte for each of its
/// groups of [`RANK_GROUP`], the span's such texels before the group (group `g` in byte `g % 4`
/// of word `1 + g / 4`; a group past the end, the span's whole count); then the count of them
/// all.
pub fn rank_directory(texels: &[Texel]) -> Vec<u32> {
    let mut words = Vec::with_capacity(rank_words(texels.len()));
    let mut before = 0u32;
    for span in texels.chunks(RANK_SPAN) {
        let mut bytes = [0u32; 2];
        let mut within = 0u32;
        let mut groups = span.chunks(RANK_GROUP);
        for g in 0..RANK_SPAN / RANK_GROUP {
            bytes[g / 4] |= within << (8 * (g % 4));
            within += groups.next().map_or(0, |group| {
                group.iter().filter(|t| !t.is_hole()).count() as u32
            });
        }
        words.extend([before, bytes[0], bytes[1]]);
        before += within;
    }
    words.push(before);
    words
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
    use crate::rbvh::ranges::tests::atlas;

    /// Texel `index`'s height code as `glsl/atlas.glsl` reads it from `words`: the band it lies
    /// in, that band's first word after the words of those before it (each rounded up), its
    /// field from one word or two, expanded to a code.
    fn device_code(a: &Atlas, words: &[u32], index: usize) -> u32 {
        let (mut word, mut found) = (0, None);
        for (bits, range) in a.bands() {
            if range.contains(&index) {
                found = Some((bits, range.start, word));
            }
            word += (range.len() * bits as usize).div_ceil(32);
        }
        let (bits, start, first) = found.expect("a texel of the atlas");
        let bit = (index - start) * bits as usize;
        let (w, shift) = (first + bit / 32, (bit % 32) as u32);
        let lo = u64::from(words[w]) >> shift;
        let hi = if shift + bits > 32 {
            u64::from(words[w + 1]) << (32 - shift)
        } else {
            0
        };
        let raw = ((lo | hi) & u64::from(u32::MAX >> (32 - bits))) as u32;
        u32::from(Texel::expand(raw, bits))
    }

    /// Texel `index`'s normal as `rbvh_atlas_normal` finds it in `words`: the directory's
    /// count before its group, plus the non-holes among the group's texels before it (their
    /// codes), or before the next group, minus those from it to the group's end, then the
    /// normal at that rank.
    /// Texel `i`'s normal as the device reads it, checked against the texel's own, and the reads
    /// that find it, the last of them the word of the normal at the texel's rank counted whole.
    fn checked_normal_reads(a: &Atlas, words: &[u32], d: &[u32], i: usize) -> Vec<Read> {
        assert_eq!(device_normal(a, words, i), a.texels[i].0 >> 16, "texel {i}");
        let reads = a.normal_reads(i, d);
        let rank = a.texels[..i].iter().filter(|t| !t.is_hole()).count();
        let normals = a.device_parts(TexelFormat::HeightNormal).normals;
        assert_eq!(
            reads.last().unwrap().offset,
            4 * (normals + rank / 2) as u64,
            "texel {i}"
        );
        reads
    }

    fn device_normal(a: &Atlas, words: &[u32], index: usize) -> u32 {
        let parts = a.device_parts(TexelFormat::HeightNormal);
        let count = RankCount::of(index, a.texels.len());
        let rank = count.rank(&words[parts.ranks..parts.normals], index, |k| {
            device_code(a, words, k) != 0xFFFF
        });
        (words[parts.normals + rank / 2] >> (16 * (rank % 2))) & 0xFFFF
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
            let parts = a.device_parts(format);
            assert_eq!(words.len(), parts.end, "{format:?}");
            assert_eq!(
                &words[parts.ranges..parts.ranks],
                &block_ranges(&a)[..],
                "{format:?}"
            );
            for (i, t) in a.texels.iter().enumerate() {
                assert_eq!(
                    device_code(&a, &words, i),
                    u32::from(t.height_code()),
                    "{format:?} texel {i}"
                );
                if format == TexelFormat::HeightNormal && !t.is_hole() {
                    assert_eq!(device_normal(&a, &words, i), t.0 >> 16, "texel {i}");
                }
                // A row's two codes: the two words from the one holding the first's field.
                let pair = a.pair_read(i);
                assert_eq!(pair.bytes, 8, "texel {i}");
                let bit = match i < 15 {
                    true => 16 * i,
                    false => {
                        let (k, band) = ((i - 15) % 10, (i - 15) / 10);
                        32 * [8, 12, 16][band] + k * [12, 10, 8][band]
                    }
                };
                assert_eq!(pair.offset, 4 * (bit / 32) as u64, "texel {i}");
            }
        }
        // Words: 15 wide texels at a half; 10 codes of 12, 10 and 8 bits (120, 100 and 80 bits);
        // each part rounded up; the two blocks' ranges (9 rows); then with normals one span's
        // directory and its total, and the 31 non-holes' normals at a half.
        let samples = a.samples();
        assert_eq!(samples, 31);
        assert_eq!(a.code_words(), 8 + 4 + 4 + 3);
        assert_eq!(a.device_parts(TexelFormat::Height).end, 19 + 2);
        assert_eq!(
            a.device_parts(TexelFormat::HeightNormal).end,
            19 + 2 + 4 + 16
        );
        // A code its band cannot hold is found.
        a.texels[40] = Texel::new(1000, glam::Vec3::Z);
        assert_eq!(a.first_code_off_its_band(), Some((40, 1000, 8)));
    }

    #[test]
    fn ranks_count_the_non_holes_before_each_span_and_group() {
        // 600 texels (three spans, the last partial) of a 16-bit atlas, every third a hole and
        // the whole second group of the second span: the directory counts what lies before.
        let a = atlas(40, 15, |x, y| {
            let k = y * 40 + x;
            match k % 3 == 0 || (288..320).contains(&k) {
                true => Texel::HOLE,
                false => Texel::new((k % 1000) as u16 * 2 + 1, glam::Vec3::Y),
            }
        });
        let d = rank_directory(&a.texels);
        assert_eq!(d.len(), rank_words(600));
        assert_eq!(d.len(), 10);
        let before = |k: usize| a.texels[..k].iter().filter(|t| !t.is_hole()).count() as u32;
        for span in 0..3 {
            assert_eq!(d[3 * span], before(span * RANK_SPAN), "span {span}");
            // The last span's 88 texels are three groups; those past the end count it whole.
            for g in 0..8 {
                let first = (span * RANK_SPAN + g * RANK_GROUP).min(600);
                let byte = (d[3 * span + 1 + g / 4] >> (8 * (g % 4))) & 0xFF;
                assert_eq!(d[3 * span] + byte, before(first), "span {span} group {g}");
            }
        }
        assert_eq!(d[9], before(600));
        let words = a.device_words(TexelFormat::HeightNormal);
        for (i, _) in a.texels.iter().enumerate().filter(|(_, t)| !t.is_hole()) {
            let reads = checked_normal_reads(&a, &words, &d, i);
            // The directory's words (one where the next group begins a span), a read a pair of
            // the group's texels before it or from it to the group's end (at most 16), the
            // normal's word.
            let (k, last) = (i % RANK_GROUP, 600 - i / RANK_GROUP * RANK_GROUP);
            let (words, counted) = match k < 16 {
                true => (2, k),
                false if i % RANK_SPAN >= RANK_SPAN - RANK_GROUP => (1, 32 - k),
                false => (2, 32.min(last) - k),
            };
            assert_eq!(reads.len(), words + counted.div_ceil(2) + 1, "texel {i}");
            assert!(counted <= 16);
        }
    }

    #[test]
    fn ranks_count_back_to_the_total_and_across_bands() {
        // 8 × 64 texels, two whole spans: a texel in the second half of a span's last group
        // counts back from the next span's count, or from the total after the last span. 35
        // rows of 16-bit codes, then 5, 5 and 19 rows of 12-, 10- and 8-bit ones: at a pitch of
        // 8 (a loaded file's) a half group may hold two bands, counted a part in each (the
        // 16-bit band ends at texel 280, the 10-bit one begins at 320 and ends at 360).
        let mut a = atlas(8, 64, |x, y| {
            let bits = match y {
                0..=34 => 16,
                35..=39 => 12,
                40..=44 => 10,
                _ => 8,
            };
            let c = (x * 37 + y * 11 + 3) % ((1 << bits.min(12)) - 1);
            let n = glam::Vec3::new(x as f32 - 3.5, 4.0, y as f32 - 31.5).normalize();
            match (x * 7 + y * 3) % 5 {
                0 => Texel::HOLE,
                _ => Texel::new((c * Texel::step(bits)) as u16, n),
            }
        });
        a.packed_rows = [5, 5, 19];
        assert_eq!(a.band_ends(), [280, 320, 360]);
        assert_eq!(a.first_code_off_its_band(), None);
        let d = rank_directory(&a.texels);
        assert_eq!(d.len(), 7);
        assert_eq!(d[6] as usize, a.samples());
        let words = a.device_words(TexelFormat::HeightNormal);
        let mut back_to_a_count = 0;
        for (i, _) in a.texels.iter().enumerate().filter(|(_, t)| !t.is_hole()) {
            let reads = checked_normal_reads(&a, &words, &d, i);
            if i % RANK_SPAN >= RANK_SPAN - RANK_GROUP / 2 {
                back_to_a_count += 1;
                let parts = a.device_parts(TexelFormat::HeightNormal);
                let next = parts.ranks + RANK_SPAN_WORDS * (i / RANK_SPAN + 1);
                assert_eq!(reads[0].offset, 4 * next as u64, "texel {i}");
            }
        }
        assert!(back_to_a_count > 10);
        // Texel 277 counts back over 277–279 (16-bit) and 280–287 (12-bit); 363 forward over
        // 352–359 (10-bit) and 360–362 (8-bit): a pair read a part, rounded up, in each band.
        for (i, pairs) in [(277, 2 + 4), (363, 4 + 2)] {
            assert!(!a.texels[i].is_hole(), "texel {i}");
            assert_eq!(a.normal_reads(i, &d).len(), 2 + pairs + 1, "texel {i}");
        }
    }
}
