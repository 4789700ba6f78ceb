#include "raytree/rays.h"

#include "core/error.h"
#include "core/parallel.h"

namespace mobirt {

void RayBatch::push(const Ray& ray, uint32_t pixel_index, const glm::vec3& ray_weight) {
  origin.emplace_back(ray.origin, ray.tmin);
  direction.emplace_back(ray.direction, ray.tmax);
  pixel.push_back(pixel_index);
  weight.push_back(ray_weight);
  unique_pixels = false;  // the pushed ray's pixel may have one already
}

void RayBatch::clear() {
  origin.clear();
  direction.clear();
  pixel.clear();
  weight.clear();
  unique_pixels = false;
}

RayBatch primary_rays(const Camera& camera, int width, int height) {
  RayBatch batch;
  batch.width = uint32_t(width);
  batch.unique_pixels = true;  // ray i is pixel i
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

namespace {

// The tiled layout of the batch's rays taken in order `order` (all of them in batch order when
// empty), written by one parallel gather into arrays not written before (a serial copy of the
// whole batch, then a serial scatter over it, cost about 0.4 ms a secondary generation).
void gather_in_simd_tiles(RayBatch& batch, std::span<const uint32_t> order) {
  const uint32_t n = batch.count();
  const uint32_t tiled = simd_tiled_rays(batch);
  RayBatch out;
  out.width = batch.width;
  out.unique_pixels = batch.unique_pixels;  // a permutation of the rays
  out.origin.resize(n);
  out.direction.resize(n);
  out.pixel.resize(n);
  out.weight.resize(n);
  parallel_for(n, 0, [&](uint32_t k) {
    const uint32_t from = order.empty() ? k : order[k];
    const uint32_t to = k < tiled ? simd_tile_texel(k, batch.width) : k;
    out.origin[to] = batch.origin[from];
    out.direction[to] = batch.direction[from];
    out.pixel[to] = batch.pixel[from];
    out.weight[to] = batch.weight[from];
  }, 4096);
  batch = std::move(out);
}

}  // namespace

void order_in_simd_tiles(RayBatch& batch) {
  if (simd_tiled_rays(batch) == 0) return;
  gather_in_simd_tiles(batch, {});
}

void order_in_simd_tiles(RayBatch& batch, std::span<const uint32_t> order) {
  if (order.size() != batch.count()) throw Error(ErrorKind::Internal, "order_in_simd_tiles: the order is not the batch's size");
  gather_in_simd_tiles(batch, order);
}

}  // namespace mobirt
