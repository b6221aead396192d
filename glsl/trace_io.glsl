// The per-trace buffers of every trace shader, at four bindings from RBVH_TRACE_IO_BINDING (which
// the includer defines: right after the structure's own arrays): rays, hits, the count of rays
// whose traversal overflowed, and per-ray steps (nodes + triangles + cells, for heat maps; written
// when flag bit 1 is set, else the binding may hold a 4-byte dummy).
#ifndef RBVH_TRACE_IO_GLSL
#define RBVH_TRACE_IO_GLSL

layout(std430, set = 0, binding = RBVH_TRACE_IO_BINDING) readonly buffer Rays {
    Ray rays[];
};
layout(std430, set = 0, binding = RBVH_TRACE_IO_BINDING + 1) writeonly buffer Hits {
    Hit hits[];
};
layout(std430, set = 0, binding = RBVH_TRACE_IO_BINDING + 2) buffer Status {
    uint overflow_rays;
};
layout(std430, set = 0, binding = RBVH_TRACE_IO_BINDING + 3) writeonly buffer Steps {
    uint steps_out[];
};

// Stores ray `i`'s result: its hit, its steps when `flags` bit 1 asks for them, and whether its
// traversal overflowed.
void rbvh_trace_store(uint i, uint flags, Hit h, uint steps, bool overflow) {
    hits[i] = h;
    if ((flags & 2u) != 0u) {
        steps_out[i] = steps;
    }
    if (overflow) {
        atomicAdd(overflow_rays, 1u);
    }
}

#endif
