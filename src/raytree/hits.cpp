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

// Hit decoding has an AVX2 path for triangles, chosen at run time (the build targets baseline
// x86-64), as the kd-tree build's sweep does.
#include "raytree/simd8.h"
#if defined(MOBIRT_SIMD8)
#define MOBIRT_DECODE_AVX2 1
#endif

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
// glsl/traverse.glsl's shadow_mask_of() casts them: lights behind the surface (as seen from the ray)
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
  return 4 * int64_t(tree.nodes.size() + tree.leaf_entries()) + 64;
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

uint32_t shadow_mask_by_light(const FlatKdTree& tree, std::span<const Light> lights, int32_t prim, const Ray& ray,
                              float t, const ShadowSettings& settings,
                              const std::function<bool(size_t, const Ray&)>& occluded) {
  uint32_t mask = 0;
  if (prim < 0) return mask;
  for_each_shadow_ray(tree, lights, prim, ray, t, settings, [&](size_t l, const Ray& shadow) {
    if (!occluded(l, shadow)) mask |= 1u << l;
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
  // Counted a bit at a time: std::popcount is a libgcc call on baseline x86-64 (no POPCNT), and
  // the mask has one or two bits set.
  uint32_t count = 0;
  for (uint32_t visible = mask & all; visible != 0; visible &= visible - 1) ++count;
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

namespace {

#if defined(MOBIRT_DECODE_AVX2)
using namespace simd8;

// The shadow rays the traversal pass cast for a batch's hits, counted as shadow_rays_cast() does
// (for_each_shadow_ray's facing test for each light the mask calls hidden), where that test has a
// vector twin: single precision, offset fixed or scaled, no spot light (its cone needs a
// normalize). Elsewhere the caller counts with shadow_rays_cast().
struct ShadowCount {
  std::span<const Light> lights;
  OffsetMode mode = OffsetMode::Scaled;
  float absolute = 0.0f;  // absolute_offset()
  const uint32_t* mask = nullptr;  // the lanes' shadow masks
  uint64_t rays = 0;  // the sum over the lanes decoded
};

bool vector_shadow_count(std::span<const Light> lights, const ShadowSettings& settings) {
  if (settings.ray_test.precision != Precision::High || settings.offset.mode == OffsetMode::NormalUlp) return false;
  return std::none_of(lights.begin(), lights.end(), [](const Light& l) { return l.type == LightType::Spot; });
}

// A material's texture transform as decode_triangles_avx2's lanes read it (decode_hits() makes
// the table): m00, m10, m20, m01, m11, m21 of glm's columns m[c][r], and two floats of padding.
constexpr uint32_t kUvTransformFloats = 8;
// decode_triangles_avx2 stores a record's floats 0-15 as two rows of eight.
static_assert(offsetof(SurfaceHit, prim) == 0 && offsetof(SurfaceHit, t) == 4 && offsetof(SurfaceHit, u) == 8 &&
              offsetof(SurfaceHit, v) == 12 && offsetof(SurfaceHit, position) == 16 &&
              offsetof(SurfaceHit, normal) == 28 && offsetof(SurfaceHit, geometric) == 40 &&
              offsetof(SurfaceHit, entering) == 52 && sizeof(bool) == 1 && offsetof(SurfaceHit, texcoord) == 56 &&
              offsetof(SurfaceHit, material) == 64);

// Eight triangle hits at once: surface_hit()'s Möller-Trumbore re-test (intersect_mt<Exact> of
// src/accel/kdtree_traverse.cpp) and surface_from_hit()'s triangle branch, operation for
// operation in the same order, so every lane is bit for bit the scalar result (target avx2 alone,
// no FMA: nothing is contracted; sqrt and division round correctly in both). Lanes whose test
// fails or whose triangle is degenerate are left to the scalar path, which handles them (the
// clamped barycentrics, the ray's own direction as normal). The slow parts are divisions and
// square roots (7 per hit) and scattered loads of triangle data, which eight lanes share.
//
// Decodes the triangle hits of rays ray[0..count) on triangles prim[0..count) (count <= 8) into
// hits[ray[k]], the shadow mask aside. Returns the lanes done; the others need surface_hit().
__attribute__((target("avx2"))) uint32_t decode_triangles_avx2(const Scene& scene, const FlatKdTree& tree,
                                                               const RayBatch& rays, const uint32_t* ray,
                                                               const int32_t* prim, int count, SurfaceHit* hits,
                                                               const float* uv_transforms, ShadowCount* shadow) {
  // A short batch repeats its first lane, so that every load reads a real triangle.
  uint32_t ray_lane[kLanes], prim_lane[kLanes];
  for (int k = 0; k < kLanes; ++k) {
    ray_lane[k] = ray[k < count ? k : 0];
    prim_lane[k] = uint32_t(prim[k < count ? k : 0]);
  }
  const Offsets ray_at(ray_lane, 4, 0);
  const V3 o = load_rows(&rays.origin[0].x, ray_at.at).xyz(0);
  const V3 d = load_rows(&rays.direction[0].x, ray_at.at).xyz(0);

  // intersect_mt<Exact> on the open ray: [tmin, tmax] = [-inf, inf] leaves t < inf (closer_hit
  // against no hit) and not NaN.
  constexpr uint32_t kTriangleFloats = 4 * MOBIRT_TEXELS_PER_TRIANGLE;
  const float* texels = &tree.triangles[0].x;
  const V3 v0 = load_rows(texels, Offsets(prim_lane, kTriangleFloats, 0).at).xyz(0);
  const V3 e1 = sub(load_rows(texels, Offsets(prim_lane, kTriangleFloats, 4).at).xyz(0), v0);
  const V3 e2 = sub(load_rows(texels, Offsets(prim_lane, kTriangleFloats, 8).at).xyz(0), v0);
  const V3 p = cross(d, e2);
  const __m256 det = dot(e1, p);
  const __m256 inv_det = _mm256_div_ps(_mm256_set1_ps(1.0f), det);
  const V3 s = sub(o, v0);
  const __m256 u = _mm256_mul_ps(dot(s, p), inv_det);
  const __m256 v = _mm256_mul_ps(negate(dot(s, cross(d, e1))), inv_det);
  const __m256 t = _mm256_mul_ps(dot(e2, cross(s, e1)), inv_det);
  const __m256 zero = _mm256_setzero_ps(), one = _mm256_set1_ps(1.0f), inf = _mm256_set1_ps(kInfinity);
  __m256 ok = _mm256_cmp_ps(det, zero, _CMP_NEQ_OQ);
  ok = _mm256_and_ps(ok, _mm256_and_ps(_mm256_cmp_ps(u, zero, _CMP_GE_OQ), _mm256_cmp_ps(u, one, _CMP_LE_OQ)));
  ok = _mm256_and_ps(ok, _mm256_cmp_ps(v, zero, _CMP_GE_OQ));
  ok = _mm256_and_ps(ok, _mm256_cmp_ps(_mm256_add_ps(u, v), one, _CMP_LE_OQ));
  ok = _mm256_and_ps(ok, _mm256_cmp_ps(t, inf, _CMP_LT_OQ));

  // surface_from_hit()'s triangle branch. Its geometric normal is the cross product of the
  // scene's edges, which are the tree's (the build's write_triangles and flatten_primitives copy
  // the posed positions into the triangle texels as they are): e1 and e2 above, not three more
  // rows loaded. The corners' normals and texture coordinates (three vec3, 9 floats; three vec2,
  // 6 floats) are read with the last corner from one float before it (rows 1 to 3), so that no
  // load reads past an array's end.
  const V3 position = add(o, scale(t, d));
  const __m256 w = _mm256_sub_ps(_mm256_sub_ps(one, u), v);
  const TriangleMesh& mesh = scene.mesh;
  const Offsets corner0(prim_lane, 9, 0), corner1(prim_lane, 9, 3), corner2(prim_lane, 9, 5);
  const V3 ngt = cross(e1, e2);
  V3 ng = ngt;
  const __m256 len = _mm256_sqrt_ps(dot(ng, ng));
  ok = _mm256_and_ps(ok, _mm256_cmp_ps(len, zero, _CMP_GT_OQ));  // else the ray's direction: scalar
  ng = divide(ng, len);
  const __m256 entering = _mm256_cmp_ps(dot(ng, d), zero, _CMP_LT_OQ);
  const V3 geometric = negate_where(ng, _mm256_xor_ps(entering, _mm256_castsi256_ps(_mm256_set1_epi32(-1))));
  V3 n = ng;
  if (!mesh.normals.empty()) {
    const float* normals = &mesh.normals[0].x;
    const V3 interpolated = add(add(scale(w, load_rows(normals, corner0.at).xyz(0)),
                                    scale(u, load_rows(normals, corner1.at).xyz(0))),
                                scale(v, load_rows(normals, corner2.at).xyz(1)));
    const __m256 nl = _mm256_sqrt_ps(dot(interpolated, interpolated));
    const __m256 usable = _mm256_and_ps(_mm256_cmp_ps(nl, _mm256_set1_ps(1e-20f), _CMP_GT_OQ),
                                        _mm256_cmp_ps(nl, inf, _CMP_LT_OQ));
    n = select(usable, divide(interpolated, nl), ng);
  }
  const V3 normal = negate_where(n, _mm256_cmp_ps(dot(n, geometric), zero, _CMP_LT_OQ));
  __m256 tu = zero, tv = zero;
  const bool textured = !mesh.texcoords.empty();
  if (textured) {
    // Three vec2 corners, 6 floats: corners 0 and 1 in one load, corner 2 in rows 2 and 3 of
    // the load from float 2.
    const float* uvs = &mesh.texcoords[0].x;
    const Rows c01 = load_rows(uvs, Offsets(prim_lane, 6, 0).at);
    const Rows c2 = load_rows(uvs, Offsets(prim_lane, 6, 2).at);
    tu = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(w, c01.r[0]), _mm256_mul_ps(u, c01.r[2])),
                       _mm256_mul_ps(v, c2.r[2]));
    tv = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(w, c01.r[1]), _mm256_mul_ps(u, c01.r[3])),
                       _mm256_mul_ps(v, c2.r[3]));
  }

  const uint32_t done = uint32_t(_mm256_movemask_ps(ok)) & ((1u << count) - 1u);

  if (shadow && !shadow->lights.empty()) {
    // for_each_shadow_ray(): the point o + t d, the tree triangle's normal ng (ngt) turned to the
    // viewer and offset_origin() along it, then each light's facing test.
    const __m256 facing = _mm256_cmp_ps(dot(ngt, d), zero, _CMP_LT_OQ);
    const __m256 view_side = _mm256_blendv_ps(_mm256_set1_ps(-1.0f), one, facing);
    const __m256 tiny = _mm256_set1_ps(1e-30f);
    const __m256 turned = _mm256_div_ps(view_side, std_max(_mm256_sqrt_ps(dot(ngt, ngt)), tiny));
    const V3 toward = scale(turned, ngt);
    __m256 offset = _mm256_set1_ps(shadow->absolute);
    if (shadow->mode == OffsetMode::Scaled) {
      const __m256 abs_mask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fffffff));
      const __m256 largest = std_max(_mm256_and_ps(position.x, abs_mask),
                                     std_max(_mm256_and_ps(position.y, abs_mask), _mm256_and_ps(position.z, abs_mask)));
      offset = std_max(offset, _mm256_mul_ps(largest, _mm256_set1_ps(float(MOBIRT_OFFSET_ULPS))));
    }
    const V3 origin = add(position, scale(offset, toward));
    for (size_t l = 0; l < shadow->lights.size(); ++l) {
      const Light& light = shadow->lights[l];
      const V3 to_light = light.type == LightType::Directional
                              ? V3{_mm256_set1_ps(-light.direction.x), _mm256_set1_ps(-light.direction.y),
                                   _mm256_set1_ps(-light.direction.z)}
                              : sub(V3{_mm256_set1_ps(light.position.x), _mm256_set1_ps(light.position.y),
                                       _mm256_set1_ps(light.position.z)},
                                    origin);
      const __m256 lit = _mm256_cmp_ps(_mm256_mul_ps(dot(ngt, to_light), view_side), zero, _CMP_GT_OQ);
      uint32_t cast = uint32_t(_mm256_movemask_ps(lit));
      for (int k = 0; k < count; ++k) cast |= ((shadow->mask[k] >> l) & 1u) << k;  // visible: cast
      for (cast &= done; cast != 0; cast &= cast - 1) ++shadow->rays;
    }
  }

  // surface_from_hit()'s texture coordinate: transform_texcoord(), glm's M * (u, v, 1) in its order,
  // (m00 u + m10 v) + m20 1 and (m01 u + m11 v) + m21 1, with each lane's material's row of
  // `uv_transforms` (decode_hits()).
  uint32_t material_lane[kLanes];
  for (int k = 0; k < kLanes; ++k) material_lane[k] = mesh.material_ids[prim_lane[k]];
  if (textured) {
    const Rows m0 = load_rows(uv_transforms, Offsets(material_lane, kUvTransformFloats, 0).at);
    const Rows m1 = load_rows(uv_transforms, Offsets(material_lane, kUvTransformFloats, 4).at);
    const __m256 su = tu, sv = tv;
    tu = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(m0.r[0], su), _mm256_mul_ps(m0.r[1], sv)),
                       _mm256_mul_ps(m0.r[2], one));
    tv = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(m0.r[3], su), _mm256_mul_ps(m1.r[0], sv)),
                       _mm256_mul_ps(m1.r[1], one));
  }

  // The records' first sixteen floats (prim to texcoord, the static_assert above) as two rows of
  // eight per lane, transposed in registers and stored with one instruction each (the fifteen
  // fields stored one float at a time from an array, and the texture transform per hit, made this
  // function 15 % dearer). `entering` as the bool's byte 1 or 0 and its padding 0.
  const __m256 row_a[kLanes] = {_mm256_castsi256_ps(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(prim_lane))),
                                t,
                                u,
                                v,
                                position.x,
                                position.y,
                                position.z,
                                normal.x};
  const __m256 row_b[kLanes] = {normal.y,
                                normal.z,
                                geometric.x,
                                geometric.y,
                                geometric.z,
                                _mm256_and_ps(entering, _mm256_castsi256_ps(_mm256_set1_epi32(1))),
                                tu,
                                tv};
  __m256 lane_a[kLanes], lane_b[kLanes];
  transpose8(row_a, lane_a);
  transpose8(row_b, lane_b);
  for (uint32_t left = done; left != 0; left &= left - 1) {
    const int k = std::countr_zero(left);
    SurfaceHit& h = hits[ray[k]];
    float* record = reinterpret_cast<float*>(&h);
    _mm256_storeu_ps(record, lane_a[k]);
    _mm256_storeu_ps(record + 8, lane_b[k]);
    h.material = material_lane[k];
  }
  return done;
}
#endif

}  // namespace

