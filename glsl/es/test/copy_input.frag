#version 100
// Test shader (GLES): copies this ray's texel of texture 1 to the output, scaled by PARAM(0).
#include "prelude_es.glsl"

SAMPLER(1, u_input);

void main() {
  OUTPUT(RAY_TEXEL(u_input) * PARAM(0));
}
