#include "raytree/rays.h"

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
  const size_t n = size_t(width) * size_t(height);
  batch.origin.reserve(n);
  batch.direction.reserve(n);
  batch.pixel.reserve(n);
  batch.weight.reserve(n);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      batch.push(camera_ray(camera, width, height, float(x) + 0.5f, float(y) + 0.5f),
                 uint32_t(y) * uint32_t(width) + uint32_t(x), glm::vec3(1.0f));
    }
  }
  return batch;
}

}  // namespace mobirt
