// The RBVH's height-field march and its leaf hook for the one traversal (traverse.glsl): the GLSL
// twin of src/rbvh/march.rs, step for step, on the packed data of src/rbvh/layout.rs. Includes
// bvh.glsl for the node and triangle buffers.
//
// The includer chooses where the buffers live by defining, before the #include:
//   RBVH_BVH_SET, RBVH_BVH_NODES_BINDING, RBVH_BVH_TRIS_BINDING   (see bvh.glsl; defaults 0, 0, 1)
//   RBVH_LEAVES_BINDING  binding of the height-field leaves (default 2)
//   RBVH_ATLAS_BINDING   binding of the texel atlas         (default 3)
// or, with RBVH_DEVICE_ADDRESS (see bvh.glsl), RBVH_LEAVES_ADDRESS and RBVH_ATLAS_ADDRESS.
// and, to trace with level of detail, RBVH_LOD (see lod.glsl for its two bindings): then
// rbvh_trace_rbvh_lod is defined too, taking each ray's cone and the LOD array sizes.
// RBVH_BLOCK_JUMPS (default true) is the condition under which the march jumps over blocks the
// ray passes above or below; the hits are the same either way. On CPU implementations such as
// lavapipe, which run every branch, the walk is faster without (see Tracer::block_jumps).
// RBVH_HEIGHT_ONLY (default false) must be true for an RBVH built with TexelFormat::Height: its
// atlas holds height codes alone (atlas.glsl), and a hit's normal is that of the cell triangle it
// hit.
#ifndef RBVH_RBVH_GLSL
#define RBVH_RBVH_GLSL

#include "bvh.glsl"
#include "grid.glsl"

#ifndef RBVH_LEAVES_BINDING
#define RBVH_LEAVES_BINDING 2
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

// 64 bytes: see GpuHeightfield.
struct RbvhLeaf {
    vec3 origin;
    uint atlas_base;
    vec3 axis_u;
    uint res_u;
    vec3 axis_v;
    uint res_v;
    vec3 axis_w;
    float h_scale;
};

// Atlas texels, as rbvh_texel returns them: bits 0-15 height code (0xFFFF = hole), bits 16-31
// the 8:8 octahedral normal; atlas.glsl reads them from the atlas's words.
#ifdef RBVH_DEVICE_ADDRESS
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer RbvhLeavesRef {
    RbvhLeaf leaves[];
};
layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer RbvhAtlasRef {
    uint texels[];
};
#define RBVH_LEAF(i) RbvhLeavesRef(RBVH_LEAVES_ADDRESS).leaves[i]
#define RBVH_ATLAS(i) RbvhAtlasRef(RBVH_ATLAS_ADDRESS).texels[i]
#else
layout(std430, set = RBVH_BVH_SET, binding = RBVH_LEAVES_BINDING) readonly buffer RbvhLeaves {
    RbvhLeaf rbvh_leaves[];
};
layout(std430, set = RBVH_BVH_SET, binding = RBVH_ATLAS_BINDING) readonly buffer RbvhAtlas {
    uint rbvh_atlas[];
};
#define RBVH_LEAF(i) rbvh_leaves[i]
#define RBVH_ATLAS(i) rbvh_atlas[i]
#endif
#define RBVH_ATLAS_WORD(i) RBVH_ATLAS(i)
#include "atlas.glsl"

