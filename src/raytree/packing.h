// The traversal pass's output texel (glsl/packing.glsl) on the CPU side: one RGBA8 texel per ray,
// read back as a little-endian uint32 (r = lowest byte).
#pragma once

#include <glm/glm.hpp>

#include <array>
#include <cstdint>
#include <string>

#include "layout.h"

namespace mobirt {

enum class Packing { Bits24_8 = MOBIRT_PACKING_24_8, Bits16_16 = MOBIRT_PACKING_16_16 };

struct TraceTexel {
  uint32_t prim_plus_one = 0;  // 0 = miss
  uint32_t mask = 0;           // shadow bits, bit i = light i visible
  bool capped = false;         // the loop cap stopped the ray: the CPU traces it

  bool hit() const { return prim_plus_one != 0; }
  int32_t prim() const { return int32_t(prim_plus_one) - 1; }
};

constexpr uint32_t max_prims(Packing p) {
  return p == Packing::Bits24_8 ? MOBIRT_MAX_PRIMS_24_8 : MOBIRT_MAX_PRIMS_16_16;
}
constexpr int max_lights(Packing p) {
  return p == Packing::Bits24_8 ? MOBIRT_MAX_LIGHTS_24_8 : MOBIRT_MAX_LIGHTS_16_16;
}

// The smallest packing that holds the scene: 24/8 unless more than 8 lights need 16/16.
// Throws Error(BadInput) naming the limit when neither holds it.
Packing choose_packing(uint64_t prims, int lights, const std::string& scene);

// The shading pass's colour (glsl/colour.glsl): 8 bits per channel in one RGBA8 texel, or 16 bits
// per channel from two passes, one writing the high bytes and one the low bytes.
enum class ColourDepth { Bits8 = 8, Bits16 = 16 };
// rgb / 255, inline and from a table of the 256 quotients (the same floats as dividing): the
// shading pass's colours are decoded once per shaded ray, where the division was three divisions
// and a call per ray.
inline constexpr auto kByteOver255 = [] {
  std::array<float, 256> t{};
  for (int i = 0; i < 256; ++i) t[size_t(i)] = float(i) / 255.0f;
  return t;
}();
inline glm::vec3 decode_colour(uint32_t texel) {
  return glm::vec3(kByteOver255[texel & 0xFFu], kByteOver255[(texel >> 8) & 0xFFu], kByteOver255[(texel >> 16) & 0xFFu]);
}
glm::vec3 decode_colour(uint32_t high, uint32_t low);        // (high x 256 + low) / 65535
// c clamped to [0, 1] and rounded to the depth's steps, as the shading pass writes it.
glm::vec3 quantize_colour(const glm::vec3& c, ColourDepth depth);

uint32_t pack_trace(Packing packing, uint32_t prim_plus_one, uint32_t mask);
uint32_t pack_capped(Packing packing);
// Inline: hit decoding calls it once per ray.
inline TraceTexel unpack_trace(Packing packing, uint32_t texel) {
  TraceTexel result;
  if (packing == Packing::Bits24_8) {
    result.prim_plus_one = texel & 0xFFFFFFu;
    result.mask = texel >> 24;
  } else {
    result.prim_plus_one = texel & 0xFFFFu;
    result.mask = texel >> 16;
  }
  // A miss never carries shadow bits: index 0 with a mask is the "capped" signal.
  if (result.prim_plus_one == 0 && result.mask != 0) {
    result.capped = true;
    result.mask = 0;
  }
  return result;
}

}  // namespace mobirt
