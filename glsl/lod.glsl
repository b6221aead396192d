// Coarse representations of inner nodes for level-of-detail traversal: the GLSL twin of
// src/lod/march.rs, step for step, on the packed data of src/lod/layout.rs, and its leaf hook for
// the one traversal (traverse.glsl). It builds on rbvh.glsl (whose march helpers and RBVH hook
// it uses, and which it includes): a shader that traces with level of detail includes this file
// (trace_rbvh_main.glsl does for trace_rbvh_lod.comp), one that does not includes rbvh.glsl alone.
//
// The includer chooses where the buffers live by defining, before the #include, what rbvh.glsl
// takes and:
//   RBVH_LODS_BINDING       binding of the per-node records
//   RBVH_LOD_TEXELS_BINDING binding of the column words
// or, with RBVH_DEVICE_ADDRESS (see bvh.glsl), RBVH_LODS_ADDRESS and RBVH_LOD_TEXELS_ADDRESS.
#ifndef RBVH_LOD_GLSL
#define RBVH_LOD_GLSL

#include "rbvh.glsl"

#ifndef RBVH_LODS_BINDING
#define RBVH_LODS_BINDING 8
#endif
#ifndef RBVH_LOD_TEXELS_BINDING
#define RBVH_LOD_TEXELS_BINDING 9
#endif

// Must equal LOD_BIT (tests/glsl_header.rs checks, on the device).
const uint RBVH_LOD_BIT = 0x40000000u;

// 48 bytes: see GpuLod.
struct RbvhLod {
    vec3 origin;
    float texel_size;   // +inf: the node has no coarse representation
    uint axis;
    uint res_u;
    uint res_v;
    uint base;
    float h_scale;
    float inv_texel;
    uint pad0;
    uint pad1;
};

// Columns: two words each, top and bottom; each bits 0-15 height code (top 0xFFFF = empty), 16-31
// normal.
#ifdef RBVH_DEVICE_ADDRESS
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer RbvhLodsRef {
    RbvhLod lods[];
};
layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer RbvhLodTexelsRef {
    uint texels[];
};
#define RBVH_LOD_RECORD(i) RbvhLodsRef(RBVH_LODS_ADDRESS).lods[i]
#define RBVH_LOD_TEXEL(i) RbvhLodTexelsRef(RBVH_LOD_TEXELS_ADDRESS).texels[i]
#else
layout(std430, set = RBVH_BVH_SET, binding = RBVH_LODS_BINDING) readonly buffer RbvhLods {
    RbvhLod rbvh_lods[];
};
layout(std430, set = RBVH_BVH_SET, binding = RBVH_LOD_TEXELS_BINDING) readonly buffer RbvhLodTexels {
    uint rbvh_lod_texels[];
};
#define RBVH_LOD_RECORD(i) rbvh_lods[i]
#define RBVH_LOD_TEXEL(i) rbvh_lod_texels[i]
#endif

// Sizes of the two arrays.
struct RbvhLodSizes {
    uint node_count;
    uint texel_len;
};

// The selection rule of src/lod/cone.rs (`selects`): cone = (width, spread). A width of +inf (no
// coarse representation) or 0 (nodes not annotated by Lod::annotated_nodes) never selects.
bool rbvh_lod_selects(float texel_size, vec2 cone, float t_entry) {
    precise float footprint = cone.x + cone.y * t_entry;
    return !isinf(texel_size) && texel_size > 0.0 && texel_size <= footprint;
}

