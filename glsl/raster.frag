#version 450
// The rasterized primary hit of a pixel (--primary raster): the triangle's index + 1 packed as the
// traversal pass packs a hit without shadow bits (glsl/packing.glsl's 24/8 layout, mask 0). One
// RGBA8 output, no texture: the ES 2.0 model. The GLSL ES 1.00 twin is glsl/es/raster.frag.
#extension GL_GOOGLE_include_directive : require
#include "layout.h"
#define PACKING MOBIRT_PACKING_24_8
#include "packing.glsl"

layout(location = 0) flat in float v_index;  // an exact integer below 2^24, flat: not interpolated
layout(location = 0) out vec4 o_texel;

void main() {
  o_texel = pack_trace(v_index, 0.0);
}
