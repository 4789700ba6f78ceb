#version 100
// Test shader (GLES): samples nine textures, one more than OpenGL ES 2.0 guarantees. Must be refused.
#include "prelude_es.glsl"

SAMPLER(1, t1);
SAMPLER(2, t2);
SAMPLER(3, t3);
SAMPLER(4, t4);
SAMPLER(5, t5);
SAMPLER(6, t6);
SAMPLER(7, t7);
SAMPLER(8, t8);
SAMPLER(9, t9);

void main() {
  OUTPUT(RAY_TEXEL(t1) + RAY_TEXEL(t2) + RAY_TEXEL(t3) + RAY_TEXEL(t4) + RAY_TEXEL(t5) +
         RAY_TEXEL(t6) + RAY_TEXEL(t7) + RAY_TEXEL(t8) + RAY_TEXEL(t9));
}
