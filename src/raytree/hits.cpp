#include "raytree/hits.h"

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <string>

#include "core/error.h"
#include "core/half.h"
#include "core/parallel.h"
#include "texels.h"

namespace mobirt {

float scene_offset(const Aabb& bounds, float epsilon) {
  const glm::vec3 e = bounds.extent();
  return epsilon * std::max(e.x, std::max(e.y, e.z));
}

float absolute_offset(const Aabb& bounds, const SurfaceOffset& offset) {
  switch (offset.mode) {
    case OffsetMode::Fixed: return offset.epsilon;
    case OffsetMode::Scaled: return scene_offset(bounds, offset.epsilon);
    case OffsetMode::NormalUlp: break;
  }
  return 0.0f;
}

glm::vec3 offset_normal_ulp(const glm::vec3& p, const glm::vec3& n) {
  glm::vec3 out;
  for (int a = 0; a < 3; ++a) {
    if (std::abs(p[a]) < float(MOBIRT_WB_ORIGIN)) {
      out[a] = p[a] + float(MOBIRT_WB_FLOAT_SCALE) * n[a];
    } else {
      const int32_t ulps = int32_t(float(MOBIRT_WB_INT_SCALE) * n[a]);  // truncated, as in the paper
      out[a] = std::bit_cast<float>(std::bit_cast<int32_t>(p[a]) + (p[a] < 0.0f ? -ulps : ulps));
    }
  }
  return out;
}

namespace {

// The barycentric weights (u, v) of v0 + e1 and v0 + e2 where the ray (o, d) meets the triangle's
// plane, unbounded (Möller-Trumbore's formulas without its tests).
glm::vec2 plane_barycentrics(const glm::vec3& v0, const glm::vec3& e1, const glm::vec3& e2, const glm::vec3& o,
                             const glm::vec3& d) {
  const glm::vec3 p = glm::cross(d, e2);
  const float inv_det = 1.0f / glm::dot(e1, p);
  const glm::vec3 s = o - v0;
  return {glm::dot(s, p) * inv_det, glm::dot(d, glm::cross(s, e1)) * inv_det};
}

}  // namespace

glm::vec3 point_on_triangle(const glm::vec3& v0, const glm::vec3& e1, const glm::vec3& e2, const glm::vec3& o,
                            const glm::vec3& d) {
  const glm::vec2 uv = plane_barycentrics(v0, e1, e2, o, d);
  return v0 + uv.x * e1 + uv.y * e2;
}

glm::vec3 offset_origin(const glm::vec3& p, const glm::vec3& n, OffsetMode mode, float absolute,
                        Precision precision) {
  if (mode == OffsetMode::NormalUlp) return offset_normal_ulp(p, n);
  float offset = absolute;
  if (mode == OffsetMode::Scaled) {
    const glm::vec3 ap = glm::abs(p);
    const float ulps = precision == Precision::Medium ? float(MOBIRT_OFFSET_HALF_ULPS) : float(MOBIRT_OFFSET_ULPS);
    offset = std::max(offset, std::max(ap.x, std::max(ap.y, ap.z)) * ulps);
  }
  return p + offset * n;
}

namespace {

// Calls f(light index, shadow ray) for every light that can light the hit, exactly as
// glsl/traverse.glsl's shadow_mask() casts them: lights behind the surface (as seen from the ray)
// and points outside a spot's outer cone get no ray. Lights whose bit is set in `skip` are not
// looked at, and when that leaves none the hit's geometry is not computed either.
template <class F>
void for_each_shadow_ray(const FlatKdTree& tree, std::span<const Light> lights, int32_t prim,
                         const Ray& ray, float t, const ShadowSettings& settings, F&& f, uint32_t skip = 0) {
  const uint32_t all = lights.empty() ? 0u : (2u << (lights.size() - 1)) - 1u;
  if ((skip & all) == all) return;
  const glm::vec3 v0 = triangle_texel::vertex(tree.triangles, prim, 0);
  const glm::vec3 e1 = triangle_texel::vertex(tree.triangles, prim, 1) - v0;
  const glm::vec3 e2 = triangle_texel::vertex(tree.triangles, prim, 2) - v0;
  // Under mediump the pass sees its ray rounded to fp16, and rounds the hit point and the shadow
  // ray too.
  const bool half = settings.ray_test.precision == Precision::Medium;
  const glm::vec3 o = half ? round_to_half(ray.origin) : ray.origin;
  const glm::vec3 d = half ? round_to_half(ray.direction) : ray.direction;
  glm::vec3 p = settings.offset.mode == OffsetMode::NormalUlp ? point_on_triangle(v0, e1, e2, o, d) : o + t * d;
  glm::vec3 ng = glm::cross(e1, e2);
  // An analytic primitive: the point on the ray (every offset mode), the surface's normal there.
  if (is_analytic(tree, prim)) {
    p = o + t * d;
    ng = analytic_normal(tree, prim, half ? round_to_half(p) : p);
  }
  if (half) p = round_to_half(p);
  const float view_side = glm::dot(ng, d) < 0.0f ? 1.0f : -1.0f;
  const glm::vec3 n = (view_side / std::max(glm::length(ng), 1e-30f)) * ng;
  glm::vec3 origin = offset_origin(p, n, settings.offset.mode, absolute_offset(tree.bounds, settings.offset),
                                   settings.ray_test.precision);
  if (half) origin = round_to_half(origin);
  for (size_t l = 0; l < lights.size(); ++l) {
    if ((skip >> l) & 1u) continue;
    const Light& light = lights[l];
    const bool directional = light.type == LightType::Directional;
    const glm::vec3 to_light = directional ? -light.direction : light.position - origin;
    bool lit = glm::dot(ng, to_light) * view_side > 0.0f;
    if (lit && light.type == LightType::Spot) {
      lit = glm::dot(glm::normalize(-to_light), light.direction) > std::cos(light.outer_cone);
    }
    if (lit) f(l, Ray{origin, to_light, 0.0f, directional ? 3.0e38f : 1.0f});
  }
}

// The CPU fallback (capped rays, shadow rays with a full stack) must end even on a corrupt tree: a
// full-stack walk of a sound tree visits every node at most once and tests every primitive
// reference at most once, so more steps than this means a cycle (issue 8: never hang).
int64_t fallback_step_bound(const FlatKdTree& tree) {
  return 4 * int64_t(tree.nodes.size() + tree.prim_list.size()) + 64;
}

[[noreturn]] void corrupt_tree(int64_t bound) {
  throw Error(ErrorKind::Internal, "kd-tree corrupt: a CPU traversal took more than " + std::to_string(bound) +
                                       " steps (a cycle in the tree)");
}

}  // namespace

uint32_t shadow_mask(const FlatKdTree& tree, std::span<const Light> lights, int32_t prim,
                     const Ray& ray, float t, const ShadowSettings& settings, int stack_depth) {
  uint32_t mask = 0;
  if (prim < 0) return mask;
  for_each_shadow_ray(tree, lights, prim, ray, t, settings, [&](size_t l, const Ray& shadow) {
    TraversalStats stats;
    const int64_t bound = stack_depth < 0 ? fallback_step_bound(tree) : -1;
    if (!occluded(tree, shadow, stack_depth, stats, bound, settings.ray_test)) mask |= 1u << l;
    if (stats.capped) corrupt_tree(bound);
  });
  return mask;
}

uint32_t shadow_mask_with(const FlatKdTree& tree, std::span<const Light> lights, int32_t prim, const Ray& ray,
                          float t, const ShadowSettings& settings,
                          const std::function<bool(const Ray&)>& is_occluded) {
  uint32_t mask = 0;
  if (prim < 0) return mask;
  for_each_shadow_ray(tree, lights, prim, ray, t, settings, [&](size_t l, const Ray& shadow) {
    if (!is_occluded(shadow)) mask |= 1u << l;
  });
  return mask;
}

std::vector<std::optional<Ray>> shadow_rays(const FlatKdTree& tree, std::span<const Light> lights, int32_t prim,
                                            const Ray& ray, float t, const ShadowSettings& settings) {
  std::vector<std::optional<Ray>> rays(lights.size());
  if (prim < 0) return rays;
  for_each_shadow_ray(tree, lights, prim, ray, t, settings, [&](size_t l, const Ray& shadow) { rays[l] = shadow; });
  return rays;
}

uint32_t shadow_ray_count(const FlatKdTree& tree, std::span<const Light> lights, int32_t prim,
                          const Ray& ray, float t, const ShadowSettings& settings) {
  uint32_t count = 0;
  if (prim < 0) return count;
  for_each_shadow_ray(tree, lights, prim, ray, t, settings, [&](size_t, const Ray&) { ++count; });
  return count;
}

uint32_t shadow_rays_cast(const FlatKdTree& tree, std::span<const Light> lights, int32_t prim, const Ray& ray,
                          float t, const ShadowSettings& settings, uint32_t mask) {
  if (prim < 0 || lights.empty()) return 0;
  const uint32_t all = (2u << (lights.size() - 1)) - 1u;
  // A visible light's ray was cast: only the lights the mask calls hidden need the facing test.
  uint32_t count = uint32_t(std::popcount(mask & all));
  for_each_shadow_ray(tree, lights, prim, ray, t, settings, [&](size_t, const Ray&) { ++count; }, mask);
  return count;
}

SurfaceHit surface_hit(const Scene& scene, const FlatKdTree& tree, const Ray& ray, int32_t prim,
                       IntersectTest test) {
  Hit h;
  h.t = kInfinity;
  // Recompute on this one triangle; the range is opened so that a hit the GPU accepted at the edge
  // of [tmin, tmax] is still found (float rounding may differ slightly between the two).
  Ray open = ray;
  open.tmin = -kInfinity;
  open.tmax = kInfinity;
  // An analytic primitive keeps tmin: its other root may lie behind the ray's origin.
  const bool analytic = is_analytic(tree, prim);
  if (analytic) open.tmin = ray.tmin;
  // The decoding runs in single precision whatever the pass's precision (the paper's CPU step).
  // A triangle goes straight to its test: intersect_primitive would ask is_analytic again.
  const RayTest single{test, Precision::High};
  const bool found = analytic ? intersect_primitive(tree, prim, open, h, single)
                              : intersect_triangle(tree, prim, open, h, single);
  if (analytic && !found) {
    // Rounding put the GPU's grazing hit just outside the CPU's: the ray's closest approach to
    // the shape's base point (a sphere's centre), where a grazing ray touches it.
    const glm::vec3 c(triangle_texel::of(tree.triangles, prim)[0]);
    const float dd = glm::dot(ray.direction, ray.direction);
    h.t = dd > 0.0f ? std::max(ray.tmin, glm::dot(c - ray.origin, ray.direction) / dd) : ray.tmin;
    h.u = h.v = 0.0f;
  } else if (!found) {
    // The GPU's test accepted it and ours does not (an edge hit, rounding, mediump): use the
    // closest point the barycentric clamp gives; t from the plane.
    const glm::vec3 v0 = triangle_texel::vertex(tree.triangles, prim, 0);
    const glm::vec3 v1 = triangle_texel::vertex(tree.triangles, prim, 1);
    const glm::vec3 v2 = triangle_texel::vertex(tree.triangles, prim, 2);
    const glm::vec3 e1 = v1 - v0, e2 = v2 - v0;
    const glm::vec3 n = glm::cross(e1, e2);
    const float denom = glm::dot(n, ray.direction);
    h.t = denom != 0.0f ? glm::dot(n, v0 - ray.origin) / denom : ray.tmin;
    // The ray's barycentrics on the triangle's plane, clamped into the triangle: a ray on an edge
    // shared with the triangle our test chose keeps its texture coordinates (the centroid, used
    // before, put pinholes of the wrong texel on quads' diagonals under GLES).
    const glm::vec2 uv = plane_barycentrics(v0, e1, e2, ray.origin, ray.direction);
    float u = uv.x, v = uv.y;
    if (!(std::isfinite(u) && std::isfinite(v))) u = v = 1.0f / 3.0f;  // the ray in the plane
    u = std::max(u, 0.0f);
    v = std::max(v, 0.0f);
    if (u + v > 1.0f) {
      const float sum = u + v;
      u /= sum;
      v /= sum;
    }
    h.u = u;
    h.v = v;
    h.prim = prim;
  }
  h.prim = prim;
  return surface_from_hit(scene, ray, h);
}

SurfaceHit retrace_capped(const Scene& scene, const FlatKdTree& tree, const Ray& ray, std::span<const Light> lights,
                          const ShadowSettings& shadows) {
  TraversalStats steps;
  const Hit h = traverse(tree, ray, -1, steps, fallback_step_bound(tree), shadows.ray_test);
  if (steps.capped) corrupt_tree(fallback_step_bound(tree));
  if (!h.valid()) return {};
  SurfaceHit hit = surface_hit(scene, tree, ray, h.prim, shadows.ray_test.test);
  hit.mask = shadow_mask(tree, lights, h.prim, ray, h.t, shadows, -1);
  return hit;
}

SurfaceHit surface_from_hit(const Scene& scene, const Ray& ray, const Hit& h) {
  SurfaceHit hit;
  const int32_t prim = h.prim;
  hit.prim = prim;
  hit.t = h.t;
  hit.u = h.u;
  hit.v = h.v;
  hit.position = ray.origin + h.t * ray.direction;

  const TriangleMesh& mesh = scene.mesh;
  if (size_t(prim) >= mesh.triangle_count()) {  // an analytic shape: its own normal and (u, v)
    const Shape& shape = scene.shapes.at(size_t(prim) - mesh.triangle_count());
    const glm::vec3 n = shape_normal(shape, hit.position);
    hit.entering = glm::dot(n, ray.direction) < 0.0f;
    hit.geometric = hit.entering ? n : -n;
    hit.normal = hit.geometric;
    hit.texcoord = shape_texcoord(shape, hit.position);
    hit.material = shape.material;
    return hit;
  }
  const size_t i0 = size_t(prim) * 3;
  const float w = 1.0f - h.u - h.v;
  const glm::vec3 e1 = mesh.positions[i0 + 1] - mesh.positions[i0];
  const glm::vec3 e2 = mesh.positions[i0 + 2] - mesh.positions[i0];
  glm::vec3 ng = glm::cross(e1, e2);
  const float len = glm::length(ng);
  ng = len > 0.0f ? ng / len : -glm::normalize(ray.direction);
  hit.entering = glm::dot(ng, ray.direction) < 0.0f;
  hit.geometric = hit.entering ? ng : -ng;

  glm::vec3 n = ng;
  if (!mesh.normals.empty()) {
    n = w * mesh.normals[i0] + h.u * mesh.normals[i0 + 1] + h.v * mesh.normals[i0 + 2];
    const float nl = glm::length(n);
    n = nl > 1e-20f && std::isfinite(nl) ? n / nl : ng;
  }
  // The shading normal faces the same side as the geometric one seen from the ray.
  hit.normal = glm::dot(n, hit.geometric) < 0.0f ? -n : n;
  hit.material = mesh.material_ids[size_t(prim)];
  if (!mesh.texcoords.empty()) {
    const glm::vec2 uv = w * mesh.texcoords[i0] + h.u * mesh.texcoords[i0 + 1] + h.v * mesh.texcoords[i0 + 2];
    hit.texcoord = transform_texcoord(scene.materials[hit.material].texture_transform, uv);
  }
  return hit;
}

std::vector<SurfaceHit> decode_hits(const Scene& scene, const FlatKdTree& tree, const RayBatch& rays,
                                    std::span<const uint32_t> texels, Packing packing,
                                    std::span<const Light> lights, const ShadowSettings& shadows,
                                    DecodeStats* stats) {
  const uint32_t n = rays.count();
  if (texels.size() < n) throw Error(ErrorKind::Internal, "decode_hits: fewer texels than rays");
  const uint32_t prims = uint32_t(scene.primitive_count());
  std::vector<SurfaceHit> hits(n);
  std::atomic<uint32_t> hit_count{0}, capped_count{0};
  std::atomic<uint64_t> shadow_count{0};
  // Rays are independent: decoded on all cores in chunks (a capped ray's CPU retrace is the slow
  // case). Each chunk counts for itself and adds once: three atomic adds per hit on one cache line
  // shared by both cores cost more than the counting.
  constexpr uint32_t kChunk = 256;
  parallel_for((n + kChunk - 1) / kChunk, 0, [&](uint32_t c) {
    uint32_t chunk_hits = 0, chunk_capped = 0;
    uint64_t chunk_shadow = 0;
    const uint32_t end = std::min(n, (c + 1) * kChunk);
    for (uint32_t i = c * kChunk; i < end; ++i) {
      const TraceTexel texel = unpack_trace(packing, texels[i]);
      if (texel.capped) {
        ++chunk_capped;
        hits[i] = retrace_capped(scene, tree, rays.ray(i), lights, shadows);
        if (hits[i].valid()) ++chunk_hits;
        continue;
      }
      if (!texel.hit()) continue;
      const int32_t prim = texel.prim();
      if (uint32_t(prim) >= prims) {
        throw Error(ErrorKind::Internal, "traversal pass returned primitive " + std::to_string(prim) +
                                             " of a scene with " + std::to_string(prims));
      }
      ++chunk_hits;
      const Ray ray = rays.ray(i);
      SurfaceHit& hit = hits[i];
      hit = surface_hit(scene, tree, ray, prim, shadows.ray_test.test);
      hit.mask = texel.mask;
      chunk_shadow += shadow_rays_cast(tree, lights, prim, ray, hit.t, shadows, texel.mask);
    }
    hit_count.fetch_add(chunk_hits, std::memory_order_relaxed);
    capped_count.fetch_add(chunk_capped, std::memory_order_relaxed);
    shadow_count.fetch_add(chunk_shadow, std::memory_order_relaxed);
  }, 1);
  DecodeStats local;
  local.hits = hit_count.load();
  local.capped = capped_count.load();
  local.shadow_rays = shadow_count.load();
  if (stats) *stats = local;
  return hits;
}

}  // namespace mobirt
