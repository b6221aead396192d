// The RBVH's height-field march and its leaf hook for the one traversal (traverse.glsl): the GLSL
// twin of src/rbvh/march/ (mod.rs lists its steps), step for step, on the packed data of
// src/rbvh/layout.rs. Includes bvh.glsl for the node and triangle buffers.
//
// The includer chooses where the buffers live by defining, before the #include:
//   RBVH_BVH_SET, RBVH_BVH_NODES_BINDING, RBVH_BVH_TRIS_BINDING   (see bvh.glsl; the triangle
//                              buffer holds ExactTriangles::device_words(), indexed, and
//                              RbvhSizes.tri_count counts its slots)
//   RBVH_HEIGHTFIELDS_BINDING  binding of the height-field leaves' records
//   RBVH_ATLAS_BINDING         binding of the texel atlas
// or, with RBVH_DEVICE_ADDRESS (see bvh.glsl), RBVH_HEIGHTFIELDS_ADDRESS and RBVH_ATLAS_ADDRESS.
// To trace with level of detail, include lod.glsl instead (it includes this file, and defines
// rbvh_trace_rbvh_lod, taking each ray's cone and the LOD array sizes; see it for its two bindings).
// RBVH_BLOCK_JUMPS (default true) is the condition under which the march jumps over blocks the
// ray passes above or below; the hits are the same either way. On CPU implementations such as
// lavapipe, which run every branch, the walk is faster without (see Tracer::block_jumps).
// RBVH_HEIGHT_ONLY (default false) must be true for an RBVH built with TexelFormat::Height: its
// atlas holds height codes alone (atlas.glsl), and a hit's normal is that of the cell triangle it
// hit.
#ifndef RBVH_RBVH_GLSL
#define RBVH_RBVH_GLSL

// The RBVH's triangle array is indexed (bvh.glsl): included first, bvh.glsl would have declared
// the exact BVH's instead.
#ifdef RBVH_BVH_GLSL
#error "include rbvh.glsl (or lod.glsl) before bvh.glsl, or without it: it includes bvh.glsl for the RBVH's arrays"
#endif
#define RBVH_INDEXED_TRIANGLES
#include "bvh.glsl"
#include "grid.glsl"

#ifdef RBVH_LEAVES_BINDING
#error "RBVH_LEAVES_BINDING is now RBVH_HEIGHTFIELDS_BINDING (and RbvhLeaf RbvhHeightfield)"
#endif
#ifndef RBVH_HEIGHTFIELDS_BINDING
#define RBVH_HEIGHTFIELDS_BINDING 2
#endif
#ifndef RBVH_ATLAS_BINDING
#define RBVH_ATLAS_BINDING 3
#endif
#ifndef RBVH_BLOCK_JUMPS
#define RBVH_BLOCK_JUMPS true
#endif
#ifndef RBVH_HEIGHT_ONLY
#define RBVH_HEIGHT_ONLY false
#endif

// Must equal MARCH_SLACK, MARCH_EDGE_PAD, MARCH_SKIRT_TEXELS, MARCH_DIAGONAL_SKIRT_TEXELS and
// Texel::MAX_CODE / HOLE_CODE (tests/glsl_header.rs checks, on the device).
#define RBVH_MARCH_SLACK 1e-5
#define RBVH_MARCH_EDGE_PAD 0.015625
#define RBVH_MARCH_SKIRT_TEXELS 1.0
#define RBVH_MARCH_DIAGONAL_SKIRT_TEXELS 0.1
#define RBVH_MAX_CODE 65534u
#define RBVH_HOLE_CODE 65535u
const uint RBVH_HEIGHTFIELD_COUNT = 0xFFFFFFFFu;

// Whether a leaf's reference (LEAF_BIT set) with `count` names a height field rather than
// triangles: the one place the shaders tell a leaf's kind, as src/rbvh/child.rs (Child) is on the
// CPU; a new kind of leaf starts in both.
bool rbvh_is_heightfield(uint count) {
    return count == RBVH_HEIGHTFIELD_COUNT;
}

// 64 bytes: see GpuHeightfield.
struct RbvhHeightfield {
    vec3 origin;
    uint atlas_base;
    vec3 axis_u;
    uint res_u;
    vec3 axis_v;
    uint res_v;
    vec3 axis_w;
    float h_scale;
};

// Atlas texels, as the host's Texel holds them: bits 0-15 height code (0xFFFF = hole), bits 16-31
// the 8:8 octahedral normal; atlas.glsl reads codes (rbvh_atlas_tile_pair) and normals
// (rbvh_atlas_normal, in bits 16-31) from the atlas's words.
#ifdef RBVH_DEVICE_ADDRESS
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer RbvhHeightfieldsRef {
    RbvhHeightfield heightfields[];
};
layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer RbvhAtlasRef {
    uint texels[];
};
#define RBVH_HEIGHTFIELD(i) RbvhHeightfieldsRef(RBVH_HEIGHTFIELDS_ADDRESS).heightfields[i]
#define RBVH_ATLAS(i) RbvhAtlasRef(RBVH_ATLAS_ADDRESS).texels[i]
#else
layout(std430, set = RBVH_BVH_SET, binding = RBVH_HEIGHTFIELDS_BINDING) readonly buffer RbvhHeightfields {
    RbvhHeightfield rbvh_heightfields[];
};
layout(std430, set = RBVH_BVH_SET, binding = RBVH_ATLAS_BINDING) readonly buffer RbvhAtlas {
    uint rbvh_atlas[];
};
#define RBVH_HEIGHTFIELD(i) rbvh_heightfields[i]
#define RBVH_ATLAS(i) rbvh_atlas[i]
#endif
#define RBVH_ATLAS_WORD(i) RBVH_ATLAS(i)
#include "atlas.glsl"

// Sizes the march needs to bound its reads.
struct RbvhSizes {
    uint node_count;
    uint tri_count;
    uint heightfield_count;
    uint atlas_pitch;  // texels per atlas row: a power of two (the march skips leaves otherwise)
    uint atlas_len;
    uint atlas_wide_len;  // texels before the bands of packed heights (atlas.glsl)
    uint atlas_end12;     // texels before the end of the 12-bit band (atlas.glsl)
    uint atlas_end10;     // texels before the end of the 10-bit band; the 8-bit band follows
};

// The direction of texel's octahedral normal before normalizing (octahedral_direction in
// layout.rs): `precise`, so that every device computes the bits the host does.
vec3 rbvh_octahedral_direction(uint texel) {
    uint code = texel >> 16;
    precise float x = float(code & 0xFFu) / 255.0 * 2.0 - 1.0;
    precise float y = float((code >> 8) & 0xFFu) / 255.0 * 2.0 - 1.0;
    precise float z = 1.0 - abs(x) - abs(y);
    precise float t = max(-z, 0.0);
    x += x >= 0.0 ? -t : t;
    y += y >= 0.0 ? -t : t;
    return vec3(x, y, z);
}

vec3 rbvh_decode_normal(uint texel) {
    return normalize(rbvh_octahedral_direction(texel));
}

// Whether texel's normal faces a ray along world `dir` (Texel::faces in layout.rs): the dot
// product with the normal's octahedral direction, summed in the same order, so that both sides
// take the same sign.
bool rbvh_faces(uint texel, vec3 dir) {
    precise vec3 n = rbvh_octahedral_direction(texel);
    precise float dot_n = n.x * dir.x + n.y * dir.y + n.z * dir.z;
    return dot_n < 0.0;
}

bool rbvh_is_hole(uint texel) {
    return (texel & 0xFFFFu) == RBVH_HOLE_CODE;
}

// The fields of `leaf`'s tile (rbvh_atlas_tile), which a texel read is an offset from.
RbvhAtlasTile rbvh_leaf_tile(RbvhHeightfield leaf, RbvhSizes sz) {
    return rbvh_atlas_tile(leaf.atlas_base, sz.atlas_wide_len, sz.atlas_end12, sz.atlas_end10);
}

