// Paints brush dabs into an RBVH's colour channel (see paint_main.glsl).
#version 460
#extension GL_GOOGLE_include_directive : require

#include "paint_main.glsl"