// Marches the columns of node `node`'s record over [tmin, t_closest); returns t (< 0 on a miss)
// and, on a hit, the word whose normal it reports (decode with rbvh_decode_normal). `columns`
// counts the columns visited. `cut` is set when the device ended the walk early (see
// traverse.glsl).
float rbvh_lod_march(uint node, RbvhLodSizes lsz, Ray ray, float t_closest, inout uint columns,
                     out uint normal_texel, inout bool cut) {
    normal_texel = RBVH_HOLE_CODE;
    // One return, as in rbvh_march (rbvh.glsl), which says why.
    float t_hit = -1.0;
    RbvhLod lod = RbvhLod(vec3(0.0), RBVH_INF, 0u, 0u, 0u, 0u, 0.0, 0.0, 0u, 0u);
    if (node < lsz.node_count) {
        lod = RBVH_LOD_RECORD(node);
    }
    uint cells = lod.res_u * lod.res_v;
    bool usable = node < lsz.node_count && !isinf(lod.texel_size) && !isnan(lod.texel_size) && lod.res_u != 0u &&
                  lod.res_v != 0u && lod.axis <= 2u && cells / max(lod.res_v, 1u) == lod.res_u &&
                  cells <= (0xFFFFFFFFu - lod.base) / 2u && lod.base + 2u * cells <= lsz.texel_len;
    // 1. Grid space.
    uint w = min(lod.axis, 2u);
    uint u = (w + 1u) % 3u;
    uint v = (w + 2u) % 3u;
    precise vec3 go = vec3((ray.origin[u] - lod.origin[u]) * lod.inv_texel,
                           (ray.origin[v] - lod.origin[v]) * lod.inv_texel,
                           ray.origin[w] - lod.origin[w]);
    precise vec3 gd = vec3(ray.dir[u] * lod.inv_texel, ray.dir[v] * lod.inv_texel, ray.dir[w]);
    vec3 inv = rbvh_safe_inverse(gd);
    // 2. Clip.
    precise float h_top = float(RBVH_MAX_CODE) * lod.h_scale;
    precise float slack = RBVH_MARCH_SLACK * (abs(go.z) + h_top) + lod.h_scale;
    vec3 bmin = vec3(0.0, 0.0, -slack);
    precise vec3 bmax = vec3(float(lod.res_u), float(lod.res_v), h_top + slack);
    float t0 = 0.0;
    bool box = rbvh_intersect_box(bmin, bmax, go, inv, ray.tmin, t_closest, t0);
    if (usable && box) {
        RBVH_COUNT_ADD(walks, 1u);
        precise vec3 e0 = (bmin - go) * inv;
        precise vec3 e1 = (bmax - go) * inv;
        vec3 e = max(e0, e1);
        float t1 = min(min(min(e.x, e.y), e.z), t_closest);
        // 3. Walk.
        precise vec3 entry = go + gd * t0;
        int last_i = int(lod.res_u) - 1;
        int last_j = int(lod.res_v) - 1;
        int step_i = rbvh_grid_step(gd.x);
        int step_j = rbvh_grid_step(gd.y);
        RbvhGridWalk walk = rbvh_grid_walk(RBVH_COLUMNS, rbvh_grid_cell(RBVH_COLUMNS, entry.x, last_i),
                                        rbvh_grid_cell(RBVH_COLUMNS, entry.y, last_j), step_i, step_j, go.xy, inv.xy,
                                        t0);
        uint limit = lod.res_u + lod.res_v;
        // A walk crosses at most res_u + res_v - 1 columns, so every normal ending is a `break`.
        bool stopped = false;
        for (uint n = 0u; n < limit; ++n) {
            if (walk.t_in > t1) {
                stopped = true;
                break;
            }
            columns += 1u;
            float t_out = min(min(walk.next_i, walk.next_j), t1);
            // 4. Column.
            uint index = lod.base + 2u * (uint(walk.cj) * lod.res_u + uint(walk.ci));
            bool inside = index + 1u < lsz.texel_len;
            uint top_word = inside ? RBVH_LOD_TEXEL(index) : RBVH_HOLE_CODE;
            uint bottom_word = inside ? RBVH_LOD_TEXEL(index + 1u) : RBVH_HOLE_CODE;
            if (!rbvh_is_hole(top_word)) {
                precise float top = float(top_word & 0xFFFFu) * lod.h_scale;
                precise float bottom = float(bottom_word & 0xFFFFu) * lod.h_scale;
                float za = rbvh_height_at(go.z, gd.z, walk.t_in);
                float zb = rbvh_height_at(go.z, gd.z, t_out);
                if (max(za, zb) >= bottom && min(za, zb) <= top) {
                    precise float t_top = (top - go.z) * inv.z;
                    precise float t_bottom = (bottom - go.z) * inv.z;
                    precise float to_top = top - za;
                    precise float to_bottom = za - bottom;
                    float t = za > top ? t_top : (za < bottom ? t_bottom : walk.t_in);
                    bool use_top = za > top || (za >= bottom && to_top <= to_bottom);
                    // The first column met ends the walk; a hit at t_closest is not nearer than
                    // the one found (the stretch ends there), so [tmin, t_closest) holds.
                    precise float t_met = min(max(t, walk.t_in), t_out);
                    bool nearer = t_met < t_closest;
                    normal_texel = nearer ? (use_top ? top_word : bottom_word) : RBVH_HOLE_CODE;
                    t_hit = nearer ? t_met : -1.0;
                    stopped = true;
                    break;
                }
            }
            if (rbvh_grid_advance(walk, RBVH_COLUMNS, step_i, step_j, last_i, last_j, go.xy, inv.xy) < 0) {
                stopped = true;
                break;
            }
        }
        if (!stopped) {
            cut = true;
        }
    }
    return t_hit;
}