// Where the blocks' height ranges start in the atlas words: after the height codes.
uint rbvh_ranges_word(RbvhSizes sz) {
    return rbvh_atlas_code_words(sz.atlas_len, sz.atlas_wide_len, sz.atlas_end12, sz.atlas_end10);
}

// Frame-space ray of one leaf. Its shear (for the cells' triangles) is not kept here but made
// where a cell's triangles are tested, as the traversal makes the ray's own shear per triangle
// leaf: twelve floats kept live across the loops cost registers, and on a GPU registers bound
// the rays in flight (on an H200 the two took trace_rbvh from 127 registers to 96: docs/speed.md,
// "On a GPU").
struct RbvhFrameRay {
    vec3 o;
    vec3 d;
    float tmin;
    float tmax;
};

// `ray` over [tmin, t_closest) in `leaf`'s frame (step 1, march/walk.rs): each coordinate summed in
// the host's order.
RbvhFrameRay rbvh_frame_ray(RbvhHeightfield leaf, Ray ray, float t_closest) {
    precise vec3 rel = ray.origin - leaf.origin;
    precise vec3 ru = rel * leaf.axis_u;
    precise vec3 rv = rel * leaf.axis_v;
    precise vec3 rw = rel * leaf.axis_w;
    precise vec3 du = ray.dir * leaf.axis_u;
    precise vec3 dv = ray.dir * leaf.axis_v;
    precise vec3 dw = ray.dir * leaf.axis_w;
    RbvhFrameRay fr;
    fr.o = vec3((ru.x + ru.y) + ru.z, (rv.x + rv.y) + rv.z, (rw.x + rw.y) + rw.z);
    fr.d = vec3((du.x + du.y) + du.z, (dv.x + dv.y) + dv.z, (dw.x + dw.y) + dw.z);
    fr.tmin = ray.tmin;
    fr.tmax = t_closest;
    return fr;
}

// One cell of the walk: its indices, the ray's parameter range over it, and its four corners'
// height codes as the walk read them (rbvh_read_corners), two 16-bit codes a word (c00 | c10 << 16,
// c01 | c11 << 16): the walk carries them from cell to cell, and on a GPU a word is a register
// (AMD's compiler reads a half-word as an operand at no cost).
struct RbvhCell {
    int i;
    int j;
    float t_in;
    float t_out;
    uint c00_c10;
    uint c01_c11;
};

uint rbvh_c00(RbvhCell cell) {
    return cell.c00_c10 & 0xFFFFu;
}

uint rbvh_c10(RbvhCell cell) {
    return cell.c00_c10 >> 16;
}

uint rbvh_c01(RbvhCell cell) {
    return cell.c01_c11 & 0xFFFFu;
}

uint rbvh_c11(RbvhCell cell) {
    return cell.c01_c11 >> 16;
}

// Whether all four corners of `cell` are samples (two triangles), not holes.
bool rbvh_cell_full(RbvhCell cell) {
    return !rbvh_is_hole(rbvh_c00(cell)) && !rbvh_is_hole(rbvh_c10(cell)) && !rbvh_is_hole(rbvh_c01(cell)) &&
           !rbvh_is_hole(rbvh_c11(cell));
}

// `cell` with the codes of its corners read from `leaf`'s tile: two reads of two words a row
// (rbvh_atlas_tile_pair).
void rbvh_read_corners(RbvhHeightfield leaf, RbvhSizes sz, inout RbvhCell cell) {
    RbvhAtlasTile tile = rbvh_leaf_tile(leaf, sz);
    uint d = uint(cell.j) * sz.atlas_pitch + uint(cell.i);
    uvec2 row0 = rbvh_atlas_tile_pair(tile, d, leaf.atlas_base + d, sz.atlas_len);
    uvec2 row1 = rbvh_atlas_tile_pair(tile, d + sz.atlas_pitch, leaf.atlas_base + d + sz.atlas_pitch, sz.atlas_len);
    cell.c00_c10 = row0.x | row0.y << 16;
    cell.c01_c11 = row1.x | row1.y << 16;
}

// Step 4 (march/cell.rs), its cheap half: reads the cell's corners and tells whether its triangles
// can be hit at all — three or four corners present, and the ray's height over
// [t_in, t_out] within their height range (with the walk's slack). Written without local
// arrays: dynamically indexed arrays become per-lane memory on SIMD implementations such as
// lavapipe.
bool rbvh_cell_candidate(RbvhHeightfield leaf, RbvhSizes sz, RbvhFrameRay fr, float slack, inout RbvhCell cell) {
    rbvh_read_corners(leaf, sz, cell);
    bool v00 = !rbvh_is_hole(rbvh_c00(cell));
    bool v10 = !rbvh_is_hole(rbvh_c10(cell));
    bool v01 = !rbvh_is_hole(rbvh_c01(cell));
    bool v11 = !rbvh_is_hole(rbvh_c11(cell));
    bool enough = int(v00) + int(v10) + int(v01) + int(v11) >= 3;
    precise float h00 = float(rbvh_c00(cell)) * leaf.h_scale;
    precise float h10 = float(rbvh_c10(cell)) * leaf.h_scale;
    precise float h01 = float(rbvh_c01(cell)) * leaf.h_scale;
    precise float h11 = float(rbvh_c11(cell)) * leaf.h_scale;
    float lo = min(min(v00 ? h00 : RBVH_INF, v10 ? h10 : RBVH_INF), min(v01 ? h01 : RBVH_INF, v11 ? h11 : RBVH_INF));
    float hi = max(max(v00 ? h00 : -RBVH_INF, v10 ? h10 : -RBVH_INF), max(v01 ? h01 : -RBVH_INF, v11 ? h11 : -RBVH_INF));
    float h_a = rbvh_height_at(fr.o.z, fr.d.z, cell.t_in);
    float h_b = rbvh_height_at(fr.o.z, fr.d.z, cell.t_out);
    precise float lo_s = lo - slack;
    precise float hi_s = hi + slack;
    return enough && !(max(h_a, h_b) < lo_s || min(h_a, h_b) > hi_s);
}

// Corner `q` of `cell` in the frame (0: c00, 1: c10, 2: c01, 3: c11), its height from its code,
// as the march places samples, at i + 1/2: made one at a time where used.
vec3 rbvh_cell_corner(RbvhHeightfield leaf, RbvhCell cell, uint q) {
    uint code = ((q & 2u) != 0u ? cell.c01_c11 : cell.c00_c10) >> ((q & 1u) << 4) & 0xFFFFu;
    precise float h = float(code) * leaf.h_scale;
    return vec3(float(cell.i + int(q & 1u)) + 0.5, float(cell.j + int(q >> 1)) + 0.5, h);
}

// The corners (rbvh_cell_corner's numbers) of the first triangle of a cell with three or four
// corners present: (c00, c10, c11) with all four, else the three present in the cycle order c00,
// c10, c11, c01 (the winding stays the quad's), as `hit` and `surface_under` in march/cell.rs and march/skirt.rs take
// it. With all four, the second is (c00, c11, c01).
uvec3 rbvh_first_triangle(RbvhCell cell) {
    bool v00 = !rbvh_is_hole(rbvh_c00(cell));
    bool v10 = !rbvh_is_hole(rbvh_c10(cell));
    bool v11 = !rbvh_is_hole(rbvh_c11(cell));
    return uvec3(v00 ? 0u : 1u, v00 ? (v10 ? 1u : 3u) : 3u, (v00 && v10) ? (v11 ? 3u : 2u) : 2u);
}

