// The body of trace_exact.comp and trace_exact_bda.comp (which defines RBVH_DEVICE_ADDRESS): one
// invocation per ray through the exact BVH. Bindings: nodes and triangles (0, 1; read through the
// device addresses in the push constants instead in the _bda twin), rays, hits, status, steps (2-5).
#ifndef RBVH_TRACE_EXACT_MAIN_GLSL
#define RBVH_TRACE_EXACT_MAIN_GLSL

layout(local_size_x = 64) in;

#include "trace_params.glsl"
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

#endif