// The level-of-detail leaf hook for traverse.glsl (RbvhLodLeafHook in src/lod/trace.rs): an inner child
// whose coarse representation the ray's cone selects at the child's box entry is pushed as
// LOD_BIT | node and its columns are marched when it comes up, instead of descending; such hits
// report id = LEAF_BIT | LOD_BIT | node. The RBVH's own leaves go to its hook.
// The ray's cone, (width, spread) (RayCone in src/lod/cone.rs), is kept in rbvh_stack's
// RBVH_STACK_CONE and read where an inner child is entered, not held in registers through the
// marches.
struct RbvhLodLeafHook {
    RbvhLeafHook rbvh;
    RbvhLodSizes lsz;
};

uint rbvh_node_count(RbvhLodLeafHook leaves) {
    return rbvh_node_count(leaves.rbvh);
}

uint rbvh_round_bound(RbvhLodLeafHook leaves) {
    return rbvh_round_bound(leaves.rbvh);
}

bool rbvh_is_leaf(RbvhLodLeafHook leaves, uint reference) {
    return (reference & (RBVH_LEAF_BIT | RBVH_LOD_BIT)) != 0u;
}

// The LOD trace's tree carries an inner child's column width in its `count`
// (Lod::annotated_nodes), so choosing needs no further read.
uint rbvh_enter(RbvhLodLeafHook leaves, uint child, uint count, float t_entry) {
    vec2 cone = uintBitsToFloat(rbvh_stack[RBVH_STACK_CONE]);
    return rbvh_lod_selects(uintBitsToFloat(count), cone, t_entry) ? child | RBVH_LOD_BIT : child;
}

bool rbvh_test(inout RbvhLodLeafHook leaves, Ray ray, bool any_hit, uint reference, uint count,
               inout float t_closest, inout uint steps, inout bool cut) {
    bool hit = false;
    // A leaf's reference may have bit 30 set (a triangle slot from 2^30 on); only an inner
    // node's carries RBVH_LOD_BIT alone.
    if ((reference & (RBVH_LEAF_BIT | RBVH_LOD_BIT)) != RBVH_LOD_BIT) {
        hit = rbvh_test(leaves.rbvh, ray, any_hit, reference, count, t_closest, steps, cut);
    } else {
        RBVH_COUNT_ADD(leaves, 1u);
        uint columns = 0u;
        uint normal_texel;
        float t = rbvh_lod_march(reference & ~RBVH_LOD_BIT, leaves.lsz, ray, t_closest, columns, normal_texel, cut);
        hit = rbvh_keep_march(leaves.rbvh, t, columns, RBVH_LEAF_BIT | reference, uvec2(normal_texel, 0u), t_closest,
                              steps);
    }
    return hit;
}

#define RBVH_TRAVERSE rbvh_traverse_rbvh_lod
#define RBVH_LEAVES RbvhLodLeafHook
#define RBVH_KEEPS_RAY
#include "traverse.glsl"
#undef RBVH_TRAVERSE
#undef RBVH_LEAVES
#undef RBVH_KEEPS_RAY

// The RBVH traced with level of detail for a ray whose cone is `cone`: as rbvh_trace_rbvh, but
// with the hook above.
Hit rbvh_trace_rbvh_lod(Ray ray, vec2 cone, bool any_hit, RbvhSizes sz, RbvhLodSizes lsz,
                        out uint steps, out bool overflow) {
    RbvhLodLeafHook leaves = RbvhLodLeafHook(rbvh_leaf_hook(sz), lsz);
    rbvh_stack[RBVH_STACK_CONE] = floatBitsToUint(cone);
    float t = rbvh_traverse_rbvh_lod(ray, any_hit, leaves, steps, overflow);
    return rbvh_rbvh_hit(leaves.rbvh, t, rbvh_kept_ray());
}

#endif
