// The body of paint.comp and paint_bda.comp (which defines RBVH_DEVICE_ADDRESS). Paints brush
// dabs into an RBVH's colour channel: one dispatch per candidate height-field leaf, one
// invocation per texel of its tile. A surface texel whose world-space sample point lies
// within a brush's radius gets that brush's colour composited over its own (src/rgba.rs
// `over`, in integer arithmetic; opaque brushes replace, the last one wins). The rule, and the
// arithmetic order, are those of src/surface/paint.rs (the CPU reference) and
// GpuHeightfield::sample_point in src/rbvh/layout.rs; `precise` forbids fused multiply-adds, so
// that both decide every texel identically. Painting in world space, not per tile, is what lets
// a stroke cross leaf borders without a seam.
#ifndef RBVH_PAINT_MAIN_GLSL
#define RBVH_PAINT_MAIN_GLSL

#include "bindings.glsl"

layout(local_size_x = 64) in;

// 32 bytes: see src/surface/paint.rs (Brush).
struct PaintBrush {
    vec3 centre;
    float radius;
    uint colour;    // packed RGBA8 (src/rgba.rs)
    uint pad0;
    uint pad1;
    uint pad2;
};
layout(std430, set = 0, binding = RBVH_PAINT_BRUSHES_BINDING) readonly buffer Brushes {
    PaintBrush brushes[];
};

// 112 bytes: see src/gpu/painter.rs (PaintParams). The leaf's frame comes with each dispatch:
// step_u and step_v, the world vectors of one texel step at a constant height over the tile's
// plane, and the unit height axis (SampleGrid in src/rbvh/layout.rs), computed once on the host
// for the GPU and the CPU reference alike.
layout(push_constant) uniform PaintParams {
    vec3 origin;
    uint atlas_base;
    vec3 step_u;
    uint res_u;
    vec3 step_v;
    uint res_v;
    vec3 axis_w;
    float h_scale;
    uint texel_offset;  // first texel of this dispatch (dispatches are split at maxComputeWorkGroupCount)
    uint brush_count;   // at most MAX_BRUSHES_PER_PASS (src/gpu/painter.rs), so the loop is bounded
    uint atlas_pitch;
    uint atlas_len;
    uint atlas_wide_len;  // texels before the bands of packed heights (atlas.glsl)
    uint atlas_end12;     // texels before the end of the 12-bit band
    uint atlas_end10;     // texels before the end of the 10-bit band
    uint reserved;        // zero: keeps the addresses 8-byte aligned
    uvec2 atlas_address;    // device addresses (low, high word) of the atlas and the colours,
    uvec2 colours_address;  // read with RBVH_DEVICE_ADDRESS; zero where they are bound
} pc;

// The atlas (as the trace shaders read it: atlas.glsl) and the colour channel:
// bound, or reached through their device addresses (src/gpu/addressing.rs).
#ifdef RBVH_DEVICE_ADDRESS
layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer PaintAtlasRef {
    uint texels[];
};
layout(buffer_reference, std430, buffer_reference_align = 4) buffer PaintColoursRef {
    uint colours[];
};
#define PAINT_ATLAS(i) PaintAtlasRef(pc.atlas_address).texels[i]
#define PAINT_COLOUR(i) PaintColoursRef(pc.colours_address).colours[i]
#else
layout(std430, set = 0, binding = RBVH_PAINT_ATLAS_BINDING) readonly buffer Atlas {
    uint atlas[];
};
layout(std430, set = 0, binding = RBVH_PAINT_COLOURS_BINDING) buffer Colours {
    uint colours[];
};
#define PAINT_ATLAS(i) atlas[i]
#define PAINT_COLOUR(i) colours[i]
#endif
#define RBVH_ATLAS_WORD(i) PAINT_ATLAS(i)
#include "atlas.glsl"

// rgba::over of src/rgba.rs, byte for byte.
uint paint_over(uint src, uint dst) {
    uint a = src >> 24;
    uint out_word = 0u;
    for (uint k = 0u; k < 3u; ++k) {
        uint s = (src >> (8u * k)) & 0xFFu;
        uint d = (dst >> (8u * k)) & 0xFFu;
        out_word |= ((s * a + d * (255u - a) + 127u) / 255u) << (8u * k);
    }
    uint alpha = (255u * a + (dst >> 24) * (255u - a) + 127u) / 255u;
    return out_word | (alpha << 24);
}

void main() {
    uint k = pc.texel_offset + gl_GlobalInvocationID.x;
    if (k >= pc.res_u * pc.res_v) {
        return;
    }
    uint i = k % pc.res_u;
    uint j = k / pc.res_u;
    uint index = pc.atlas_base + j * pc.atlas_pitch + i;
    if (index >= pc.atlas_len) {
        return;
    }
    uint code = rbvh_atlas_code(index, pc.atlas_len, pc.atlas_wide_len, pc.atlas_end12, pc.atlas_end10);
    if (code == 0xFFFFu) {
        return;
    }
    float s = float(i) + 0.5;
    float t = float(j) + 0.5;
    precise float h = float(code) * pc.h_scale;
    precise vec3 p = pc.origin + pc.step_u * s + pc.step_v * t + pc.axis_w * h;
    bool painted = false;
    uint colour = PAINT_COLOUR(index);
    for (uint b = 0u; b < pc.brush_count; ++b) {
        PaintBrush brush = brushes[b];
        precise vec3 d = p - brush.centre;
        precise float d2 = d.x * d.x + d.y * d.y + d.z * d.z;
        precise float r2 = brush.radius * brush.radius;
        if (d2 <= r2) {
            painted = true;
            colour = paint_over(brush.colour, colour);
        }
    }
    if (painted) {
        PAINT_COLOUR(index) = colour;
    }
}

#endif
