#include "raytree/rays.h"

#include "core/error.h"
#include "core/parallel.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace mobirt {

void RayBatch::push(const Ray& ray, uint32_t pixel_index, const glm::vec3& ray_weight) {
  origin.emplace_back(ray.origin, ray.tmin);
  direction.emplace_back(ray.direction, ray.tmax);
  pixel.push_back(pixel_index);
  weight.push_back(ray_weight);
  unique_pixels = false;  // the pushed ray's pixel may have one already
}

void RayBatch::reserve(uint32_t n) {
  origin.reserve(n);
  direction.reserve(n);
  pixel.reserve(n);
  weight.reserve(n);
}

void RayBatch::resize(uint32_t n) {
  origin.resize(n);
  direction.resize(n);
  pixel.resize(n);
  weight.resize(n);
}

void RayBatch::clear() {
  origin.clear();
  direction.clear();
  pixel.clear();
  weight.clear();
  unique_pixels = false;
}

namespace {

#if defined(__SSE2__)
// Rays x0 .. x0 + 3 of row y of primary_rays(), written at i .. i + 3: CameraBasis::ray()'s
// operations, in its order, four pixels to a register (IEEE multiplies, adds, divisions and square
// roots give the same floats in the lanes as one at a time; the build targets baseline x86-64,
// which has no FMA for either to be contracted into: a build for a CPU with FMA could contract
// the two differently, and RayTree.PrimaryRaysAreCameraRaysBitForBit would say so), the
// directions transposed into the batch's vec4s. The scalar loop cost about 10 ns of CPU a ray,
// 2 % of a toaster frame's CPU and 6 % of the wood doll's (perf), most of it its two divisions and
// square root one ray at a time.
void primary_rays_x4(const CameraBasis& basis, float sy, uint32_t x0, uint32_t i, const __m128& eye,
                     RayBatch& batch) {
  const __m128 x = _mm_add_ps(_mm_cvtepi32_ps(_mm_add_epi32(_mm_set1_epi32(int32_t(x0)), _mm_setr_epi32(0, 1, 2, 3))),
                              _mm_set1_ps(0.5f));
  // sx = (2 x / width - 1) tan_half aspect, evaluated left to right as there.
  __m128 sx = _mm_div_ps(_mm_mul_ps(_mm_set1_ps(2.0f), x), _mm_set1_ps(basis.width));
  sx = _mm_mul_ps(_mm_mul_ps(_mm_sub_ps(sx, _mm_set1_ps(1.0f)), _mm_set1_ps(basis.tan_half)),
                  _mm_set1_ps(basis.aspect));
  // forward + sx right + sy up, component by component: (forward + sx right) + sy up.
  const auto axis = [&](int a) {
    return _mm_add_ps(_mm_add_ps(_mm_set1_ps(basis.forward[a]), _mm_mul_ps(sx, _mm_set1_ps(basis.right[a]))),
                      _mm_set1_ps(sy * basis.up[a]));
  };
  __m128 dx = axis(0), dy = axis(1), dz = axis(2);
  // glm::normalize: v * (1 / sqrt(dot(v, v))), dot = (x x + y y) + z z.
  const __m128 dot = _mm_add_ps(_mm_add_ps(_mm_mul_ps(dx, dx), _mm_mul_ps(dy, dy)), _mm_mul_ps(dz, dz));
  const __m128 inv = _mm_div_ps(_mm_set1_ps(1.0f), _mm_sqrt_ps(dot));
  dx = _mm_mul_ps(dx, inv);
  dy = _mm_mul_ps(dy, inv);
  dz = _mm_mul_ps(dz, inv);
  __m128 tmax = _mm_set1_ps(Ray{}.tmax);
  _MM_TRANSPOSE4_PS(dx, dy, dz, tmax);
  float* direction = reinterpret_cast<float*>(batch.direction.data() + i);
  _mm_storeu_ps(direction, dx);
  _mm_storeu_ps(direction + 4, dy);
  _mm_storeu_ps(direction + 8, dz);
  _mm_storeu_ps(direction + 12, tmax);
  float* origin = reinterpret_cast<float*>(batch.origin.data() + i);
  for (int k = 0; k < 4; ++k) _mm_storeu_ps(origin + 4 * k, eye);
  _mm_storeu_si128(reinterpret_cast<__m128i*>(&batch.pixel[i]),
                   _mm_add_epi32(_mm_set1_epi32(int32_t(i)), _mm_setr_epi32(0, 1, 2, 3)));
  float* weight = reinterpret_cast<float*>(batch.weight.data() + i);  // four vec3 of 1: twelve floats
  const __m128 one = _mm_set1_ps(1.0f);
  _mm_storeu_ps(weight, one);
  _mm_storeu_ps(weight + 4, one);
  _mm_storeu_ps(weight + 8, one);
}
#endif

}  // namespace

RayBatch primary_rays(const Camera& camera, int width, int height) {
  RayBatch batch;
  batch.width = uint32_t(width);
  batch.unique_pixels = true;  // ray i is pixel i
  const uint32_t n = uint32_t(width) * uint32_t(height);
  batch.resize(n);  // unwritten (RayArray): every ray is written below, on all cores
  const CameraBasis basis(camera, width, height);
  static_assert(sizeof(glm::vec4) == 16 && sizeof(glm::vec3) == 12, "primary_rays_x4 stores packed vectors");
  parallel_for(uint32_t(height), 0, [&](uint32_t y) {
    uint32_t x = 0, i = y * uint32_t(width);
#if defined(__SSE2__)
    const __m128 eye = _mm_setr_ps(basis.eye.x, basis.eye.y, basis.eye.z, basis.znear);  // ray() copies them
    const float sy = basis.row_offset(float(y) + 0.5f);  // once per row
    for (; x + 4 <= uint32_t(width); x += 4, i += 4) primary_rays_x4(basis, sy, x, i, eye, batch);
#endif
    for (; x < uint32_t(width); ++x, ++i) {
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
  out.resize(n);
  parallel_for(n, 0, [&](uint32_t k) {
    const uint32_t from = order.empty() ? k : order[k];
    const uint32_t to = simd_tile_place(k, tiled, batch.width);
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
