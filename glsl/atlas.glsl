// Reading a texel of the atlas as src/rbvh/ranges.rs lays it out (Atlas::device_words): the wide
// texels before `wide_len` (16-bit height codes), then the narrow band's 8-bit codes four to a
// word, then, unless `height_only`, the narrow band's normals two to a word; the blocks' height
// ranges after all of them (rbvh_atlas_texel_words). A narrow code byte c is the 16-bit code
// c * 257 (Texel::narrow_code_of), so 255 is the hole code, and every reader sees 16-bit codes.
//
// The includer defines RBVH_ATLAS_WORD(i), the atlas's word i, before the #include.
#ifndef RBVH_ATLAS_GLSL
#define RBVH_ATLAS_GLSL

// Words of the texels: where the block ranges start.
uint rbvh_atlas_texel_words(uint len, uint wide_len, bool height_only) {
    uint narrow = len - wide_len;
    uint wide_words = height_only ? (wide_len + 1u) >> 1 : wide_len;
    uint normal_words = height_only ? 0u : (narrow + 1u) >> 1;
    return wide_words + ((narrow + 3u) >> 2) + normal_words;
}

// The height code of texel `index` of an atlas of `len` texels (0xFFFF, a hole, at or beyond
// `len`): what the walk reads. One load either side of `wide_len`, chosen by selects rather than
// a branch: SIMD implementations such as lavapipe run both sides of a branch whose lanes differ,
// and the two loads of a texel read both ways cost the march a tenth of its speed there.
// One return, the hole's made before the read: an early return, once inlined into the walk's
// loops, leaves a value the compiler carries from one leaf to the next (docs/speed.md, "Values the
// compiler carried from leaf to leaf").
uint rbvh_atlas_code(uint index, uint len, uint wide_len, bool height_only) {
    uint code = 0xFFFFu;
    if (index < len) {
        bool narrow = index >= wide_len;
        uint k = index - wide_len;
        uint wide_words = height_only ? (wide_len + 1u) >> 1 : wide_len;
        // A byte of the narrow band, a half-word without normals above it, else the texel's
        // word; word indices and shifts made apart (a bit offset would overflow 32 bits past 2^27
        // texels).
        uint word = narrow ? wide_words + (k >> 2) : (height_only ? index >> 1 : index);
        uint shift = narrow ? (k & 3u) << 3 : (height_only ? (index & 1u) << 4 : 0u);
        uint bits = (RBVH_ATLAS_WORD(word) >> shift) & (narrow ? 0xFFu : 0xFFFFu);
        code = narrow ? bits * 0x101u : bits;
    }
    return code;
}

// Texel `index` of an atlas with normals: its height code in bits 0-15 and its 8:8 octahedral
// normal in bits 16-31 (a hole at or beyond `len`), as the host's Texel holds it.
uint rbvh_atlas_texel(uint index, uint len, uint wide_len) {
    uint texel = 0xFFFFu;
    if (index < wide_len && index < len) {
        texel = RBVH_ATLAS_WORD(index);
    } else if (index < len) {
        uint k = index - wide_len;
        uint normals = wide_len + ((len - wide_len + 3u) >> 2);
        uint normal = (RBVH_ATLAS_WORD(normals + (k >> 1)) << ((~k & 1u) << 4)) & 0xFFFF0000u;
        texel = rbvh_atlas_code(index, len, wide_len, false) | normal;
    }
    return texel;
}

#endif
