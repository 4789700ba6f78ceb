// Test shader: five uniform texel buffers and four 2D images, nine sampled textures in all (one
// more than OpenGL ES 2.0 guarantees), so texel buffers count against the 8. Must be refused.
#version 450
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_samplerless_texture_functions : require
#define MOBIRT_DATA_TEXEL_BUFFERS
#include "prelude_vk.glsl"

DATA_SAMPLER(1, b1);
DATA_SAMPLER(2, b2);
DATA_SAMPLER(3, b3);
DATA_SAMPLER(4, b4);
DATA_SAMPLER(5, b5);
SAMPLER(6, t6);
SAMPLER(7, t7);
SAMPLER(8, t8);
SAMPLER(9, t9);

// RAY_TEXEL reads buffers under MOBIRT_DATA_TEXEL_BUFFERS: the images are fetched here by hand.
#define IMAGE_TEXEL(tex) texelFetch(tex, ivec2(gl_FragCoord.xy), 0)

void main() {
  float i = floor(gl_FragCoord.x);
  OUTPUT(DATA_TEXEL(b1, i) + DATA_TEXEL(b2, i) + DATA_TEXEL(b3, i) + DATA_TEXEL(b4, i) + DATA_TEXEL(b5, i) +
         IMAGE_TEXEL(t6) + IMAGE_TEXEL(t7) + IMAGE_TEXEL(t8) + IMAGE_TEXEL(t9));
}
