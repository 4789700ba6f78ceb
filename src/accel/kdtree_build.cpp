// Binned-SAH kd-tree construction (Shevtsov, Soupikov and Kapustin 2007, "Highly parallel fast
// kd-tree construction for interactive ray tracing of dynamic scenes"), flattened into the texel
// arrays of glsl/layout.h.
//
// Per node and axis: `bins` uniform bins over the node box; each reference (a triangle and its box
// inside the node) counts its box's min into one bin and its max into another; one sweep over the
// bin boundaries gives, for every candidate plane, the references below and above, and the SAH
//   cost = traversal_cost + intersection_cost * (1 - empty_bonus if a side is empty)
//                                              * (P_below N_below + P_above N_above) / P
// The node becomes a leaf when no plane beats intersection_cost * N, when N <= max_leaf_prims or at
// the depth limit. Axes with a zero extent are skipped (planar scenes), boxes with zero area are
// leaves.
//
// Classification at the chosen plane s: a reference goes below when its box min <= s and above
// when its box max >= s, so a triangle that touches the plane is referenced on both sides. This is
// what makes traversal robust for rays that lie in a split plane (they visit the below side only,
// see kdtree_traverse.cpp).
//
// Split clipping: a reference that straddles the plane gets the bounds of its triangle clipped
// exactly to each child: the triangle polygon is clipped against the node box and split by the
// plane (Sutherland-Hodgman in double precision, bounds rounded outwards to float, then
// intersected with the reference's box). A side the triangle misses, although its box overlaps
// it, gets no reference. That is KdBuildMode::Quality; KdBuildMode::Fast (the default) splits the
// whole triangle by the plane instead (kdclip::split_triangle: 3 edges against one plane, no
// clipping to the node box first, the crossings in float padded by a few ulps) and intersects its
// parts' bounds with the reference's box, a superset of the exact bounds. (The crossings were
// computed in double and rounded to the tightest floats until session 42: float with a pad took
// 3.7-4.6 % off a build's instructions, fish, toaster and torus 100K, for SAH within 1.1 %.)
// Measured (callgrind, one single-threaded build): fish 34.1M -> 26.8M instructions, toaster
// 210M -> 166M, torus 100K 872M -> 793M; SAH cost 185.0 -> 185.7, 223.7 -> 221.8, 3012 -> 2976;
// refs/tri +1 to +9%; traversal steps per ray within 0.2%. The cheaper alternative, clipping only
// the reference's box to the child box, builds exactly the same tree as no clipping at all (the
// binning clamps to the node box and the classification compares with a plane inside it), so
// exact clipping is the only one worth having. Measured (-O2, one thread, 32 bins, pbrt costs, the first serial builder), clipping
// off -> on:
//   Utah toasters 11,141 tris: refs/tri 13.8 -> 6.4, SAH 1669 -> 893, build 26 -> 32 ms,
//                              traversal 1.71 -> 1.92 Mrays/s (full stack, one thread)
//   SPD balls 9,830 tris:      refs/tri 7.2 -> 3.3, SAH 169 -> 128, build 13 -> 12 ms
//   random soup 100K tris:     refs/tri 7.3 -> 3.4, SAH 5880 -> 3569, build 461 -> 370 ms
//
// How the build is organised (issue 5: fast, parallel, and the same tree for any thread count):
// - A node's children are binned by the node (their boxes are known once its plane is chosen):
//   top nodes bin in the partition pass itself, subtree nodes right after it while the references
//   are in cache, and only children that can split. A node's split thus needs no pass of its own
//   over its references; only the root is binned separately.
// - Nodes of about 2 kBinSampleRefs references or more (the root, and the children of top nodes
//   of twice that) bin a fixed-stride sample of their references, about kBinSampleRefs or more
//   (Shevtsov et al. 2007). Measured (callgrind, one thread, fast): torus 1M 5,065M -> 4,739M
//   instructions, SAH 6684 -> 6628, steps per ray 89.0 -> 88.0; torus 100K -1 %; the toaster,
//   Utah toasters and torus 100K sample their top nodes and still make the same trees.
// - The sweep of a small node (up to kSparseSweepRefs references, kSparseSweepRefsAvx2 on AVX2
//   CPUs) visits only the planes next to an occupied bin (a bit per bin); larger nodes, whose
//   bins are mostly occupied, evaluate every plane four (SSE2) or eight (AVX2) at a time. Deep
//   nodes hold a handful of references, and a dense sweep over every bin of every axis was the
//   largest cost of the first builder (perf: 40% of its time on the toaster, 58% on a
//   100K-triangle soup).
// - Nodes of at least subtree_refs_ references (1,024; a quarter of a small scene, at least 256)
//   are "top nodes": each is a task, its children run
//   in parallel (tbb::parallel_invoke), the below child keeps the node's reference buffer (the
//   partition writes it in place), the above child gets one from a pool, and the largest nodes
//   partition their references in parallel blocks. A smaller node is built with its whole subtree
//   by one task, depth first, in one reference arena used as a stack (a split writes the above
//   child's references in place and the below child's after the node's, the below child is built
//   next), into nodes and leaf entries of its own with indices local to it.
// - A last pass lays the parts out depth first (a node's below child is the next node, its above
//   child follows the below child's subtree), relocates each part's local indices and sets the
//   empty-child flags while copying it, the parts in parallel.
// Every decision (split, which nodes are top nodes, the order of references in a partition,
// where each part lands) depends on the references alone, never on the threads or the order in
// which tasks run, so the arrays are the same, byte for byte, for any thread count, and the same
// as the first serial builder's. Only the SAH cost in the statistics is summed per part, so its
// last bits may differ from a single running sum.
#include <tbb/enumerable_thread_specific.h>
#include <tbb/info.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>
#include <tbb/parallel_reduce.h>
#include <tbb/blocked_range.h>
#include <tbb/scalable_allocator.h>
#include <tbb/task_arena.h>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif
// The dense sweep also has an AVX2 twin, chosen at run time (the build targets baseline x86-64).
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#define MOBIRT_KD_AVX2 1
#include <immintrin.h>
#endif

#include <glm/glm.hpp>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <mutex>
#include <new>
#include <string>
#include <utility>
#include <vector>

#include "accel/kdtree.h"
#include "accel/kdtree_clip.h"
#include "core/error.h"
#include "layout.h"
#include "texels.h"

namespace mobirt {

namespace {

using kdclip::Box;
using kdclip::clip_and_split;

// No split plane closer than this (relative to the scene's size and coordinate magnitude) to the
// node's faces. Without it the SAH, rewarded by the empty bonus, cuts ever thinner empty slabs off
// flat walls (down to 1e-9 thick next to a floor at y = 0); their planes then round to the same
// ray parameter t as the wall's and the traversal cannot order them: a kd-restart lost the wall
// behind such a tie. With the limit, two planes on one axis along any root-to-leaf path are at
// least 1e-5 * scale apart, far more than the rounding of t for rays starting within ~80 scene
// sizes of the scene. The SAH cost hardly changes (those slabs were empty).
constexpr float kMinWidthRelative = 1e-5f;

// Work split. Fixed numbers, never derived from the thread count: the tree must not depend on it.
constexpr size_t kSubtreeRefs = 1024;  // a node with fewer references: one task builds its subtree
// ... or with fewer than a quarter of the scene's primitives, down to this many: a scene of a few
// thousand triangles otherwise made two or three subtree tasks of uneven size, and the second
// thread spun in TBB for a third of the build (fish, 1,392 triangles, 2 threads: 0.98 -> 0.75 ms,
// the tree the same; docs/performance-history.md, *Smaller tasks for small scenes*).
constexpr size_t kMinSubtreeRefs = 256;
constexpr size_t kBlockRefs = 8192;    // top nodes of 2 blocks or more partition blocks in parallel
// Nodes of up to this many references sweep only the planes next to occupied bins; larger ones
// (whose bins are mostly occupied) evaluate every plane, four at a time. The AVX2 sweep (eight
// planes at a time) pays from fewer references on: the same tree either way (both sweeps take the
// same plane), fewer instructions (torus 100K -11 %, toaster -3 %).
constexpr size_t kSparseSweepRefs = 16;
constexpr size_t kSparseSweepRefsAvx2 = 3;
// Large nodes choose their plane from a sample of their references (Shevtsov et al. 2007 bin a
// subset of a large node): a node of n references bins every m-th, m the largest power of two
// with about kBinSampleRefs or more references left in the sample, so that n >= 2 kBinSampleRefs
// before any is skipped. The sample is a fixed stride over the node's references in their order,
// the same for any thread count.
constexpr size_t kBinSampleRefs = 4096;
// KdBuildOptions::small_split_gain of --build fast. Measured (fast, callgrind of one thread; gain
// 0 -> 0.15, nodes of up to 3 references): fish nodes 13,571 -> 11,883, SAH 185.7 -> 188.4,
// steps per ray 14.70 -> 14.46; toaster 73,177 -> 63,649, 221.8 -> 225.7, 23.83 -> 23.61; Utah
// toasters 97,387 -> 76,457, 897 -> 925, 29.72 -> 29.45. 0.2 takes 3-4 % more nodes off but
// puts the Utah toasters at 5.0 % above the first builder's SAH; nodes of up to 4 references
// put fish at 4.9 %.
constexpr float kFastSmallSplitGain = 0.15f;
// The leaf size of --build fast (kd_leaf_size). Measured (mobirt_kdprofile, 2 threads, idle
// machine; nodes, build wall ms, steps per ray, leaf size 1 -> 3): fish 11,883 -> 6,675, 2.18 ->
// 1.36, 14.46 -> 14.25; toaster 63,649 -> 40,071, 9.17 -> 6.47, 23.61 -> 23.48; Utah toasters
// 76,457 -> 54,477, 10.85 -> 7.76, 29.45 -> 29.03; the tori, whose trees stop at the depth
// limit, within 2 %. The traversal passes' JIT instructions per frame and Mrays/s: README.
// With 3, fast's small_split_gain no longer applies (it is for nodes of up to 3 references).
constexpr int kFastLeafSize = 3;
// KdBuildOptions::cluster_refs of --build fast (kd_cluster_refs). Measured (mobirt_kdprofile, one
// thread; cluster 0 -> 6: nodes, references per triangle, build ms, CPU steps per ray):
//   fish          6,675 -> 4,393    5.61 -> 3.97   1.22 -> 0.89   14.25 -> 14.47
//   toaster      40,071 -> 26,915   4.98 -> 3.65   8.30 -> 6.44   23.48 -> 23.60
//   marbles      23,225 -> 17,949   3.96 -> 3.26   4.82 -> 4.09   20.25 -> 20.38
//   Utah toasters 54,477 -> 40,977  5.83 -> 4.79   12.8 -> 9.3    29.03 -> 28.97
// the tori (their trees stop at the depth limit) within 5 %; SAH cost (pbrt's) +11 to +17 %. The
// traversal passes' JIT instructions per frame (200x120, depth 2): toaster +1.9 %, marbles
// +3.1 %, fish -1.7 %, Utah toasters -2.4 %; mobirt bench, three alternated runs: fps x0.97 to
// x1.06 per cell, median x1.014. 4 and 5 leave most chains (a fan has 6 triangles: toaster 39,043
// and 38,681 nodes); 8 to 16 take a little more build time off for more steps per ray.
constexpr int kFastClusterRefs = 6;

// KdBuildOptions::build_ref_cost's default: what one reference at one node costs the build, in
// the SAH's units (a traversal step 1, a triangle test intersection_cost = 80). The toaster's full
// build spends some 20 ns of CPU per reference at a node (9 ms for about 400,000), its CPU walk
// some 0.25 ns per SAH unit: about 100. Measured in mobirt bench (--levels bounce1,bounce2
// --frames 12 --warmup 2 --no-cpu --no-serial-twin --backend vulkan, four rounds each, Zen 4):
// 100, 400 and 1,600 within a few hundredths of one another on the toaster, marbles, fish and
// doll; the Utah toasters' + 1 bounce (its walks 69,500 a frame, its full tree 6.9 ms) 0.76-0.79x
// Embree's with 100 against 0.82-0.84 with 400 and 0.81-0.86 with 1,600 (README, *The tree a
// frame's walks pay for*). 400: as fast there, the less aggressive of the two. Measured while
// --mirrors auto still traced the Utah toasters' floor; again after dadd524 drew it (two rounds,
// 08:23-08:26 UTC): 400 against 1,600 the same on the Utah toasters, toaster and marbles, and
// 1,600 slower on the fish (+ 1 bounce 0.76-0.82x Embree's against 0.86-0.88, + 2 bounces
// 0.69-0.71 against 0.74-0.75).
constexpr double kKdBuildRefCost = 400.0;

// KdBuildOptions::deep_levels of --build fast (kd_deep_levels): pbrt's depth limit stops the
// project's meshes (they reach it), and the leaves it forces hold the references that cost the
// traversal passes the most triangle tests. Up to 4 more levels for nodes of more than 10
// references cut the passes' JIT instructions per frame (200x120, depth 2; the doll at 400x240
// with its light) by 5.3 % (toaster), 5.8 % (fish), 4.7 % (marbles), 3.8 % (Utah toasters) and
// 13.4 % (Utah wood doll) for 9-16 % more build CPU; raising the hard limit by 4 instead cut
// 5.5 % off the toaster's for 50 % more build time (README, "Nodes past the depth limit").
constexpr int kFastDeepLevels = 4;

Box to_box(const Aabb& a) { return Box{{a.lo.x, a.lo.y, a.lo.z}, {a.hi.x, a.hi.y, a.hi.z}}; }

// The surface area as the first builder computed it: float extents, double arithmetic; 0 for an
// empty box.
[[gnu::always_inline]] inline double area(const Box& b) {
  if (b.lo[0] > b.hi[0] || b.lo[1] > b.hi[1] || b.lo[2] > b.hi[2]) return 0.0;
  const double x = b.hi[0] - b.lo[0];
  const double y = b.hi[1] - b.lo[1];
  const double z = b.hi[2] - b.lo[2];
  return 2.0 * (x * y + y * z + z * x);
}

// A reference: a triangle and its bounds inside the node (the full box without split clipping).
// lo and hi are adjacent: the six bounds are binned as one run of floats.
struct alignas(16) Ref {
  float lo[3];
  float hi[3];
  uint32_t prim;
  uint32_t unused;  // pads to 32 bytes
};
static_assert(sizeof(Ref) == 32 && offsetof(Ref, hi) == 3 * sizeof(float));

void copy_refs(Ref* to, const Ref* from, size_t count) {
  if (count > 0) std::memcpy(to, from, count * sizeof(Ref));
}

// References in memory from TBB's scalable allocator, never value-initialised (every slot is
// written before it is read).
class RefBuffer {
 public:
  RefBuffer() = default;
  explicit RefBuffer(size_t capacity) { reserve(capacity); }
  RefBuffer(RefBuffer&& o) noexcept
      : data_(std::exchange(o.data_, nullptr)), size_(std::exchange(o.size_, 0)),
        capacity_(std::exchange(o.capacity_, 0)) {}
  RefBuffer& operator=(RefBuffer&& o) noexcept {
    std::swap(data_, o.data_);
    std::swap(size_, o.size_);
    std::swap(capacity_, o.capacity_);
    return *this;
  }
  RefBuffer(const RefBuffer&) = delete;
  RefBuffer& operator=(const RefBuffer&) = delete;
  ~RefBuffer() { scalable_free(data_); }

