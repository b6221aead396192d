// The body of trace_rbvh.comp and trace_rbvh_lod.comp (which defines RBVH_LOD): one invocation per
// ray. Bindings: the RBVH's four arrays, rays, hits, status, steps; with RBVH_LOD also the LOD
// records and columns (see lod.glsl) and the per-ray cones.
#ifndef RBVH_TRACE_RBVH_MAIN_GLSL
#define RBVH_TRACE_RBVH_MAIN_GLSL

layout(local_size_x = 64) in;

#include "rbvh.glsl"

layout(std430, set = 0, binding = 4) readonly buffer Rays {
    Ray rays[];
};
layout(std430, set = 0, binding = 5) writeonly buffer Hits {
    Hit hits[];
};
// Rays whose traversal overflowed the stack or the visit bound.
layout(std430, set = 0, binding = 6) buffer Status {
    uint overflow_rays;
};
// Per-ray steps (nodes + triangles + cells) for heat maps, when flag bit 1 is set.
layout(std430, set = 0, binding = 7) writeonly buffer Steps {
    uint steps_out[];
};
#ifdef RBVH_LOD
// Per-ray cones (width, spread): see RayCone in src/lod/cone.rs.
layout(std430, set = 0, binding = 10) readonly buffer Cones {
    vec2 cones[];
};
#endif

// Shared with trace_exact.comp and src/gpu/tracer.rs (TraceParams).
layout(push_constant) uniform Params {
    uint ray_offset;  // first ray of this dispatch (dispatches are split at maxComputeWorkGroupCount)
    uint ray_count;   // rays in the whole batch
    uint flags;       // bit 0: any hit; bit 1: write per-ray steps
    uint node_count;
    uint tri_count;
    uint leaf_count;
    uint atlas_pitch;
    uint atlas_len;
    uint lod_node_count;  // LOD records (0 without LOD)
    uint lod_texel_len;   // LOD column words
} pc;

void main() {
    uint i = pc.ray_offset + gl_GlobalInvocationID.x;
    if (i >= pc.ray_count) {
        return;
    }
    RbvhSizes sz = RbvhSizes(pc.node_count, pc.tri_count, pc.leaf_count, pc.atlas_pitch, pc.atlas_len);
    uint steps;
    bool overflow;
#ifdef RBVH_LOD
    RbvhLodSizes lsz = RbvhLodSizes(pc.lod_node_count, pc.lod_texel_len);
    Hit h = rbvh_trace_rbvh_lod(rays[i], cones[i], (pc.flags & 1u) != 0u, sz, lsz, steps, overflow);
#else
    Hit h = rbvh_trace_rbvh(rays[i], (pc.flags & 1u) != 0u, sz, steps, overflow);
#endif
    hits[i] = h;
    if ((pc.flags & 2u) != 0u) {
        steps_out[i] = steps;
    }
    if (overflow) {
        atomicAdd(overflow_rays, 1u);
    }
}

#endif