// Step 4 (march/cell.rs), its costly half: the cell's two (or one) triangles; returns t (< 0 on a
// miss) and, on a hit, which of them was hit (`tri`: 0 the first, 1 the second; see
// rbvh_cell_facet). `cut` is set when the device ended the loop early (see traverse.glsl).
float rbvh_cell_triangles(RbvhHeightfield leaf, RbvhFrameRay fr, RbvhCell cell, out int tri, inout bool cut) {
    uvec3 first = rbvh_first_triangle(cell);
    RbvhShear shear = rbvh_shear(Ray(fr.o, fr.tmin, fr.d, fr.tmax));
    vec3 a = rbvh_sheared(shear, rbvh_cell_corner(leaf, cell, first.x));
    vec3 b = rbvh_sheared(shear, rbvh_cell_corner(leaf, cell, first.y));
    precise float w = b.x * a.y - b.y * a.x;
    vec3 c = rbvh_sheared(shear, rbvh_cell_corner(leaf, cell, first.z));
    precise float u = c.x * b.y - c.y * b.x;
    precise float v = a.x * c.y - a.y * c.x;
    vec3 d = rbvh_sheared(shear, rbvh_cell_corner(leaf, cell, 2u));
    precise float u2 = d.x * c.y - d.y * c.x;
    precise float v2 = a.x * d.y - a.y * d.x;
    // One call site for both triangles: the second's corners' depths and edge functions take
    // the first's places after it.
    float b_z = b.z;
    float c_z = c.z;
    float t_hit = -1.0;
    tri = 0;
    int tris = rbvh_cell_full(cell) ? 2 : 1;
    int k = 0;
    for (; k < tris; ++k) {
        float t = rbvh_intersect_edges(u, v, w, a.z, b_z, c_z, fr.tmin, t_hit >= 0.0 ? t_hit : fr.tmax);
        if (t >= 0.0) {
            t_hit = t;
            tri = k;
        }
        precise float w2 = 0.0 - v;
        u = u2;
        v = v2;
        w = w2;
        b_z = c_z;
        c_z = d.z;
    }
    if (k < tris) {
        cut = true;
    }
    return t_hit;
}

// The frame-space normal of triangle `tri` of `cell` (rbvh_cell_triangles): (b - a) x (c - a)
// of its frame-space corners, for height-only RBVHs (facet_normal in march/normal.rs).
vec3 rbvh_cell_facet(RbvhHeightfield leaf, RbvhCell cell, int tri) {
    uvec3 first = rbvh_first_triangle(cell);
    vec3 a = rbvh_cell_corner(leaf, cell, first.x);
    vec3 b = rbvh_cell_corner(leaf, cell, tri == 0 ? first.y : 3u);
    vec3 c = rbvh_cell_corner(leaf, cell, tri == 0 ? first.z : 2u);
    precise vec3 e1 = b - a;
    precise vec3 e2 = c - a;
    return vec3(e1.y * e2.z - e1.z * e2.y, e1.z * e2.x - e1.x * e2.z, e1.x * e2.y - e1.y * e2.x);
}

// The skirt of `full` texels under the edge from corner texel `ca` to `cb`, met at fraction `f`
// along it (clamped) at `t` (skirt_hit and skirt_depth in march/skirt.rs): true when `t` lies in the
// ray's interval and the ray is below the edge there by at most the skirt's depth: `full` under
// an edge of two samples taken from the surface (even codes: Texel::is_sampled); from such a
// sample to an extrapolated one, `full` at the sampled end tapering to nothing half-way; none
// under two extrapolated ones (`uu` = |axis_u|^2, so that no square root is needed).
bool rbvh_skirt_at(RbvhHeightfield leaf, RbvhFrameRay fr, float slack, float uu, uint ca, uint cb, float f, float full,
                   float t) {
    bool sa = (ca & 1u) == 0u;
    bool sb = (cb & 1u) == 0u;
    if (!sa && !sb) {
        return false;
    }
    float g = clamp(f, 0.0, 1.0);
    precise float share = (sa && sb) ? 1.0 : max(sa ? 1.0 - 2.0 * g : 2.0 * g - 1.0, 0.0);
    precise float a = float(ca & 0xFFFFu) * leaf.h_scale;
    precise float b = float(cb & 0xFFFFu) * leaf.h_scale;
    precise float edge_h = a + (b - a) * g;
    precise float below = edge_h - rbvh_height_at(fr.o.z, fr.d.z, t);
    precise float depth = full * share;
    precise float depth2 = below * below * uu;
    return t >= fr.tmin && t < fr.tmax && below >= -slack && depth2 <= depth * depth;
}

// The skirt under the edge of `cell` (skirt in march/skirt.rs) that the ray entered at cell.t_in from a
// cell with fewer than four samples or through the tile's side, across its edge
// on `axis` (0: an s boundary, 1: a t boundary) stepping `step` along it, when both samples of
// that edge are present: t_in on a hit, else -1.
float rbvh_skirt(RbvhHeightfield leaf, RbvhFrameRay fr, float slack, float uu, RbvhCell cell, int axis, int step) {
    bool across_s = axis == 0;
    uint ca = across_s ? (step > 0 ? rbvh_c00(cell) : rbvh_c10(cell)) : (step > 0 ? rbvh_c00(cell) : rbvh_c01(cell));
    uint cb = across_s ? (step > 0 ? rbvh_c01(cell) : rbvh_c11(cell)) : (step > 0 ? rbvh_c10(cell) : rbvh_c11(cell));
    bool present = !rbvh_is_hole(ca) && !rbvh_is_hole(cb);
    precise float at_s = fr.o.x + fr.d.x * cell.t_in;
    precise float at_t = fr.o.y + fr.d.y * cell.t_in;
    precise float along = across_s ? at_t - (float(cell.j) + 0.5) : at_s - (float(cell.i) + 0.5);
    bool hit = present && rbvh_skirt_at(leaf, fr, slack, uu, ca, cb, along, RBVH_MARCH_SKIRT_TEXELS, cell.t_in);
    return hit ? cell.t_in : -1.0;
}

// The skirt under the diagonal of `cell`, whose corners are three samples and a hole
// (diagonal_skirt in march/skirt.rs; MARCH_DIAGONAL_SKIRT_TEXELS deep): where the ray crosses the
// diagonal that faces the hole, within [t_in, t_out], from the hole's side. That t on a hit,
// else -1.
float rbvh_diagonal_skirt(RbvhHeightfield leaf, RbvhFrameRay fr, float slack, float uu, RbvhCell cell) {
    bool h00 = rbvh_is_hole(rbvh_c00(cell));
    bool h01 = rbvh_is_hole(rbvh_c01(cell));
    bool h11 = rbvh_is_hole(rbvh_c11(cell));
    // Through c10 and c01 (fs + ft = 1) for a hole at c00 or c11, else through c00 and c11.
    bool anti = h00 || h11;
    uint ca = anti ? rbvh_c10(cell) : rbvh_c00(cell);
    uint cb = anti ? rbvh_c01(cell) : rbvh_c11(cell);
    float side = (h00 || h01) ? -1.0 : 1.0;
    precise float fs0 = fr.o.x - (float(cell.i) + 0.5);
    precise float ft0 = fr.o.y - (float(cell.j) + 0.5);
    precise float q0 = anti ? (fs0 + ft0) - 1.0 : fs0 - ft0;
    precise float dq = anti ? fr.d.x + fr.d.y : fr.d.x - fr.d.y;
    precise float t = -q0 / dq;
    bool crosses = dq * side < 0.0 && t >= cell.t_in && t <= cell.t_out;
    precise float f = anti ? ft0 + fr.d.y * t : fs0 + fr.d.x * t;
    bool hit = crosses && rbvh_skirt_at(leaf, fr, slack, uu, ca, cb, f, RBVH_MARCH_DIAGONAL_SKIRT_TEXELS, t);
    return hit ? t : -1.0;
}

