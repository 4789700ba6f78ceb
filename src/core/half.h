// Rounding to IEEE 754 binary16 (fp16), as the emulated mediump of the traversal pass does
// (glsl/layout.h, MOBIRT_PRECISION_MEDIUM): the value a packHalf2x16 / unpackHalf2x16 round trip
// gives, returned as a float.
#pragma once

#include <glm/glm.hpp>

#include <bit>
#include <cmath>
#include <cstdint>

namespace mobirt {

// x rounded to the nearest fp16 value, ties to even; beyond the largest fp16 (65504) it becomes
// infinite, below 2^-14 it keeps fp16's subnormal spacing of 2^-24. NaN and infinities pass.
inline float round_to_half(float x) {
  const uint32_t bits = std::bit_cast<uint32_t>(x);
  const uint32_t sign = bits & 0x80000000u;
  const uint32_t magnitude = bits & 0x7FFFFFFFu;
  if (magnitude >= 0x7F800000u) return x;
  if (magnitude < 0x38800000u) {
    // Below 2^-14: multiples of 2^-24. Scaling by a power of two is exact; nearbyint rounds to
    // nearest even in the default rounding mode.
    return std::nearbyint(x * 16777216.0f) * (1.0f / 16777216.0f);
  }
  // Normal fp16: keep 10 of the 23 fraction bits, rounding to nearest even (a carry moves into the
  // exponent, as it should).
  uint32_t rounded = magnitude + 0x0FFFu + ((magnitude >> 13) & 1u);
  rounded &= ~0x1FFFu;
  if (rounded > 0x477FE000u) rounded = 0x7F800000u;  // over 65504: infinite
  return std::bit_cast<float>(sign | rounded);
}

inline glm::vec3 round_to_half(const glm::vec3& v) {
  return {round_to_half(v.x), round_to_half(v.y), round_to_half(v.z)};
}

}  // namespace mobirt
