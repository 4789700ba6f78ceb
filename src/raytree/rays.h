// A generation of rays as the traversal pass reads them: two RGBA32F textures laid out in rows of
// `width` (ray i at (i mod width, i div width)), plus the CPU-side bookkeeping of the ray tree.
#pragma once

#include <glm/glm.hpp>

#include <cstdint>
#include <vector>

#include "core/camera.h"
#include "core/geometry.h"

namespace mobirt {

struct RayBatch {
  uint32_t width = 0;                 // texels per row of the ray textures and the pass output
  std::vector<glm::vec4> origin;      // xyz, tmin
  std::vector<glm::vec4> direction;   // xyz, tmax
  std::vector<uint32_t> pixel;        // the image pixel each ray adds to
  std::vector<glm::vec3> weight;      // the ray's weight in that pixel

  uint32_t count() const { return uint32_t(origin.size()); }
  uint32_t rows() const { return width == 0 ? 0 : (count() + width - 1) / width; }
  Ray ray(uint32_t i) const {
    return Ray{glm::vec3(origin[i]), glm::vec3(direction[i]), origin[i].w, direction[i].w};
  }
  void push(const Ray& ray, uint32_t pixel_index, const glm::vec3& ray_weight);
  void clear();
};

// One ray through the centre of every pixel, in pixel order (width = image width).
RayBatch primary_rays(const Camera& camera, int width, int height);

}  // namespace mobirt