// Which of `cell`'s triangles holds a skirt hit at t, for its facet (surface_under in march/skirt.rs):
// with four corners the second, (c00, c11, c01), where s < t within the cell, else the first.
int rbvh_skirt_triangle(RbvhFrameRay fr, RbvhCell cell, float t) {
    precise float fs = (fr.o.x + fr.d.x * t) - (float(cell.i) + 0.5);
    precise float ft = (fr.o.y + fr.d.y * t) - (float(cell.j) + 0.5);
    return rbvh_cell_full(cell) && fs < ft ? 1 : 0;
}

// Step 5 (march/normal.rs), its first half: where in `cell` a hit at `t_hit` lies and which corners it
// has, for rbvh_normal_texel: bit 0 right of the cell's middle, bit 1 above it, bits 2-5 corners
// c00, c10, c01, c11 present; never 0 for a hit (a cell with a surface has three corners). The
// normals are read once a ray is done (rbvh_rbvh_hit), not in the SIMD loops: read after every
// marched hit they cost lavapipe a tenth of its speed.
uint rbvh_cell_normal_choice(RbvhFrameRay fr, RbvhCell cell, float t_hit) {
    precise float s = fr.o.x + fr.d.x * t_hit;
    precise float r = fr.o.y + fr.d.y * t_hit;
    bool right = clamp(floor(s), float(cell.i), float(cell.i + 1)) > float(cell.i);
    bool up = clamp(floor(r), float(cell.j), float(cell.j + 1)) > float(cell.j);
    return uint(right) | uint(up) << 1 | uint(!rbvh_is_hole(rbvh_c00(cell))) << 2
        | uint(!rbvh_is_hole(rbvh_c10(cell))) << 3 | uint(!rbvh_is_hole(rbvh_c01(cell))) << 4
        | uint(!rbvh_is_hole(rbvh_c11(cell))) << 5;
}

// Step 5 (march/normal.rs), its second half: the texel whose normal a hit reports, given its cell's
// texel c00 at atlas index `k00` and rbvh_cell_normal_choice: the nearest present corner sample,
// or, when that faces away from the world direction `dir` and another present corner faces it,
// the first such in the order c00, c10, c01, c11 (nearest_normal in march/normal.rs).
uint rbvh_normal_texel(RbvhSizes sz, uint k00, uint choice, vec3 dir) {
    bool right = (choice & 1u) != 0u;
    bool up = (choice & 2u) != 0u;
    uint corner = (up ? 2u : 0u) + (right ? 1u : 0u);
    if ((choice & (4u << corner)) == 0u) {
        corner = uint(findLSB(choice >> 2));
    }
    uint nearest = rbvh_atlas_normal(k00 + (corner & 1u) + (corner >> 1) * sz.atlas_pitch, sz.atlas_len,
                                     sz.atlas_pitch, sz.atlas_wide_len, sz.atlas_end12, sz.atlas_end10);
    if (!rbvh_faces(nearest, dir)) {
        for (uint q = 0u; q < 4u; ++q) {
            if ((choice & (4u << q)) == 0u) {
                continue;
            }
            uint c = rbvh_atlas_normal(k00 + (q & 1u) + (q >> 1) * sz.atlas_pitch, sz.atlas_len,
                                       sz.atlas_pitch, sz.atlas_wide_len, sz.atlas_end12, sz.atlas_end10);
            if (rbvh_faces(c, dir)) {
                nearest = c;
                break;
            }
        }
    }
    return nearest;
}

// A skirt's depth in frame units, with a margin for the square root's rounding (skirt_h in
// march/walk.rs; `uu` = |axis_u|^2): made where a block or a rim cell is checked rather than kept
// through the walk, where it would hold a register.
float rbvh_skirt_height(float uu) {
    precise float h = 1.001 * RBVH_MARCH_SKIRT_TEXELS / sqrt(uu);
    return h;
}

// The last cell of the 8x8 atlas block holding cell c (at atlas column or row a) that a walk
// stepping by `step` reaches, clamped to [0, last] (Blocks's exit_cell in march/blocks.rs).
int rbvh_block_exit(int c, uint a, int step, int last) {
    int first = c - int(a & 7u);
    return step > 0 ? min(first + 7, last) : max(first, 0);
}

// Whether the ray, at heights o_h + d_h * t from t_a to t_b, passes block `block`'s height range
// wholly above or below, beyond the march's slack and, below, the skirt's depth (a block passed
// below by less may hold a skirt hit; skirt_h has a margin for the square root's rounding): then
// none of its cells can be hit (Blocks's jump in march/blocks.rs). An empty block's range is
// inverted, and every ray passes it.
bool rbvh_block_clear(RbvhHeightfield leaf, RbvhSizes sz, uint block, float o_h, float d_h, float t_a, float t_b,
                      float slack, float uu) {
    uint range = RBVH_ATLAS(rbvh_ranges_word(sz) + block);
    uint code_lo = range & 0xFFFFu;
    uint code_hi = range >> 16;
    precise float lo_s = float(code_lo) * leaf.h_scale - slack - rbvh_skirt_height(uu);
    precise float hi_s = float(code_hi) * leaf.h_scale + slack;
    float h_a = rbvh_height_at(o_h, d_h, t_a);
    float h_b = rbvh_height_at(o_h, d_h, t_b);
    return code_lo > code_hi || max(h_a, h_b) < lo_s || min(h_a, h_b) > hi_s;
}

// Whether a ray at heights o_h + d_h * t over the cell's stretch passes between its lowest
// sample less the skirt's depth and its highest sample: only such a ray can be caught by the
// cell's skirts; the others need not leave the walk's inner loop. A hole's code is the largest,
// so it takes no part in the highest. Each bound has a quantum beyond the skirt's own slack,
// against the rounding of the edge's height there.
bool rbvh_rim_reach(RbvhHeightfield leaf, RbvhCell cell, float o_h, float d_h, float slack, float uu) {
    uint code_lo = min(min(rbvh_c00(cell), rbvh_c10(cell)), min(rbvh_c01(cell), rbvh_c11(cell)));
    uint code_hi = max(max(rbvh_is_hole(rbvh_c00(cell)) ? 0u : rbvh_c00(cell),
                           rbvh_is_hole(rbvh_c10(cell)) ? 0u : rbvh_c10(cell)),
                       max(rbvh_is_hole(rbvh_c01(cell)) ? 0u : rbvh_c01(cell),
                           rbvh_is_hole(rbvh_c11(cell)) ? 0u : rbvh_c11(cell)));
    float h_in = rbvh_height_at(o_h, d_h, cell.t_in);
    float h_out = rbvh_height_at(o_h, d_h, cell.t_out);
    precise float skirt_h = rbvh_skirt_height(uu);
    return max(h_in, h_out) >= float(code_lo) * leaf.h_scale - slack - skirt_h - abs(leaf.h_scale) &&
           min(h_in, h_out) <= float(code_hi) * leaf.h_scale + slack + abs(leaf.h_scale);
}

// The walk's loop bound: twice the (res_u - 1) + (res_v - 1) - 1 cells a walk can step through.
uint rbvh_walk_bound(int last_i, int last_j) {
    return 2u * uint(last_i + last_j + 1);
}

// The walk's steps along s and t (-1, 0, 1) and the edge the current main cell was entered
// across (0: s, 1: t, -1: none), two bits each, and its flags, in one word: on a GPU each value
// the walk carries from cell to cell holds a register through it (docs/speed.md, "Values the
// compiler carried from leaf to leaf").
// The current cell is the extra one across a grid vertex (rbvh_walk_cell).
const uint RBVH_WALK_EXTRA = 64u;
// The last main cell walked had fewer than four samples, or there was none (prev_open in
// march/walk.rs, which says why, and why a block jump may leave it as it was).
const uint RBVH_WALK_PREV_OPEN = 128u;
// Why the inner loop handed the cell to the outer one: its triangles may be hit (TESTS), or its
// skirts (RIM: under the edge it was entered across, EDGE_RIM, or its diagonal, DIAGONAL).
const uint RBVH_WALK_TESTS = 256u;
const uint RBVH_WALK_RIM = 512u;
const uint RBVH_WALK_EDGE_RIM = 1024u;
const uint RBVH_WALK_DIAGONAL = 2048u;
const uint RBVH_WALK_FOUND = RBVH_WALK_TESTS | RBVH_WALK_RIM | RBVH_WALK_EDGE_RIM | RBVH_WALK_DIAGONAL;
// The walk ended on its own (a hit, or the ray left the tile), not by a loop the device cut.
const uint RBVH_WALK_STOPPED = 4096u;

