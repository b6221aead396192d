// Reading the atlas as src/rbvh/words.rs lays it out (Atlas::device_words), in either texel
// format: the 16-bit band's height codes two to a word, then the bands of packed heights —
// 12-bit texels up to `end12`, 10-bit ones up to `end10`, 8-bit ones up to `len` — each band its
// fields one after another from the lowest bit of its first word; the blocks' height ranges
// after the codes (rbvh_atlas_code_words); then, with normals, the rank directory and the
// normals of the texels that are not holes, in atlas order, two to a word (rbvh_atlas_normal).
// Every part starts on a word. A packed field c of b bits is the 16-bit code c * step(b)
// (Texel::step: 15, 63 and 257 for 12, 10 and 8 bits), all ones a hole, so every reader sees
// 16-bit codes.
//
// The includer defines RBVH_ATLAS_WORD(i), the atlas's word i, before the #include.
#ifndef RBVH_ATLAS_GLSL
#define RBVH_ATLAS_GLSL

// Words `n` fields of `bits` bits take, rounded up; counted in groups of 32 fields so that no
// product overflows 32 bits (n up to 2^32 - 1).
uint rbvh_atlas_words(uint n, uint bits) {
    return (n >> 5u) * bits + (((n & 31u) * bits + 31u) >> 5u);
}

// Words of the height codes: where the blocks' height ranges start.
uint rbvh_atlas_code_words(uint len, uint wide_len, uint end12, uint end10) {
    return rbvh_atlas_words(wide_len, 16u) + rbvh_atlas_words(end12 - wide_len, 12u) +
           rbvh_atlas_words(end10 - end12, 10u) + rbvh_atlas_words(len - end10, 8u);
}

// The band (0: 16-bit, 1: 12-bit, 2: 10-bit, 3: 8-bit) that holds texel `index`.
uint rbvh_atlas_band(uint index, uint wide_len, uint end12, uint end10) {
    return index < wide_len ? 0u : (index < end12 ? 1u : (index < end10 ? 2u : 3u));
}

// Where a tile's fields lie (rbvh_atlas_tile): the word holding the field of its texel (0, 0), and
// in bits 0-7 that field's first bit in the word, in bits 8-15 the band's field width, in bits
// 16-31 the step a field counts in.
struct RbvhAtlasTile {
    uint word;
    uint phase_bits_step;
};

// The fields of the tile whose texel (0, 0) is atlas texel `base`: its band's width and first word
// chosen by selects rather than a branch (SIMD implementations such as lavapipe run both sides of
// a branch whose lanes differ). A tile lies in one band (rbvh_tile_fits), so a cell's four corners
// are offsets from it. The walk makes it for each cell: kept through a leaf's walk, it cost RADV
// 8 VGPRs (64 against 56) for no speed measured on lavapipe (docs/speed.md, "Heights in 10 and
// 12 bits on lavapipe").
RbvhAtlasTile rbvh_atlas_tile(uint base, uint wide_len, uint end12, uint end10) {
    uint band = rbvh_atlas_band(base, wide_len, end12, end10);
    uint words12 = rbvh_atlas_words(wide_len, 16u);
    uint words10 = words12 + rbvh_atlas_words(end12 - wide_len, 12u);
    uint words8 = words10 + rbvh_atlas_words(end10 - end12, 10u);
    uint bits = band == 0u ? 16u : (band == 1u ? 12u : (band == 2u ? 10u : 8u));
    uint start = band == 0u ? 0u : (band == 1u ? wide_len : (band == 2u ? end12 : end10));
    uint first = band == 0u ? 0u : (band == 1u ? words12 : (band == 2u ? words10 : words8));
    uint step = band == 0u ? 1u : (band == 1u ? 15u : (band == 2u ? 63u : 257u));
    // Word index and bit apart (a bit offset would overflow 32 bits past 2^27 texels).
    uint k = base - start;
    uint word = first + (k >> 5u) * bits + (((k & 31u) * bits) >> 5u);
    return RbvhAtlasTile(word, (((k & 31u) * bits) & 31u) | bits << 8u | step << 16u);
}

// The bits from `offset` (below 64) of the 64-bit value hi:lo, as many as fit in 32.
uint rbvh_atlas_window(uint lo, uint hi, uint offset) {
    uint low = offset < 32u ? lo >> offset : hi >> (offset - 32u);
    uint high = (offset > 0u && offset < 32u) ? hi << (32u - offset) : 0u;
    return low | high;
}

// The height code of a field read from the tile (0xFFFF, a hole, where `inside` is false): a
// field `c` is the code c * step, all ones a hole.
uint rbvh_atlas_decode(RbvhAtlasTile tile, uint field, bool inside) {
    uint mask = 0xFFFFu >> (16u - min((tile.phase_bits_step >> 8u) & 0xFFu, 16u));
    uint c = field & mask;
    return inside && c != mask ? c * (tile.phase_bits_step >> 16u) : 0xFFFFu;
}

// The word holding the field of the tile's texel `d` texels after its texel (0, 0), and the
// field's first bit in it: counted in groups of 32 fields, as rbvh_atlas_tile counts, so that no
// product overflows 32 bits whatever the tile's size in a loaded file.
uvec2 rbvh_atlas_tile_field(RbvhAtlasTile tile, uint d) {
    uint bits = (tile.phase_bits_step >> 8u) & 0xFFu;
    uint bit = (tile.phase_bits_step & 0xFFu) + (d & 31u) * bits;
    return uvec2(tile.word + (d >> 5u) * bits + (bit >> 5u), bit & 31u);
}

