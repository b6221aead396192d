// The body of trace_rbvh.comp, trace_rbvh_lod.comp (which defines RBVH_LOD) and
// trace_rbvh_instances.comp (which defines RBVH_INSTANCES: the two-level RBVH), and of their
// *_bda twins (which define RBVH_DEVICE_ADDRESS): one invocation per ray. Bindings (bindings.glsl):
// the RBVH's four arrays, rays, hits, status, counters; with RBVH_LOD also the LOD records and
// columns (see lod.glsl) and the per-ray cones; with RBVH_INSTANCES the instances. The *_bda twins
// read the structure's arrays (the RBVH's four, the LOD's two, the instances) through the device
// addresses in the push constants instead.
#ifndef RBVH_TRACE_RBVH_MAIN_GLSL
#define RBVH_TRACE_RBVH_MAIN_GLSL

#include "bindings.glsl"

layout(local_size_x = 64) in;

// Specialised true (src/gpu/tracer.rs, COUNT_CONSTANT_ID) for the pipeline that counts each ray's
// work; the timed pipeline keeps it false, and the compiler drops the counting.
layout(constant_id = 0) const bool rbvh_count = false;
#define RBVH_COUNT rbvh_count
// Specialised by the tracer (src/gpu/tracer.rs, JUMPS_CONSTANT_ID; off on CPU implementations).
layout(constant_id = 1) const bool rbvh_block_jumps = true;
#define RBVH_BLOCK_JUMPS rbvh_block_jumps
// Specialised true (src/gpu/tracer.rs, HEIGHT_ONLY_CONSTANT_ID) for an RBVH built with
// TexelFormat::Height; never for the LOD trace, which needs the texels' normals.
layout(constant_id = 2) const bool rbvh_height_only = false;
#define RBVH_HEIGHT_ONLY rbvh_height_only

#include "trace_params.glsl"
#include "trace_io.glsl"
#include "rbvh.glsl"
#ifdef RBVH_LOD
#include "lod.glsl"
#endif

#ifdef RBVH_LOD
// Per-ray cones (width, spread): see RayCone in src/lod/cone.rs.
layout(std430, set = 0, binding = RBVH_CONES_BINDING) readonly buffer Cones {
    vec2 cones[];
};
#endif

void main() {
    uint i = pc.ray_offset + gl_GlobalInvocationID.x;
    if (i >= pc.ray_count) {
        return;
    }
    RbvhSizes sz = RbvhSizes(pc.node_count, pc.tri_count, pc.heightfield_count, pc.atlas_pitch, pc.atlas_len,
                             pc.atlas_wide_len, pc.atlas_end12, pc.atlas_end10);
    uint steps;
    bool overflow;
#ifdef RBVH_LOD
    RbvhLodSizes lsz = RbvhLodSizes(pc.lod_node_count, pc.lod_texel_len);
    Hit h = rbvh_trace_rbvh_lod(rbvh_trace_load(i), cones[i], (pc.flags & 1u) != 0u, sz, lsz, steps, overflow);
#elif defined(RBVH_INSTANCES)
    Hit h = rbvh_trace_rbvh_instances(rbvh_trace_load(i), (pc.flags & 1u) != 0u, sz, pc.instance_count, steps, overflow);
#else
    Hit h = rbvh_trace_rbvh(rbvh_trace_load(i), (pc.flags & 1u) != 0u, sz, steps, overflow);
#endif
    rbvh_trace_store(i, h, overflow);
}

#endif