  Ref* data() { return data_; }
  const Ref* data() const { return data_; }
  size_t size() const { return size_; }
  size_t capacity() const { return capacity_; }
  void set_size(size_t size) { size_ = size; }  // at most the capacity
  // Keeps the first size() references.
  void reserve(size_t capacity) {
    if (capacity <= capacity_) return;
    auto* grown = static_cast<Ref*>(scalable_malloc(capacity * sizeof(Ref)));
    if (!grown) throw std::bad_alloc();
    copy_refs(grown, data_, size_);
    scalable_free(data_);
    data_ = grown;
    capacity_ = capacity;
  }

 private:
  Ref* data_ = nullptr;
  size_t size_ = 0;
  size_t capacity_ = 0;
};

// The reference buffers of the top nodes, recycled within one build: a buffer a node has
// partitioned serves a later node, so the build touches about as much fresh memory as one arena
// would (with a new buffer per node, page faults took a tenth of a 1M-triangle build).
class BufferPool {
 public:
  RefBuffer take(size_t capacity) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      size_t best = free_.size();
      for (size_t i = 0; i < free_.size(); ++i) {
        if (free_[i].capacity() >= capacity && (best == free_.size() || free_[i].capacity() < free_[best].capacity())) {
          best = i;
        }
      }
      if (best < free_.size()) {
        RefBuffer b = std::move(free_[best]);
        free_[best] = std::move(free_.back());
        free_.pop_back();
        b.set_size(0);
        return b;
      }
    }
    return RefBuffer(capacity);
  }
  void give(RefBuffer&& b) {
    if (b.capacity() == 0) return;
    std::lock_guard<std::mutex> lock(mutex_);
    free_.push_back(std::move(b));
  }

 private:
  std::mutex mutex_;
  std::vector<RefBuffer> free_;
};

std::string count_text(size_t n) {
  const std::string digits = std::to_string(n);
  std::string s;
  for (size_t i = 0; i < digits.size(); ++i) {
    if (i > 0 && (digits.size() - i) % 3 == 0) s += ',';
    s += digits[i];
  }
  return s;
}

// Bin i of axis a covers [lo + i * width / bins, lo + (i + 1) * width / bins) of the node box.
// The six bounds of a reference (lo xyz, hi xyz) are binned together: origin and scale hold one
// lane per bound, padded to 8.
struct Binner {
  alignas(16) float origin[8] = {};
  alignas(16) float scale[8] = {};
  float top = 0.0f;

  Binner() = default;
  Binner(const Box& box, int bins) : top(float(bins - 1)) {
    for (int a = 0; a < 3; ++a) {
      const float width = box.hi[a] - box.lo[a];
      const float s = active_width(width, float(bins)) ? float(bins) / width : 0.0f;
      origin[a] = origin[a + 3] = box.lo[a];
      scale[a] = scale[a + 3] = s;  // inactive axes: everything in bin 0, never swept
    }
  }

  // An axis of a box this wide is split and swept: a box thinner than float can bin (bins / width
  // overflows: 0 * inf would be NaN) is not. For a positive width the quotient is finite exactly
  // when it is below inf (a comparison, cheaper than std::isfinite).
  static bool active_width(float width, float bins) { return width > 0.0f && bins / width < kInfinity; }

  // index[j] = offset[j] + the bin of bound j (r.lo[0..2], r.hi[0..2]), the bin being
  // clamp((x - origin) * scale, 0, bins - 1).
  void bin(const Ref& r, const int32_t* offset, int32_t* index) const {
#if defined(__SSE2__)
    const __m128 zero = _mm_setzero_ps();
    const __m128 last = _mm_set1_ps(top);
    const __m128 v0 = _mm_loadu_ps(r.lo);  // lo xyz, hi x
    const __m128 v1 = _mm_castsi128_ps(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(r.hi + 1)));
    const __m128 f0 = _mm_mul_ps(_mm_sub_ps(v0, _mm_load_ps(origin)), _mm_load_ps(scale));
    const __m128 f1 = _mm_mul_ps(_mm_sub_ps(v1, _mm_load_ps(origin + 4)), _mm_load_ps(scale + 4));
    const __m128i b0 = _mm_cvttps_epi32(_mm_min_ps(_mm_max_ps(f0, zero), last));
    const __m128i b1 = _mm_cvttps_epi32(_mm_min_ps(_mm_max_ps(f1, zero), last));
    _mm_store_si128(reinterpret_cast<__m128i*>(index),
                    _mm_add_epi32(b0, _mm_load_si128(reinterpret_cast<const __m128i*>(offset))));
    _mm_store_si128(reinterpret_cast<__m128i*>(index + 4),
                    _mm_add_epi32(b1, _mm_load_si128(reinterpret_cast<const __m128i*>(offset + 4))));
#else
    const auto bin_of = [&](float x, int j) {
      return offset[j] + static_cast<int32_t>(std::min(std::max((x - origin[j]) * scale[j], 0.0f), top));
    };
    for (int a = 0; a < 3; ++a) {
      index[a] = bin_of(r.lo[a], a);
      index[a + 3] = bin_of(r.hi[a], a + 3);
    }
#endif
  }
};

// Per axis, how many reference boxes have their min (row 2a) and their max (row 2a + 1) in each
// bin. Rows are padded with 8 zeros: the sweep reads 4 or 8 bins at a time.
class Histogram {
 public:
  explicit Histogram(int bins) : stride_(bins + 8), counts_(size_t(6 * stride_), 0u) {
    const int rows[6] = {0, 2, 4, 1, 3, 5};  // lo x, y, z, hi x, y, z
    for (int j = 0; j < 6; ++j) offsets_[j] = rows[j] * stride_;
  }

  const uint32_t* mins(int axis) const { return counts_.data() + 2 * axis * stride_; }
  const uint32_t* maxs(int axis) const { return counts_.data() + (2 * axis + 1) * stride_; }

  void add(const Binner& binner, const Ref& r) {
    alignas(16) int32_t index[8];
    binner.bin(r, offsets_, index);
    uint32_t* c = counts_.data();
    ++c[index[0]];
    ++c[index[1]];
    ++c[index[2]];
    ++c[index[3]];
    ++c[index[4]];
    ++c[index[5]];
    tracked_ = false;
  }

#if defined(MOBIRT_KD_AVX2)
  // add() for refs[0..n) on AVX2 CPUs: a reference's 8 floats (lo xyz, hi xyz, the primitive's bits
  // and the padding) binned in one register, Binner::bin's operations per lane in its order (sub,
  // mul, max with 0, min with the last bin, truncate), so the same bins; the last two lanes are
  // zeroed first (a primitive's bits read as a float are subnormal, which some CPUs handle in
  // microcode) and are not counted. Half the instructions of add() a reference (the six counts are
  // the rest).
  __attribute__((target("avx2"))) void add_all_avx2(const Binner& binner, const Ref* refs, size_t n) {
    const __m256 origin = _mm256_loadu_ps(binner.origin);
    const __m256 scale = _mm256_loadu_ps(binner.scale);
    const __m256 zero = _mm256_setzero_ps();
    const __m256 last = _mm256_set1_ps(binner.top);
    const __m256i offsets = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(offsets_));
    uint32_t* c = counts_.data();
    for (size_t i = 0; i < n; ++i) {
      const __m256 bounds = _mm256_blend_ps(_mm256_loadu_ps(refs[i].lo), zero, 0xC0);
      const __m256 f = _mm256_mul_ps(_mm256_sub_ps(bounds, origin), scale);
      const __m256i b = _mm256_add_epi32(_mm256_cvttps_epi32(_mm256_min_ps(_mm256_max_ps(f, zero), last)), offsets);
      const __m128i b0 = _mm256_castsi256_si128(b);
      const __m128i b1 = _mm256_extracti128_si256(b, 1);
      ++c[_mm_cvtsi128_si32(b0)];
      ++c[_mm_extract_epi32(b0, 1)];
      ++c[_mm_extract_epi32(b0, 2)];
      ++c[_mm_extract_epi32(b0, 3)];
      ++c[_mm_cvtsi128_si32(b1)];
      ++c[_mm_extract_epi32(b1, 1)];
    }
    tracked_ = false;
  }
