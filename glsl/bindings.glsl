// The descriptor bindings (set 0) of the library's own pipelines: the one table of them. Each
// *_main.glsl includes it before the headers, so that they bind where it says; build.rs reads every
// `#define RBVH_<NAME>_BINDING <n>` line of it into the constants of src/gpu/bindings.rs (`<NAME>`,
// documented by the comment after it), by which the tracer and the painter bind their buffers.
// That file's test checks each pipeline's bindings against its SPIR-V, and tests/glsl_header.rs
// that the #ifndef defaults an engine gets from bvh.glsl, rbvh.glsl and lod.glsl are these. Not
// for engines, which choose their own bindings through those headers' macros.
#ifndef RBVH_BINDINGS_GLSL
#define RBVH_BINDINGS_GLSL

// The trace shaders (trace_exact, trace_exact_instances, trace_rbvh, trace_rbvh_lod): one
// numbering for them all, each binding what it reads. Their *_bda twins read the structure's arrays through device addresses
// instead, and bind only the per-trace buffers and the cones.
#define RBVH_BVH_NODES_BINDING 0     // The tree's nodes (bvh.glsl).
#define RBVH_BVH_TRIS_BINDING 1      // The triangles of triangle leaves (bvh.glsl).
#define RBVH_HEIGHTFIELDS_BINDING 2  // The height-field leaves' records (rbvh.glsl).
#define RBVH_ATLAS_BINDING 3         // The atlas words (rbvh.glsl).
#define RBVH_RAYS_BINDING 4          // The rays (trace_io.glsl).
#define RBVH_HITS_BINDING 5          // The hits (trace_io.glsl).
#define RBVH_STATUS_BINDING 6        // The count of rays whose traversal overflowed (trace_io.glsl).
#define RBVH_COUNTERS_BINDING 7      // The per-ray counters' first eight words, or a 4-byte dummy (trace_io.glsl).
#define RBVH_LODS_BINDING 8          // The level of detail's per-node records (lod.glsl).
#define RBVH_LOD_TEXELS_BINDING 9    // The level of detail's column words (lod.glsl).
#define RBVH_CONES_BINDING 10        // The rays' cones (trace_rbvh_main.glsl, with RBVH_LOD).
#define RBVH_BVH_INSTANCES_BINDING 11  // The instances of a two-level BVH (bvh.glsl, RBVH_INSTANCES).
#define RBVH_COUNTERS_TAIL_BINDING 12  // The per-ray counters' last two words, or a 4-byte dummy (trace_io.glsl).

// The paint shader (paint_main.glsl); paint_bda binds the brushes alone.
#define RBVH_PAINT_ATLAS_BINDING 0    // The atlas words, as the trace shaders read them.
#define RBVH_PAINT_BRUSHES_BINDING 1  // The brushes of one pass.
#define RBVH_PAINT_COLOURS_BINDING 2  // The colour channel, a word per atlas texel.

#endif