// The height codes of the tile's texels `d` and `d + 1` texels after its texel (0, 0) (d = j *
// pitch + i; atlas texel `index` and the next; holes at or beyond `len`): what the walk reads, a
// row of a cell. Both fields lie in the two words from the first's (a field of a packed band may
// cross into the next word, 20 to 24 bits for the two; the 16-bit band's are two halves of one
// word or of two), read together, so that a cell's four corners take four reads, as one word each did.
// The words read lie inside the buffer: the blocks' height ranges follow the codes.
uvec2 rbvh_atlas_tile_pair(RbvhAtlasTile tile, uint d, uint index, uint len) {
    uint bits = (tile.phase_bits_step >> 8u) & 0xFFu;
    uvec2 at = rbvh_atlas_tile_field(tile, d);
    uint word = at.x;
    uint shift = at.y;
    uint lo = RBVH_ATLAS_WORD(word);
    uint hi = RBVH_ATLAS_WORD(word + 1u);
    return uvec2(rbvh_atlas_decode(tile, rbvh_atlas_window(lo, hi, shift), index < len),
                 rbvh_atlas_decode(tile, rbvh_atlas_window(lo, hi, shift + bits), index + 1u < len));
}

// The height code of the tile's texel `d` alone (as rbvh_atlas_tile_pair's first).
uint rbvh_atlas_tile_code(RbvhAtlasTile tile, uint d, uint index, uint len) {
    uint bits = (tile.phase_bits_step >> 8u) & 0xFFu;
    uvec2 at = rbvh_atlas_tile_field(tile, d);
    uint word = at.x;
    uint shift = at.y;
    uint field = RBVH_ATLAS_WORD(word) >> shift;
    if (shift + bits > 32u) {
        field |= RBVH_ATLAS_WORD(word + 1u) << (32u - shift);
    }
    return rbvh_atlas_decode(tile, field, index < len);
}

// The height code of texel `index` alone (painting).
uint rbvh_atlas_code(uint index, uint len, uint wide_len, uint end12, uint end10) {
    return rbvh_atlas_tile_code(rbvh_atlas_tile(index, wide_len, end12, end10), 0u, index, len);
}

// Texels that are not holes among atlas texels [from, to), at most 16 of them, read a row of two
// at a time from their bands' fields (a part in each band the texels span).
uint rbvh_atlas_samples_between(uint from, uint to, uint len, uint wide_len, uint end12, uint end10) {
    uint samples = 0u;
    uint at = from;
    for (uint part = 0u; part < 4u && at < to; ++part) {
        uint band = rbvh_atlas_band(at, wide_len, end12, end10);
        uint end = min(to, band == 0u ? wide_len : (band == 1u ? end12 : (band == 2u ? end10 : len)));
        RbvhAtlasTile tile = rbvh_atlas_tile(at, wide_len, end12, end10);
        for (uint d = 0u; d < 16u && at + d < end; d += 2u) {
            uvec2 pair = rbvh_atlas_tile_pair(tile, d, at + d, len);
            samples += uint(pair.x != 0xFFFFu) + uint(at + d + 1u < end && pair.y != 0xFFFFu);
        }
        at = end;
    }
    return samples;
}

// The normal of atlas texel `index`, not a hole, of an atlas with normals, in bits 16-31 (bits
// 0-15 zero), where the host's Texel holds it. The normals are kept for the texels that are not
// holes alone, texel `index`'s at its rank, the number of such texels before it. The rank
// directory after the blocks' height ranges (src/rbvh/words.rs: a word a span of 256 texels
// counting those before the span, in the next two a byte a group of 32 counting those in the
// span before the group, and after the last span the count of all) gives those before its group
// of 32, or before the next group; the texels between, at most 16, are counted from their codes
// (RankCount in src/rbvh/words.rs).
uint rbvh_atlas_normal(uint index, uint len, uint pitch, uint wide_len, uint end12, uint end10) {
    uint rows = len / max(pitch, 1u);
    uint blocks = ((pitch + 7u) >> 3) * ((rows + 7u) >> 3);
    uint ranks = rbvh_atlas_code_words(len, wide_len, end12, end10) + blocks;
    uint normals = ranks + ((len >> 8) + uint((len & 255u) != 0u)) * 3u + 1u;
    uint span = ranks + (index >> 8) * 3u;
    uint first = index & ~31u;
    bool forward = (index & 31u) < 16u;
    uint group = ((index >> 5) & 7u) + (forward ? 0u : 1u);
    uint before = RBVH_ATLAS_WORD(group == 8u ? span + 3u : span);
    if (group < 8u) {
        before += (RBVH_ATLAS_WORD(span + 1u + (group >> 2)) >> ((group & 3u) << 3)) & 0xFFu;
    }
    uint counted = rbvh_atlas_samples_between(forward ? first : index, forward ? index : first + min(32u, len - first), len,
                                              wide_len, end12, end10);
    uint rank = forward ? before + counted : before - counted;
    return (RBVH_ATLAS_WORD(normals + (rank >> 1)) << ((~rank & 1u) << 4)) & 0xFFFF0000u;
}

#endif