#endif

  // add() for the nodes of few references that sweep sparsely (bins <= 64): also keeps a bit per
  // occupied bin of each axis, so that the sweep need not scan the bins for them and clear() need
  // not touch every count (the two scans were a tenth of a toaster build).
  void add_tracked(const Binner& binner, const Ref& r) {
    alignas(16) static constexpr int32_t kNoOffsets[8] = {};
    alignas(16) int32_t bin[8];
    binner.bin(r, kNoOffsets, bin);
    uint32_t* c = counts_.data();
    for (int j = 0; j < 6; ++j) ++c[offsets_[j] + bin[j]];
    for (int a = 0; a < 3; ++a) occupied_[a] |= (uint64_t(1) << bin[a]) | (uint64_t(1) << bin[a + 3]);
  }

  // The bins of axis a that hold a min or a max, when every reference came through add_tracked
  // since the last clear(); tracked() says whether they did.
  bool tracked() const { return tracked_; }
  // How many references were binned (each has its min in one bin of axis 0).
  size_t binned() const {
    size_t total = 0;
    for (int b = 0; b < stride_; ++b) total += counts_[size_t(b)];
    return total;
  }
  uint64_t occupied(int a) const { return occupied_[a]; }

  void merge(const Histogram& o) {
    for (size_t i = 0; i < counts_.size(); ++i) counts_[i] += o.counts_[i];
    tracked_ = false;
  }

  void clear() {
    if (tracked_) {
      for (int a = 0; a < 3; ++a) {
        uint32_t* lo = counts_.data() + 2 * a * stride_;
        uint32_t* hi = lo + stride_;
        for (uint64_t bits = occupied_[a]; bits != 0; bits &= bits - 1) {
          const int b = std::countr_zero(bits);
          lo[b] = 0;
          hi[b] = 0;
        }
      }
    } else {
      std::fill(counts_.begin(), counts_.end(), 0u);
    }
    occupied_[0] = occupied_[1] = occupied_[2] = 0;
    tracked_ = true;
  }

 private:
  int stride_;
  alignas(16) int32_t offsets_[8] = {};  // row of each bound of Binner::bin
  std::vector<uint32_t> counts_;         // [axis][min, max][stride]
  uint64_t occupied_[3] = {};            // add_tracked's bits per axis
  bool tracked_ = true;                  // no add() or merge() since the last clear()
};

// Leaf and cost totals of a part of the tree.
struct Tally {
  size_t leaves = 0;
  size_t empty_leaves = 0;
  size_t prim_references = 0;
  size_t max_leaf_size = 0;
  int max_depth_reached = 0;
  double cost = 0.0;  // SAH cost times the root's area

  void add(const Tally& o) {
    leaves += o.leaves;
    empty_leaves += o.empty_leaves;
    prim_references += o.prim_references;
    max_leaf_size = std::max(max_leaf_size, o.max_leaf_size);
    max_depth_reached = std::max(max_depth_reached, o.max_depth_reached);
    cost += o.cost;
  }
};

// A piece of the tree built by one task: a top node with its two children, or a subtree in node
// and leaf-entry arrays of its own (indices local to them, relocated when laid out).
struct Part {
  int axis = -1;  // a top node: split axis and position, children below and above
  float split = 0.0f;
  std::unique_ptr<Part> below;
  std::unique_ptr<Part> above;
  std::vector<glm::vec4> nodes;  // a subtree
  std::vector<int32_t> prims;  // the leaves' primitives, leaf after leaf
  Tally tally;             // this part alone; the whole after total()
  size_t node_total = 0;   // after total(): nodes and leaf entries including the children
  size_t prim_total = 0;
};

struct Split {
  int axis = -1;  // -1: no plane beats a leaf
  float position = 0.0f;
};

// One child's side of a partition: references appended at `out`, binned into `hist` for the
// child's own split when it can have one.
struct ChildSink {
  Ref* out = nullptr;
  size_t count = 0;
  Histogram* hist = nullptr;
  Binner binner;
  size_t sample_mask = 0;  // bins the references whose index in `out` has these bits clear

  void push(const Ref& r) {
    const size_t i = count++;
    out[i] = r;
    if (hist && (i & sample_mask) == 0) hist->add(binner, r);
  }
};

// A subtree node's side of a partition: its children are binned after it, so a push only appends
// (no binner to set up, no histogram to test: 3 % of a toaster build).
struct AppendSink {
  Ref* out = nullptr;
  size_t count = 0;

  void push(const Ref& r) { out[count++] = r; }
};

// A node of a subtree waiting to be built.
struct Task {
  size_t offset;     // references in the arena at [offset, offset + count)
  size_t count;
  Box box;
  double area;       // area(box), computed once by the parent
  int depth;
  int64_t parent;    // node (local) whose "above" index is this task's node, or -1
  Histogram* hist;   // its references binned, or null when it must be a leaf
};

// The scratch memory of one thread's subtree builds; nothing in it carries over between them.
struct SubtreeScratch {
  RefBuffer arena;
  std::vector<Histogram> hists;          // [2 * depth + side]: children's histograms by depth
  std::vector<Task> tasks;
};

class Builder {
 public:
  Builder(std::span<const glm::vec3> positions, std::span<const Shape> shapes, const KdBuildOptions& options)
      : positions_(positions), shapes_(shapes), options_(options), bins_(std::max(2, options.bins)),
        triangle_count_(positions.size() / 3 + shapes.size()) {
#if defined(MOBIRT_KD_AVX2)
    avx2_ = options.sweep_simd != KdSweepSimd::Sse2 && __builtin_cpu_supports("avx2");
    if (avx2_) sparse_refs_ = kSparseSweepRefsAvx2;
#endif
    small_split_gain_ = options.small_split_gain >= 0.0f ? options.small_split_gain
                        : options.build == KdBuildMode::Fast ? kFastSmallSplitGain
                                                             : 0.0f;
    max_leaf_prims_ = size_t(kd_leaf_size(options));
    subtree_refs_ = std::clamp(triangle_count_ / 4, kMinSubtreeRefs, kSubtreeRefs);
    cluster_refs_ = size_t(kd_cluster_refs(options));
    empty_bonus_ = kd_empty_bonus(options);
    deep_refs_ = size_t(std::max(options.deep_refs, 0));
    build_ref_cost_ = kd_build_ref_cost(options);
    rays_leaf_limit_ = size_t(std::max(options.rays_leaf_limit, 0));
  }

  // Into `tree`, whose arrays keep their memory: emptied first, so that resizing them writes
  // nothing, and one that grows past its capacity gets exactly its size, copying nothing of the
  // last tree (a resize from its old size would move it and double the capacity).
  void build(FlatKdTree& tree) {
    tree.clear();
    const size_t n = triangle_count_;
    tree.max_depth = kdtree_depth_limit(n, options_.max_depth);
    // Past pbrt's limit only nodes of more than deep_refs references split (kd_deep_levels).
    depth_limit_ = tree.max_depth;
    tree.max_depth += kd_deep_levels(options_);
    max_depth_ = tree.max_depth;
    std::unique_ptr<Part> root;
    // The triangle texels do not depend on the tree: written while it is built.
    tbb::parallel_invoke([&] { write_triangles(tree); }, [&] { root = build_root(tree.bounds); });
    total(*root);
    const Tally& t = root->tally;
    if (root->node_total > kKdIndexLimit) throw too_many_nodes();
    if (root->prim_total > kKdMaxLeafEntries) throw too_many_prim_references();
    tree.nodes.resize(root->node_total);
    tree.leaf_prims.resize(root->prim_total * MOBIRT_TEXELS_PER_TRIANGLE);
    lay_out(*root, 0, 0, tree);

    KdBuildStats& s = tree.stats;
    s.nodes = tree.nodes.size();
    s.leaves = t.leaves;
    s.empty_leaves = t.empty_leaves;
    s.prim_references = t.prim_references;
    s.max_leaf_size = t.max_leaf_size;
    s.max_depth_reached = t.max_depth_reached;
    const double root_area = area(to_box(tree.bounds));
    s.sah_cost = root_area > 0.0 ? t.cost / root_area : options_.intersection_cost * double(n);
  }

 private:
  void write_triangles(FlatKdTree& tree) const {
    tree.triangles.reserve(triangle_count_ * MOBIRT_TEXELS_PER_TRIANGLE);
    for (const glm::vec3& p : positions_) tree.triangles.emplace_back(p, 0.0f);
    for (const Shape& shape : shapes_) {
      tree.triangles.resize(tree.triangles.size() + MOBIRT_TEXELS_PER_TRIANGLE);
      shape_texels(shape, tree.triangles.data() + tree.triangles.size() - MOBIRT_TEXELS_PER_TRIANGLE);
    }
  }

  // Root references and bounds, the root's histogram, then the tree.
  std::unique_ptr<Part> build_root(Aabb& bounds) {
    const size_t n = triangle_count_;
    RefBuffer refs = pool_.take(n);
    refs.set_size(n);
    const size_t blocks = (n + kBlockRefs - 1) / kBlockRefs;
    std::vector<Aabb> block_bounds(blocks);
    // 1 where a block has a non-finite vertex: checked here, in parallel, rather than by a serial
    // pass before the build (1 % of a 1M-triangle build's instructions).
    std::vector<uint8_t> block_non_finite(blocks, 0);
    tbb::parallel_for(size_t(0), blocks, [&](size_t b) {
      Aabb box;
      bool finite = true;
      for (size_t i = b * kBlockRefs, end = std::min(n, i + kBlockRefs); i < end; ++i) {
        glm::vec3 lo, hi;
        if (i < positions_.size() / 3) {
          const glm::vec3* v = positions_.data() + 3 * i;
          finite &= bool(int(is_finite(v[0])) & int(is_finite(v[1])) & int(is_finite(v[2])));  // no branches
          lo = glm::min(v[0], glm::min(v[1], v[2]));
          hi = glm::max(v[0], glm::max(v[1], v[2]));
        } else {  // an analytic primitive: its box
          const Aabb shape = shape_bounds(shapes_[i - positions_.size() / 3]);
          lo = shape.lo;
          hi = shape.hi;
        }
        refs.data()[i] = Ref{{lo.x, lo.y, lo.z}, {hi.x, hi.y, hi.z}, static_cast<uint32_t>(i), 0};
        box.lo = glm::min(box.lo, lo);
        box.hi = glm::max(box.hi, hi);
      }
      block_bounds[b] = box;
      block_non_finite[b] = !finite;
    });
    for (size_t b = 0; b < blocks; ++b) {
      if (block_non_finite[b]) throw non_finite_vertex(b * kBlockRefs);
    }
    for (const Aabb& box : block_bounds) bounds.extend(box);
    const Box root = to_box(bounds);
    if (n > 0) {
      const glm::vec3 magnitude = glm::max(glm::abs(bounds.lo), glm::abs(bounds.hi));
      const glm::vec3 ext = bounds.extent();
      const float scale = std::max({ext.x, ext.y, ext.z, magnitude.x, magnitude.y, magnitude.z});
      min_width_ = std::max(kMinWidthRelative * scale, std::numeric_limits<float>::min());
    }
    const double root_area = area(root);
    rays_per_area_ = options_.rays > 0.0 && root_area > 0.0 ? options_.rays / root_area : 0.0;
    std::unique_ptr<Histogram> hist;
    if (n >= subtree_refs_ && can_split(n, 0, area(root))) {
      hist = std::make_unique<Histogram>(bins_);
      std::vector<Histogram> block_hists(blocks, Histogram(bins_));
      const Binner binner(root, bins_);
      const size_t mask = sample_mask(n);
      tbb::parallel_for(size_t(0), blocks, [&](size_t b) {
        for (size_t i = b * kBlockRefs, end = std::min(n, i + kBlockRefs); i < end; i += mask + 1) {
          block_hists[b].add(binner, refs.data()[i]);
        }
      });
      for (const Histogram& h : block_hists) hist->merge(h);
    }
    return build_part(std::move(refs), root, 0, std::move(hist));
  }

