// Traces a batch of rays through a two-level RBVH (a top level over instances of meshes, each an
// RBVH in its own space): closest hit, or any hit (occlusion).
#version 460
#extension GL_GOOGLE_include_directive : require

#define RBVH_INSTANCES 1
#include "trace_rbvh_main.glsl"
