#include "raytree/packing.h"

#include "core/error.h"

namespace mobirt {

Packing choose_packing(uint64_t prims, int lights, const std::string& scene) {
  if (lights > MOBIRT_MAX_LIGHTS) {
    throw input_error(scene, std::to_string(lights) + " lights, but a pass packs at most " +
                                 std::to_string(MOBIRT_MAX_LIGHTS) +
                                 " shadow bits: remove lights or pass at most 16 with --light");
  }
  if (lights <= MOBIRT_MAX_LIGHTS_24_8) {
    if (prims > MOBIRT_MAX_PRIMS_24_8) {
      throw input_error(scene, std::to_string(prims) + " triangles, over the 24-bit hit index limit of " +
                                   std::to_string(MOBIRT_MAX_PRIMS_24_8) + ": simplify the scene");
    }
    return Packing::Bits24_8;
  }
  if (prims > MOBIRT_MAX_PRIMS_16_16) {
    throw input_error(scene, std::to_string(lights) + " lights need the 16/16 packing, which holds at most " +
                                 std::to_string(MOBIRT_MAX_PRIMS_16_16) + " triangles, but the scene has " +
                                 std::to_string(prims) + ": use at most 8 lights or fewer triangles");
  }
  return Packing::Bits16_16;
}

glm::vec3 decode_colour(uint32_t high, uint32_t low) {
  glm::vec3 c;
  for (int i = 0; i < 3; ++i) {
    c[i] = float(((high >> (8 * i)) & 0xFFu) * 256u + ((low >> (8 * i)) & 0xFFu)) / 65535.0f;
  }
  return c;
}

glm::vec3 quantize_colour(const glm::vec3& c, ColourDepth depth) {
  const float steps = depth == ColourDepth::Bits16 ? 65535.0f : 255.0f;
  return glm::floor(glm::clamp(c, 0.0f, 1.0f) * steps + 0.5f) / steps;
}

uint32_t pack_trace(Packing packing, uint32_t prim_plus_one, uint32_t mask) {
  if (packing == Packing::Bits24_8) return (prim_plus_one & 0xFFFFFFu) | ((mask & 0xFFu) << 24);
  return (prim_plus_one & 0xFFFFu) | ((mask & 0xFFFFu) << 16);
}

uint32_t pack_capped(Packing packing) {
  return packing == Packing::Bits24_8 ? 0xFF000000u : 0xFFFF0000u;
}

}  // namespace mobirt
