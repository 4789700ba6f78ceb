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

// Reorders a batch made in a spatially coherent order (secondary rays follow their parents) so
// that every 8 rays made one after the other fill one 4x2 tile of the ray textures: llvmpipe runs
// a fragment shader on the 4x2 fragments of half a 4x4 block in lock step, and a group of similar
// rays finishes its traversal loops together. Rows of tiles need 2 rows of the batch; the rays
// after the last full pair of rows keep their order. Needs width to be a multiple of 4 (else the
// batch is left as it is).
void order_in_simd_tiles(RayBatch& batch);

}  // namespace mobirt
