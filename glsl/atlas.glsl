// Reading a texel of the atlas as src/rbvh/ranges.rs lays it out (Atlas::device_words): the
// 16-bit band's texels before `wide_len` (one word each, height code and normal, or two to a word
// height only), then the bands of packed heights — 12-bit texels up to `end12`, 10-bit ones up to
// `end10`, 8-bit ones up to `len` — each band its fields one after another from the lowest bit of
// its first word, then, unless `height_only`, the packed bands' normals two to a word; the
// blocks' height ranges after all of them (rbvh_atlas_texel_words). Every part starts on a word.
// A packed field c of b bits is the 16-bit code c * step(b) (Texel::step: 15, 63 and 257 for 12,
// 10 and 8 bits), all ones a hole, so every reader sees 16-bit codes.
//
// The includer defines RBVH_ATLAS_WORD(i), the atlas's word i, before the #include.
#ifndef RBVH_ATLAS_GLSL
#define RBVH_ATLAS_GLSL

// Words `n` fields of `bits` bits take, rounded up; counted in groups of 32 fields so that no
// product overflows 32 bits (n up to 2^32 - 1).
uint rbvh_atlas_words(uint n, uint bits) {
    return (n >> 5u) * bits + (((n & 31u) * bits + 31u) >> 5u);
}

// Words of the height codes: where the packed bands' normals start.
uint rbvh_atlas_code_words(uint len, uint wide_len, uint end12, uint end10, bool height_only) {
    return rbvh_atlas_words(wide_len, height_only ? 16u : 32u) + rbvh_atlas_words(end12 - wide_len, 12u) +
           rbvh_atlas_words(end10 - end12, 10u) + rbvh_atlas_words(len - end10, 8u);
}

// Words of the texels: where the block ranges start.
uint rbvh_atlas_texel_words(uint len, uint wide_len, uint end12, uint end10, bool height_only) {
    uint normal_words = height_only ? 0u : (len - wide_len + 1u) >> 1;
    return rbvh_atlas_code_words(len, wide_len, end12, end10, height_only) + normal_words;
}

// The band (0: 16-bit, 1: 12-bit, 2: 10-bit, 3: 8-bit) that holds texel `index`.
uint rbvh_atlas_band(uint index, uint wide_len, uint end12, uint end10) {
    return index < wide_len ? 0u : (index < end12 ? 1u : (index < end10 ? 2u : 3u));
}

// Where a tile's fields lie (rbvh_atlas_tile): the word holding the field of its texel (0, 0), and
// in bits 0-7 that field's first bit in the word, in bits 8-15 the band's field width (32 for the
// 16-bit band with normals, whose word holds both), in bits 16-31 the step a field counts in.
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
RbvhAtlasTile rbvh_atlas_tile(uint base, uint wide_len, uint end12, uint end10, bool height_only) {
    uint band = rbvh_atlas_band(base, wide_len, end12, end10);
    uint wide_bits = height_only ? 16u : 32u;
    uint words12 = rbvh_atlas_words(wide_len, wide_bits);
    uint words10 = words12 + rbvh_atlas_words(end12 - wide_len, 12u);
    uint words8 = words10 + rbvh_atlas_words(end10 - end12, 10u);
    uint bits = band == 0u ? wide_bits : (band == 1u ? 12u : (band == 2u ? 10u : 8u));
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
// cross into the next word, 20 to 24 bits for the two; the 16-bit band's are two halves or two
// words), read together, so that a cell's four corners take four reads, as one word each did.
// The words read lie inside the buffer: the blocks' height ranges follow the texels.
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

// The height code of texel `index` alone (painting, a hit's normal).
uint rbvh_atlas_code(uint index, uint len, uint wide_len, uint end12, uint end10, bool height_only) {
    return rbvh_atlas_tile_code(rbvh_atlas_tile(index, wide_len, end12, end10, height_only), 0u, index, len);
}

// Texel `index` of an atlas with normals: its height code in bits 0-15 and its 8:8 octahedral
// normal in bits 16-31 (a hole at or beyond `len`), as the host's Texel holds it.
uint rbvh_atlas_texel(uint index, uint len, uint wide_len, uint end12, uint end10) {
    uint texel = 0xFFFFu;
    if (index < wide_len && index < len) {
        texel = RBVH_ATLAS_WORD(index);
    } else if (index < len) {
        uint k = index - wide_len;
        uint normals = rbvh_atlas_code_words(len, wide_len, end12, end10, false);
        uint normal = (RBVH_ATLAS_WORD(normals + (k >> 1)) << ((~k & 1u) << 4)) & 0xFFFF0000u;
        texel = rbvh_atlas_code(index, len, wide_len, end12, end10, false) | normal;
    }
    return texel;
}

#endif