uint rbvh_walk_dirs(int step_i, int step_j, int entered) {
    return uint(step_i + 1) | uint(step_j + 1) << 2 | uint(entered + 1) << 4 | RBVH_WALK_PREV_OPEN;
}

int rbvh_walk_step_i(uint dirs) {
    return int(dirs & 3u) - 1;
}

int rbvh_walk_step_j(uint dirs) {
    return int((dirs >> 2) & 3u) - 1;
}

int rbvh_walk_entered(uint dirs) {
    return int((dirs >> 4) & 3u) - 1;
}

uint rbvh_walk_entered_across(uint dirs, int entered) {
    return (dirs & ~(3u << 4)) | uint(entered + 1) << 4;
}

bool rbvh_walk_extra(uint dirs) {
    return (dirs & RBVH_WALK_EXTRA) != 0u;
}

// The cell the walk `w` is on (its codes not yet read): its main cell, or,
// with RBVH_WALK_EXTRA, the extra cell across the grid vertex the ray passes next, before the
// step (the walk of march/walk.rs). Made from the walk's state where needed rather than carried
// beside it.
RbvhCell rbvh_walk_cell(RbvhGridWalk w, uint dirs, float t1) {
    float t_next = min(min(w.next_i, w.next_j), t1);
    bool extra = rbvh_walk_extra(dirs);
    bool across_s = w.next_i <= w.next_j;
    int i = extra && !across_s ? w.ci + rbvh_walk_step_i(dirs) : w.ci;
    int j = extra && across_s ? w.cj + rbvh_walk_step_j(dirs) : w.cj;
    return RbvhCell(i, j, extra ? t_next : w.t_in, extra ? min(max(w.next_i, w.next_j), t1) : t_next, 0u, 0u);
}

// Whether `leaf`'s tile lies within the atlas as the march needs it (tile_fits in src/rbvh/layout.rs):
// two samples or more each way, a power-of-two pitch (the builder makes it one, and the file
// reader and the upload refuse any other; it spares divisions: SIMD implementations such as
// lavapipe run both sides of a branch, and a vector division there is eight scalar ones), no
// wrap across atlas rows (the block jumps count on it), and its last texel in the atlas, in the
// band of its first (rbvh_read_corners reads a tile with its first texel's band).
bool rbvh_tile_fits(RbvhHeightfield leaf, RbvhSizes sz) {
    bool pitch = sz.atlas_pitch != 0u && (sz.atlas_pitch & (sz.atlas_pitch - 1u)) == 0u;
    bool sides = leaf.res_u >= 2u && leaf.res_v >= 2u && leaf.res_u <= sz.atlas_pitch;
    bool row = (leaf.atlas_base & (sz.atlas_pitch - 1u)) + leaf.res_u <= sz.atlas_pitch;
    uint last_texel = leaf.atlas_base + (leaf.res_v - 1u) * sz.atlas_pitch + (leaf.res_u - 1u);
    bool band = rbvh_atlas_band(leaf.atlas_base, sz.atlas_wide_len, sz.atlas_end12, sz.atlas_end10) ==
                rbvh_atlas_band(last_texel, sz.atlas_wide_len, sz.atlas_end12, sz.atlas_end10);
    return pitch && sides && row && last_texel < sz.atlas_len && last_texel >= leaf.atlas_base && band;
}

