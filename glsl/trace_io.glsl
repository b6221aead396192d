// The per-trace buffers of every trace shader, at the bindings bindings.glsl gives them (which the
// includer includes): rays, hits, the count of rays whose traversal overflowed, and per-ray
// counters (RayCounters, src/probe.rs; counted in place by the counting specialization, RBVH_COUNT,
// else each counters binding may hold a 4-byte dummy). Included before the structure's headers, so
// that the traversals count in the ray's records (RBVH_COUNTER, see common.glsl).
//
// The ray, the hit and both counter records are 32 bytes each, likely so that one offset serves
// them all through the walk: the counters, ten words, are split into a record of eight and a
// record of the two-level structures' two (six words reserved), each in its own binding. Counted
// in registers instead, they took the counting pipelines 16 VGPRs above the timed ones on RADV
// navi21; in one 40-byte record, 8 (docs/speed.md, "Counters out of the registers", where the
// split and counting cells_tested after the cell's test reach the timed ones' 56 together).
#ifndef RBVH_TRACE_IO_GLSL
#define RBVH_TRACE_IO_GLSL

// Before common.glsl, which otherwise counts in a private variable.
#ifdef RBVH_COMMON_GLSL
#error "include trace_io.glsl before common.glsl and the structure's headers, so that they count in its records"
#endif
#define RBVH_COUNTER(field) rbvh_counters_of_##field.field
#define rbvh_counters_of_nodes counters_head[rbvh_ray_slot]
#define rbvh_counters_of_leaves counters_head[rbvh_ray_slot]
#define rbvh_counters_of_walks counters_head[rbvh_ray_slot]
#define rbvh_counters_of_cells counters_head[rbvh_ray_slot]
#define rbvh_counters_of_cells_tested counters_head[rbvh_ray_slot]
#define rbvh_counters_of_jumps counters_head[rbvh_ray_slot]
#define rbvh_counters_of_triangle_leaves counters_head[rbvh_ray_slot]
#define rbvh_counters_of_triangles counters_head[rbvh_ray_slot]
#define rbvh_counters_of_instances counters_tail[rbvh_ray_slot]
#define rbvh_counters_of_top_nodes counters_tail[rbvh_ray_slot]
#include "common.glsl"

layout(std430, set = 0, binding = RBVH_RAYS_BINDING) readonly buffer Rays {
    Ray rays[];
};
layout(std430, set = 0, binding = RBVH_HITS_BINDING) writeonly buffer Hits {
    Hit hits[];
};
layout(std430, set = 0, binding = RBVH_STATUS_BINDING) buffer Status {
    uint overflow_rays;
};
// RayCounters' first eight words.
struct RbvhCountersHead {
    uint nodes;
    uint leaves;
    uint walks;
    uint cells;
    uint cells_tested;
    uint jumps;
    uint triangle_leaves;
    uint triangles;
};
// RayCounters' last two words, and six that keep the record 32 bytes.
struct RbvhCountersTail {
    uint instances;
    uint top_nodes;
    uint reserved[6];
};
layout(std430, set = 0, binding = RBVH_COUNTERS_BINDING) buffer CountersHead {
    RbvhCountersHead counters_head[];
};
layout(std430, set = 0, binding = RBVH_COUNTERS_TAIL_BINDING) buffer CountersTail {
    RbvhCountersTail counters_tail[];
};
// The ray being traced, whose records RBVH_COUNTER names. Set by rbvh_trace_load.
uint rbvh_ray_slot;

// Ray `i`, which this invocation traces (and, when counting, counts in its records).
Ray rbvh_trace_load(uint i) {
    rbvh_ray_slot = i;
    return rays[i];
}

// Stores ray `i`'s result: its hit, and whether its traversal overflowed.
void rbvh_trace_store(uint i, Hit h, bool overflow) {
    hits[i] = h;
    if (overflow) {
        atomicAdd(overflow_rays, 1u);
    }
}

#endif
