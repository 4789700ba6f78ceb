// main() of the numerics test shader, shared by glsl/test/numerics.frag (Vulkan) and
// glsl/es/test/numerics.frag (GLES): the numeric primitives the traversal pass relies on, one case
// per ray, against the CPU's answers. PARAM(0).x picks the function:
//   0: f16_round of the four input values; 1: Wachter and Binder's offset_normal_ulp of p (input
//   xyz) along n (operand xyz); each texel channel is 1 where the result equals the CPU's
//   (expected texture) bit for bit, else 0.
//   2: pack_trace(input.x, input.y), the traversal pass's output texel (PACKING).
//   3 (Vulkan: NUMERICS_DATA_INDEX): data_index(input.x), the int a buffer is indexed with, its four
//   bytes in the output's (under WIDE_INDICES as the pass is specialised).
//   4: light_buffer_part_contains(input.x, input.y, input.z), 1 in the first channel where true.
#include "offset.glsl"
#include "packing.glsl"
#include "light_buffer.glsl"

SAMPLER(1, u_input);
SAMPLER(2, u_operand);
SAMPLER(3, u_expected);

void main() {
  vec4 x = RAY_TEXEL(u_input);
  float function = PARAM(0).x;
  if (function == 2.0) {
    OUTPUT(pack_trace(x.x, x.y));
    return;
  }
  if (function == 4.0) {
    OUTPUT(vec4(light_buffer_part_contains(x.x, x.y, x.z) ? 1.0 : 0.0, 0.0, 0.0, 0.0));
    return;
  }
#ifdef NUMERICS_DATA_INDEX
  if (function == 3.0) {
    int i = data_index(x.x);
    OUTPUT(vec4(float(i & 255), float((i >> 8) & 255), float((i >> 16) & 255), float((i >> 24) & 255)) / 255.0);
    return;
  }
#endif
  vec4 r = vec4(f16_round(x.x), f16_round(x.y), f16_round(x.z), f16_round(x.w));
  if (function == 1.0) {
    vec4 n = RAY_TEXEL(u_operand);
    r = vec4(offset_normal_ulp(x.x, n.x), offset_normal_ulp(x.y, n.y), offset_normal_ulp(x.z, n.z), 0.0);
  }
  OUTPUT(vec4(equal(r, RAY_TEXEL(u_expected))));
}
