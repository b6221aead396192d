// Traces a batch of rays through the exact BVH: closest hit, or any hit (occlusion).
#version 460
#extension GL_GOOGLE_include_directive : require

layout(local_size_x = 64) in;

#include "bvh.glsl"

layout(std430, set = 0, binding = 2) readonly buffer Rays {
    Ray rays[];
};
layout(std430, set = 0, binding = 3) writeonly buffer Hits {
    Hit hits[];
};
// Rays whose traversal overflowed the stack or the visit bound.
layout(std430, set = 0, binding = 4) buffer Status {
    uint overflow_rays;
};
// Optional per-ray step counts for heat maps (binding may hold a 4-byte dummy when unused).
layout(std430, set = 0, binding = 5) writeonly buffer Steps {
    uint steps_out[];
};

// Shared with trace_rbvh.comp and src/gpu/tracer.rs (TraceParams); the last five are unused here.
layout(push_constant) uniform Params {
    uint ray_offset;  // first ray of this dispatch (dispatches are split at maxComputeWorkGroupCount)
    uint ray_count;   // rays in the whole batch
    uint flags;       // bit 0: any hit; bit 1: write per-ray steps
    uint node_count;
    uint tri_count;
    uint leaf_count;
    uint atlas_pitch;
    uint atlas_len;
    uint lod_node_count;
    uint lod_texel_len;
} pc;

void main() {
    uint i = pc.ray_offset + gl_GlobalInvocationID.x;
    if (i >= pc.ray_count) {
        return;
    }
    uint steps;
    bool overflow;
    Hit h = rbvh_trace_bvh(rays[i], (pc.flags & 1u) != 0u, pc.node_count, steps, overflow);
    hits[i] = h;
    if ((pc.flags & 2u) != 0u) {
        steps_out[i] = steps;
    }
    if (overflow) {
        atomicAdd(overflow_rays, 1u);
    }
}
