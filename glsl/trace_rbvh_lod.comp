// Traces a batch of rays through an RBVH with level of detail: each ray's cone picks the coarse
// representations of inner nodes it sees at less than a column per footprint (src/lod).
#version 460
#extension GL_GOOGLE_include_directive : require

#define RBVH_LOD 1
#include "trace_rbvh_main.glsl"
