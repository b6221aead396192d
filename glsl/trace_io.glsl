// The per-trace buffers of every trace shader, at the bindings bindings.glsl gives them (which the
// includer includes): rays, hits, the count of rays whose traversal overflowed, and per-ray
// counters (RbvhCounters, 10 words a ray; written only by the counting specialization, RBVH_COUNT,
// else the binding may hold a 4-byte dummy).
#ifndef RBVH_TRACE_IO_GLSL
#define RBVH_TRACE_IO_GLSL

layout(std430, set = 0, binding = RBVH_RAYS_BINDING) readonly buffer Rays {
    Ray rays[];
};
layout(std430, set = 0, binding = RBVH_HITS_BINDING) writeonly buffer Hits {
    Hit hits[];
};
layout(std430, set = 0, binding = RBVH_STATUS_BINDING) buffer Status {
    uint overflow_rays;
};
layout(std430, set = 0, binding = RBVH_COUNTERS_BINDING) writeonly buffer Counters {
    RbvhCounters counters_out[];
};

// Stores ray `i`'s result: its hit, its counters when counting, and whether its traversal
// overflowed.
void rbvh_trace_store(uint i, Hit h, bool overflow) {
    hits[i] = h;
    if (RBVH_COUNT) {
        counters_out[i] = rbvh_counters;
    }
    if (overflow) {
        atomicAdd(overflow_rays, 1u);
    }
}

#endif
