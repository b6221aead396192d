// As trace_rbvh_instances.comp, reading the RBVH's arrays and the instances through buffer device
// addresses: for arrays over maxStorageBufferRange (src/gpu/addressing.rs).
#version 460
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_buffer_reference_uvec2 : require

#define RBVH_DEVICE_ADDRESS 1
#define RBVH_INSTANCES 1
#include "trace_rbvh_main.glsl"
