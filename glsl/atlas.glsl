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

// The height code of texel `index` of an atlas of `len` texels (0xFFFF, a hole, at or beyond
// `len`): what the walk reads. Its band's width, first texel and first word chosen by selects
// rather than a branch: SIMD implementations such as lavapipe run both sides of a branch whose
// lanes differ, and the two loads of a texel read both ways cost the march a tenth of its speed
// there. A field that crosses into the next word (12- and 10-bit ones, at most 32 bits in all)
// takes that word's low bits too. One return, the hole's made before the read: an early return,
// once inlined into the walk's loops, leaves a value the compiler carries from one leaf to the
// next (docs/speed.md, "Values the compiler carried from leaf to leaf").
uint rbvh_atlas_code(uint index, uint len, uint wide_len, uint end12, uint end10, bool height_only) {
    uint code = 0xFFFFu;
    if (index < len) {
        bool wide = index < wide_len;
        bool in12 = index < end12;
        bool in10 = index < end10;
        uint wide_bits = height_only ? 16u : 32u;
        uint words12 = rbvh_atlas_words(wide_len, wide_bits);
        uint words10 = words12 + rbvh_atlas_words(end12 - wide_len, 12u);
        uint words8 = words10 + rbvh_atlas_words(end10 - end12, 10u);
        uint bits = wide ? wide_bits : (in12 ? 12u : (in10 ? 10u : 8u));
        uint start = wide ? 0u : (in12 ? wide_len : (in10 ? end12 : end10));
        uint first = wide ? 0u : (in12 ? words12 : (in10 ? words10 : words8));
        uint step = wide ? 1u : (in12 ? 15u : (in10 ? 63u : 257u));
        // Word indices and shifts made apart (a bit offset would overflow 32 bits past 2^27
        // texels).
        uint k = index - start;
        uint word = first + (k >> 5u) * bits + (((k & 31u) * bits) >> 5u);
        uint shift = ((k & 31u) * bits) & 31u;
        uint field = RBVH_ATLAS_WORD(word) >> shift;
        if (shift + bits > 32u) {
            field |= RBVH_ATLAS_WORD(word + 1u) << (32u - shift);
        }
        uint mask = (1u << min(bits, 16u)) - 1u;
        field &= mask;
        code = field == mask ? 0xFFFFu : field * step;
    }
    return code;
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
