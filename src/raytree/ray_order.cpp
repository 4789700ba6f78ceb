#include "raytree/ray_order.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <memory>
#include <utility>

#include "core/parallel.h"

namespace mobirt {

namespace {

// The 7 bits of v spread to every third bit (bit i to bit 3i).
constexpr uint32_t spread_bits_3(uint32_t v) {
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
static_assert(kKeyBits == 2 * kRadixBits, "coherent_ray_order sorts the key in two digits");
constexpr uint32_t kBuckets = 1u << kRadixBits;

// spread_bits_3 of every quantised coordinate: three loads a key instead of 12 shifts and masks
// (the key was a quarter of the sort's time).
constexpr std::array<uint32_t, kMortonSteps> kSpread = [] {
  std::array<uint32_t, kMortonSteps> t{};
  for (uint32_t v = 0; v < kMortonSteps; ++v) t[v] = spread_bits_3(v);
  return t;
}();

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
      morton |= kSpread[q] << a;
    }
    const uint32_t octant = (direction.x < 0.0f ? 1u : 0u) | (direction.y < 0.0f ? 2u : 0u) |
                            (direction.z < 0.0f ? 4u : 0u);
    return octant << kMortonBits | morton;
  }
};

uint32_t octant(const glm::vec4& d) {
  return (d.x < 0.0f ? 1u : 0u) | (d.y < 0.0f ? 2u : 0u) | (d.z < 0.0f ? 4u : 0u);
}

// Per part of the array being sorted, the count of each digit, then (after exclusive_offsets)
// where the part's next ray of each digit goes.
using DigitCounts = std::array<uint32_t, kBuckets>;

// The two digits of a ray as the sort carries it (key << 32 | index): the key's low and high
// kRadixBits.
uint32_t low_digit(uint64_t keyed) { return uint32_t(keyed >> 32) & (kBuckets - 1); }
uint32_t high_digit(uint64_t keyed) { return uint32_t(keyed >> (32 + kRadixBits)); }

// Counts to offsets: digit by digit, part by part within a digit, the order a stable pass over
// the whole array would place them in.
void exclusive_offsets(std::vector<DigitCounts>& counts) {
  uint32_t sum = 0;
  for (uint32_t d = 0; d < kBuckets; ++d) {
    for (DigitCounts& c : counts) sum += std::exchange(c[d], sum);
  }
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
  // An LSD radix sort (stable: a comparison sort of 100K keys costs several times more), on all
  // cores: each pass counts digits per part of the array, and each part scatters its rays to the
  // offsets of its digits, so the result is the serial sort's for any number of parts or threads.
  // A ray travels as key << 32 | index, one array to scatter instead of two.
  const uint32_t n = batch.count();
  // Parts of 16,384 rays or more, at most 32 (512 KiB of counts). (Parts of 8,192, which two
  // cores share more evenly, measured no faster on the fish's 72,531 rays.)
  const uint32_t part_rays = std::max(16384u, (n + 31) / 32);
  const uint32_t parts = chunk_count(n, part_rays);
  const MortonFrame frame(bounds);
  const std::unique_ptr<uint64_t[]> keyed = std::make_unique_for_overwrite<uint64_t[]>(n);
  const std::unique_ptr<uint64_t[]> by_low = std::make_unique_for_overwrite<uint64_t[]>(n);
  std::vector<DigitCounts> counts(parts);
  parallel_for_chunks(n, part_rays, 0, [&](uint32_t p, uint32_t begin, uint32_t end) {
    DigitCounts& c = counts[p];  // zeros: made by the vector
    for (uint32_t i = begin; i < end; ++i) {
      const uint32_t key = frame.key(glm::vec3(batch.origin[i]), glm::vec3(batch.direction[i]));
      keyed[i] = uint64_t(key) << 32 | i;
      ++c[low_digit(keyed[i])];
    }
  });
  exclusive_offsets(counts);
  parallel_for_chunks(n, part_rays, 0, [&](uint32_t p, uint32_t begin, uint32_t end) {
    DigitCounts& next = counts[p];
    for (uint32_t i = begin; i < end; ++i) by_low[next[low_digit(keyed[i])]++] = keyed[i];
  });
  parallel_for_chunks(n, part_rays, 0, [&](uint32_t p, uint32_t begin, uint32_t end) {
    DigitCounts& c = counts[p];
    c.fill(0);
    for (uint32_t i = begin; i < end; ++i) ++c[high_digit(by_low[i])];
  });
  exclusive_offsets(counts);
  std::vector<uint32_t> order(n);
  parallel_for_chunks(n, part_rays, 0, [&](uint32_t p, uint32_t begin, uint32_t end) {
    DigitCounts& next = counts[p];
    for (uint32_t i = begin; i < end; ++i) order[next[high_digit(by_low[i])]++] = uint32_t(by_low[i]);
  });
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
