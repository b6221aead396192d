// Traces a batch of rays through an RBVH: closest hit, or any hit (occlusion).
#version 460
#extension GL_GOOGLE_include_directive : require

#include "trace_rbvh_main.glsl"
