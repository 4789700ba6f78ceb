// Hit decoding: the traversal pass says which triangle each ray hit and which lights it sees; the
// CPU recomputes the hit on that one triangle (t, barycentrics, point, interpolated normal,
// texture coordinates, material) and hands it to the shading pass and the ray tree.
#pragma once

#include <glm/glm.hpp>

#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include "accel/kdtree.h"
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

// The traversal pass's lights as the shadow rays see them (shared by the GPU uniforms and the
// CPU fallback so that both test the same rays).
struct ShadowSettings {
  float epsilon = 1e-6f;  // origin offset along the geometric normal, as a share of the scene's size
};

// The self-intersection offset of a new ray's origin at p, along the geometric normal: `absolute`
// (epsilon x the scene box's largest side), but never below 2 float ulps of p (MOBIRT_OFFSET_ULPS
// x max |p|). Relative to the scene, so it holds from 1e-4 to 1e5; floored by float precision,
// so it holds 1e5 away from the origin. glsl/traverse.glsl computes the same.
float ray_offset(const glm::vec3& p, float absolute);
float scene_offset(const Aabb& bounds, float epsilon);  // epsilon x the box's largest side

// Shadow mask of a hit on the CPU, the same rays as glsl/traverse.glsl's shadow_mask().
uint32_t shadow_mask(const FlatKdTree& tree, std::span<const Light> lights, int32_t prim,
                     const Ray& ray, float t, const ShadowSettings& settings, int stack_depth);

// The shadow rays the traversal pass casts for this hit, one entry per light (none for a light
// that cannot light it), for profiling tools (tools/profile/simd_stats.cpp).
std::vector<std::optional<Ray>> shadow_rays(const FlatKdTree& tree, std::span<const Light> lights, int32_t prim,
                                            const Ray& ray, float t, const ShadowSettings& settings);

// How many shadow rays the traversal pass cast for this hit (for rays-per-second figures).
uint32_t shadow_ray_count(const FlatKdTree& tree, std::span<const Light> lights, int32_t prim,
                          const Ray& ray, float t, const ShadowSettings& settings);

struct DecodeStats {
  uint32_t hits = 0;
  uint64_t shadow_rays = 0;  // shadow rays the GPU cast for the hits it decided
  uint32_t capped = 0;   // rays the GPU loop cap stopped, traced on the CPU instead
};

// Decodes the read-back texels of one pass. Capped rays are traced on the CPU (closest hit and
// shadow mask), so a loop cap never changes the image.
// `lights`: the lights the pass cast shadow rays to (none when shadows are off).
std::vector<SurfaceHit> decode_hits(const Scene& scene, const FlatKdTree& tree, const RayBatch& rays,
                                    std::span<const uint32_t> texels, Packing packing,
                                    std::span<const Light> lights, const ShadowSettings& shadows,
                                    DecodeStats* stats = nullptr);

// The full surface record of a known hit (t and barycentrics recomputed on that one triangle).
SurfaceHit surface_hit(const Scene& scene, const FlatKdTree& tree, const Ray& ray, int32_t prim);

}  // namespace mobirt