  // The stride minus one at which a node of n references is binned (0: every reference).
  static size_t sample_mask(size_t n) {
    return n >= 2 * kBinSampleRefs ? std::bit_floor(n / kBinSampleRefs) - 1 : 0;
  }

  bool can_split(size_t n, int depth, double box_area) const {
    return n > max_leaf_prims_ && depth < max_depth_ && box_area > 0.0 && (depth < depth_limit_ || n > deep_refs_) &&
           !rays_forbid_split(n, box_area);
  }

  // Whether the rays rule (choose_split, KdBuildOptions::rays) rejects every split of a node of n
  // references, whatever its SAH cost: the rays expected to enter it save at most a leaf's whole
  // cost, intersection_cost * n, when a split costs nothing. Such a node is made a leaf before its
  // references are binned and its planes swept, work the rule then threw away (on the toaster's
  // tree for 2,500 rays most of the nodes the rule makes leaves). The same tree, bit for bit: with
  // X = rays_per_area_ * box_area >= 0 and 0 <= leaf_cost - cost <= leaf_cost (cost >= 0 with
  // non-negative costs), X * (leaf_cost - cost) <= X * leaf_cost in floating point too (rounding
  // is monotone), so choose_split's test would reject as well.
  bool rays_forbid_split(size_t n, double box_area) const {
    if (!(rays_per_area_ > 0.0) || n > rays_leaf_limit_) return false;
    if (!(options_.traversal_cost >= 0.0f && options_.intersection_cost >= 0.0f)) return false;
    const double leaf_cost = options_.intersection_cost * double(n);
    return !(rays_per_area_ * box_area * leaf_cost > build_ref_cost_ * double(n));
  }

  // ---- Top nodes -------------------------------------------------------------------------------

  std::unique_ptr<Part> build_part(RefBuffer refs, const Box& box, int depth, std::unique_ptr<Histogram> hist) {
    auto part = std::make_unique<Part>();
    const size_t n = refs.size();
    if (n < subtree_refs_) {
      // A subtree's nodes need every reference binned: a sample (rare, after a very uneven split
      // of a large node) is binned again by build_subtree.
      if (hist && hist->binned() != n) hist.reset();
      build_subtree(refs.data(), n, box, depth, hist.get(), *part, scratch_.local());
      pool_.give(std::move(refs));
      return part;
    }
    const double box_area = area(box);
    const bool splittable = can_split(n, depth, box_area);
    // The sample's stride was set from the parent's count: after a very uneven split it can leave
    // a node with too few references binned, and the node is binned again in full.
    if (splittable && hist->binned() < std::min(n, kBinSampleRefs / 2)) bin_into(*hist, refs.data(), n, box);
    const Split split = splittable ? choose_split(*hist, box, n, box_area, hist->binned()) : Split{};
    if (split.axis < 0) {
      make_leaf(refs.data(), n, depth, box_area, *part);
      pool_.give(std::move(refs));
      return part;
    }
    // Named boxes, not a structured binding: the lambdas below capture them (clang < 16 cannot).
    const std::pair<Box, Box> children = child_boxes(box, split);
    const Box& below_box = children.first;
    const Box& above_box = children.second;
    std::unique_ptr<Histogram> below_hist = child_histogram(depth + 1, below_box);
    std::unique_ptr<Histogram> above_hist = child_histogram(depth + 1, above_box);
    // The below side stays in the node's buffer (written in place), the above side gets one.
    RefBuffer above = pool_.take(n);
    if (n < 2 * kBlockRefs) {
      const size_t mask = sample_mask(n / 2);
      ChildSink b{refs.data(), 0, below_hist.get(), Binner(below_box, bins_), mask};
      ChildSink a{above.data(), 0, above_hist.get(), Binner(above_box, bins_), mask};
      partition(refs.data(), n, box, split, b, a);
      refs.set_size(b.count);
      above.set_size(a.count);
    } else {
      partition_blocks(refs, above, box, split, below_box, above_box, below_hist.get(), above_hist.get());
    }
    part->axis = split.axis;
    part->split = split.position;
    part->tally.cost = options_.traversal_cost * box_area;
    tbb::parallel_invoke(
        [&] { part->below = build_part(std::move(refs), below_box, depth + 1, std::move(below_hist)); },
        [&] { part->above = build_part(std::move(above), above_box, depth + 1, std::move(above_hist)); });
    return part;
  }

  std::unique_ptr<Histogram> child_histogram(int depth, const Box& box) const {
    // Children that must be leaves whatever their count need none; one that has too few
    // references gets one it does not use (the count is known only after the partition).
    if (depth >= max_depth_ || !(area(box) > 0.0)) return nullptr;
    return std::make_unique<Histogram>(bins_);
  }

  // The partition of a large node: blocks of kBlockRefs references in parallel, the below side
  // in place inside each block, the above side into the same stretch of a scratch buffer, then
  // both gathered in block order (the order of one pass over the node).
  void partition_blocks(RefBuffer& refs, RefBuffer& above, const Box& box, Split split, const Box& below_box,
                        const Box& above_box, Histogram* below_hist, Histogram* above_hist) {
    const size_t n = refs.size();
    const size_t blocks = (n + kBlockRefs - 1) / kBlockRefs;
    RefBuffer scratch = std::move(above);  // n references
    std::vector<size_t> below_counts(blocks + 1, 0);
    std::vector<size_t> above_counts(blocks + 1, 0);
    std::vector<Histogram> below_hists(below_hist ? blocks : 0, Histogram(bins_));
    std::vector<Histogram> above_hists(above_hist ? blocks : 0, Histogram(bins_));
    const Binner below_binner(below_box, bins_);
    const Binner above_binner(above_box, bins_);
    // A child has about half the node's references (its count is known only afterwards).
    const size_t mask = sample_mask(n / 2);
    tbb::parallel_for(size_t(0), blocks, [&](size_t block) {
      const size_t start = block * kBlockRefs;
      const size_t count = std::min(kBlockRefs, n - start);
      ChildSink b{refs.data() + start, 0, below_hist ? &below_hists[block] : nullptr, below_binner, mask};
      ChildSink a{scratch.data() + start, 0, above_hist ? &above_hists[block] : nullptr, above_binner, mask};
      partition(refs.data() + start, count, box, split, b, a);
      below_counts[block + 1] = b.count;
      above_counts[block + 1] = a.count;
    });
    for (size_t block = 0; block < blocks; ++block) {
      below_counts[block + 1] += below_counts[block];
      above_counts[block + 1] += above_counts[block];
    }
    RefBuffer below = pool_.take(below_counts[blocks]);
    below.set_size(below_counts[blocks]);
    above = pool_.take(above_counts[blocks]);
    above.set_size(above_counts[blocks]);
    tbb::parallel_for(size_t(0), blocks, [&](size_t block) {
      const size_t start = block * kBlockRefs;
      copy_refs(below.data() + below_counts[block], refs.data() + start, below_counts[block + 1] - below_counts[block]);
      copy_refs(above.data() + above_counts[block], scratch.data() + start, above_counts[block + 1] - above_counts[block]);
    });
    for (const Histogram& h : below_hists) below_hist->merge(h);
    for (const Histogram& h : above_hists) above_hist->merge(h);
    pool_.give(std::move(scratch));
    pool_.give(std::exchange(refs, std::move(below)));
  }

  // ---- Subtrees of one task --------------------------------------------------------------------

  void build_subtree(const Ref* refs, size_t n, const Box& box, int depth, Histogram* hist, Part& out,
                     SubtreeScratch& s) {
    s.arena.set_size(0);
    s.arena.reserve(std::max<size_t>(4 * n, 64));
    // Two slots per depth (children of depth max_depth_ are leaves), made before any is used: the
    // vector never moves while a subtree holds pointers into it.
    while (s.hists.size() < 2 * size_t(max_depth_ + 1)) s.hists.emplace_back(bins_);
    s.tasks.clear();
    const double box_area = area(box);
    if (!hist && can_split(n, depth, box_area)) {  // the root of a small tree: nobody binned it
      hist = &histogram_slot(s, depth, 0);
      bin_into(*hist, refs, n, box);
    }
    // The subtree's root reads the node's buffer itself and writes its children into the arena
    // where they would be had its references been copied there first (that copy was 0.9 % of a
    // 1M-triangle build's instructions).
    process(Task{0, n, box, box_area, depth, -1, hist}, out, s, refs);
    while (!s.tasks.empty()) {
      const Task task = s.tasks.back();
      s.tasks.pop_back();
      process(task, out, s);
    }
  }

  // The histogram of a child of a subtree node (its slot by depth and side), or null when the
  // child must be a leaf.
  Histogram* bin_child(SubtreeScratch& s, const Ref* refs, size_t n, const Box& box, double box_area, int depth,
                       int side) const {
    if (!can_split(n, depth, box_area)) return nullptr;
    Histogram& hist = histogram_slot(s, depth, side);
    bin_into(hist, refs, n, box);
    return &hist;
  }

  // hist cleared, then refs[0..n) binned over box, tracked when the node sweeps sparsely.
  void bin_into(Histogram& hist, const Ref* refs, size_t n, const Box& box) const {
    hist.clear();
    const Binner binner(box, bins_);
    if (sparse_sweep(n)) {
      for (size_t i = 0; i < n; ++i) hist.add_tracked(binner, refs[i]);
    } else {
#if defined(MOBIRT_KD_AVX2)
      if (avx2_) {
        hist.add_all_avx2(binner, refs, n);
        return;
      }
#endif
      for (size_t i = 0; i < n; ++i) hist.add(binner, refs[i]);
    }
  }

  bool sparse_sweep(size_t n) const { return bins_ <= 64 && n <= sparse_refs_; }

  Histogram& histogram_slot(SubtreeScratch& s, int depth, int side) const { return s.hists[2 * size_t(depth) + size_t(side)]; }

