// The body of trace_exact.comp and trace_exact_bda.comp (which defines RBVH_DEVICE_ADDRESS), and
// of trace_exact_instances.comp and its _bda twin (which define RBVH_INSTANCES: the two-level
// exact BVH): one invocation per ray through the exact BVH. Bindings (bindings.glsl): nodes and
// triangles, with RBVH_INSTANCES the instances (read through the device addresses in the push
// constants instead in the _bda twins), rays, hits, status, counters.
#ifndef RBVH_TRACE_EXACT_MAIN_GLSL
#define RBVH_TRACE_EXACT_MAIN_GLSL

#include "bindings.glsl"

layout(local_size_x = 64) in;

// Specialised true (src/gpu/tracer.rs, COUNT_CONSTANT_ID) for the pipeline that counts each ray's
// work; the timed pipeline keeps it false, and the compiler drops the counting.
layout(constant_id = 0) const bool rbvh_count = false;
#define RBVH_COUNT rbvh_count

#include "trace_params.glsl"
#include "trace_io.glsl"
#include "bvh.glsl"

void main() {
    uint i = pc.ray_offset + gl_GlobalInvocationID.x;
    if (i >= pc.ray_count) {
        return;
    }
    uint steps;
    bool overflow;
#ifdef RBVH_INSTANCES
    Hit h = rbvh_trace_instances(rbvh_trace_load(i), (pc.flags & 1u) != 0u,
                                 BvhInstanceSizes(pc.node_count, pc.tri_count, pc.instance_count), steps, overflow);
#else
    Hit h = rbvh_trace_bvh(rbvh_trace_load(i), (pc.flags & 1u) != 0u, BvhSizes(pc.node_count, pc.tri_count), steps, overflow);
#endif
    rbvh_trace_store(i, h, overflow);
}

#endif
