// Traces a batch of rays through the exact BVH: closest hit, or any hit (occlusion).
#version 460
#extension GL_GOOGLE_include_directive : require

#include "trace_exact_main.glsl"
