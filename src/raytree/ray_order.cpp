#include "raytree/ray_order.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <utility>

#include "core/parallel.h"

namespace mobirt {

namespace {

// The 7 bits of v spread to every third bit (bit i to bit 3i).
uint32_t spread_bits_3(uint32_t v) {
  v &= 0x7f;
  v = (v | (v << 16)) & 0x030000ff;
  v = (v | (v << 8)) & 0x0300f00f;
  v = (v | (v << 4)) & 0x030c30c3;
  v = (v | (v << 2)) & 0x09249249;
  return v;
}

constexpr uint32_t kMortonSteps = 128;  // per axis: 7 bits, 21 in all, 3 more for the octant
constexpr int kMortonBits = 21;
constexpr int kKeyBits = kMortonBits + 3;
constexpr int kRadixBits = 12;          // 2 passes cover the 24-bit key (a 16 KiB histogram)

}  // namespace

namespace {

// The quantisation of origins: (p - lo) * scale in [0, kMortonSteps) per axis.
struct MortonFrame {
  glm::vec3 lo;
  glm::vec3 scale;
  explicit MortonFrame(const Aabb& bounds)
      : lo(bounds.lo), scale(float(kMortonSteps) / glm::max(bounds.hi - bounds.lo, glm::vec3(1e-30f))) {}
  uint32_t key(const glm::vec3& origin, const glm::vec3& direction) const {
    uint32_t morton = 0;
    for (int a = 0; a < 3; ++a) {
      const float f = (origin[a] - lo[a]) * scale[a];
      // NaN and out-of-box origins clamp to the box (an order, never an error).
      const uint32_t q = f >= 0.0f ? uint32_t(std::min(f, float(kMortonSteps - 1))) : 0u;
      morton |= spread_bits_3(q) << a;
    }
    const uint32_t octant = (direction.x < 0.0f ? 1u : 0u) | (direction.y < 0.0f ? 2u : 0u) |
                            (direction.z < 0.0f ? 4u : 0u);
    return octant << kMortonBits | morton;
  }
};

}  // namespace

namespace {

uint32_t octant(const glm::vec4& d) {
  return (d.x < 0.0f ? 1u : 0u) | (d.y < 0.0f ? 2u : 0u) | (d.z < 0.0f ? 4u : 0u);
}

}  // namespace

float octant_change_rate(const RayBatch& batch) {
  const uint32_t n = batch.count();
  if (n < 2) return 0.0f;
  uint32_t changes = 0;
  for (uint32_t i = 1; i < n; ++i) changes += octant(batch.direction[i]) != octant(batch.direction[i - 1]) ? 1u : 0u;
  return float(changes) / float(n - 1);
}

uint32_t ray_order_key(const glm::vec3& origin, const glm::vec3& direction, const Aabb& bounds) {
  return MortonFrame(bounds).key(origin, direction);
}

std::vector<uint32_t> coherent_ray_order(const RayBatch& batch, const Aabb& bounds) {
  const uint32_t n = batch.count();
  std::vector<uint32_t> keys(n), order(n), keys_tmp(n), order_tmp(n);
  const MortonFrame frame(bounds);
  parallel_for(n, 0, [&](uint32_t i) {
    keys[i] = frame.key(glm::vec3(batch.origin[i]), glm::vec3(batch.direction[i]));
    order[i] = i;
  }, 4096);
  // LSD radix sort, stable: a comparison sort of 100K keys costs several times more.
  constexpr uint32_t kBuckets = 1u << kRadixBits;
  for (int shift = 0; shift < kKeyBits; shift += kRadixBits) {
    std::array<uint32_t, kBuckets> start{};
    for (uint32_t i = 0; i < n; ++i) ++start[(keys[i] >> shift) & (kBuckets - 1)];
    uint32_t sum = 0;
    for (uint32_t& s : start) sum += std::exchange(s, sum);
    for (uint32_t i = 0; i < n; ++i) {
      const uint32_t slot = start[(keys[i] >> shift) & (kBuckets - 1)]++;
      keys_tmp[slot] = keys[i];
      order_tmp[slot] = order[i];
    }
    keys.swap(keys_tmp);
    order.swap(order_tmp);
  }
  return order;
}

void order_for_traversal(RayBatch& batch, const Aabb& bounds, float sort_above) {
  const uint32_t n = batch.count();
  if (n < 2) return;
  if (octant_change_rate(batch) < sort_above) {
    order_in_simd_tiles(batch);
    return;
  }
  // One gather: the k-th ray of the sorted order straight to its texel of the tiled layout.
  order_in_simd_tiles(batch, coherent_ray_order(batch, bounds));
}

}  // namespace mobirt
