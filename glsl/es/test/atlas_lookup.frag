#version 100
// Test shader (GLES): atlas.glsl's lookup for one (uv, texture) per ray (see glsl/test/).
#include "prelude_es.glsl"
#include "atlas.glsl"

SAMPLER(MOBIRT_BIND_HIT_TEXCOORD, u_lookup);

void main() {
  vec4 lookup = RAY_TEXEL(u_lookup);
  OUTPUT(vec4(sample_atlas(lookup.z, lookup.xy), 1.0));
}