// Marches leaf `li` over [tmin, t_closest); returns t (< 0 on a miss) and, on a hit, where its
// normal comes from (`normal_cell`): the cell's c00 atlas index, and rbvh_cell_normal_choice, or
// with RBVH_HEIGHT_ONLY 1 + which of the cell's triangles was hit (0, 1) or 3 for a skirt, for
// rbvh_height_field_facet once the ray is done. `cells` counts cells visited. `cut` is set when
// the device ended a loop early (see traverse.glsl).
//
// Written with one return, as are the helpers the walk inlines: an early return leaves, once
// inlined into the traversal's loop, values the compiler carries from one leaf to the next, each a
// register through the walk (docs/speed.md, "Values the compiler carried from leaf to leaf").
float rbvh_march(uint li, RbvhSizes sz, Ray ray, float t_closest, out uint cells, out uvec2 normal_cell,
                 inout bool cut) {
    cells = 0u;
    normal_cell = uvec2(0u);
    float t_hit = -1.0;
    RbvhHeightfield leaf = RbvhHeightfield(vec3(0.0), 0u, vec3(0.0), 0u, vec3(0.0), 0u, vec3(0.0), 0.0);
    if (li < sz.heightfield_count) {
        leaf = RBVH_HEIGHTFIELD(li);
    }
    // 1. Frame.
    RbvhFrameRay fr = rbvh_frame_ray(leaf, ray, t_closest);
    vec3 o = fr.o;
    vec3 d = fr.d;
    vec3 inv = rbvh_safe_inverse(d);
    // 2. Clip to the padded tile box.
    precise float h_top = float(RBVH_MAX_CODE) * leaf.h_scale;
    precise float slack = RBVH_MARCH_SLACK * (abs(o.z) + abs(h_top)) + abs(leaf.h_scale);
    vec3 bmin = vec3(0.5 - RBVH_MARCH_EDGE_PAD, 0.5 - RBVH_MARCH_EDGE_PAD, -slack);
    precise vec3 bmax = vec3(float(leaf.res_u) - 0.5 + RBVH_MARCH_EDGE_PAD,
                             float(leaf.res_v) - 0.5 + RBVH_MARCH_EDGE_PAD, h_top + slack);
    float t0 = 0.0;
    bool box = rbvh_intersect_box(bmin, bmax, o, inv, fr.tmin, fr.tmax, t0);
    if (li < sz.heightfield_count && rbvh_tile_fits(leaf, sz) && rbvh_ray_valid(Ray(fr.o, fr.tmin, fr.d, fr.tmax)) &&
        box) {
        RBVH_COUNT_ADD(walks, 1u);
        uint shift = uint(findLSB(sz.atlas_pitch));
        uint rows = sz.atlas_len >> shift;
        precise vec3 e0 = (bmin - o) * inv;
        precise vec3 e1 = (bmax - o) * inv;
        vec3 e = max(e0, e1);
        float t1 = min(min(min(e.x, e.y), e.z), fr.tmax);
        // The edge (0: s, 1: t, -1: none) the current cell was entered across, for the skirt: the
        // first cell's when the ray enters the tile's box through its s or t side.
        vec3 near = min(e0, e1);
        int entered = t0 <= fr.tmin ? -1 : (t0 == near.x ? 0 : (t0 == near.y ? 1 : -1));
        precise float uu = (leaf.axis_u.x * leaf.axis_u.x + leaf.axis_u.y * leaf.axis_u.y) + leaf.axis_u.z * leaf.axis_u.z;

        // 3. Walk.
        int last_i = int(leaf.res_u) - 2;
        int last_j = int(leaf.res_v) - 2;
        precise vec3 entry = o + d * t0;
        int step_i = rbvh_grid_step(d.x);
        int step_j = rbvh_grid_step(d.y);
        precise float corner_slack = RBVH_MARCH_SLACK * (((abs(o.x) + abs(o.y)) + float(leaf.res_u)) + float(leaf.res_v));
        // Within rounding of the boundary behind the entry, the walk starts behind it (march/walk.rs).
        RbvhGridWalk w = rbvh_grid_walk(
            RBVH_BETWEEN_SAMPLES,
            rbvh_grid_start(RBVH_BETWEEN_SAMPLES, entry.x, step_i, last_i, o.x, inv.x, d.x, t0, corner_slack),
            rbvh_grid_start(RBVH_BETWEEN_SAMPLES, entry.y, step_j, last_j, o.y, inv.y, d.y, t0, corner_slack), step_i,
            step_j, o.xy, inv.xy, t0);
        // The walk of march/walk.rs: a main cell, then (when the ray passes a grid vertex too closely to
        // resolve) the extra cell across it, then the step. "While-while" as in the traversal: the
        // inner loop steps through cells while their cheap test (rbvh_cell_candidate) rejects them,
        // and the outer loop tests the triangles of the cell that passes it, so that on SIMD
        // hardware the triangle tests run once for the lanes that reached such a cell, not beside
        // every step (on the dragon close-up at Q2, 1 in 3 cells of a primary ray passes, 1 in 24
        // of an AO ray). The step after a cell whose triangles missed opens the next inner round.
        // A single call site of each test keeps the inlined code from being duplicated. The walk
        // carries only its position (`w`: grid.glsl's one walk, which the block jumps move too),
        // `dirs`, the block checked, the cells walked and the codes of the cell handed to the outer
        // loop; that cell is made anew from them (rbvh_walk_cell).
        // Block jumps (src/rbvh/ranges.rs): the blocks' height ranges follow the height codes.
        uint block_pitch = (sz.atlas_pitch + 7u) >> 3;
        uint block_count = ((rows + 7u) >> 3) * block_pitch;
        uint checked_block = 0xFFFFFFFFu;
        // The codes of the cell that left the inner loop (RbvhCell's words).
        uint c00_c10 = 0u;
        uint c01_c11 = 0u;
        uint dirs = rbvh_walk_dirs(step_i, step_j, entered);
        // Both loops are bounded by the cells walked, which every round of either adds to or ends.
        while (cells < rbvh_walk_bound(last_i, last_j)) {
            dirs &= ~RBVH_WALK_FOUND;
            while (cells < rbvh_walk_bound(last_i, last_j)) {
                // Every round but the first steps from the cell before: to the extra cell across a
                // grid vertex the ray passes within rounding of (march/walk.rs walks it between the two
                // main cells), else to the next main cell.
                if (cells > 0u) {
                    int step_i = rbvh_walk_step_i(dirs);
                    int step_j = rbvh_walk_step_j(dirs);
                    if (!rbvh_walk_extra(dirs) &&
                        rbvh_grid_across_vertex(w, step_i, step_j, last_i, last_j, d.xy, corner_slack)) {
                        dirs |= RBVH_WALK_EXTRA;
                    } else {
                        dirs &= ~RBVH_WALK_EXTRA;
                        int axis = rbvh_grid_advance(w, RBVH_BETWEEN_SAMPLES, step_i, step_j, last_i, last_j, o.xy,
                                                     inv.xy);
                        if (axis < 0) {
                            dirs |= RBVH_WALK_STOPPED;
                            break;
                        }
                        dirs = rbvh_walk_entered_across(dirs, axis);
                    }
                }
                if (!rbvh_walk_extra(dirs)) {
                    // Past the box's exit, the cell stepped into within rounding of it is walked too.
                    if (w.t_in > t1) {
                        precise float past = (w.t_in - t1) * abs(rbvh_walk_entered(dirs) == 0 ? d.x : d.y);
                        if (rbvh_walk_entered(dirs) < 0 || !(past <= corner_slack)) {
                            dirs |= RBVH_WALK_STOPPED;
                            break;
                        }
                    }
                    // On entering a block: if the ray passes wholly above or below its height range
                    // (with the cell test's slack), none of its cells can be hit, and the walk moves
                    // straight to the block's exit cell, as it would reach it cell by cell.
                    uint k = leaf.atlas_base + uint(w.cj) * sz.atlas_pitch + uint(w.ci);
                    uint ax = k & (sz.atlas_pitch - 1u);
                    uint ay = k >> shift;
                    uint block = (ay >> 3) * block_pitch + (ax >> 3);
                    if (RBVH_BLOCK_JUMPS && block != checked_block && block < block_count) {
                        checked_block = block;
                        int step_i = rbvh_walk_step_i(dirs);
                        int step_j = rbvh_walk_step_j(dirs);
                        int edge_i = rbvh_block_exit(w.ci, ax, step_i, last_i);
                        int edge_j = rbvh_block_exit(w.cj, ay, step_j, last_j);
                        float leave_i = rbvh_grid_boundary_t(RBVH_BETWEEN_SAMPLES, edge_i, step_i, o.x, inv.x);
                        float leave_j = rbvh_grid_boundary_t(RBVH_BETWEEN_SAMPLES, edge_j, step_j, o.y, inv.y);
                        if (rbvh_block_clear(leaf, sz, block, o.z, d.z, w.t_in, min(min(leave_i, leave_j), t1), slack,
                                             uu)) {
                            RBVH_COUNT_ADD(jumps, 1u);
                            if (t1 < min(leave_i, leave_j)) {
                                dirs |= RBVH_WALK_STOPPED;
                                break;
                            }
                            int crossed = rbvh_grid_jump(w, RBVH_BETWEEN_SAMPLES, step_i, step_j, edge_i, edge_j,
                                                         leave_i, leave_j, o.xy, inv.xy);
                            if (crossed >= 0) {
                                dirs = rbvh_walk_entered_across(dirs, crossed);
                            }
                        }
                    }
                }
                RbvhCell cell = rbvh_walk_cell(w, dirs, t1);
                cells += 1u;
                bool tests = rbvh_cell_candidate(leaf, sz, fr, slack, cell);
                // A main cell with a surface entered from one with a hole (or through the tile's
                // side), or with three samples (its diagonal faces the hole), may hold a skirt hit:
                // tested in the outer loop too, so that the inner one stays small.
                c00_c10 = cell.c00_c10;
                c01_c11 = cell.c01_c11;
                bool rim = false;
                bool edge_rim = false;
                bool diagonal = false;
                if (!rbvh_walk_extra(dirs)) {
                    int valid = int(!rbvh_is_hole(rbvh_c00(cell))) + int(!rbvh_is_hole(rbvh_c10(cell))) +
                                int(!rbvh_is_hole(rbvh_c01(cell))) + int(!rbvh_is_hole(rbvh_c11(cell)));
                    edge_rim = rbvh_walk_entered(dirs) >= 0 && (dirs & RBVH_WALK_PREV_OPEN) != 0u && valid >= 3;
                    diagonal = valid == 3;
                    dirs = valid < 4 ? dirs | RBVH_WALK_PREV_OPEN : dirs & ~RBVH_WALK_PREV_OPEN;
                    rim = (edge_rim || diagonal) && rbvh_rim_reach(leaf, cell, o.z, d.z, slack, uu);
                }
                if (tests || rim) {
                    dirs |= (tests ? RBVH_WALK_TESTS : 0u) | (rim ? RBVH_WALK_RIM : 0u) |
                            (edge_rim ? RBVH_WALK_EDGE_RIM : 0u) | (diagonal ? RBVH_WALK_DIAGONAL : 0u);
                    break;
                }
            }
            if ((dirs & RBVH_WALK_FOUND) == 0u) {
                break;
            }
            RbvhCell cell = rbvh_walk_cell(w, dirs, t1);
            cell.c00_c10 = c00_c10;
            cell.c01_c11 = c01_c11;
            // What was hit: 0 or 1, the cell's first or second triangle; 2, a skirt.
            int kind = 2;
            float t = -1.0;
            if ((dirs & RBVH_WALK_RIM) != 0u) {
                int entered = rbvh_walk_entered(dirs);
                int step = entered == 0 ? rbvh_walk_step_i(dirs) : rbvh_walk_step_j(dirs);
                t = (dirs & RBVH_WALK_EDGE_RIM) != 0u ? rbvh_skirt(leaf, fr, slack, uu, cell, entered, step) : -1.0;
                if (t < 0.0 && (dirs & RBVH_WALK_DIAGONAL) != 0u) {
                    t = rbvh_diagonal_skirt(leaf, fr, slack, uu, cell);
                }
            }
            if (t < 0.0 && (dirs & RBVH_WALK_TESTS) != 0u) {
                t = rbvh_cell_triangles(leaf, fr, cell, kind, cut);
                // Counted after the test: counted before it, the counting pipelines took 8 VGPRs
                // more than the timed ones on RADV navi21 with the counters in trace_io.glsl's
                // records (docs/speed.md, "Counters out of the registers").
                RBVH_COUNT_ADD(cells_tested, 1u);
            }
            if (t >= 0.0) {
                // Where the hit's normal comes from, recorded here so that no cell outlives the walk.
                uint k00 = leaf.atlas_base + uint(cell.j) * sz.atlas_pitch + uint(cell.i);
                normal_cell = uvec2(k00, RBVH_HEIGHT_ONLY ? uint(1 + kind) : rbvh_cell_normal_choice(fr, cell, t));
                t_hit = t;
                dirs |= RBVH_WALK_STOPPED;
                break;
            }
        }
        if ((dirs & RBVH_WALK_STOPPED) == 0u && cells < rbvh_walk_bound(last_i, last_j)) {
            cut = true;
        }
    }
    return t_hit;
}

