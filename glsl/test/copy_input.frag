// Test shader: copies this ray's texel of texture 1 to the output, scaled by PARAM(0).
// Exercises uniforms, textures, the ray layout and the RGBA8 packing.
#version 450
#extension GL_GOOGLE_include_directive : require
#include "prelude_vk.glsl"

SAMPLER(1, u_input);

void main() {
  OUTPUT(RAY_TEXEL(u_input) * PARAM(0));
}
