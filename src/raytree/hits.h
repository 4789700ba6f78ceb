// Hit decoding: the traversal pass says which triangle each ray hit and which lights it sees; the
// CPU recomputes the hit on that one triangle (t, barycentrics, point, interpolated normal,
// texture coordinates, material) and hands it to the shading pass and the ray tree.
#pragma once

#include <glm/glm.hpp>

#include <cstddef>
#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <vector>

#include "accel/kdtree.h"
#include "core/memory.h"
#include "layout.h"
#include "raytree/packing.h"
#include "raytree/rays.h"
#include "scene/scene.h"

namespace mobirt {

struct SurfaceHit {
  int32_t prim = -1;          // -1 = miss
  float t = 0.0f;
  float u = 0.0f, v = 0.0f;   // barycentric weights of v1 and v2
  glm::vec3 position{0.0f};
  glm::vec3 normal{0.0f};     // interpolated shading normal, unit, turned to face the ray
  glm::vec3 geometric{0.0f};  // unit geometric normal, turned to face the ray
  bool entering = true;       // the ray hit the front face (geometric normal against the ray)
  glm::vec2 texcoord{0.0f};
  uint32_t material = 0;
  uint32_t mask = 0;          // shadow bits
  bool valid() const { return prim >= 0; }
};
// SurfaceHit as floats, for the eight-lane next generation (raytree/simd8.h's load_rows), which
// reads its vec3s as rows of four: each with the float after it, still inside the record.
inline constexpr uint32_t kSurfaceHitFloats = sizeof(SurfaceHit) / sizeof(float);
inline constexpr uint32_t kSurfaceHitPosition = offsetof(SurfaceHit, position) / sizeof(float);
inline constexpr uint32_t kSurfaceHitNormal = offsetof(SurfaceHit, normal) / sizeof(float);
inline constexpr uint32_t kSurfaceHitGeometric = offsetof(SurfaceHit, geometric) / sizeof(float);
static_assert(sizeof(SurfaceHit) % sizeof(float) == 0 &&
              offsetof(SurfaceHit, geometric) + 4 * sizeof(float) <= sizeof(SurfaceHit));

// Self-intersection offset of a ray that leaves a surface (shadow, mirror and refracted rays),
// along the geometric normal (glsl/layout.h, MOBIRT_OFFSET_*; --offset and --epsilon).
enum class OffsetMode {
  Fixed = MOBIRT_OFFSET_FIXED,          // epsilon in scene units
  Scaled = MOBIRT_OFFSET_SCALED,        // epsilon x the scene's size, at least 2 ulps of the point
  NormalUlp = MOBIRT_OFFSET_NORMAL_ULP  // Wachter and Binder 2019; epsilon unused
};
struct SurfaceOffset {
  OffsetMode mode = OffsetMode::Scaled;
  float epsilon = 1e-6f;
};

// How the traversal pass treats its rays: the shadow rays' origin offset, and the ray/triangle
// test of every ray it traces (shared by the GPU specialisation and uniforms and the CPU fallback,
// so that both test the same rays).
struct ShadowSettings {
  SurfaceOffset offset;
  RayTest ray_test;  // the ray/triangle test and its precision (--intersect, --precision)
};

// The absolute part of the offset, the traversal pass's uniform: epsilon (fixed), epsilon x the
// scene box's largest side (scaled, scene_offset), 0 (normal-ulp has none).
float absolute_offset(const Aabb& bounds, const SurfaceOffset& offset);
float scene_offset(const Aabb& bounds, float epsilon);  // epsilon x the box's largest side

// The origin of a ray leaving the surface at p on the side of the unit normal n; `absolute` from
// absolute_offset(). Scaled: p + max(absolute, 2 ulps of max |p|) n (fp16 ulps under mediump), so
// that it holds from scale 1e-4 to 1e5 and 1e5 away from the origin. glsl/offset.glsl computes
// the same.
glm::vec3 offset_origin(const glm::vec3& p, const glm::vec3& n, OffsetMode mode, float absolute,
                        Precision precision = Precision::High);

// The hit point of the ray (o, d) on the triangle (v0, v0 + e1, v0 + e2) from its barycentric
// coordinates, which normal-ulp offsets start from (as Wachter and Binder do): its error is
// relative to the vertices, where o + t d carries one relative to the ray's length.
glm::vec3 point_on_triangle(const glm::vec3& v0, const glm::vec3& e1, const glm::vec3& e2, const glm::vec3& o,
                            const glm::vec3& d);

// Wachter and Binder 2019 (Ray Tracing Gems, ch. 6): each component of p moved along n by
// int(256 n) units in the last place of its float representation (an integer added to its bits),
// or by n / 65536 where |p| < 1/32, where ulps get too small to clear the surface.
glm::vec3 offset_normal_ulp(const glm::vec3& p, const glm::vec3& n);

// Shadow mask of a hit on the CPU, the same rays as glsl/traverse.glsl's shadow_mask_of().
uint32_t shadow_mask(const FlatKdTree& tree, std::span<const Light> lights, int32_t prim,
                     const Ray& ray, float t, const ShadowSettings& settings, int stack_depth);

// The same shadow rays answered by another occlusion test (a CPU ray engine such as the Embree
// baseline). Only tree.triangles and tree.bounds are read, so a tree without nodes will do.
// shadow_mask_by_light: the test may differ by light, occluded(l, shadow ray) for light l (the
// renderer's CPU walks: light buffers for some lights, walks for others).
uint32_t shadow_mask_by_light(const FlatKdTree& tree, std::span<const Light> lights, int32_t prim, const Ray& ray,
                              float t, const ShadowSettings& settings,
                              const std::function<bool(size_t, const Ray&)>& occluded);
uint32_t shadow_mask_with(const FlatKdTree& tree, std::span<const Light> lights, int32_t prim, const Ray& ray,
                          float t, const ShadowSettings& settings,
                          const std::function<bool(const Ray&)>& is_occluded);

// The shadow rays the traversal pass casts for this hit, one entry per light (none for a light
// that cannot light it), for profiling tools (tools/profile/simd_stats.cpp).
std::vector<std::optional<Ray>> shadow_rays(const FlatKdTree& tree, std::span<const Light> lights, int32_t prim,
                                            const Ray& ray, float t, const ShadowSettings& settings);

// How many shadow rays the traversal pass cast for this hit (for rays-per-second figures).
uint32_t shadow_ray_count(const FlatKdTree& tree, std::span<const Light> lights, int32_t prim,
                          const Ray& ray, float t, const ShadowSettings& settings);

// The same count for a hit whose shadow mask the pass returned: every light whose bit is set got a
// ray, the others are tested as above. Equals shadow_ray_count() when the pass and the CPU agree
// on which lights face the hit (they may differ on a grazing light, where this one follows the
// pass). decode_hits() counts with it.
uint32_t shadow_rays_cast(const FlatKdTree& tree, std::span<const Light> lights, int32_t prim, const Ray& ray,
                          float t, const ShadowSettings& settings, uint32_t mask);

struct DecodeStats {
  uint32_t hits = 0;
  uint64_t shadow_rays = 0;  // shadow rays the GPU cast for the hits it decided
  uint32_t capped = 0;   // rays the GPU loop cap stopped, traced on the CPU instead
};

// The surface records of one generation of rays, made on all cores: a byte per ray that says
// whether it hit, and a record for each hit. A miss's record is neither written nor read:
// operator[] gives SurfaceHit{} for it. The wood doll's rays mostly miss, and writing a 72-byte
// record for each of its 91,000 misses in decoding, then reading them back, was about 8 % of its
// frame's CPU (perf); the bytes are 96 KB.
//
// Its size constructor and resize() write nothing (core/memory.h, UnwrittenAllocator): whoever
// fills it marks every ray, set() or set_miss(), from any number of threads (one ray each).
class SurfaceHits {
 public:
  SurfaceHits() = default;
  explicit SurfaceHits(uint32_t n) { resize(n); }
  // A copy of records that are all written (a miss: prim < 0).
  static SurfaceHits copy_of(std::span<const SurfaceHit> records);

