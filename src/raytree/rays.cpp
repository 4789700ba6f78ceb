#include "raytree/rays.h"

#include "core/parallel.h"

#include <algorithm>
#include <cmath>

namespace mobirt {

void RayBatch::push(const Ray& ray, uint32_t pixel_index, const glm::vec3& ray_weight) {
  origin.emplace_back(ray.origin, ray.tmin);
  direction.emplace_back(ray.direction, ray.tmax);
  pixel.push_back(pixel_index);
  weight.push_back(ray_weight);
}

void RayBatch::clear() {
  origin.clear();
  direction.clear();
  pixel.clear();
  weight.clear();
}

RayBatch primary_rays(const Camera& camera, int width, int height) {
  RayBatch batch;
  batch.width = uint32_t(width);
  const uint32_t n = uint32_t(width) * uint32_t(height);
  batch.origin.resize(n);
  batch.direction.resize(n);
  batch.pixel.resize(n);
  batch.weight.resize(n);
  // CameraBasis::ray's operations in its order, inline: the same floats for every ray (tested
  // against camera_ray), without a call and a returned Ray per pixel, which had made this stage
  // 26 ns of CPU per ray. The x term depends on the column only.
  const CameraBasis basis(camera, width, height);
  std::vector<float> sx(size_t(std::max(width, 0)));
  for (int x = 0; x < width; ++x) sx[size_t(x)] = (2.0f * (float(x) + 0.5f) / basis.width - 1.0f) * basis.tan_half * basis.aspect;
  const glm::vec4 origin(basis.eye, basis.znear);
  parallel_for(uint32_t(height), 0, [&](uint32_t y) {
    const float sy = (1.0f - 2.0f * (float(y) + 0.5f) / basis.height) * basis.tan_half;
    const glm::vec3 row = basis.forward;
    const glm::vec3 up = sy * basis.up;
    const uint32_t first = y * uint32_t(width);
    for (uint32_t x = 0; x < uint32_t(width); ++x) {
      const uint32_t i = first + x;
      // glm::normalize(forward + sx * right + sy * up): v * (1 / sqrt(dot(v, v))).
      const glm::vec3 v = row + sx[x] * basis.right + up;
      const float inv_length = 1.0f / std::sqrt(v.x * v.x + v.y * v.y + v.z * v.z);
      batch.origin[i] = origin;
      batch.direction[i] = glm::vec4(v * inv_length, Ray{}.tmax);
      batch.pixel[i] = i;
      batch.weight[i] = glm::vec3(1.0f);
    }
  }, 16);
  return batch;
}

void order_in_simd_tiles(RayBatch& batch) {
  const uint32_t tiled = simd_tiled_rays(batch);
  if (tiled == 0) return;
  RayBatch out;
  out.width = batch.width;
  out.origin = batch.origin;
  out.direction = batch.direction;
  out.pixel = batch.pixel;
  out.weight = batch.weight;
  for (uint32_t k = 0; k < tiled; ++k) {
    const uint32_t i = simd_tile_texel(k, batch.width);
    out.origin[i] = batch.origin[k];
    out.direction[i] = batch.direction[k];
    out.pixel[i] = batch.pixel[k];
    out.weight[i] = batch.weight[k];
  }
  batch = std::move(out);
}

}  // namespace mobirt