  // The task's references are in the arena at task.offset, or at `source` (the subtree's root):
  // either way its children are written into the arena.
  void process(const Task& task, Part& out, SubtreeScratch& s, const Ref* source = nullptr) {
    const Box& box = task.box;
    const size_t n = task.count;
    const double box_area = task.area;
    const Split split =
        task.hist && can_split(n, task.depth, box_area) ? choose_split(*task.hist, box, n, box_area, n) : Split{};
    if (split.axis < 0) {
      make_leaf(source ? source : s.arena.data() + task.offset, n, task.depth, box_area, out, task.parent);
      return;
    }
    const auto [below_box, above_box] = child_boxes(box, split);
    const int child_depth = task.depth + 1;
    // The above side is written in place (each reference read adds at most one above it, so the
    // writes never pass the reads), the below side after the node's references: the below child
    // is built next, on top of the arena.
    const size_t below_offset = task.offset + n;
    if (below_offset + n > s.arena.capacity()) {
      s.arena.set_size(below_offset);  // all that must survive the reallocation
      s.arena.reserve(std::max(below_offset + n, 2 * s.arena.capacity()));
    }
    Ref* refs = s.arena.data() + task.offset;
    AppendSink b{s.arena.data() + below_offset, 0};
    AppendSink a{refs, 0};
    partition(source ? source : refs, n, box, split, b, a);
    // The children are binned after the partition, their references still in cache, and only those
    // that can split (many are leaves of one reference).
    const double below_area = area(below_box);
    const double above_area = area(above_box);
    Histogram* below_hist = bin_child(s, b.out, b.count, below_box, below_area, child_depth, 0);
    Histogram* above_hist = bin_child(s, a.out, a.count, above_box, above_area, child_depth, 1);

    const size_t index = emit(out, glm::vec4(split.position, 0.0f, static_cast<float>(split.axis), 0.0f), task.parent);
    out.tally.cost += options_.traversal_cost * box_area;
    s.tasks.push_back(
        Task{task.offset, a.count, above_box, above_area, child_depth, static_cast<int64_t>(index), above_hist});
    s.tasks.push_back(Task{below_offset, b.count, below_box, below_area, child_depth, -1, below_hist});
  }

  size_t emit(Part& out, const glm::vec4& node, int64_t parent) const {
    const size_t index = out.nodes.size();
    if (index >= kKdIndexLimit) throw too_many_nodes();
    out.nodes.push_back(node);
    if (parent >= 0) out.nodes[static_cast<size_t>(parent)].y = static_cast<float>(index);
    return index;
  }

  // ---- Shared by top nodes and subtrees ---------------------------------------------------------

  void make_leaf(const Ref* refs, size_t count, int depth, double box_area, Part& out, int64_t parent = -1) const {
    glm::vec4 node(0.0f, static_cast<float>(count), static_cast<float>(MOBIRT_NODE_LEAF), 0.0f);
    if (count > 0) {
      const size_t start = out.prims.size();
      if (start + count > kKdMaxLeafEntries) throw too_many_prim_references();
      node.x = static_cast<float>(start);
      for (size_t i = 0; i < count; ++i) out.prims.push_back(static_cast<int32_t>(refs[i].prim));
    }
    emit(out, node, parent);
    Tally& t = out.tally;
    t.leaves += 1;
    if (count == 0) t.empty_leaves += 1;
    t.prim_references += count;
    t.max_leaf_size = std::max(t.max_leaf_size, count);
    t.max_depth_reached = std::max(t.max_depth_reached, depth);
    t.cost += options_.intersection_cost * double(count) * box_area;
  }

  static std::pair<Box, Box> child_boxes(const Box& box, Split split) {
    Box below = box;
    below.hi[split.axis] = split.position;
    Box above = box;
    above.lo[split.axis] = split.position;
    return {below, above};
  }

  // The sweep over the candidate planes of every active axis. Plane i (1 .. k-1) lies at
  // lo + i * step; the child areas are linear in i: P_below / P = c + g * i,
  // P_above / P = c + g * (k - i). The counts are constant between bins that hold no minimum or
  // maximum and the cost is linear in i there: only the ends of such runs can be the minimum, so
  // only planes next to a bin that holds one are candidates (and the first and the last plane).
  // `binned` of the n references are in hist (fewer when the node was binned from a sample): the
  // sweep counts the sample, and its best cost, scaled to n, is compared with the leaf's.
  Split choose_split(const Histogram& hist, const Box& box, size_t n, double box_area, size_t binned) const {
    const double leaf_cost = options_.intersection_cost * double(n);
    const int k = bins_;
    float best_cost = kInfinity;
    Split best;
    const double inv_area = 1.0 / box_area;
    // Per node, not per axis (a tenth of the sweep's set-up on the toaster): the widths, whether
    // the sweep is sparse, 2 * min_width_.
    const float width[3] = {box.hi[0] - box.lo[0], box.hi[1] - box.lo[1], box.hi[2] - box.lo[2]};
    const bool sparse = sparse_sweep(n);
    const float min_step = 2.0f * min_width_;
    const float fk = float(k);
    for (int a = 0; a < 3; ++a) {
      if (!Binner::active_width(width[a], fk)) continue;
      const double o1 = width[a == 2 ? 0 : a + 1];
      const double o2 = width[a == 0 ? 2 : a - 1];
      const float step = width[a] / fk;
      const SweepAxis axis{
          hist.mins(a), hist.maxs(a), k, static_cast<uint32_t>(binned),
          static_cast<float>(2.0 * o1 * o2 * inv_area),
          static_cast<float>(2.0 * double(step) * (o1 + o2) * inv_area),
          box.lo[a], box.hi[a], step,
          // Planes computed as lo + i * step are monotone in i; every plane must keep
          // min_width_ from the node's faces (checked one by one only when the bins are that thin).
          step >= min_step,
          // Nodes of few references (all binned): no plane that keeps them all on one side and
          // duplicates some into the other (KdBuildOptions::cluster_refs).
          n <= cluster_refs_ && binned == n};
      if (sparse) {
        sweep_sparse(axis, hist.tracked() ? hist.occupied(a) : occupied_bins(axis), a, best_cost, best);
      } else {
        sweep(axis, a, best_cost, best);
      }
    }
    if (best.axis < 0) return Split{};
    const double cost = binned == n ? double(best_cost)
                                    : options_.traversal_cost + (double(best_cost) - options_.traversal_cost) *
                                                                    double(n) / double(binned);
    const bool small = n <= size_t(std::max(0, options_.small_node_refs));
    if (!(cost < (small ? leaf_cost * (1.0 - double(small_split_gain_)) : leaf_cost))) return Split{};
    // The rays the tree is built for (KdBuildOptions::rays): a split that saves them less walking
    // than it costs to build is not made.
    if (rays_per_area_ > 0.0 && n <= rays_leaf_limit_ && !(rays_per_area_ * box_area * (leaf_cost - cost) > build_ref_cost_ * double(n))) {
      return Split{};
    }
    return best;
  }

  struct SweepAxis {
    const uint32_t* mins;  // per bin, then 8 zeros
    const uint32_t* maxs;
    int bins;
    uint32_t total;
    float c;               // P_below / P = c + g * i
    float g;
    float lo, hi, step;    // plane i at lo + i * step
    bool all_valid;        // every plane keeps min_width_ from the faces
    bool whole_fans;       // no plane with `total` references on one side and any on the other
  };

  // Plane i of an axis, with `below` and `above` references on its sides: the plane becomes the
  // best when its SAH cost is below best_cost (and it keeps min_width_ from the faces).
  void consider_plane(const SweepAxis& s, int i, uint32_t below, uint32_t above, int axis, float& best_cost,
                      Split& best) const {
    const int k = s.bins;
    if (s.whole_fans && ((below == s.total && above != 0) || (above == s.total && below != 0))) return;
    const float empty_min_bins = options_.empty_bonus_min_width * float(k);
    const float pb = s.c + s.g * float(i);
    const float pa = s.c + s.g * float(k - i);
    float cost = pb * float(below) + pa * float(above);
    if ((below == 0 && float(i) >= empty_min_bins) || (above == 0 && float(k - i) >= empty_min_bins)) {
      cost *= 1.0f - empty_bonus_;
    }
    cost = options_.traversal_cost + options_.intersection_cost * cost;
    if (cost < best_cost) {
      const float position = s.lo + float(i) * s.step;
      if (!s.all_valid && !(position - s.lo >= min_width_ && s.hi - position >= min_width_)) return;
      best_cost = cost;
      best.axis = axis;
      best.position = position;
    }
  }

  // Bit b set when bin b holds a min or a max (bins <= 64).
  static uint64_t occupied_bins(const SweepAxis& s) {
    uint64_t bits = 0;
#if defined(__SSE2__)
    const __m128i zero = _mm_setzero_si128();
    for (int b = 0; b < s.bins; b += 4) {
      const __m128i counts = _mm_or_si128(_mm_loadu_si128(reinterpret_cast<const __m128i*>(s.mins + b)),
                                          _mm_loadu_si128(reinterpret_cast<const __m128i*>(s.maxs + b)));
      const int empty = _mm_movemask_ps(_mm_castsi128_ps(_mm_cmpeq_epi32(counts, zero)));
      bits |= uint64_t(~empty & 0xF) << b;  // the padding's zeros leave bits past the last bin clear
    }
#else
    for (int b = 0; b < s.bins; ++b) bits |= uint64_t((s.mins[b] | s.maxs[b]) != 0) << b;
#endif
    return bits;
  }

  // sweep() for few references (bins <= 64): the candidate planes one by one, from a bit per
  // occupied bin, instead of every plane.
  void sweep_sparse(const SweepAxis& s, uint64_t events, int axis, float& best_cost, Split& best) const {
    const int k = s.bins;
    // Plane i is a candidate when bin i or bin i - 1 holds an event; planes 1 and k - 1 always.
    // Walked event by event (plane b before bin b's counts, plane b + 1 after), in increasing
    // order, each plane once: the planes of the bit-per-plane walk, with fewer bit operations.
    uint32_t below = 0;
    uint32_t ended = 0;
    int last = 0;  // the last plane considered
    if ((events & 1u) == 0) {
      consider_plane(s, 1, 0, s.total, axis, best_cost, best);
      last = 1;
    }
    for (uint64_t bins = events; bins != 0; bins &= bins - 1) {
      const int bin = std::countr_zero(bins);
      if (bin > last) {
        consider_plane(s, bin, below, s.total - ended, axis, best_cost, best);
        last = bin;
      }
      below += s.mins[bin];
      ended += s.maxs[bin];
      if (bin + 1 < k) {
        consider_plane(s, bin + 1, below, s.total - ended, axis, best_cost, best);
        last = bin + 1;
      }
    }
    if (last < k - 1) consider_plane(s, k - 1, below, s.total - ended, axis, best_cost, best);
  }

