// The float precision of the intersection arithmetic (glsl/layout.h, MOBIRT_PRECISION_*): mp(x)
// is x under highp, and x rounded to fp16 under the emulated mediump (f16_round). PRECISION is a
// specialization constant (a #define on GLES), so a highp pass carries no rounding code at all.
// The CPU mirror is round_to_half() in src/core/half.h. Included by both preludes, after
// PRECISION and PRECISE.
#ifndef MOBIRT_PRECISION_GLSL
#define MOBIRT_PRECISION_GLSL

// The binade of a > 0: the integer e with 2^e <= a < 2^(e+1). log2 gives it up to rounding near
// powers of two, which the exact powers correct.
float float_binade(float a) {
  float e = floor(log2(a));
  if (exp2(e) > a) {
    e = e - 1.0;
  } else if (exp2(e + 1.0) <= a) {
    e = e + 1.0;
  }
  return e;
}

// x rounded to the nearest fp16 value (ties to even), as a float. fp16 keeps 11 significant
// bits, so its spacing at |x| is 2^(binade - 10), and never less than 2^-24 (its subnormals);
// scaling by a power of two is exact, so is the rounding of the scaled value. Arithmetic on both
// backends: GLSL ES 1.00 has no packHalf2x16, and on Vulkan a packHalf2x16/unpackHalf2x16 round
// trip, exact on its own, no longer gave the CPU's bits once lavapipe compiled it inside the
// traversal shader (the default scene at 200x120: ray 7667 hit triangle 149, which the rounding
// of every operation misses). tests/numerics_test.cpp checks it bit for bit on both backends.
float f16_round(float x) {
  float a = abs(x);
  if (a >= 65520.0) return x * 3.0e38 * 3.0e38;  // rounds beyond 65504: infinite
  if (a == 0.0) return x;
  float e = max(float_binade(a), -14.0) - 10.0;
  float r = a * exp2(-e);
  float f = floor(r);
  float d = r - f;
  if (d > 0.5 || (d == 0.5 && mod(f, 2.0) == 1.0)) f = f + 1.0;
  return sign(x) * f * exp2(e);
}

float mp(float x) {
  return PRECISION == MOBIRT_PRECISION_MEDIUM ? f16_round(x) : x;
}

vec3 mp(vec3 v) {
  return PRECISION == MOBIRT_PRECISION_MEDIUM ? vec3(f16_round(v.x), f16_round(v.y), f16_round(v.z)) : v;
}

// cross() and dot() for the intersection arithmetic. Drivers expand the built-ins into fused
// multiply-adds (Mesa's SPIR-V path builds cross() from an ffma), which round differently from the
// CPU's separate operations. Under highp that changes a result by an ulp at most, which the
// parity tests tolerate, and the built-ins are kept; under mediump the difference survives the
// rounding to fp16 and changes hits, so every product and sum is rounded on its own, in the CPU's
// (glm's) order, and PRECISE (NoContraction on Vulkan) keeps them apart.
vec3 mp_cross(vec3 a, vec3 b) {
  PRECISE vec3 plus = a.yzx * b.zxy;
  PRECISE vec3 minus = a.zxy * b.yzx;
  PRECISE vec3 r = plus - minus;
  return PRECISION == MOBIRT_PRECISION_MEDIUM ? r : cross(a, b);
}

float mp_dot(vec3 a, vec3 b) {
  PRECISE vec3 m = a * b;
  PRECISE float r = (m.x + m.y) + m.z;
  return PRECISION == MOBIRT_PRECISION_MEDIUM ? r : dot(a, b);
}

#endif  // MOBIRT_PRECISION_GLSL