  void resize(uint32_t n) {
    records_.resize(n);
    hit_.resize(n);
  }
  size_t size() const { return hit_.size(); }

  bool hit(uint32_t i) const { return hit_[i] != 0; }
  // Ray i's record; SurfaceHit{} for a miss.
  const SurfaceHit& operator[](uint32_t i) const { return hit_[i] != 0 ? records_[i] : kMiss; }
  // A byte per ray, 1 for a hit.
  const uint8_t* hit_flags() const { return hit_.data(); }

  // Ray i's record, or a miss when h is one.
  void set(uint32_t i, const SurfaceHit& h) {
    const bool valid = h.valid();
    if (valid) records_[i] = h;
    hit_[i] = valid ? 1 : 0;
  }
  void set_miss(uint32_t i) { hit_[i] = 0; }
  // The record of ray i, to be written or finished in place; set_hit(i) marks it a hit.
  SurfaceHit& record(uint32_t i) { return records_[i]; }
  SurfaceHit* records() { return records_.data(); }
  const SurfaceHit* records() const { return records_.data(); }  // a hit's record is hits[i]'s
  void set_hit(uint32_t i) { hit_[i] = 1; }

  class const_iterator {
   public:
    const_iterator(const SurfaceHits* hits, uint32_t i) : hits_(hits), i_(i) {}
    const SurfaceHit& operator*() const { return (*hits_)[i_]; }
    const_iterator& operator++() {
      ++i_;
      return *this;
    }
    bool operator!=(const const_iterator& o) const { return i_ != o.i_; }