  // One axis of the sweep: the first candidate plane of it whose cost is below best_cost and
  // below every earlier candidate's becomes the best (the order of the first builder's loop).
  void sweep(const SweepAxis& s, int axis, float& best_cost, Split& best) const {
    const int k = s.bins;
#if defined(MOBIRT_KD_AVX2)
    if (avx2_) {
      sweep_avx2(s, axis, best_cost, best);
      return;
    }
#endif
#if defined(__SSE2__)
    const float trav = options_.traversal_cost;
    const float isect = options_.intersection_cost;
    const float empty_factor = 1.0f - empty_bonus_;
    const float empty_min_bins = options_.empty_bonus_min_width * float(k);
    // Planes i .. i + 3 in the lanes. The references below plane j are the minima in bins < j:
    // a running prefix sum of bins j - 1. Costs of planes that are not candidates (or past
    // k - 1, or too close to a face) become +inf; per lane the first smallest cost is kept with
    // its plane, then the smallest plane among the lanes that hold the smallest cost wins.
    const __m128i zero = _mm_setzero_si128();
    const __m128 one = _mm_set1_ps(1.0f);
    const __m128 inf = _mm_set1_ps(kInfinity);
    const __m128 kf = _mm_set1_ps(float(k));
    const __m128 c = _mm_set1_ps(s.c);
    const __m128 g = _mm_set1_ps(s.g);
    const __m128 min_bins = _mm_set1_ps(empty_min_bins);
    const __m128 factor = _mm_set1_ps(empty_factor);
    const __m128 vtrav = _mm_set1_ps(trav);
    const __m128 visect = _mm_set1_ps(isect);
    const __m128 lo = _mm_set1_ps(s.lo);
    const __m128 hi = _mm_set1_ps(s.hi);
    const __m128 step = _mm_set1_ps(s.step);
    const __m128 min_width = _mm_set1_ps(min_width_);
    const __m128i total = _mm_set1_epi32(static_cast<int32_t>(s.total));
    __m128i below_before = zero;
    __m128i ended_before = zero;
    __m128 fi = _mm_set_ps(4.0f, 3.0f, 2.0f, 1.0f);
    __m128 lane_best = inf;
    __m128 lane_plane = _mm_setzero_ps();
    for (int i = 1; i < k; i += 4, fi = _mm_add_ps(fi, _mm_set1_ps(4.0f))) {
      const __m128i min_prev = _mm_loadu_si128(reinterpret_cast<const __m128i*>(s.mins + i - 1));
      const __m128i max_prev = _mm_loadu_si128(reinterpret_cast<const __m128i*>(s.maxs + i - 1));
      const __m128i min_cur = _mm_loadu_si128(reinterpret_cast<const __m128i*>(s.mins + i));
      const __m128i max_cur = _mm_loadu_si128(reinterpret_cast<const __m128i*>(s.maxs + i));
      __m128i below = _mm_add_epi32(min_prev, _mm_slli_si128(min_prev, 4));
      below = _mm_add_epi32(_mm_add_epi32(below, _mm_slli_si128(below, 8)), below_before);
      __m128i ended = _mm_add_epi32(max_prev, _mm_slli_si128(max_prev, 4));
      ended = _mm_add_epi32(_mm_add_epi32(ended, _mm_slli_si128(ended, 8)), ended_before);
      below_before = _mm_shuffle_epi32(below, 0xFF);
      ended_before = _mm_shuffle_epi32(ended, 0xFF);
      const __m128i above = _mm_sub_epi32(total, ended);
      const __m128 fk = _mm_sub_ps(kf, fi);
      const __m128 pb = _mm_add_ps(c, _mm_mul_ps(g, fi));
      const __m128 pa = _mm_add_ps(c, _mm_mul_ps(g, fk));
      __m128 cost = _mm_add_ps(_mm_mul_ps(pb, _mm_cvtepi32_ps(below)), _mm_mul_ps(pa, _mm_cvtepi32_ps(above)));
      const __m128 empty =
          _mm_or_ps(_mm_and_ps(_mm_castsi128_ps(_mm_cmpeq_epi32(below, zero)), _mm_cmpge_ps(fi, min_bins)),
                    _mm_and_ps(_mm_castsi128_ps(_mm_cmpeq_epi32(above, zero)), _mm_cmpge_ps(fk, min_bins)));
      cost = _mm_or_ps(_mm_and_ps(empty, _mm_mul_ps(cost, factor)), _mm_andnot_ps(empty, cost));
      cost = _mm_add_ps(vtrav, _mm_mul_ps(visect, cost));
      // A candidate: an event in bin i or i - 1, or the first or the last plane; none past k - 1.
      const __m128i events = _mm_or_si128(_mm_or_si128(min_prev, max_prev), _mm_or_si128(min_cur, max_cur));
      __m128 candidate = _mm_or_ps(_mm_cmpeq_ps(fi, one), _mm_cmpeq_ps(fk, one));
      candidate = _mm_or_ps(candidate, _mm_andnot_ps(_mm_castsi128_ps(_mm_cmpeq_epi32(events, zero)),
                                                     _mm_castsi128_ps(_mm_set1_epi32(-1))));
      candidate = _mm_and_ps(candidate, _mm_and_ps(_mm_cmpge_ps(fk, one), _mm_cmpord_ps(cost, cost)));
      if (!s.all_valid) {
        const __m128 position = _mm_add_ps(lo, _mm_mul_ps(fi, step));
        candidate = _mm_and_ps(candidate, _mm_and_ps(_mm_cmpge_ps(_mm_sub_ps(position, lo), min_width),
                                                     _mm_cmpge_ps(_mm_sub_ps(hi, position), min_width)));
      }
      if (s.whole_fans) {
        const __m128i keeps_below = _mm_andnot_si128(_mm_cmpeq_epi32(above, zero), _mm_cmpeq_epi32(below, total));
        const __m128i keeps_above = _mm_andnot_si128(_mm_cmpeq_epi32(below, zero), _mm_cmpeq_epi32(above, total));
        candidate = _mm_andnot_ps(_mm_castsi128_ps(_mm_or_si128(keeps_below, keeps_above)), candidate);
      }
      const __m128 better = _mm_and_ps(candidate, _mm_cmplt_ps(cost, lane_best));
      lane_best = _mm_or_ps(_mm_and_ps(better, cost), _mm_andnot_ps(better, lane_best));
      lane_plane = _mm_or_ps(_mm_and_ps(better, fi), _mm_andnot_ps(better, lane_plane));
    }
    alignas(16) float costs[4];
    alignas(16) float planes[4];
    _mm_store_ps(costs, lane_best);
    _mm_store_ps(planes, lane_plane);
    take_best_lane(costs, planes, 4, s, axis, best_cost, best);
#else
    uint32_t below = 0;
    uint32_t ended = 0;  // references whose max lies in a bin below the plane
    for (int i = 1; i < k; ++i) {
      const uint32_t change_before = s.mins[i - 1] | s.maxs[i - 1];
      below += s.mins[i - 1];
      ended += s.maxs[i - 1];
      if (i > 1 && i + 1 < k && (change_before | s.mins[i] | s.maxs[i]) == 0) continue;
      consider_plane(s, i, below, s.total - ended, axis, best_cost, best);
    }
#endif
  }

  // The SIMD sweeps' lanes: the smallest cost, then the lowest plane, becomes the best plane of
  // the axis when it is below best_cost.
  static void take_best_lane(const float* costs, const float* planes, int lanes, const SweepAxis& s, int axis,
                             float& best_cost, Split& best) {
    int lane = 0;
    for (int j = 1; j < lanes; ++j) {
      if (costs[j] < costs[lane] || (costs[j] == costs[lane] && planes[j] < planes[lane])) lane = j;
    }
    if (costs[lane] < best_cost) {
      best_cost = costs[lane];
      best.axis = axis;
      best.position = s.lo + planes[lane] * s.step;
    }
  }

#if defined(MOBIRT_KD_AVX2)
  // sweep() eight planes at a time: the same arithmetic per plane (no FMA: target avx2 alone
  // does not enable it) and the same choice, the smallest cost and then the lowest plane, so the
  // same tree as the SSE2 sweep on any CPU. Halves the dense sweep, a third of a 100K build.
  __attribute__((target("avx2"))) void sweep_avx2(const SweepAxis& s, int axis, float& best_cost,
                                                  Split& best) const {
    const int k = s.bins;
    const __m256i zero = _mm256_setzero_si256();
    const __m256 one = _mm256_set1_ps(1.0f);
    const __m256 inf = _mm256_set1_ps(kInfinity);
    const __m256 kf = _mm256_set1_ps(float(k));
    const __m256 c = _mm256_set1_ps(s.c);
    const __m256 g = _mm256_set1_ps(s.g);
    const __m256 min_bins = _mm256_set1_ps(options_.empty_bonus_min_width * float(k));
    const __m256 factor = _mm256_set1_ps(1.0f - empty_bonus_);
    const __m256 vtrav = _mm256_set1_ps(options_.traversal_cost);
    const __m256 visect = _mm256_set1_ps(options_.intersection_cost);
    const __m256 lo = _mm256_set1_ps(s.lo);
    const __m256 hi = _mm256_set1_ps(s.hi);
    const __m256 step = _mm256_set1_ps(s.step);
    const __m256 min_width = _mm256_set1_ps(min_width_);
    const __m256i total = _mm256_set1_epi32(static_cast<int32_t>(s.total));
    const __m256i lane3 = _mm256_set1_epi32(3);
    const __m256i lane7 = _mm256_set1_epi32(7);
    __m256i below_before = zero;
    __m256i ended_before = zero;
    __m256 fi = _mm256_setr_ps(1.0f, 2.0f, 3.0f, 4.0f, 5.0f, 6.0f, 7.0f, 8.0f);
    __m256 lane_best = inf;
    __m256 lane_plane = _mm256_setzero_ps();
    for (int i = 1; i < k; i += 8, fi = _mm256_add_ps(fi, _mm256_set1_ps(8.0f))) {
      const __m256i min_prev = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(s.mins + i - 1));
      const __m256i max_prev = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(s.maxs + i - 1));
      const __m256i min_cur = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(s.mins + i));
      const __m256i max_cur = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(s.maxs + i));
      const __m256i events = _mm256_or_si256(_mm256_or_si256(min_prev, max_prev), _mm256_or_si256(min_cur, max_cur));
      // Eight planes next to no event, neither the first nor the last plane: none is a candidate
      // and the counts carried on do not change (small nodes leave whole groups of bins empty).
      if (i != 1 && i + 8 <= k - 1 && _mm256_testz_si256(events, events)) continue;
      // Inclusive prefix sums over the 8 lanes: within each half, then the low half's total
      // added to the high half.
      __m256i below = _mm256_add_epi32(min_prev, _mm256_slli_si256(min_prev, 4));
      below = _mm256_add_epi32(below, _mm256_slli_si256(below, 8));
      below = _mm256_add_epi32(below, _mm256_blend_epi32(zero, _mm256_permutevar8x32_epi32(below, lane3), 0xF0));
      below = _mm256_add_epi32(below, below_before);
      __m256i ended = _mm256_add_epi32(max_prev, _mm256_slli_si256(max_prev, 4));
      ended = _mm256_add_epi32(ended, _mm256_slli_si256(ended, 8));
      ended = _mm256_add_epi32(ended, _mm256_blend_epi32(zero, _mm256_permutevar8x32_epi32(ended, lane3), 0xF0));
      ended = _mm256_add_epi32(ended, ended_before);
      below_before = _mm256_permutevar8x32_epi32(below, lane7);
      ended_before = _mm256_permutevar8x32_epi32(ended, lane7);
      const __m256i above = _mm256_sub_epi32(total, ended);
      const __m256 fk = _mm256_sub_ps(kf, fi);
      const __m256 pb = _mm256_add_ps(c, _mm256_mul_ps(g, fi));
      const __m256 pa = _mm256_add_ps(c, _mm256_mul_ps(g, fk));
      __m256 cost = _mm256_add_ps(_mm256_mul_ps(pb, _mm256_cvtepi32_ps(below)),
                                  _mm256_mul_ps(pa, _mm256_cvtepi32_ps(above)));
      const __m256 empty = _mm256_or_ps(
          _mm256_and_ps(_mm256_castsi256_ps(_mm256_cmpeq_epi32(below, zero)), _mm256_cmp_ps(fi, min_bins, _CMP_GE_OQ)),
          _mm256_and_ps(_mm256_castsi256_ps(_mm256_cmpeq_epi32(above, zero)), _mm256_cmp_ps(fk, min_bins, _CMP_GE_OQ)));
      cost = _mm256_blendv_ps(cost, _mm256_mul_ps(cost, factor), empty);
      cost = _mm256_add_ps(vtrav, _mm256_mul_ps(visect, cost));
      __m256 candidate = _mm256_or_ps(_mm256_cmp_ps(fi, one, _CMP_EQ_OQ), _mm256_cmp_ps(fk, one, _CMP_EQ_OQ));
      candidate = _mm256_or_ps(candidate, _mm256_xor_ps(_mm256_castsi256_ps(_mm256_cmpeq_epi32(events, zero)),
                                                        _mm256_castsi256_ps(_mm256_set1_epi32(-1))));
      candidate = _mm256_and_ps(candidate, _mm256_and_ps(_mm256_cmp_ps(fk, one, _CMP_GE_OQ),
                                                         _mm256_cmp_ps(cost, cost, _CMP_ORD_Q)));
      if (!s.all_valid) {
        const __m256 position = _mm256_add_ps(lo, _mm256_mul_ps(fi, step));
        candidate = _mm256_and_ps(
            candidate, _mm256_and_ps(_mm256_cmp_ps(_mm256_sub_ps(position, lo), min_width, _CMP_GE_OQ),
                                     _mm256_cmp_ps(_mm256_sub_ps(hi, position), min_width, _CMP_GE_OQ)));
      }
      if (s.whole_fans) {
        const __m256i keeps_below = _mm256_andnot_si256(_mm256_cmpeq_epi32(above, zero), _mm256_cmpeq_epi32(below, total));
        const __m256i keeps_above = _mm256_andnot_si256(_mm256_cmpeq_epi32(below, zero), _mm256_cmpeq_epi32(above, total));
        candidate = _mm256_andnot_ps(_mm256_castsi256_ps(_mm256_or_si256(keeps_below, keeps_above)), candidate);
      }
      const __m256 better = _mm256_and_ps(candidate, _mm256_cmp_ps(cost, lane_best, _CMP_LT_OQ));
      lane_best = _mm256_blendv_ps(lane_best, cost, better);
      lane_plane = _mm256_blendv_ps(lane_plane, fi, better);
    }
    // take_best_lane's choice (the smallest cost, then the lowest plane) by shuffles instead of a
    // loop over the lanes, which was a tenth of the sweeps of a toaster build.
    const __m256 min_cost = min_lanes_avx2(lane_best);
    const __m256 tied = _mm256_cmp_ps(lane_best, min_cost, _CMP_EQ_OQ);
    const float cost = _mm256_cvtss_f32(min_cost);
    if (cost < best_cost) {
      best_cost = cost;
      best.axis = axis;
      best.position = s.lo + _mm256_cvtss_f32(min_lanes_avx2(_mm256_blendv_ps(inf, lane_plane, tied))) * s.step;
    }
  }

  // Every lane set to the smallest of v's eight.
  __attribute__((target("avx2"))) static __m256 min_lanes_avx2(__m256 v) {
    v = _mm256_min_ps(v, _mm256_permute2f128_ps(v, v, 1));
    v = _mm256_min_ps(v, _mm256_shuffle_ps(v, v, _MM_SHUFFLE(1, 0, 3, 2)));
    return _mm256_min_ps(v, _mm256_shuffle_ps(v, v, _MM_SHUFFLE(2, 3, 0, 1)));
  }