// The RBVH's leaf hook for traverse.glsl: height fields marched, hybrid triangle leaves tested as
// the exact BVH's (RbvhLeafHook in src/rbvh/march/hook.rs). It keeps the nearest hit in one word, `best`:
// a triangle's slot (below LEAF_BIT: slots are fewer than 2^31), or the id of a height field (or,
// with level of detail, a chosen node), LEAF_BIT set; RBVH_INVALID while none. Where a height
// field's hit takes its normal from is kept in rbvh_stack's RBVH_STACK_HIT (written with `best`,
// read only when `best` is a height field's), not in a register through every later march: a
// height field's hit, its cell's c00 at atlas index x and, in y, rbvh_cell_normal_choice
// (RBVH_HEIGHT_ONLY: the triangle or skirt hit; see rbvh_march); a level-of-detail hit, its
// normal texel in x and 0 in y. The hit's id and
// normal are read and decoded once, after the loops (rbvh_rbvh_hit), so that the SIMD loops do not
// carry them.
struct RbvhLeafHook {
    RbvhSizes sz;
    uint best;
};

RbvhLeafHook rbvh_leaf_hook(RbvhSizes sz) {
    return RbvhLeafHook(sz, RBVH_INVALID);
}

uint rbvh_node_count(RbvhLeafHook leaves) {
    return leaves.sz.node_count;
}

// One round per marched or tested leaf (a tree has at most one leaf more than it has inner nodes;
// with level of detail, chosen nodes replace subtrees), plus the last, which finds the stack empty.
uint rbvh_round_bound(RbvhLeafHook leaves) {
    return leaves.sz.node_count + leaves.sz.heightfield_count + 1u;
}

bool rbvh_is_leaf(RbvhLeafHook leaves, uint reference) {
    return (reference & RBVH_LEAF_BIT) != 0u;
}

uint rbvh_enter(RbvhLeafHook leaves, uint child, uint count, float t_entry) {
    return child;
}

// Keeps what marching a leaf found, for this hook and lod.glsl's: the cells (or columns) walked
// in `steps` and the counters, and, when t is a hit, t as the nearest with the hit's id and where
// its normal comes from. Whether it was a hit.
bool rbvh_keep_march(inout RbvhLeafHook leaves, float t, uint walked, uint id, uvec2 normal, inout float t_closest,
                     inout uint steps) {
    steps += walked;
    RBVH_COUNT_ADD(cells, walked);
    bool hit = t >= 0.0;
    if (hit) {
        t_closest = t;
        leaves.best = id;
        rbvh_stack[RBVH_STACK_HIT] = normal;
    }
    return hit;
}

bool rbvh_test(inout RbvhLeafHook leaves, Ray ray, bool any_hit, uint reference, uint count,
               inout float t_closest, inout uint steps, inout bool cut) {
    bool hit = false;
    if (!rbvh_is_heightfield(count)) {
        uint first = reference & ~RBVH_LEAF_BIT;
        // The shear is made per leaf rather than kept across the loops: see RbvhFrameRay.
        hit = rbvh_test_triangles(rbvh_shear(ray), ray, any_hit, first,
                                  rbvh_slot_end(first, count, leaves.sz.tri_count), leaves.sz.tri_count,
                                  t_closest, leaves.best, steps, cut);
    } else {
        RBVH_COUNT_ADD(leaves, 1u);
        uint cells;
        uvec2 normal_cell;
        float t = rbvh_march(reference & ~RBVH_LEAF_BIT, leaves.sz, ray, t_closest, cells, normal_cell, cut);
        hit = rbvh_keep_march(leaves, t, cells, reference, normal_cell, t_closest, steps);
    }
    return hit;
}

#define RBVH_TRAVERSE rbvh_traverse_rbvh
#define RBVH_LEAVES RbvhLeafHook
#define RBVH_KEEPS_RAY
#include "traverse.glsl"
#undef RBVH_TRAVERSE
#undef RBVH_LEAVES
#undef RBVH_KEEPS_RAY

// The world normal of a height-only RBVH's hit at t along `ray` in leaf `li`, whose cell's c00 is
// at atlas index `k00` and `kind` is what rbvh_march hit (1 + triangle, or 3: a skirt): the facet
// of the cell triangle hit, made from the cell's texels read again (facet_normal in march/normal.rs). Made
// once the ray is done, so that neither the walk nor the traversal carries it.
vec3 rbvh_height_field_facet(RbvhSizes sz, uint li, uint k00, uint kind, Ray ray, float t) {
    RbvhHeightfield leaf = RBVH_HEIGHTFIELD(li);
    uint rel = k00 - leaf.atlas_base;
    int i = int(rel & (sz.atlas_pitch - 1u));
    int j = int(rel >> uint(findLSB(sz.atlas_pitch)));
    RbvhCell cell = RbvhCell(i, j, t, t, 0u, 0u);
    rbvh_read_corners(leaf, sz, cell);
    int tri = kind == 3u ? rbvh_skirt_triangle(rbvh_frame_ray(leaf, ray, t), cell, t) : int(kind) - 1;
    vec3 facet = rbvh_cell_facet(leaf, cell, tri);
    // Normals map back by the frame's transpose.
    precise vec3 n = (leaf.axis_u * facet.x + leaf.axis_v * facet.y) + leaf.axis_w * facet.z;
    return normalize(n);
}

// The hit that `leaves` kept at distance t along `ray`: a triangle's id and normal, read now, or a
// height field's id (LEAF_BIT | leaf index; with level of detail LEAF_BIT | LOD_BIT | node) and
// its texel's normal, read now (RBVH_HEIGHT_ONLY: its facet's, rbvh_height_field_facet).
Hit rbvh_rbvh_hit(RbvhLeafHook leaves, float t, Ray ray) {
    vec3 nrm;
    uint id = leaves.best;
    if (id == RBVH_INVALID) {
        return rbvh_miss();
    } else if ((id & RBVH_LEAF_BIT) == 0u) {
        BvhTriangle tri = rbvh_bvh_triangle(id, leaves.sz.tri_count);
        id = tri.prim;
        nrm = rbvh_unit_normal(tri.v0, tri.v1, tri.v2);
    } else if (RBVH_HEIGHT_ONLY) {
        uvec2 b = rbvh_stack[RBVH_STACK_HIT];
        nrm = rbvh_height_field_facet(leaves.sz, id & ~RBVH_LEAF_BIT, b.x, b.y, ray, t);
    } else {
        uvec2 b = rbvh_stack[RBVH_STACK_HIT];
        uint texel = b.y == 0u ? b.x : rbvh_normal_texel(leaves.sz, b.x, b.y, ray.dir);
        nrm = rbvh_decode_normal(texel);
    }
    return Hit(t, nrm.x, nrm.y, nrm.z, id, 0u, 0u, 0u);
}

