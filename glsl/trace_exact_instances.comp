// Traces a batch of rays through a two-level exact BVH (a top level over instances of meshes):
// closest hit, or any hit (occlusion).
#version 460
#extension GL_GOOGLE_include_directive : require

#define RBVH_INSTANCES 1
#include "trace_exact_main.glsl"
