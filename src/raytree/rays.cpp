#include "raytree/rays.h"

#include "core/parallel.h"

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
  batch.origin.resize(n);  // unwritten (RayArray): every ray is written below, on all cores
  batch.direction.resize(n);
  batch.pixel.resize(n);
  batch.weight.resize(n);
  const CameraBasis basis(camera, width, height);
  parallel_for(uint32_t(height), 0, [&](uint32_t y) {
    for (uint32_t x = 0, i = y * uint32_t(width); x < uint32_t(width); ++x, ++i) {
      const Ray ray = basis.ray(float(x) + 0.5f, float(y) + 0.5f);
      batch.origin[i] = glm::vec4(ray.origin, ray.tmin);
      batch.direction[i] = glm::vec4(ray.direction, ray.tmax);
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
