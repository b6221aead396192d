// The push constants of every trace shader (src/gpu/tracer.rs, TraceParams; tests/layout.rs
// checks that both sides agree). With RBVH_DEVICE_ADDRESS it also names, for the headers, where
// each structure array lives: `addresses` in binding order — nodes, triangles, height fields,
// atlas, LOD records, LOD columns, instances (the exact BVH uses the first two, the two-level exact
// BVH those and the last, the two-level RBVH the first four and the last).
#ifndef RBVH_TRACE_PARAMS_GLSL
#define RBVH_TRACE_PARAMS_GLSL

layout(push_constant) uniform Params {
    uint ray_offset;  // first ray of this dispatch (dispatches are split at maxComputeWorkGroupCount)
    uint ray_count;   // rays in the whole batch
    uint flags;       // bit 0: any hit
    uint node_count;
    uint tri_count;
    uint heightfield_count;
    uint atlas_pitch;
    uint atlas_len;
    uint atlas_wide_len;  // atlas texels before the bands of packed heights (atlas.glsl)
    uint atlas_end12;     // atlas texels before the end of the 12-bit band
    uint atlas_end10;     // atlas texels before the end of the 10-bit band
    uint lod_node_count;  // LOD records (0 without LOD)
    uint lod_texel_len;   // LOD column words
    uint instance_count;  // instances of a two-level BVH (0 without)
    uvec2 addresses[7];   // device addresses (low, high word); zero where arrays are bound
} pc;

#ifdef RBVH_DEVICE_ADDRESS
#define RBVH_BVH_NODES_ADDRESS pc.addresses[0]
#define RBVH_BVH_TRIS_ADDRESS pc.addresses[1]
#define RBVH_HEIGHTFIELDS_ADDRESS pc.addresses[2]
#define RBVH_ATLAS_ADDRESS pc.addresses[3]
#define RBVH_LODS_ADDRESS pc.addresses[4]
#define RBVH_LOD_TEXELS_ADDRESS pc.addresses[5]
#define RBVH_BVH_INSTANCES_ADDRESS pc.addresses[6]
#endif

#endif