#endif

  // Sends each reference to the side(s) of the plane its box reaches, in order (so leaf lists stay
  // sorted by primitive index). Either output may be `refs` itself: each reference read adds at
  // most one to each side, after it has been read.
  template <class Sink>
  void partition(const Ref* refs, size_t n, const Box& box, Split split, Sink& below, Sink& above) const {
    const int a = split.axis;
    const float s = split.position;
    for (size_t i = 0; i < n; ++i) {
      const Ref r = refs[i];
      if (r.hi[a] < s) {
        below.push(r);
      } else if (r.lo[a] > s) {
        above.push(r);
      } else {
        straddle(r, box, split, below, above);
      }
    }
  }

  // A reference whose box reaches the plane: referenced on both sides, its box clipped to each
  // side's part of the triangle (split clipping) or cut at the plane.
  template <class Sink>
  void straddle(const Ref& r, const Box& box, Split split, Sink& below, Sink& above) const {
    const int a = split.axis;
    const float s = split.position;
    if (!options_.split_clipping) {
      below.push(r);
      above.push(r);
      return;
    }
    Ref rb = r;
    rb.hi[a] = s;
    Ref ra = r;
    ra.lo[a] = s;
    // A shape's part on each side is its box cut at the plane (rb, ra), conservative.
    if (r.lo[a] < s && s < r.hi[a] && size_t(r.prim) < positions_.size() / 3) {
      Box cb;
      Box ca;
      const glm::vec3* v = positions_.data() + 3 * size_t(r.prim);
      const int sides = options_.build == KdBuildMode::Fast ? kdclip::split_triangle(v, a, s, cb, ca)
                                                            : clip_and_split(v, box, a, s, cb, ca);
      const bool hit_b = (sides & 1) != 0;
      const bool hit_a = (sides & 2) != 0;
      if (hit_b || hit_a) {  // both empty can only be rounding: keep the box clip then
        if (hit_b && intersect(rb, cb)) below.push(rb);
        if (hit_a && intersect(ra, ca)) above.push(ra);
        return;
      }
    }
    below.push(rb);
    above.push(ra);
  }

  // r's box cut down to `box`; false when nothing is left.
  static bool intersect(Ref& r, const Box& box) {
#if defined(__SSE2__)
    // Two overlapping runs of four bounds, (lo xyz, hi x) and (lo z, hi xyz): max for the lows,
    // min for the highs, in std::max's and std::min's operand order (the same bits as the loop).
    const __m128 r0 = _mm_loadu_ps(r.lo);
    const __m128 r1 = _mm_loadu_ps(r.lo + 2);
    const __m128 b0 = _mm_loadu_ps(box.lo);
    const __m128 b1 = _mm_loadu_ps(box.lo + 2);
    const __m128 lows0 = _mm_castsi128_ps(_mm_setr_epi32(-1, -1, -1, 0));
    const __m128 lows1 = _mm_castsi128_ps(_mm_setr_epi32(-1, 0, 0, 0));
    const __m128 c0 = _mm_or_ps(_mm_and_ps(lows0, _mm_max_ps(b0, r0)), _mm_andnot_ps(lows0, _mm_min_ps(b0, r0)));
    const __m128 c1 = _mm_or_ps(_mm_and_ps(lows1, _mm_max_ps(b1, r1)), _mm_andnot_ps(lows1, _mm_min_ps(b1, r1)));
    _mm_storeu_ps(r.lo, c0);
    _mm_storeu_ps(r.lo + 2, c1);
    // lo xyz (c0's lanes 0-2) against hi xyz (c1's lanes 1-3).
    return (_mm_movemask_ps(_mm_cmpgt_ps(c0, _mm_shuffle_ps(c1, c1, _MM_SHUFFLE(3, 3, 2, 1)))) & 7) == 0;
#else
    bool empty = false;
    for (int a = 0; a < 3; ++a) {
      r.lo[a] = std::max(r.lo[a], box.lo[a]);
      r.hi[a] = std::min(r.hi[a], box.hi[a]);
      empty = empty || r.lo[a] > r.hi[a];
    }
    return !empty;
#endif
  }

  // ---- Layout -----------------------------------------------------------------------------------

  static void total(Part& part) {
    if (part.axis < 0) {
      part.node_total = part.nodes.size();
      part.prim_total = part.prims.size();
      return;
    }
    total(*part.below);
    total(*part.above);
    part.node_total = 1 + part.below->node_total + part.above->node_total;
    part.prim_total = part.below->prim_total + part.above->prim_total;
    Tally whole = part.tally;
    whole.add(part.below->tally);
    whole.add(part.above->tally);
    part.tally = whole;
  }

  static bool is_empty_leaf(const glm::vec4& node) {
    return node_texel::is_leaf(node) && node_texel::leaf_count(node) == 0.0f;
  }

  // Whether a part's first node (its root) is an empty leaf.
  static bool empty_root(const Part& part) {
    return part.axis < 0 && !part.nodes.empty() && is_empty_leaf(part.nodes.front());
  }

  // Depth first: a top node, its below child's part next, then its above child's part. The
  // empty-child flags are set here, the parts in parallel and each one's nodes still in cache,
  // the very flags of mark_empty_children (a serial pass over the whole tree after it, with a
  // cache miss per above child: 0.4 % of a 1M-triangle build's instructions, all on one thread).
  static void lay_out(const Part& part, size_t node_base, size_t prim_base, FlatKdTree& tree) {
    if (part.axis >= 0) {
      const size_t above = node_base + 1 + part.below->node_total;
      glm::vec4& node = tree.nodes[node_base];
      node = node_texel::interior(part.split, static_cast<float>(above), static_cast<float>(part.axis));
      node_texel::set_empty_flags(node, empty_root(*part.below), empty_root(*part.above));
      tbb::parallel_invoke([&] { lay_out(*part.below, node_base + 1, prim_base, tree); },
                           [&] { lay_out(*part.above, above, prim_base + part.below->prim_total, tree); });
      return;
    }
    const float node_offset = static_cast<float>(node_base);
    const float prim_offset = static_cast<float>(prim_base);
    glm::vec4* out = tree.nodes.data() + node_base;
    const std::vector<glm::vec4>& nodes = part.nodes;
    for (size_t i = 0; i < nodes.size(); ++i) {
      glm::vec4 node = nodes[i];
      // Exact: every index and every sum stays below 2^24 (checked before the layout).
      if (!node_texel::is_leaf(node)) {
        // Both children are in this part: the below one next, the above one at its local index.
        node_texel::set_empty_flags(node, is_empty_leaf(nodes[i + 1]),
                                    is_empty_leaf(nodes[static_cast<size_t>(node_texel::above_child(node))]));
        node_texel::above_child(node) += node_offset;
      } else if (node_texel::leaf_count(node) > 0.0f) {
        node_texel::leaf_first(node) += prim_offset;
      }
      out[i] = node;
    }
    // The leaves' primitives written straight into the texels the shader reads (write_triangles
    // wrote the triangle texels before the layout began).
    glm::vec4* entry = tree.leaf_prims.data() + prim_base * MOBIRT_TEXELS_PER_TRIANGLE;
    for (const int32_t prim : part.prims) {
      leaf_prim_texel::write(entry, triangle_texel::of(tree.triangles, prim), prim);
      entry += MOBIRT_TEXELS_PER_TRIANGLE;
    }
  }

  static bool is_finite(const glm::vec3& p) { return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z); }

  // The first non-finite vertex from triangle `first` on.
  Error non_finite_vertex(size_t first) const {
    size_t i = 3 * first;
    while (is_finite(positions_[i])) ++i;
    return Error(ErrorKind::BadInput, "kd-tree: triangle " + std::to_string(i / 3) + " vertex " +
                                          std::to_string(i % 3) + " has a non-finite position (NaN or infinity)");
  }

  Error too_many_nodes() const {
    return Error(ErrorKind::BadInput,
                 "kd-tree for " + count_text(triangle_count_) + " triangles needs more than " +
                     count_text(kKdIndexLimit) +
                     " nodes, the limit of exact float indices (2^24) in the node texture; "
                     "lower max_depth or raise max_leaf_prims");
  }

  Error too_many_prim_references() const {
    return Error(ErrorKind::BadInput,
                 "kd-tree for " + count_text(triangle_count_) + " triangles needs more than " +
                     count_text(kKdMaxLeafEntries) +
                     " leaf references, the limit of exact float indices (2^24) in the "
                     "leaf-primitive texture (" + std::to_string(MOBIRT_TEXELS_PER_TRIANGLE) +
                     " texels each); lower the depth limit (--max-depth)");
  }

  std::span<const glm::vec3> positions_;
  std::span<const Shape> shapes_;
  const KdBuildOptions& options_;
  int bins_;
  size_t triangle_count_;
  int max_depth_ = 0;    // the hard limit: pbrt's depth limit plus kd_deep_levels
  int depth_limit_ = 0;  // pbrt's depth limit, past which only nodes of more than deep_refs_ split
  float min_width_ = std::numeric_limits<float>::min();
  // KdBuildOptions::rays per unit of the root's surface area (0: unbounded), and build_ref_cost.
  double rays_per_area_ = 0.0;
  double build_ref_cost_ = kKdBuildRefCost;
  size_t rays_leaf_limit_ = 0;
  bool avx2_ = false;  // the CPU runs sweep_avx2
  size_t sparse_refs_ = kSparseSweepRefs;
  float small_split_gain_ = 0.0f;  // options_.small_split_gain, the mode's when -1
  size_t max_leaf_prims_ = 1;      // kd_leaf_size(options_)
  size_t cluster_refs_ = 0;        // kd_cluster_refs(options_)
  float empty_bonus_ = 0.5f;       // kd_empty_bonus(options_)
  size_t deep_refs_ = 0;           // options_.deep_refs
  size_t subtree_refs_ = kSubtreeRefs;  // smaller nodes are built by one task with their subtree
  BufferPool pool_;
  tbb::enumerable_thread_specific<SubtreeScratch> scratch_;
};

}  // namespace

