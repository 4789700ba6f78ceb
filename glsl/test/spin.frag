// Test shader: loops that only their caps stop. The work depends on the input texel, so the
// compiler cannot fold it. Output: the iterations of both loops together (r = low byte .. b =
// high byte), and a = 255 when the loops did not end by their own data-dependent exit (the test's
// inputs never meet it), so a test can check that the caps were honoured.
//
// Mesa's llvmpipe/lavapipe (gallivm) stops every loop of a shader invocation once the loops
// together have iterated 65535 times (LP_MAX_TGSI_LOOP_ITERATIONS, one budget shared by all
// loops, counted per SIMD group of fragments): the second loop shows that the budget is shared,
// and diverging columns show that a ray's budget is spent by its neighbours too.
#version 450
#extension GL_GOOGLE_include_directive : require
#include "prelude_vk.glsl"

// Test-only specialization constants: the second loop's cap, and whether odd columns skip the
// first loop (so that neighbouring rays diverge).
layout(constant_id = 16) const int SECOND_LOOP_STEPS = 0;
layout(constant_id = 17) const bool ODD_COLUMNS_SKIP_FIRST_LOOP = false;

SAMPLER(1, u_input);

vec4 churn(vec4 state) { return fract(state * 1.618034 + vec4(0.1, 0.2, 0.3, 0.4)); }

void main() {
  vec4 state = RAY_TEXEL(u_input);
  const int first_cap = ODD_COLUMNS_SKIP_FIRST_LOOP && (int(gl_FragCoord.x) & 1) == 1 ? 0 : MAX_STEPS;
  int steps = 0;
  for (;;) {
    if (steps >= first_cap) break;
    state = churn(state);
    if (state.w < -1.0) break;  // never true for inputs in [0, 1]
    ++steps;
  }
  int second = 0;
  for (;;) {
    if (second >= SECOND_LOOP_STEPS) break;
    state = churn(state);
    if (state.w < -1.0) break;
    ++second;
  }
  const int total = steps + second;
  const bool natural_exit = state.w < -1.0;
  const vec4 packed = vec4(float(total & 255), float((total >> 8) & 255), float((total >> 16) & 255),
                           natural_exit ? 0.0 : 255.0);
  OUTPUT(packed / 255.0);
}