// Sizes the march needs to bound its reads.
struct RbvhSizes {
    uint node_count;
    uint tri_count;
    uint leaf_count;
    uint atlas_pitch;  // texels per atlas row: a power of two (the march skips leaves otherwise)
    uint atlas_len;
    uint atlas_wide_len;  // texels before the narrow band (atlas.glsl)
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

// The height code of sample (i, j) of `leaf`'s tile: the walk needs no normals (a hit's are read
// once the ray is done, rbvh_normal_texel), so that a texel of the narrow band is one read.
uint rbvh_texel(RbvhLeaf leaf, RbvhSizes sz, int i, int j) {
    uint index = leaf.atlas_base + uint(j) * sz.atlas_pitch + uint(i);
    return rbvh_atlas_code(index, sz.atlas_len, sz.atlas_wide_len, RBVH_HEIGHT_ONLY);
}

// Where the blocks' height ranges start in the atlas words: after the texels' words.
uint rbvh_texel_words(RbvhSizes sz) {
    return rbvh_atlas_texel_words(sz.atlas_len, sz.atlas_wide_len, RBVH_HEIGHT_ONLY);
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

// One cell of the walk: its indices, the ray's parameter range over it, and its four corners'
// height codes as the walk read them (rbvh_texel).
struct RbvhCell {
    int i;
    int j;
    float t_in;
    float t_out;
    uint c00;
    uint c10;
    uint c01;
    uint c11;
};

// Step 4 of march.rs, its cheap half: reads the cell's corners and tells whether its triangles
// can be hit at all — three or four corners present, and the ray's height over
// [t_in, t_out] within their height range (with the walk's slack). Written without local
// arrays: dynamically indexed arrays become per-lane memory on SIMD implementations such as
// lavapipe.
bool rbvh_cell_candidate(RbvhLeaf leaf, RbvhSizes sz, RbvhFrameRay fr, float slack, inout RbvhCell cell) {
    cell.c00 = rbvh_texel(leaf, sz, cell.i, cell.j);
    cell.c10 = rbvh_texel(leaf, sz, cell.i + 1, cell.j);
    cell.c01 = rbvh_texel(leaf, sz, cell.i, cell.j + 1);
    cell.c11 = rbvh_texel(leaf, sz, cell.i + 1, cell.j + 1);
    bool v00 = !rbvh_is_hole(cell.c00);
    bool v10 = !rbvh_is_hole(cell.c10);
    bool v01 = !rbvh_is_hole(cell.c01);
    bool v11 = !rbvh_is_hole(cell.c11);
    if (int(v00) + int(v10) + int(v01) + int(v11) < 3) {
        return false;
    }
    precise float h00 = float(cell.c00 & 0xFFFFu) * leaf.h_scale;
    precise float h10 = float(cell.c10 & 0xFFFFu) * leaf.h_scale;
    precise float h01 = float(cell.c01 & 0xFFFFu) * leaf.h_scale;
    precise float h11 = float(cell.c11 & 0xFFFFu) * leaf.h_scale;
    float lo = min(min(v00 ? h00 : RBVH_INF, v10 ? h10 : RBVH_INF), min(v01 ? h01 : RBVH_INF, v11 ? h11 : RBVH_INF));
    float hi = max(max(v00 ? h00 : -RBVH_INF, v10 ? h10 : -RBVH_INF), max(v01 ? h01 : -RBVH_INF, v11 ? h11 : -RBVH_INF));
    float h_a = rbvh_height_at(fr.o.z, fr.d.z, cell.t_in);
    float h_b = rbvh_height_at(fr.o.z, fr.d.z, cell.t_out);
    precise float lo_s = lo - slack;
    precise float hi_s = hi + slack;
    return !(max(h_a, h_b) < lo_s || min(h_a, h_b) > hi_s);
}

// The first triangle of a cell with three or four corners present (`v..`, at points `p..`: in
// the frame, or sheared for the ray): (c00, c10, c11) with all four, else the three present in
// the cycle order c00, c10, c11, c01 (the winding stays the quad's), as `hit` and `surface_under`
// in march.rs take it.
void rbvh_first_triangle(bool v00, bool v10, bool v11, vec3 p00, vec3 p10, vec3 p01, vec3 p11,
                         out vec3 a, out vec3 b, out vec3 c) {
    a = v00 ? p00 : p10;
    b = v00 ? (v10 ? p10 : p11) : p11;
    c = (v00 && v10) ? (v11 ? p11 : p01) : p01;
}

// Step 4 of march.rs, its costly half: the cell's two (or one) triangles; returns t (< 0 on a
// miss) and, on a hit, the frame-space normal of the triangle hit, (b - a) x (c - a) of its
// frame-space corners (used by height-only RBVHs). `cut` is set when the device ended the loop
// early (see traverse.glsl).
float rbvh_cell_triangles(RbvhLeaf leaf, RbvhFrameRay fr, RbvhCell cell, out vec3 facet, inout bool cut) {
    bool v00 = !rbvh_is_hole(cell.c00);
    bool v10 = !rbvh_is_hole(cell.c10);
    bool v01 = !rbvh_is_hole(cell.c01);
    bool v11 = !rbvh_is_hole(cell.c11);
    precise float h00 = float(cell.c00 & 0xFFFFu) * leaf.h_scale;
    precise float h10 = float(cell.c10 & 0xFFFFu) * leaf.h_scale;
    precise float h01 = float(cell.c01 & 0xFFFFu) * leaf.h_scale;
    precise float h11 = float(cell.c11 & 0xFFFFu) * leaf.h_scale;
    float s0 = float(cell.i) + 0.5;
    float s1 = float(cell.i + 1) + 0.5;
    float r0 = float(cell.j) + 0.5;
    float r1 = float(cell.j + 1) + 0.5;
    vec3 p00 = vec3(s0, r0, h00);
    vec3 p10 = vec3(s1, r0, h10);
    vec3 p01 = vec3(s0, r1, h01);
    vec3 p11 = vec3(s1, r1, h11);
    // The four corners in the ray's sheared frame once, for both triangles, rather than each
    // triangle's three in its own test: the same values (those intersect_triangle in
    // src/geom/triangle.rs makes of each corner), and far fewer live at once inside the walk
    // (docs/speed.md, "What holds the RBVH tracer's registers").
    RbvhShear shear = rbvh_shear(Ray(fr.o, fr.tmin, fr.d, fr.tmax));
    vec3 q00 = rbvh_sheared(shear, p00);
    vec3 q10 = rbvh_sheared(shear, p10);
    vec3 q01 = rbvh_sheared(shear, p01);
    vec3 q11 = rbvh_sheared(shear, p11);
    vec3 a;
    vec3 b;
    vec3 c;
    rbvh_first_triangle(v00, v10, v11, q00, q10, q01, q11, a, b, c);
    // Then, with all four, (c00, c11, c01) when nearer; one call site for both triangles.
    float t_hit = -1.0;
    facet = vec3(0.0);
    int tris = (v00 && v10 && v01 && v11) ? 2 : 1;
    int k = 0;
    for (; k < tris; ++k) {
        vec3 b_k = k == 0 ? b : q11;
        vec3 c_k = k == 0 ? c : q01;
        float t = rbvh_intersect_sheared(a, b_k, c_k, fr.tmin, t_hit >= 0.0 ? t_hit : fr.tmax);
        if (t >= 0.0) {
            t_hit = t;
            if (RBVH_HEIGHT_ONLY) {
                // The facet from the frame-space corners of the triangle hit.
                vec3 pa;
                vec3 pb;
                vec3 pc;
                rbvh_first_triangle(v00, v10, v11, p00, p10, p01, p11, pa, pb, pc);
                vec3 pb_k = k == 0 ? pb : p11;
                vec3 pc_k = k == 0 ? pc : p01;
                precise vec3 e1 = pb_k - pa;
                precise vec3 e2 = pc_k - pa;
                precise vec3 n = vec3(e1.y * e2.z - e1.z * e2.y, e1.z * e2.x - e1.x * e2.z,
                                      e1.x * e2.y - e1.y * e2.x);
                facet = n;
            }
        }
    }
    if (k < tris) {
        cut = true;
    }
    return t_hit;
}

// The skirt of `full` texels under the edge from corner texel `ca` to `cb`, met at fraction `f`
// along it (clamped) at `t` (skirt_hit and skirt_depth in march.rs): true when `t` lies in the
// ray's interval and the ray is below the edge there by at most the skirt's depth: `full` under
// an edge of two samples taken from the surface (even codes: Texel::is_sampled); from such a
// sample to an extrapolated one, `full` at the sampled end tapering to nothing half-way; none
// under two extrapolated ones (`uu` = |axis_u|^2, so that no square root is needed).
bool rbvh_skirt_at(RbvhLeaf leaf, RbvhFrameRay fr, float slack, float uu, uint ca, uint cb, float f, float full,
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

// The skirt under the edge of `cell` (skirt in march.rs) that the ray entered at cell.t_in from a
// cell with fewer than four samples or through the tile's side, across its edge
// on `axis` (0: an s boundary, 1: a t boundary) stepping `step` along it, when both samples of
// that edge are present: t_in on a hit, else -1.
float rbvh_skirt(RbvhLeaf leaf, RbvhFrameRay fr, float slack, float uu, RbvhCell cell, int axis, int step) {
    bool across_s = axis == 0;
    uint ca = across_s ? (step > 0 ? cell.c00 : cell.c10) : (step > 0 ? cell.c00 : cell.c01);
    uint cb = across_s ? (step > 0 ? cell.c01 : cell.c11) : (step > 0 ? cell.c10 : cell.c11);
    if (rbvh_is_hole(ca) || rbvh_is_hole(cb)) {
        return -1.0;
    }
    precise float at_s = fr.o.x + fr.d.x * cell.t_in;
    precise float at_t = fr.o.y + fr.d.y * cell.t_in;
    precise float along = across_s ? at_t - (float(cell.j) + 0.5) : at_s - (float(cell.i) + 0.5);
    return rbvh_skirt_at(leaf, fr, slack, uu, ca, cb, along, RBVH_MARCH_SKIRT_TEXELS, cell.t_in) ? cell.t_in : -1.0;
}

// The skirt under the diagonal of `cell`, whose corners are three samples and a hole
// (diagonal_skirt in march.rs; MARCH_DIAGONAL_SKIRT_TEXELS deep): where the ray crosses the
// diagonal that faces the hole, within [t_in, t_out], from the hole's side. That t on a hit,
// else -1.
float rbvh_diagonal_skirt(RbvhLeaf leaf, RbvhFrameRay fr, float slack, float uu, RbvhCell cell) {
    bool h00 = rbvh_is_hole(cell.c00);
    bool h01 = rbvh_is_hole(cell.c01);
    bool h11 = rbvh_is_hole(cell.c11);
    // Through c10 and c01 (fs + ft = 1) for a hole at c00 or c11, else through c00 and c11.
    bool anti = h00 || h11;
    uint ca = anti ? cell.c10 : cell.c00;
    uint cb = anti ? cell.c01 : cell.c11;
    float side = (h00 || h01) ? -1.0 : 1.0;
    precise float fs0 = fr.o.x - (float(cell.i) + 0.5);
    precise float ft0 = fr.o.y - (float(cell.j) + 0.5);
    precise float q0 = anti ? (fs0 + ft0) - 1.0 : fs0 - ft0;
    precise float dq = anti ? fr.d.x + fr.d.y : fr.d.x - fr.d.y;
    if (!(dq * side < 0.0)) {
        return -1.0;
    }
    precise float t = -q0 / dq;
    if (!(t >= cell.t_in && t <= cell.t_out)) {
        return -1.0;
    }
    precise float f = anti ? ft0 + fr.d.y * t : fs0 + fr.d.x * t;
    return rbvh_skirt_at(leaf, fr, slack, uu, ca, cb, f, RBVH_MARCH_DIAGONAL_SKIRT_TEXELS, t) ? t : -1.0;
}

// The frame-space normal of a skirt hit at t in `cell` for height-only texels: the facet of the
// cell's triangle over the point (surface_under in march.rs): with four corners (c00, c10, c11)
// where s >= t within the cell, else (c00, c11, c01); with three, the one triangle.
vec3 rbvh_skirt_facet(RbvhLeaf leaf, RbvhFrameRay fr, RbvhCell cell, float t) {
    bool v00 = !rbvh_is_hole(cell.c00);
    bool v10 = !rbvh_is_hole(cell.c10);
    bool v01 = !rbvh_is_hole(cell.c01);
    bool v11 = !rbvh_is_hole(cell.c11);
    float s0 = float(cell.i) + 0.5;
    float s1 = float(cell.i + 1) + 0.5;
    float r0 = float(cell.j) + 0.5;
    float r1 = float(cell.j + 1) + 0.5;
    vec3 p00 = vec3(s0, r0, float(cell.c00 & 0xFFFFu) * leaf.h_scale);
    vec3 p10 = vec3(s1, r0, float(cell.c10 & 0xFFFFu) * leaf.h_scale);
    vec3 p01 = vec3(s0, r1, float(cell.c01 & 0xFFFFu) * leaf.h_scale);
    vec3 p11 = vec3(s1, r1, float(cell.c11 & 0xFFFFu) * leaf.h_scale);
    vec3 a;
    vec3 b;
    vec3 c;
    rbvh_first_triangle(v00, v10, v11, p00, p10, p01, p11, a, b, c);
    precise float fs = (fr.o.x + fr.d.x * t) - s0;
    precise float ft = (fr.o.y + fr.d.y * t) - r0;
    if (v00 && v10 && v01 && v11 && fs < ft) {
        b = p11;
        c = p01;
    }
    precise vec3 e1 = b - a;
    precise vec3 e2 = c - a;
    return vec3(e1.y * e2.z - e1.z * e2.y, e1.z * e2.x - e1.x * e2.z, e1.x * e2.y - e1.y * e2.x);
}

// Step 5 of march.rs, its first half: where in `cell` a hit at `t_hit` lies and which corners it
// has, for rbvh_normal_texel: bit 0 right of the cell's middle, bit 1 above it, bits 2-5 corners
// c00, c10, c01, c11 present; never 0 for a hit (a cell with a surface has three corners). The
// normals are read once a ray is done (rbvh_rbvh_hit), not in the SIMD loops: read after every
// marched hit they cost lavapipe a tenth of its speed.
uint rbvh_cell_normal_choice(RbvhFrameRay fr, RbvhCell cell, float t_hit) {
    precise float s = fr.o.x + fr.d.x * t_hit;
    precise float r = fr.o.y + fr.d.y * t_hit;
    bool right = clamp(floor(s), float(cell.i), float(cell.i + 1)) > float(cell.i);
    bool up = clamp(floor(r), float(cell.j), float(cell.j + 1)) > float(cell.j);
    return uint(right) | uint(up) << 1 | uint(!rbvh_is_hole(cell.c00)) << 2
        | uint(!rbvh_is_hole(cell.c10)) << 3 | uint(!rbvh_is_hole(cell.c01)) << 4
        | uint(!rbvh_is_hole(cell.c11)) << 5;
}

// Step 5 of march.rs, its second half: the texel whose normal a hit reports, given its cell's
// texel c00 at atlas index `k00` and rbvh_cell_normal_choice: the nearest present corner sample,
// or, when that faces away from the world direction `dir` and another present corner faces it,
// the first such in the order c00, c10, c01, c11 (nearest_normal in march.rs).
uint rbvh_normal_texel(RbvhSizes sz, uint k00, uint choice, vec3 dir) {
    bool right = (choice & 1u) != 0u;
    bool up = (choice & 2u) != 0u;
    uint corner = (up ? 2u : 0u) + (right ? 1u : 0u);
    if ((choice & (4u << corner)) == 0u) {
        corner = uint(findLSB(choice >> 2));
    }
    uint nearest = rbvh_atlas_texel(k00 + (corner & 1u) + (corner >> 1) * sz.atlas_pitch, sz.atlas_len,
                                    sz.atlas_wide_len);
    if (!rbvh_faces(nearest, dir)) {
        for (uint q = 0u; q < 4u; ++q) {
            if ((choice & (4u << q)) == 0u) {
                continue;
            }
            uint c = rbvh_atlas_texel(k00 + (q & 1u) + (q >> 1) * sz.atlas_pitch, sz.atlas_len,
                                      sz.atlas_wide_len);
            if (rbvh_faces(c, dir)) {
                nearest = c;
                break;
            }
        }
    }
    return nearest;
}

// The walk's first cell along one axis (`start` in march.rs): the cell holding the entry, or
// the one behind it where the ray crosses their boundary within `slack` texels of the entry at
// `t0`, or after it (a flat tile's box is thinner than the rounding of the frame coordinates).
int rbvh_walk_start(float entry, int step, int last, float o, float inv, float d, float t0, float slack) {
    int c = rbvh_grid_cell(RBVH_BETWEEN_SAMPLES, entry, last);
    int back = c - step;
    if (step != 0 && back >= 0 && back <= last) {
        precise float gap = (t0 - rbvh_grid_boundary_t(RBVH_BETWEEN_SAMPLES, back, step, o, inv)) * abs(d);
        if (gap <= slack) {
            return back;
        }
    }
    return c;
}

// The walk's loop bound: twice the (res_u - 1) + (res_v - 1) - 1 cells a walk can step through,
// made from the last cell indices where it is used rather than kept through the walk, where it
// held a register (docs/speed.md, "What holds the RBVH tracer's registers").
uint rbvh_walk_bound(int last_i, int last_j) {
    return 2u * uint(last_i + last_j + 1);
}

// Marches leaf `li` over [tmin, t_closest); returns t (< 0 on a miss) and, on a hit, where its
// normal's texel is (`normal_cell`: the cell's c00 atlas index and rbvh_cell_normal_choice, for
// rbvh_normal_texel once the ray is done), or with RBVH_HEIGHT_ONLY the world normal of the cell
// triangle hit (`facet_normal`, as facet_normal in march.rs). `cells` counts
// cells visited. `cut` is set when the device ended a loop early (see traverse.glsl).
float rbvh_march(uint li, RbvhSizes sz, Ray ray, float t_closest, inout uint cells, out uvec2 normal_cell,
                 out vec3 facet_normal, inout bool cut) {
    normal_cell = uvec2(0u);
    facet_normal = vec3(0.0);
    if (li >= sz.leaf_count) {
        return -1.0;
    }
    RbvhLeaf leaf = RBVH_LEAF(li);
    if (leaf.res_u < 2u || leaf.res_v < 2u || leaf.res_u > sz.atlas_pitch) {
        return -1.0;
    }
    // The tile's corner in the atlas. The pitch is a power of two (the builder makes it one, and
    // the file reader and the upload refuse any other), which spares divisions: SIMD
    // implementations such as lavapipe run both sides of a branch, and a vector division there is
    // eight scalar ones. A tile must not wrap across atlas rows (as in tile_fits of march.rs): the
    // block jumps below count on it.
    if (sz.atlas_pitch == 0u || (sz.atlas_pitch & (sz.atlas_pitch - 1u)) != 0u) {
        return -1.0;
    }
    uint shift = uint(findLSB(sz.atlas_pitch));
    uint tile_u = leaf.atlas_base & (sz.atlas_pitch - 1u);
    uint tile_v = leaf.atlas_base >> shift;
    uint rows = sz.atlas_len >> shift;
    if (tile_u + leaf.res_u > sz.atlas_pitch) {
        return -1.0;
    }
    uint last_texel = leaf.atlas_base + (leaf.res_v - 1u) * sz.atlas_pitch + (leaf.res_u - 1u);
    if (last_texel >= sz.atlas_len || last_texel < leaf.atlas_base) {
        return -1.0;
    }
    // 1. Frame.
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
    Ray frame = Ray(fr.o, fr.tmin, fr.d, fr.tmax);
    if (!rbvh_ray_valid(frame)) {
        return -1.0;
    }
    vec3 o = fr.o;
    vec3 d = fr.d;
    vec3 inv = rbvh_safe_inverse(d);
    // 2. Clip to the padded tile box.
    precise float h_top = float(RBVH_MAX_CODE) * leaf.h_scale;
    precise float slack = RBVH_MARCH_SLACK * (abs(o.z) + abs(h_top)) + abs(leaf.h_scale);
    vec3 bmin = vec3(0.5 - RBVH_MARCH_EDGE_PAD, 0.5 - RBVH_MARCH_EDGE_PAD, -slack);
    precise vec3 bmax = vec3(float(leaf.res_u) - 0.5 + RBVH_MARCH_EDGE_PAD,
                             float(leaf.res_v) - 0.5 + RBVH_MARCH_EDGE_PAD, h_top + slack);
    float t0;
    if (!rbvh_intersect_box(bmin, bmax, o, inv, fr.tmin, fr.tmax, t0)) {
        return -1.0;
    }
    RBVH_COUNT_ADD(walks, 1u);
    precise vec3 e0 = (bmin - o) * inv;
    precise vec3 e1 = (bmax - o) * inv;
    vec3 e = max(e0, e1);
    float t1 = min(min(min(e.x, e.y), e.z), fr.tmax);
    // The edge (0: s, 1: t, -1: none) the current cell was entered across, for the skirt: the
    // first cell's when the ray enters the tile's box through its s or t side.
    vec3 near = min(e0, e1);
    int entered = t0 <= fr.tmin ? -1 : (t0 == near.x ? 0 : (t0 == near.y ? 1 : -1));
    precise float uu = (leaf.axis_u.x * leaf.axis_u.x + leaf.axis_u.y * leaf.axis_u.y) + leaf.axis_u.z * leaf.axis_u.z;
    precise float skirt_h = 1.001 * RBVH_MARCH_SKIRT_TEXELS / sqrt(uu);

    // 3. Walk.
    int last_i = int(leaf.res_u) - 2;
    int last_j = int(leaf.res_v) - 2;
    precise vec3 entry = o + d * t0;
    int step_i = rbvh_grid_step(d.x);
    int step_j = rbvh_grid_step(d.y);
    precise float corner_slack = RBVH_MARCH_SLACK * (((abs(o.x) + abs(o.y)) + float(leaf.res_u)) + float(leaf.res_v));
    // Within rounding of the boundary behind the entry, the walk starts behind it (march.rs).
    int ci = rbvh_walk_start(entry.x, step_i, last_i, o.x, inv.x, d.x, t0, corner_slack);
    int cj = rbvh_walk_start(entry.y, step_j, last_j, o.y, inv.y, d.y, t0, corner_slack);
    float next_i = rbvh_grid_boundary_t(RBVH_BETWEEN_SAMPLES, ci, step_i, o.x, inv.x);
    float next_j = rbvh_grid_boundary_t(RBVH_BETWEEN_SAMPLES, cj, step_j, o.y, inv.y);
    // The walk of march.rs: a main cell, then (when the ray passes a grid vertex too closely to
    // resolve) the extra cell across it, then the step. "While-while" as in the traversal: the
    // inner loop steps through cells while their cheap test (rbvh_cell_candidate) rejects them,
    // and the outer loop tests the triangles of the cell that passes it, so that on SIMD
    // hardware the triangle tests run once for the lanes that reached such a cell, not beside every
    // step (on the dragon close-up at Q2, 1 in 3 cells of a primary ray passes, 1 in 24 of an AO
    // ray). The step after a cell whose triangles missed opens the next inner round (`advance`).
    // A single call site of each test keeps the inlined code from being duplicated.
    // Block jumps (src/rbvh/ranges.rs): the blocks' height ranges follow the texels.
    uint block_pitch = (sz.atlas_pitch + 7u) >> 3;
    uint block_count = ((rows + 7u) >> 3) * block_pitch;
    uint checked_block = 0xFFFFFFFFu;
    float t_in = t0;
    float t_out = t0;
    RbvhCell cell = RbvhCell(ci, cj, t0, t0, 0u, 0u, 0u, 0u);
    bool is_extra = false;
    bool finished = false;
    bool stopped = false;
    bool advance = false;
    bool skirt = false;
    // Whether the last main cell walked had fewer than four samples, or there was none
    // (prev_open in march.rs, which says why, and why a block jump may leave it as it was).
    bool prev_open = true;
    bool rim = false;
    bool edge_rim = false;
    bool diagonal = false;
    bool tests = false;
    float t_hit = -1.0;
    vec3 facet = vec3(0.0);
    uint n = 0u;
    for (uint round = 0u; round < rbvh_walk_bound(last_i, last_j); ++round) {
        bool candidate = false;
        for (; n < rbvh_walk_bound(last_i, last_j); ++n) {
            if (advance) {
                if (is_extra) {
                    is_extra = false;
                    if (finished) {
                        stopped = true;
                        break;
                    }
                } else {
                    bool across_s = next_i <= next_j;
                    if (step_i != 0 && step_j != 0) {
                        precise float gap = across_s ? (next_j - next_i) * abs(d.y) : (next_i - next_j) * abs(d.x);
                        int xi = across_s ? ci : ci + step_i;
                        int xj = across_s ? cj + step_j : cj;
                        if (gap <= corner_slack && xi >= 0 && xi <= last_i && xj >= 0 && xj <= last_j) {
                            is_extra = true;
                            cell.i = xi;
                            cell.j = xj;
                            cell.t_in = t_out;
                            cell.t_out = min(max(next_i, next_j), t1);
                        }
                    }
                    if (across_s) {
                        if (step_i == 0) {
                            finished = true;
                        } else {
                            ci += step_i;
                            t_in = next_i;
                            entered = 0;
                            if (ci < 0 || ci > last_i) {
                                finished = true;
                            } else {
                                next_i = rbvh_grid_boundary_t(RBVH_BETWEEN_SAMPLES, ci, step_i, o.x, inv.x);
                            }
                        }
                    } else {
                        cj += step_j;
                        t_in = next_j;
                        entered = 1;
                        if (cj < 0 || cj > last_j) {
                            finished = true;
                        } else {
                            next_j = rbvh_grid_boundary_t(RBVH_BETWEEN_SAMPLES, cj, step_j, o.y, inv.y);
                        }
                    }
                    if (finished && !is_extra) {
                        stopped = true;
                        break;
                    }
                }
            }
            advance = true;
            if (!is_extra) {
                // Past the box's exit, the cell stepped into within rounding of it is walked too.
                if (t_in > t1) {
                    precise float past = (t_in - t1) * abs(entered == 0 ? d.x : d.y);
                    if (entered < 0 || !(past <= corner_slack)) {
                        stopped = true;
                        break;
                    }
                }
                // On entering a block: if the ray passes wholly above or below its height range
                // (with the cell test's slack), none of its cells can be hit, and the walk moves
                // straight to the block's exit cell, as it would reach it cell by cell.
                uint ax = tile_u + uint(ci);
                uint ay = tile_v + uint(cj);
                uint block = (ay >> 3) * block_pitch + (ax >> 3);
                if (RBVH_BLOCK_JUMPS && block != checked_block && block < block_count) {
                    checked_block = block;
                    int i0 = int(ax & ~7u) - int(tile_u);
                    int j0 = int(ay & ~7u) - int(tile_v);
                    int edge_i = step_i > 0 ? min(i0 + 7, last_i) : max(i0, 0);
                    int edge_j = step_j > 0 ? min(j0 + 7, last_j) : max(j0, 0);
                    float leave_i = rbvh_grid_boundary_t(RBVH_BETWEEN_SAMPLES, edge_i, step_i, o.x, inv.x);
                    float leave_j = rbvh_grid_boundary_t(RBVH_BETWEEN_SAMPLES, edge_j, step_j, o.y, inv.y);
                    uint range = RBVH_ATLAS(rbvh_texel_words(sz) + block);
                    uint code_lo = range & 0xFFFFu;
                    uint code_hi = range >> 16;
                    // Below by less than the skirt's depth, a block may hold a skirt hit (skirt_h
                    // has a margin for the square root's rounding).
                    precise float lo_s = float(code_lo) * leaf.h_scale - slack - skirt_h;
                    precise float hi_s = float(code_hi) * leaf.h_scale + slack;
                    float h_a = rbvh_height_at(o.z, d.z, t_in);
                    float h_b = rbvh_height_at(o.z, d.z, min(min(leave_i, leave_j), t1));
                    if (code_lo > code_hi || max(h_a, h_b) < lo_s || min(h_a, h_b) > hi_s) {
                        RBVH_COUNT_ADD(jumps, 1u);
                        if (t1 < min(leave_i, leave_j)) {
                            stopped = true;
                            break;
                        }
                        // Leaving through the i side (first on a tie, as the walk steps i
                        // first): the j steps before it, then the step into the edge column; or
                        // the same with i and j swapped. One loop for both sides: lavapipe runs
                        // every loop at least once, whether or not a lane needs it.
                        bool out_i = leave_i <= leave_j;
                        int minor_step = out_i ? step_j : step_i;
                        int major_step = out_i ? step_i : step_j;
                        float leave = out_i ? leave_i : leave_j;
                        int minor = out_i ? cj : ci;
                        float next = out_i ? next_j : next_i;
                        float minor_o = out_i ? o.y : o.x;
                        float minor_inv = out_i ? inv.y : inv.x;
                        float t_last = t_in;
                        for (int m = 0; m < 8 && minor_step != 0 && (out_i ? next < leave : next <= leave); ++m) {
                            t_last = next;
                            entered = out_i ? 1 : 0;
                            minor += minor_step;
                            next = rbvh_grid_boundary_t(RBVH_BETWEEN_SAMPLES, minor, minor_step, minor_o, minor_inv);
                        }
                        if (minor_step != 0 && (out_i ? next < leave : next <= leave)) {
                            cut = true;  // ended early by the device
                        }
                        int major = out_i ? ci : cj;
                        int edge = out_i ? edge_i : edge_j;
                        float major_next = out_i ? next_i : next_j;
                        if (major != edge) {
                            float into_edge = rbvh_grid_boundary_t(RBVH_BETWEEN_SAMPLES, edge - major_step, major_step,
                                                                   out_i ? o.x : o.y, out_i ? inv.x : inv.y);
                            if (into_edge >= t_last) {
                                entered = out_i ? 0 : 1;
                            }
                            t_last = max(t_last, into_edge);
                            major = edge;
                            major_next = leave;
                        }
                        ci = out_i ? major : minor;
                        cj = out_i ? minor : major;
                        next_i = out_i ? major_next : next;
                        next_j = out_i ? next : major_next;
                        t_in = t_last;
                    }
                }
            }
            t_out = min(min(next_i, next_j), t1);
            if (!is_extra) {
                cell.i = ci;
                cell.j = cj;
                cell.t_in = t_in;
                cell.t_out = t_out;
            }
            cells += 1u;
            tests = rbvh_cell_candidate(leaf, sz, fr, slack, cell);
            // A main cell with a surface entered from one with a hole (or through the tile's
            // side), or with three samples (its diagonal faces the hole), may hold a skirt hit:
            // tested in the outer loop too, so that the inner one stays small.
            rim = false;
            if (!is_extra) {
                int valid = int(!rbvh_is_hole(cell.c00)) + int(!rbvh_is_hole(cell.c10)) +
                            int(!rbvh_is_hole(cell.c01)) + int(!rbvh_is_hole(cell.c11));
                edge_rim = entered >= 0 && prev_open && valid >= 3;
                diagonal = valid == 3;
                prev_open = valid < 4;
                rim = edge_rim || diagonal;
                if (rim) {
                    // Only a ray between the cell's lowest sample less the skirt's depth and its
                    // highest sample can be caught by its skirts: the others need not leave the
                    // inner loop. A hole's code is the largest, so it takes no part in the
                    // highest. Each bound has a quantum beyond the skirt's own slack, against the
                    // rounding of the edge's height there.
                    uint code_lo = min(min(cell.c00 & 0xFFFFu, cell.c10 & 0xFFFFu), min(cell.c01 & 0xFFFFu, cell.c11 & 0xFFFFu));
                    uint code_hi = max(max(rbvh_is_hole(cell.c00) ? 0u : cell.c00 & 0xFFFFu,
                                           rbvh_is_hole(cell.c10) ? 0u : cell.c10 & 0xFFFFu),
                                       max(rbvh_is_hole(cell.c01) ? 0u : cell.c01 & 0xFFFFu,
                                           rbvh_is_hole(cell.c11) ? 0u : cell.c11 & 0xFFFFu));
                    float h_in = rbvh_height_at(o.z, d.z, cell.t_in);
                    float h_out = rbvh_height_at(o.z, d.z, cell.t_out);
                    rim = max(h_in, h_out) >= float(code_lo) * leaf.h_scale - slack - skirt_h - abs(leaf.h_scale) &&
                          min(h_in, h_out) <= float(code_hi) * leaf.h_scale + slack + abs(leaf.h_scale);
                }
            }
            if (tests || rim) {
                candidate = true;
                break;
            }
        }
        if (!candidate) {
            break;
        }
        if (rim) {
            float t_skirt = edge_rim ? rbvh_skirt(leaf, fr, slack, uu, cell, entered, entered == 0 ? step_i : step_j) : -1.0;
            if (t_skirt < 0.0 && diagonal) {
                t_skirt = rbvh_diagonal_skirt(leaf, fr, slack, uu, cell);
            }
            if (t_skirt >= 0.0) {
                skirt = true;
                t_hit = t_skirt;
                stopped = true;
                break;
            }
        }
        if (tests) {
            RBVH_COUNT_ADD(cells_tested, 1u);
            float t = rbvh_cell_triangles(leaf, fr, cell, facet, cut);
            if (t >= 0.0) {
                t_hit = t;
                stopped = true;
                break;
            }
        }
        n += 1u;
    }
    if (!stopped && n < rbvh_walk_bound(last_i, last_j)) {
        cut = true;
    }
    if (t_hit >= 0.0) {
        if (RBVH_HEIGHT_ONLY && skirt) {
            facet = rbvh_skirt_facet(leaf, fr, cell, t_hit);
        }
        if (RBVH_HEIGHT_ONLY) {
            // The leaf's frame again (read anew rather than kept through the walk): normals map
            // back by the frame's transpose.
            RbvhLeaf frame_leaf = RBVH_LEAF(li);
            precise vec3 n = (frame_leaf.axis_u * facet.x + frame_leaf.axis_v * facet.y) + frame_leaf.axis_w * facet.z;
            facet_normal = normalize(n);
        } else {
            uint k00 = leaf.atlas_base + uint(cell.j) * sz.atlas_pitch + uint(cell.i);
            normal_cell = uvec2(k00, rbvh_cell_normal_choice(fr, cell, t_hit));
        }
    }
    return t_hit;
}

// The RBVH's leaf hook for traverse.glsl: height fields marched, hybrid triangle leaves tested as
// the exact BVH's (RbvhLeaves in src/rbvh/march.rs). It keeps the nearest hit: a triangle's slot,
// or the id of a height field (or, with level of detail, a chosen node) and where its normal
// comes from. Its id and normal are read and decoded once, after the loops (rbvh_rbvh_hit), so
// that the SIMD loops do not carry them.
struct RbvhLeafHook {
    RbvhSizes sz;
    uint best_id;
    uint best_slot;
    // A height field's hit: its cell's c00 at atlas index x and rbvh_cell_normal_choice in y
    // (rbvh_normal_texel); a level-of-detail hit: its normal texel in x and 0 in y.
    uvec2 best_normal;
    vec3 best_facet;  // RBVH_HEIGHT_ONLY: the hit's normal, made by the march
};

RbvhLeafHook rbvh_leaf_hook(RbvhSizes sz) {
    return RbvhLeafHook(sz, RBVH_INVALID, RBVH_INVALID, uvec2(RBVH_HOLE_CODE, 0u), vec3(0.0));
}

uint rbvh_node_count(RbvhLeafHook leaves) {
    return leaves.sz.node_count;
}

// One round per marched or tested leaf (a tree has at most one leaf more than it has inner nodes;
// with level of detail, chosen nodes replace subtrees), plus the first.
uint rbvh_round_bound(RbvhLeafHook leaves) {
    return leaves.sz.node_count + leaves.sz.leaf_count + 1u;
}

bool rbvh_is_leaf(RbvhLeafHook leaves, uint reference) {
    return (reference & RBVH_LEAF_BIT) != 0u;
}

uint rbvh_enter(RbvhLeafHook leaves, uint child, uint count, float t_entry) {
    return child;
}

bool rbvh_test(inout RbvhLeafHook leaves, Ray ray, bool any_hit, uint reference, uint count,
               inout float t_closest, inout uint steps, inout bool cut) {
    if (count != RBVH_HEIGHTFIELD_COUNT) {
        uint first = reference & ~RBVH_LEAF_BIT;
        // The shear is made per leaf rather than kept across the loops: see RbvhFrameRay.
        return rbvh_test_triangles(rbvh_shear(ray), ray, any_hit, first,
                                   rbvh_slot_end(first, count, leaves.sz.tri_count), t_closest,
                                   leaves.best_slot, steps, cut);
    }
    RBVH_COUNT_ADD(leaves, 1u);
    uint cells = 0u;
    uvec2 normal_cell;
    vec3 facet_normal;
    float t = rbvh_march(reference & ~RBVH_LEAF_BIT, leaves.sz, ray, t_closest, cells, normal_cell, facet_normal, cut);
    steps += cells;
    RBVH_COUNT_ADD(cells, cells);
    if (t < 0.0) {
        return false;
    }
    t_closest = t;
    leaves.best_id = reference;
    leaves.best_slot = RBVH_INVALID;
    leaves.best_normal = normal_cell;
    leaves.best_facet = facet_normal;
    return true;
}

#define RBVH_TRAVERSE rbvh_traverse_rbvh
#define RBVH_LEAVES RbvhLeafHook
#include "traverse.glsl"
#undef RBVH_TRAVERSE
#undef RBVH_LEAVES

// The hit that `leaves` kept at distance t along a ray in direction `dir`: a triangle's id and
// normal, read now, or a height field's id (LEAF_BIT | leaf index; with level of detail
// LEAF_BIT | LOD_BIT | node) and its texel's normal, read now (RBVH_HEIGHT_ONLY: the facet's,
// made by the march).
Hit rbvh_rbvh_hit(RbvhLeafHook leaves, float t, vec3 dir) {
    vec3 nrm;
    uint id = leaves.best_id;
    if (leaves.best_slot != RBVH_INVALID) {
        BvhTriangle tri = RBVH_BVH_TRIANGLE(leaves.best_slot);
        id = tri.prim;
        nrm = normalize(cross(tri.v1 - tri.v0, tri.v2 - tri.v0));
    } else if (id == RBVH_INVALID) {
        return rbvh_miss();
    } else if (RBVH_HEIGHT_ONLY) {
        nrm = leaves.best_facet;
    } else {
        uvec2 b = leaves.best_normal;
        uint texel = b.y == 0u ? b.x : rbvh_normal_texel(leaves.sz, b.x, b.y, dir);
        nrm = rbvh_decode_normal(texel);
    }
    return Hit(t, nrm.x, nrm.y, nrm.z, id, 0u, 0u, 0u);
}

// The RBVH's closest (or, with `any_hit`, any) hit: traverse.glsl with the RBVH's leaves.
// `steps` = nodes visited + triangles tested + cells marched; `overflow` as in traverse.glsl.
Hit rbvh_trace_rbvh(Ray ray, bool any_hit, RbvhSizes sz, out uint steps, out bool overflow) {
    RbvhLeafHook leaves = rbvh_leaf_hook(sz);
    float t = rbvh_traverse_rbvh(ray, any_hit, leaves, steps, overflow);
    return rbvh_rbvh_hit(leaves, t, ray.dir);
}

// With RBVH_LOD, also rbvh_trace_rbvh_lod: the same traversal with lod.glsl's hook.
#ifdef RBVH_LOD
#include "lod.glsl"
#endif

#endif