int kd_leaf_size(const KdBuildOptions& options) {
  if (options.max_leaf_prims >= 0) return options.max_leaf_prims;
  return options.build == KdBuildMode::Fast ? kFastLeafSize : 1;
}

double kd_build_ref_cost(const KdBuildOptions& options) {
  return options.build_ref_cost >= 0.0 ? options.build_ref_cost : kKdBuildRefCost;
}

int kd_cluster_refs(const KdBuildOptions& options) {
  if (options.cluster_refs >= 0) return options.cluster_refs;
  return options.build == KdBuildMode::Fast ? kFastClusterRefs : 0;
}

float kd_empty_bonus(const KdBuildOptions& options) {
  if (options.empty_bonus >= 0.0f) return options.empty_bonus;
  return options.build == KdBuildMode::Fast && options.rays > 0.0 ? kKdWalksEmptyBonus : 0.5f;
}

int kd_deep_levels(const KdBuildOptions& options) {
  if (options.deep_levels >= 0) return options.deep_levels;
  return options.build == KdBuildMode::Fast ? kFastDeepLevels : 0;
}

const char* kd_build_mode_name(KdBuildMode mode) { return mode == KdBuildMode::Fast ? "fast" : "quality"; }

bool parse_kd_build_mode(std::string_view text, KdBuildMode& mode) {
  for (KdBuildMode m : {KdBuildMode::Quality, KdBuildMode::Fast}) {
    if (text == kd_build_mode_name(m)) {
      mode = m;
      return true;
    }
  }
  return false;
}

int kdtree_depth_limit(size_t triangle_count, int max_depth_option) {
  if (max_depth_option >= 0) return max_depth_option;
  int log2n = 0;
  for (size_t n = triangle_count; n > 1; n >>= 1) ++log2n;
  return static_cast<int>(std::lround(8.0 + 1.3 * log2n));
}

FlatKdTree build_kdtree(std::span<const glm::vec3> positions, const KdBuildOptions& options) {
  return build_kdtree(positions, {}, options);
}

FlatKdTree build_kdtree(std::span<const glm::vec3> positions, std::span<const Shape> shapes,
                        const KdBuildOptions& options) {
  FlatKdTree tree;
  rebuild_kdtree(tree, positions, shapes, options);
  return tree;
}

namespace {

// Whole triangles, and no more primitives than exact float indices address: a build's and a
// flattening's first check.
void check_primitive_count(std::span<const glm::vec3> positions, std::span<const Shape> shapes) {
  if (positions.size() % 3 != 0) {
    throw Error(ErrorKind::BadInput, "kd-tree: " + count_text(positions.size()) +
                                         " positions do not make whole triangles (3 per triangle)");
  }
  const size_t n = positions.size() / 3 + shapes.size();
  if (n > kKdMaxTriangles) {
    throw Error(ErrorKind::BadInput,
                "kd-tree: " + count_text(n) + " triangles need " + count_text(3 * n) +
                    " triangle texels, more than the " + count_text(kKdIndexLimit) +
                    " that exact float indices (2^24) address; at most " +
                    count_text(kKdMaxTriangles) + " triangles");
  }
}

// rebuild_kdtree without its clean-up on an error.
void build_into(FlatKdTree& tree, std::span<const glm::vec3> positions, std::span<const Shape> shapes,
                const KdBuildOptions& options) {
  check_primitive_count(positions, shapes);
  // Non-finite positions are found by the build's parallel bounds pass (Builder::build_root).
  if (options.bins < 2) {
    throw Error(ErrorKind::BadInput,
                "kd-tree: bins must be at least 2 (got " + std::to_string(options.bins) + ")");
  }
  if (options.bins > kKdMaxBins) {  // each thread keeps two histograms per tree level
    throw Error(ErrorKind::BadInput, "kd-tree: bins must be at most " + std::to_string(kKdMaxBins) + " (got " +
                                         std::to_string(options.bins) + ")");
  }
  if (!(options.small_split_gain == -1.0f || (options.small_split_gain >= 0.0f && options.small_split_gain < 1.0f))) {
    throw Error(ErrorKind::BadInput, "kd-tree: small_split_gain must be in [0, 1), or -1 for the build mode's (got " +
                                         std::to_string(options.small_split_gain) + ")");
  }
  if (options.max_leaf_prims < -1) {
    throw Error(ErrorKind::BadInput, "kd-tree: max_leaf_prims must be -1 (the build mode's) or more (got " +
                                         std::to_string(options.max_leaf_prims) + ")");
  }
  if (!((options.empty_bonus >= 0.0f && options.empty_bonus < 1.0f) || options.empty_bonus == -1.0f)) {
    throw Error(ErrorKind::BadInput, "kd-tree: empty_bonus must be in [0, 1), or -1 for the build's (got " +
                                         std::to_string(options.empty_bonus) + ")");
  }
  if (options.cluster_refs < -1) {
    throw Error(ErrorKind::BadInput, "kd-tree: cluster_refs must be -1 (the build mode's) or more (got " +
                                         std::to_string(options.cluster_refs) + ")");
  }
  if (options.deep_levels < -1 || options.deep_levels > 32) {
    throw Error(ErrorKind::BadInput, "kd-tree: deep_levels must be -1 (the build mode's) to 32 (got " +
                                         std::to_string(options.deep_levels) + ")");
  }
  if (options.deep_refs < 0) {
    throw Error(ErrorKind::BadInput, "kd-tree: deep_refs must be 0 or more (got " +
                                         std::to_string(options.deep_refs) + ")");
  }
  if (!(options.rays >= 0.0 && std::isfinite(options.rays))) {
    throw Error(ErrorKind::BadInput, "kd-tree: rays must be 0 (unbounded) or a finite count (got " +
                                         std::to_string(options.rays) + ")");
  }
  if (!(options.build_ref_cost == -1.0 || (options.build_ref_cost >= 0.0 && std::isfinite(options.build_ref_cost)))) {
    throw Error(ErrorKind::BadInput, "kd-tree: build_ref_cost must be -1 (the default) or a finite cost of 0 or more (got " +
                                         std::to_string(options.build_ref_cost) + ")");
  }
  if (options.rays_leaf_limit < 0) {
    throw Error(ErrorKind::BadInput, "kd-tree: rays_leaf_limit must be 0 or more (got " +
                                         std::to_string(options.rays_leaf_limit) + ")");
  }
  if (options.threads < 0) {
    throw Error(ErrorKind::BadInput, "kd-tree: threads must be 0 (all) or more (got " +
                                         std::to_string(options.threads) + ")");
  }
  for (size_t k = 0; k < shapes.size(); ++k) {
    const Aabb box = shape_bounds(shapes[k]);
    if (!std::isfinite(box.lo.x + box.lo.y + box.lo.z + box.hi.x + box.hi.y + box.hi.z)) {
      throw Error(ErrorKind::BadInput, "kd-tree: shape " + std::to_string(k) + " has non-finite bounds");
    }
  }
  Builder builder(positions, shapes, options);
  if (options.threads == 0) {
    builder.build(tree);
  } else {
    // More threads than the machine has would only make TBB warn (the tree is the same anyway).
    tbb::task_arena arena(std::min(options.threads, tbb::info::default_concurrency()));
    arena.execute([&] { builder.build(tree); });
  }
}

}  // namespace

void flatten_primitives(FlatKdTree& tree, std::span<const glm::vec3> positions, std::span<const Shape> shapes) {
  tree.clear();
  try {
    check_primitive_count(positions, shapes);
    const size_t n = positions.size() / 3 + shapes.size();
    tree.triangles.resize(n * MOBIRT_TEXELS_PER_TRIANGLE);
    // The texels and the box in one parallel pass over the vertices; a non-finite vertex is
    // refused as the build refuses it.
    struct Box {
      Aabb box;
      size_t first_bad = SIZE_MAX;
    };
    const Box total = tbb::parallel_reduce(
        tbb::blocked_range<size_t>(0, positions.size(), 3 * 4096), Box{},
        [&](const tbb::blocked_range<size_t>& r, Box b) {
          for (size_t i = r.begin(); i < r.end(); ++i) {
            const glm::vec3& p = positions[i];
            tree.triangles[i] = glm::vec4(p, 0.0f);
            if (std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z)) {
              b.box.extend(p);
            } else {
              b.first_bad = std::min(b.first_bad, i);
            }
          }
          return b;
        },
        [](Box a, const Box& b) {
          a.box.extend(b.box);
          a.first_bad = std::min(a.first_bad, b.first_bad);
          return a;
        });
    if (total.first_bad != SIZE_MAX) {
      throw Error(ErrorKind::BadInput, "kd-tree: triangle " + std::to_string(total.first_bad / 3) + " vertex " +
                                           std::to_string(total.first_bad % 3) +
                                           " has a non-finite position (NaN or infinity)");
    }
    tree.bounds = total.box;
    glm::vec4* shape_out = tree.triangles.data() + positions.size();
    for (size_t k = 0; k < shapes.size(); ++k) {
      const Aabb box = shape_bounds(shapes[k]);
      if (!std::isfinite(box.lo.x + box.lo.y + box.lo.z + box.hi.x + box.hi.y + box.hi.z)) {
        throw Error(ErrorKind::BadInput, "kd-tree: shape " + std::to_string(k) + " has non-finite bounds");
      }
      tree.bounds.extend(box);
      shape_texels(shapes[k], shape_out + k * MOBIRT_TEXELS_PER_TRIANGLE);
    }
  } catch (...) {
    tree = FlatKdTree{};
    throw;
  }
}

void rebuild_kdtree(FlatKdTree& tree, std::span<const glm::vec3> positions, std::span<const Shape> shapes,
                    const KdBuildOptions& options) {
  try {
    build_into(tree, positions, shapes, options);
  } catch (...) {
    tree = FlatKdTree{};  // neither the previous tree nor a half-built one, and no memory kept
    throw;
  }
}

}  // namespace mobirt
