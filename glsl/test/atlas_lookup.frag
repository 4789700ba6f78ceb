// Test shader: the atlas lookup of atlas.glsl for one (uv, texture) per ray, read from an RGBA32F
// ray-layout texture (xy = uv, z = texture index), written as linear RGB in RGBA8. Tests compare it
// with sample_atlas() on the CPU.
#version 450
#extension GL_GOOGLE_include_directive : require
#include "prelude_vk.glsl"
#include "atlas.glsl"

SAMPLER(MOBIRT_BIND_HIT_TEXCOORD, u_lookup);

void main() {
  vec4 lookup = RAY_TEXEL(u_lookup);
  OUTPUT(vec4(sample_atlas(lookup.z, lookup.xy), 1.0));
}