// The RBVH's closest (or, with `any_hit`, any) hit: traverse.glsl with the RBVH's leaves.
// `steps` = nodes visited + triangles tested + cells marched; `overflow` as in traverse.glsl.
Hit rbvh_trace_rbvh(Ray ray, bool any_hit, RbvhSizes sz, out uint steps, out bool overflow) {
    RbvhLeafHook leaves = rbvh_leaf_hook(sz);
    float t = rbvh_traverse_rbvh(ray, any_hit, leaves, steps, overflow);
    return rbvh_rbvh_hit(leaves, t, rbvh_kept_ray());
}

#ifdef RBVH_INSTANCES
// The two-level RBVH's hook (trace_instanced in src/rbvh/march/hook.rs: src/bvh/top_level.rs's
// InstanceHook around RbvhLeafHook): top-level
// leaves enter instances (bvh.glsl's records), the meshes' leaves are the RBVH's own, marched and
// tested in the mesh's space, and the leaves of the mesh the top level grafts (bvh::GRAFTED, the
// first instance where it is the identity) are marched there with the world ray.
// The instance entered last (RBVH_STACK_INSTANCE's x; in the top level the grafted one, 0), which
// is the one the ray is in while the traversal is inside one, and the nearest hit's
// (RBVH_STACK_HIT_INSTANCE's x) are kept in rbvh_stack, not in registers through every march. A
// hit copies the instance's index where it is found, read after the march: while the hook read
// that index before the march too (to check that the ray was inside an instance), the compiler
// kept it in a register through the march (72 VGPRs with block jumps where the flat tracer takes
// 56), so the hit was marked "the instance the ray is in" and named later, which cost lavapipe
// a store in every round (docs/speed.md, "The two-level RBVH tracer's registers";
// docs/paper-scale.md, "What two levels cost a ray on lavapipe"). The traversal now hands the
// hook the leaves met inside an instance or grafted in the top level, and the index is read once
// the march is done.

struct RbvhInstanceHook {
    RbvhLeafHook inner;
    uint instance_count;
};

uint rbvh_node_count(RbvhInstanceHook leaves) {
    return leaves.inner.sz.node_count;
}

// The top level's rounds and each instance's (its leaves and nodes, as for one RBVH), at most
// 2^32 − 2 so that the loops' counters cannot wrap.
uint rbvh_round_bound(RbvhInstanceHook leaves) {
    uint per_tree = min(rbvh_round_bound(leaves.inner), 0xFFFFFFFEu);
    uint trees = min(leaves.instance_count, 0xFFFFFFFEu) + 1u;
    return trees > 0xFFFFFFFEu / per_tree ? 0xFFFFFFFEu : trees * per_tree;
}

bool rbvh_is_leaf(RbvhInstanceHook leaves, uint reference) {
    return (reference & RBVH_LEAF_BIT) != 0u;
}

uint rbvh_enter(RbvhInstanceHook leaves, uint child, uint count, float t_entry) {
    return child;
}

// The nearest hit's instance so far.
uint rbvh_hit_instance() {
    return rbvh_stack[RBVH_STACK_HIT_INSTANCE].x;
}

// traverse.glsl's instance hooks; the first two return their results, with one exit (see
// traverse.glsl).
uint rbvh_instance_root(RbvhInstanceHook leaves, uint reference, uint count) {
    uint k = reference & ~RBVH_LEAF_BIT;
    uint root = RBVH_INVALID;
    if (k < leaves.instance_count) {
        root = RBVH_BVH_INSTANCE(k).root;
    }
    return root;
}

// Enters instance leaf `reference`: it becomes the instance entered last (which the ray goes into
// unless the stack is full). The ray comes from rbvh_level_ray.
Ray rbvh_enter_instance(inout RbvhInstanceHook leaves, uint reference, Ray ray) {
    uint k = reference & ~RBVH_LEAF_BIT;
    rbvh_stack[RBVH_STACK_INSTANCE].x = k;
    return ray;
}

// The world ray, or inside an instance the ray in its mesh's space: the instance entered last is
// the one the ray is in.
Ray rbvh_level_ray(RbvhInstanceHook leaves, bool inside) {
    Ray ray = rbvh_kept_world_ray();
    if (inside) {
        ray = rbvh_ray_into(RBVH_BVH_INSTANCE(rbvh_stack[RBVH_STACK_INSTANCE].x), ray);
    }
    return ray;
}

// Leaves the instance entered last: the leaves met next are the top level's, the grafted mesh's.
// The ray comes from rbvh_level_ray.
void rbvh_exit_instance(inout RbvhInstanceHook leaves, inout Ray ray) {
    rbvh_stack[RBVH_STACK_INSTANCE].x = 0u;
}

bool rbvh_test(inout RbvhInstanceHook leaves, Ray ray, bool any_hit, uint reference, uint count,
               inout float t_closest, inout uint steps, inout bool cut) {
    // The traversal hands over the meshes' leaves alone, met inside an instance or grafted in the
    // top level; RBVH_STACK_INSTANCE names either (the grafted one, 0, outside any instance).
    bool hit = rbvh_test(leaves.inner, ray, any_hit, reference, count, t_closest, steps, cut);
    if (hit) {
        rbvh_stack[RBVH_STACK_HIT_INSTANCE].x = rbvh_stack[RBVH_STACK_INSTANCE].x;
    }
    return hit;
}

#define RBVH_TRAVERSE rbvh_traverse_rbvh_instances
#define RBVH_LEAVES RbvhInstanceHook
#define RBVH_KEEPS_RAY
#define RBVH_TRAVERSE_INSTANCES
#include "traverse.glsl"
#undef RBVH_TRAVERSE
#undef RBVH_LEAVES
#undef RBVH_KEEPS_RAY
#undef RBVH_TRAVERSE_INSTANCES

// The two-level RBVH's closest (or, with `any_hit`, any) hit: its instance in `instance_id`, ids
// as rbvh_trace_rbvh's (a height field's among every mesh's records), the normal made in the
// mesh's space from the ray taken there again, then taken to world space by the instance.
Hit rbvh_trace_rbvh_instances(Ray ray, bool any_hit, RbvhSizes sz, uint instance_count, out uint steps,
                              out bool overflow) {
    RbvhInstanceHook leaves = RbvhInstanceHook(rbvh_leaf_hook(sz), instance_count);
    rbvh_stack[RBVH_STACK_INSTANCE].x = 0u;
    rbvh_stack[RBVH_STACK_HIT_INSTANCE].x = RBVH_INVALID;
    float t = rbvh_traverse_rbvh_instances(ray, any_hit, leaves, steps, overflow);
    if (leaves.inner.best == RBVH_INVALID) {
        return rbvh_miss();
    }
    uint k = rbvh_hit_instance();
    BvhInstance inst = RBVH_BVH_INSTANCE(k);
    Hit h = rbvh_rbvh_hit(leaves.inner, t, rbvh_ray_into(inst, rbvh_kept_world_ray()));
    vec3 n = rbvh_normal_out(inst, vec3(h.nx, h.ny, h.nz));
    return Hit(h.t, n.x, n.y, n.z, h.id, k, 0u, 0u);
}
#endif  // RBVH_INSTANCES

#endif