   private:
    const SurfaceHits* hits_;
    uint32_t i_;
  };
  const_iterator begin() const { return {this, 0}; }
  const_iterator end() const { return {this, uint32_t(size())}; }

 private:
  static constinit inline const SurfaceHit kMiss{};
  std::vector<SurfaceHit, UnwrittenAllocator<SurfaceHit>> records_;
  std::vector<uint8_t, UnwrittenAllocator<uint8_t>> hit_;
};

// Decodes the read-back texels of one pass. Capped rays are traced on the CPU (closest hit and
// shadow mask), so a loop cap never changes the image.
// `lights`: the lights the pass cast shadow rays to (none when shadows are off). `mask_or` is
// OR-ed into every hit's shadow mask: the scene's lights when shadows are off, so that every light
// lights every surface facing it.
SurfaceHits decode_hits(const Scene& scene, const FlatKdTree& tree, const RayBatch& rays,
                        std::span<const uint32_t> texels, Packing packing, std::span<const Light> lights,
                        const ShadowSettings& shadows, DecodeStats* stats = nullptr, uint32_t mask_or = 0);

// A ray the GPU's loop cap stopped, traced on the CPU instead: the full-stack walk, the surface
// record and the shadow mask (a miss: prim -1). Throws Error(Internal) on a corrupt tree.
SurfaceHit retrace_capped(const Scene& scene, const FlatKdTree& tree, const Ray& ray, std::span<const Light> lights,
                          const ShadowSettings& shadows);

// The surface record of a hit whose t and barycentrics are known (hit.prim >= 0).
SurfaceHit surface_from_hit(const Scene& scene, const Ray& ray, const Hit& hit);

// The full surface record of a known hit (t and barycentrics recomputed on that one triangle with
// `test` in single precision).
SurfaceHit surface_hit(const Scene& scene, const FlatKdTree& tree, const Ray& ray, int32_t prim,
                       IntersectTest test = IntersectTest::MollerTrumbore);

}  // namespace mobirt
