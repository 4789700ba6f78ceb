// A generation of rays as the traversal pass reads them: two RGBA32F textures laid out in rows of
// `width` (ray i at (i mod width, i div width)), plus the CPU-side bookkeeping of the ray tree.
#pragma once

#include <glm/glm.hpp>

#include <cstdint>
#include <span>
#include <vector>

#include "core/camera.h"
#include "core/geometry.h"
#include "core/memory.h"

namespace mobirt {

// The arrays of a batch: resize() writes nothing (core/memory.h, UnwrittenAllocator), whoever
// makes a batch that way writes every ray.
template <class T>
using RayArray = std::vector<T, UnwrittenAllocator<T>>;

struct RayBatch {
  uint32_t width = 0;             // texels per row of the ray textures and the pass output
  RayArray<glm::vec4> origin;     // xyz, tmin
  RayArray<glm::vec4> direction;  // xyz, tmax
  RayArray<uint32_t> pixel;       // the image pixel each ray adds to
  RayArray<glm::vec3> weight;     // the ray's weight in that pixel
  // No pixel has two rays in the batch (primary rays, in any order): their colours can be added to
  // the image on all cores. A generation of secondary rays may hold two rays of one pixel (a glass
  // hit's mirror and refracted rays), added in their order.
  bool unique_pixels = false;

  uint32_t count() const { return uint32_t(origin.size()); }
  uint32_t rows() const { return width == 0 ? 0 : (count() + width - 1) / width; }
  Ray ray(uint32_t i) const {
    return Ray{glm::vec3(origin[i]), glm::vec3(direction[i]), origin[i].w, direction[i].w};
  }
  void push(const Ray& ray, uint32_t pixel_index, const glm::vec3& ray_weight);
  void reserve(uint32_t n);  // room for n rays in every array, none written
  void resize(uint32_t n);   // n rays in every array, none written: whoever calls it writes them
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
// The same layout for the rays taken in the order `order` (a permutation of the batch's indices):
// the k-th ray of the order goes where order_in_simd_tiles puts the k-th ray. One parallel gather.
void order_in_simd_tiles(RayBatch& batch, std::span<const uint32_t> order);

// Where order_in_simd_tiles puts the k-th ray of a batch of rows `width` (a multiple of 4), for k
// inside the full pairs of rows: texel index y * width + x.
inline uint32_t simd_tile_texel(uint32_t k, uint32_t width) {
  // The k-th ray goes to lane k mod 8 of tile k / 8; tiles run along a pair of rows.
  const uint32_t tile = k / 8, lane = k % 8;
  const uint32_t x = (tile % (width / 4)) * 4 + lane % 4;
  const uint32_t y = (tile / (width / 4)) * 2 + lane / 4;
  return y * width + x;
}

// Rays of a batch in full pairs of rows, which order_in_simd_tiles lays out in tiles (0 when the
// width is not a multiple of 4).
inline uint32_t simd_tiled_rays(const RayBatch& batch) {
  const uint32_t w = batch.width;
  if (w == 0 || w % 4 != 0) return 0;
  return batch.count() / (2 * w) * (2 * w);
}

// Where order_in_simd_tiles puts the k-th ray of a batch whose first `tiled` rays are tiled
// (simd_tiled_rays): its tile texel, or k itself past them.
inline uint32_t simd_tile_place(uint32_t k, uint32_t tiled, uint32_t width) {
  return k < tiled ? simd_tile_texel(k, width) : k;
}

}  // namespace mobirt
