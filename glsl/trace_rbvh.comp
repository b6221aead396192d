// Traces a batch of rays through an RBVH: closest hit, or any hit (occlusion).
#version 460
#extension GL_GOOGLE_include_directive : require

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
} pc;

void main() {
    uint i = pc.ray_offset + gl_GlobalInvocationID.x;
    if (i >= pc.ray_count) {
        return;
    }
    RbvhSizes sz = RbvhSizes(pc.node_count, pc.tri_count, pc.leaf_count, pc.atlas_pitch, pc.atlas_len);
    uint steps;
    bool overflow;
    Hit h = rbvh_trace_rbvh(rays[i], (pc.flags & 1u) != 0u, sz, steps, overflow);
    hits[i] = h;
    if ((pc.flags & 2u) != 0u) {
        steps_out[i] = steps;
    }
    if (overflow) {
        atomicAdd(overflow_rays, 1u);
    }
}