SurfaceHits SurfaceHits::copy_of(std::span<const SurfaceHit> records) {
  SurfaceHits hits(uint32_t(records.size()));
  for (uint32_t i = 0; i < uint32_t(records.size()); ++i) hits.set(i, records[i]);
  return hits;
}

SurfaceHits decode_hits(const Scene& scene, const FlatKdTree& tree, const RayBatch& rays,
                        std::span<const uint32_t> texels, Packing packing, std::span<const Light> lights,
                        const ShadowSettings& shadows, DecodeStats* stats, uint32_t mask_or) {
  const uint32_t n = rays.count();
  if (texels.size() < n) throw Error(ErrorKind::Internal, "decode_hits: fewer texels than rays");
  const uint32_t prims = uint32_t(scene.primitive_count());
  SurfaceHits hits(n);  // every ray marked below, in parallel (a miss: no record written)
  std::atomic<uint32_t> hit_count{0}, capped_count{0};
  std::atomic<uint64_t> shadow_count{0};
  // Rays are independent: decoded on all cores in chunks (a capped ray's CPU retrace is the slow
  // case). Each chunk counts for itself and adds once: three atomic adds per hit on one cache line
  // shared by both cores cost more than the counting.
  constexpr uint32_t kChunk = 256;
#if defined(MOBIRT_DECODE_AVX2)
  // The AVX2 path re-tests with Möller-Trumbore; the watertight test stays scalar.
  static const bool avx2 = __builtin_cpu_supports("avx2");
  const bool batched = avx2 && shadows.ray_test.test == IntersectTest::MollerTrumbore;
  const bool batch_counts = vector_shadow_count(lights, shadows);
  const float absolute = absolute_offset(tree.bounds, shadows.offset);
  std::vector<float> uv_transforms(std::max<size_t>(scene.materials.size(), 1) * kUvTransformFloats, 0.0f);
  for (size_t m = 0; m < scene.materials.size(); ++m) {
    const glm::mat3& t = scene.materials[m].texture_transform;
    float* row = &uv_transforms[m * kUvTransformFloats];
    row[0] = t[0][0], row[1] = t[1][0], row[2] = t[2][0], row[3] = t[0][1], row[4] = t[1][1], row[5] = t[2][1];
  }
#endif
  const uint32_t triangles = uint32_t(scene.mesh.triangle_count());
  const uint32_t all_lights = lights.empty() ? 0u : (2u << (lights.size() - 1)) - 1u;
  parallel_for_chunks(n, kChunk, 0, [&](uint32_t, uint32_t begin, uint32_t end) {
    uint32_t chunk_hits = 0, chunk_capped = 0;
    uint64_t chunk_shadow = 0;
    // The last steps of a hit whose surface record is made: its mask and shadow-ray count.
    const auto finish = [&](uint32_t i, uint32_t mask) {
      SurfaceHit& hit = hits.record(i);
      hit.mask = mask | mask_or;
      // Every light visible (the common case): one ray each, what shadow_rays_cast() returns
      // without its call.
      if ((mask & all_lights) == all_lights) {
        chunk_shadow += lights.size();
      } else {
        chunk_shadow += shadow_rays_cast(tree, lights, hit.prim, rays.ray(i), hit.t, shadows, mask);
      }
    };
    const auto decode_scalar = [&](uint32_t i, int32_t prim, uint32_t mask) {
      hits.record(i) = surface_hit(scene, tree, rays.ray(i), prim, shadows.ray_test.test);
      hits.set_hit(i);
      finish(i, mask);
    };
#if defined(MOBIRT_DECODE_AVX2)
    uint32_t batch_ray[kLanes], batch_mask[kLanes];
    int32_t batch_prim[kLanes];
    int batch_size = 0;
    const auto flush = [&] {
      ShadowCount count{lights, shadows.offset.mode, absolute, batch_mask};
      const uint32_t done = decode_triangles_avx2(scene, tree, rays, batch_ray, batch_prim, batch_size, hits.records(),
                                                  uv_transforms.data(), batch_counts ? &count : nullptr);
      chunk_shadow += count.rays;
      for (int k = 0; k < batch_size; ++k) {
        if ((done >> k) & 1u) {
          hits.set_hit(batch_ray[k]);
          if (batch_counts) {
            hits.record(batch_ray[k]).mask = batch_mask[k] | mask_or;
          } else {
            finish(batch_ray[k], batch_mask[k]);
          }
        } else {
          decode_scalar(batch_ray[k], batch_prim[k], batch_mask[k]);
        }
      }
      batch_size = 0;
    };
#endif
    for (uint32_t i = begin; i < end; ++i) {
      const TraceTexel texel = unpack_trace(packing, texels[i]);
      if (texel.capped) {
        ++chunk_capped;
        SurfaceHit h = retrace_capped(scene, tree, rays.ray(i), lights, shadows);
        if (h.valid()) {
          h.mask |= mask_or;
          ++chunk_hits;
        }
        hits.set(i, h);
        continue;
      }
      if (!texel.hit()) {
        hits.set_miss(i);
        continue;
      }
      const int32_t prim = texel.prim();
      if (uint32_t(prim) >= prims) {
        throw Error(ErrorKind::Internal, "traversal pass returned primitive " + std::to_string(prim) +
                                             " of a scene with " + std::to_string(prims));
      }
      ++chunk_hits;
#if defined(MOBIRT_DECODE_AVX2)
      if (batched && uint32_t(prim) < triangles) {
        batch_ray[batch_size] = i;
        batch_prim[batch_size] = prim;
        batch_mask[batch_size] = texel.mask;
        if (++batch_size == kLanes) flush();
        continue;
      }
#endif
      decode_scalar(i, prim, texel.mask);
    }
#if defined(MOBIRT_DECODE_AVX2)
    if (batch_size > 0) flush();
#endif
    hit_count.fetch_add(chunk_hits, std::memory_order_relaxed);
    capped_count.fetch_add(chunk_capped, std::memory_order_relaxed);
    shadow_count.fetch_add(chunk_shadow, std::memory_order_relaxed);
  });
  DecodeStats local;
  local.hits = hit_count.load();
  local.capped = capped_count.load();
  local.shadow_rays = shadow_count.load();
  if (stats) *stats = local;
  return hits;
}

}  // namespace mobirt
