#include "raytree/secondary.h"

#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

#include "core/parallel.h"
#include "raytree/simd8.h"

namespace mobirt {

namespace {

// One chunk's new rays, made in order into a batch sized for two rays a hit (unwritten,
// RayBatch::resize): each ray is written at `made` and the batch cut to the rays made at the end
// (push_back's four capacity checks a ray cost more than the stores).
struct RaySink {
  RayBatch out;
  uint32_t made = 0;
  SecondaryStats stats;
  float min_weight = 0.0f;

  bool culled(const glm::vec3& w) const { return std::max(w.x, std::max(w.y, w.z)) < min_weight; }
  // A new ray, made unless its weight is culled; `counter` counts the rays made.
  void add(const glm::vec4& origin, const glm::vec4& direction, uint32_t pixel, const glm::vec3& w, bool culled,
           uint32_t& counter) {
    if (culled) {
      ++stats.culled;
      return;
    }
    out.origin[made] = origin;
    out.direction[made] = direction;
    out.pixel[made] = pixel;
    out.weight[made] = w;
    ++made;
    ++counter;
  }
};

// One hit's rays, one at a time: split_weight(), mirror_direction() and offset_origin(), its
// mirror ray first.
void make_rays(const Scene& scene, const RayBatch& rays, uint32_t i, const SurfaceHit& h,
               const SecondarySettings& settings, float absolute, RaySink& sink) {
  const Material& m = scene.materials[h.material];
  const glm::vec3 d = glm::normalize(glm::vec3(rays.direction[i]));
  const glm::vec3 weight = rays.weight[i];
  // Normals face the incoming ray (hits.h); the shading normal bends the directions, the
  // geometric one decides which side of the surface each new ray starts on.
  const glm::vec3& ng = h.geometric;
  const glm::vec3& ns = h.normal;
  // Wachter and Binder's offset starts from the point on the triangle (point_on_triangle()).
  glm::vec3 p = h.position;
  if (settings.offset.mode == OffsetMode::NormalUlp && size_t(h.prim) < scene.mesh.triangle_count()) {
    const glm::vec3* v = &scene.mesh.positions[3 * size_t(h.prim)];
    p = v[0] + h.u * (v[1] - v[0]) + h.v * (v[2] - v[0]);
  }
  const WeightSplit<float> split = split_weight(m, d, ns, ng, h.entering);
  if (split.total_internal_reflection) ++sink.stats.total_internal_reflections;
  // The origin only for a ray made (past the weight cut), on the side it leaves to.
  const auto emit = [&](float side, const glm::vec3& direction, const glm::vec3& w, uint32_t& counter) {
    const bool culled = sink.culled(w);
    const glm::vec3 origin = culled ? p : offset_origin(p, side * ng, settings.offset.mode, absolute);
    sink.add(glm::vec4(origin, 0.0f), glm::vec4(direction, kInfinity), rays.pixel[i], w, culled, counter);
  };
  if (split.reflect > 0.0f) emit(1.0f, mirror_direction(d, ns, ng), weight * split.reflect, sink.stats.reflected);
  if (split.refract > 0.0f) emit(-1.0f, split.refracted, weight * split.refract, sink.stats.refracted);
}

#if defined(MOBIRT_SIMD8)
using namespace simd8;

__attribute__((target("avx2"))) inline __m256 load8(const float* v) { return _mm256_load_ps(v); }
__attribute__((target("avx2"))) inline V3 normalize(const V3& v) {
  return scale(_mm256_div_ps(_mm256_set1_ps(1.0f), _mm256_sqrt_ps(dot(v, v))), v);
}
// The lanes whose weight is cut: std::max(x, std::max(y, z)) < min_weight.
__attribute__((target("avx2"))) inline int culled_lanes(const V3& w, __m256 min_weight) {
  return _mm256_movemask_ps(_mm256_cmp_ps(std_max(w.x, std_max(w.y, w.z)), min_weight, _CMP_LT_OQ));
}
// make_rays() for the hits of rays ray[0..count) (count <= 8, each a hit on a material that
// reflects or refracts), eight at a time: split_weight(), mirror_direction() and offset_origin()
// (fixed or scaled) operation for operation in their order, so that every lane is the scalar
// result bit for bit (simd8.h), the rays added in the same order. A batch without glass (the
// toaster's floor, one mirror ray a hit) skips the refraction.
__attribute__((target("avx2"))) void make_rays_avx2(const Scene& scene, const RayBatch& rays,
                                                    const SurfaceHit* records, const uint32_t* ray, int count,
                                                    const SecondarySettings& settings, float absolute,
                                                    RaySink& sink) {
  uint32_t lane_ray[kLanes];
  alignas(32) float wx[kLanes], wy[kLanes], wz[kLanes], refl[kLanes], trans[kLanes], n1s[kLanes], n2s[kLanes];
  alignas(32) int32_t fresnel[kLanes];
  for (int k = 0; k < kLanes; ++k) {
    const uint32_t i = ray[k < count ? k : 0];  // a short batch repeats its first lane
    lane_ray[k] = i;
    const SurfaceHit& h = records[i];
    const Material& m = scene.materials[h.material];
    const glm::vec3& w = rays.weight[i];
    wx[k] = w.x;
    wy[k] = w.y;
    wz[k] = w.z;
    refl[k] = m.reflectance;
    trans[k] = m.transmittance;
    n1s[k] = h.entering ? 1.0f : m.ior;
    n2s[k] = h.entering ? m.ior : 1.0f;
    fresnel[k] = m.fresnel ? -1 : 0;
  }
  const float* base = reinterpret_cast<const float*>(records);
  const Offsets direction_at(lane_ray, 4, 0);
  const Offsets position_at(lane_ray, kSurfaceHitFloats, kSurfaceHitPosition);
  const Offsets normal_at(lane_ray, kSurfaceHitFloats, kSurfaceHitNormal);
  const Offsets geometric_at(lane_ray, kSurfaceHitFloats, kSurfaceHitGeometric);
  const V3 d = normalize(load_rows(&rays.direction[0].x, direction_at.at).xyz(0));
  const V3 p = load_rows(base, position_at.at).xyz(0);
  const V3 ns = load_rows(base, normal_at.at).xyz(0);
  const V3 ng = load_rows(base, geometric_at.at).xyz(0);
  const __m256 zero = _mm256_setzero_ps(), one = _mm256_set1_ps(1.0f), inf = _mm256_set1_ps(kInfinity);
  const __m256 min_weight = _mm256_set1_ps(sink.min_weight);
  const V3 w = {load8(wx), load8(wy), load8(wz)};
  const __m256 r = load8(refl), t = load8(trans);
  const __m256 has_t = _mm256_cmp_ps(t, zero, _CMP_GT_OQ);
  const int glass = _mm256_movemask_ps(has_t) & ((1 << count) - 1);

  // offset_origin(): the step along the geometric normal, offset * n (and offset * -n, its
  // negation: the origin below is p - step).
  __m256 offset = _mm256_set1_ps(absolute);
  if (settings.offset.mode == OffsetMode::Scaled) {
    const __m256 abs_mask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fffffff));
    const __m256 largest = std_max(_mm256_and_ps(p.x, abs_mask),
                                   std_max(_mm256_and_ps(p.y, abs_mask), _mm256_and_ps(p.z, abs_mask)));
    offset = std_max(offset, _mm256_mul_ps(largest, _mm256_set1_ps(float(MOBIRT_OFFSET_ULPS))));
  }
  const V3 step = scale(offset, ng);

  // split_weight(): refract_direction() with eta = n1 / n2, then Schlick where the material asks.
  __m256 reflect = r, refract = t, tir = zero;
  alignas(16) glm::vec4 below[kLanes], refracted[kLanes], refracted_weight[kLanes];
  int refracted_culled = 0;
  if (glass != 0) {
    const __m256 n1 = load8(n1s), n2 = load8(n2s);
    const __m256 eta = _mm256_div_ps(n1, n2);
    const __m256 eta2 = _mm256_mul_ps(eta, eta);
    const __m256 cos_i = negate(dot(d, ns));
    const __m256 under = _mm256_sub_ps(one, _mm256_mul_ps(eta2, _mm256_sub_ps(one, _mm256_mul_ps(cos_i, cos_i))));
    const __m256 bend = _mm256_sub_ps(_mm256_mul_ps(eta, cos_i), _mm256_sqrt_ps(under));
    const V3 bent = normalize(add(scale(eta, d), scale(bend, ns)));
    tir = _mm256_and_ps(has_t, _mm256_or_ps(_mm256_cmp_ps(under, zero, _CMP_LT_OQ),
                                            _mm256_cmp_ps(dot(bent, ng), zero, _CMP_GE_OQ)));
    // schlick_fresnel(clamp(cos_i, 0, 1), n1, n2).
    __m256 c0 = _mm256_blendv_ps(cos_i, zero, _mm256_cmp_ps(cos_i, zero, _CMP_LT_OQ));
    c0 = _mm256_blendv_ps(c0, one, _mm256_cmp_ps(one, c0, _CMP_LT_OQ));
    __m256 r0 = _mm256_div_ps(_mm256_sub_ps(n1, n2), _mm256_add_ps(n1, n2));
    r0 = _mm256_mul_ps(r0, r0);
    const __m256 dense = _mm256_cmp_ps(n1, n2, _CMP_GT_OQ);
    const __m256 sin2_t = _mm256_mul_ps(eta2, _mm256_sub_ps(one, _mm256_mul_ps(c0, c0)));
    const __m256 all_reflected = _mm256_and_ps(dense, _mm256_cmp_ps(sin2_t, one, _CMP_GE_OQ));
    const __m256 c = _mm256_blendv_ps(c0, _mm256_sqrt_ps(_mm256_sub_ps(one, sin2_t)), dense);
    const __m256 m = _mm256_sub_ps(one, c);
    __m256 tail = _mm256_mul_ps(_mm256_sub_ps(one, r0), m);
    for (int power = 1; power < 5; ++power) tail = _mm256_mul_ps(tail, m);
    const __m256 f = _mm256_blendv_ps(_mm256_add_ps(r0, tail), one, all_reflected);
    const __m256 fres = _mm256_andnot_ps(tir, _mm256_and_ps(has_t, load8(reinterpret_cast<const float*>(fresnel))));
    reflect = _mm256_blendv_ps(r, _mm256_add_ps(r, _mm256_mul_ps(t, f)), fres);
    reflect = _mm256_blendv_ps(reflect, _mm256_add_ps(r, t), tir);
    refract = _mm256_blendv_ps(t, _mm256_mul_ps(t, _mm256_sub_ps(one, f)), fres);
    refract = _mm256_blendv_ps(refract, zero, tir);
    lanes_to_vec4(sub(p, step), zero, &below[0].x);
    lanes_to_vec4(bent, inf, &refracted[0].x);
    const V3 refracted_w = scale(refract, w);
    lanes_to_vec4(refracted_w, zero, &refracted_weight[0].x);
    refracted_culled = culled_lanes(refracted_w, min_weight);
  }

  // mirror_direction(d, ns, ng).
  const __m256 two = _mm256_set1_ps(2.0f);
  const V3 about_ns = sub(d, scale(_mm256_mul_ps(two, dot(d, ns)), ns));
  const V3 about_ng = sub(d, scale(_mm256_mul_ps(two, dot(d, ng)), ng));
  const V3 mirror = select(_mm256_cmp_ps(dot(about_ns, ng), zero, _CMP_LE_OQ), about_ng, about_ns);
  alignas(16) glm::vec4 above[kLanes], mirrored[kLanes], mirror_weight[kLanes];
  lanes_to_vec4(add(p, step), zero, &above[0].x);
  lanes_to_vec4(mirror, inf, &mirrored[0].x);
  const V3 mirror_w = scale(reflect, w);
  lanes_to_vec4(mirror_w, zero, &mirror_weight[0].x);

  const int reflects = _mm256_movemask_ps(_mm256_cmp_ps(reflect, zero, _CMP_GT_OQ));
  const int refracts = _mm256_movemask_ps(_mm256_cmp_ps(refract, zero, _CMP_GT_OQ)) & glass;
  const int tirs = _mm256_movemask_ps(tir) & glass;
  const int mirror_culled = culled_lanes(mirror_w, min_weight);
  for (int k = 0; k < count; ++k) {
    const uint32_t pixel = rays.pixel[lane_ray[k]];
    if ((tirs >> k) & 1) ++sink.stats.total_internal_reflections;
    if ((reflects >> k) & 1) {
      sink.add(above[k], mirrored[k], pixel, glm::vec3(mirror_weight[k]), (mirror_culled >> k) & 1,
               sink.stats.reflected);
    }
    if ((refracts >> k) & 1) {
      sink.add(below[k], refracted[k], pixel, glm::vec3(refracted_weight[k]), (refracted_culled >> k) & 1,
               sink.stats.refracted);
    }
  }
}
#endif

}  // namespace

bool scene_has_secondary_rays(const Scene& scene) {
  for (const Material& m : scene.materials) {
    if (m.reflectance > 0.0f || m.transmittance > 0.0f) return true;
  }
  return false;
}

RayBatch next_generation(const Scene& scene, const Aabb& scene_bounds, const RayBatch& rays,
                         const SurfaceHits& hits, const SecondarySettings& settings,
                         SecondaryStats* stats) {
  const float absolute = absolute_offset(scene_bounds, settings.offset);
#if defined(MOBIRT_SIMD8)
  // Eight hits at a time where the CPU has AVX2 (make_rays_avx2: the same rays bit for bit), for
  // the offsets it has (normal-ulp's integer steps stay scalar).
  static const bool avx2 = __builtin_cpu_supports("avx2");
  const bool batched = avx2 && settings.offset.mode != OffsetMode::NormalUlp;
#endif
  // The rays' hits in chunks on all cores, each chunk's new rays in order in a part of its own,
  // then the parts one after the other: the rays of one loop over the hits, in its order. (One
  // loop on one core took 2.5-3.5 ms of the Embree column's toaster frame with 2 bounces, and as
  // long in every other column, which all make their rays here.)
  constexpr uint32_t kChunk = 2048;
  const uint32_t n = rays.count();
  const uint32_t chunks = chunk_count(n, kChunk);
  struct Part {
    RayBatch rays;
    SecondaryStats stats;
  };
  std::vector<Part> parts(chunks);
  parallel_for_chunks(n, kChunk, 0, [&](uint32_t c, uint32_t begin, uint32_t end) {
    // Made in locals and moved into the part at the end: neighbouring parts share cache lines.
    // Room for a mirror and a refracted ray per hit, made at once (arrays grown by doubling copied
    // each ray about twice more).
    RaySink sink;
    sink.out.resize(2 * (end - begin));
    sink.min_weight = settings.min_weight;
#if defined(MOBIRT_SIMD8)
    uint32_t batch[kLanes];
    int batch_size = 0;
#endif
    for (uint32_t i = begin; i < end; ++i) {
      const SurfaceHit& h = hits[i];
      if (!h.valid()) continue;
      const Material& m = scene.materials[h.material];
      if (m.reflectance <= 0.0f && m.transmittance <= 0.0f) continue;
#if defined(MOBIRT_SIMD8)
      if (batched) {
        batch[batch_size] = i;
        if (++batch_size == kLanes) {
          make_rays_avx2(scene, rays, hits.records(), batch, batch_size, settings, absolute, sink);
          batch_size = 0;
        }
        continue;
      }
#endif
      make_rays(scene, rays, i, h, settings, absolute, sink);
    }
#if defined(MOBIRT_SIMD8)
    if (batch_size > 0) make_rays_avx2(scene, rays, hits.records(), batch, batch_size, settings, absolute, sink);
#endif
    sink.out.resize(sink.made);  // shrinks: nothing moves
    parts[c].rays = std::move(sink.out);
    parts[c].stats = sink.stats;
  });

  std::vector<uint32_t> first(chunks + 1, 0);
  SecondaryStats total;
  for (uint32_t c = 0; c < chunks; ++c) {
    first[c + 1] = first[c] + parts[c].rays.count();
    const SecondaryStats& l = parts[c].stats;
    total.reflected += l.reflected;
    total.refracted += l.refracted;
    total.total_internal_reflections += l.total_internal_reflections;
    total.culled += l.culled;
  }
  RayBatch next;
  next.width = rays.width;
  next.resize(first[chunks]);  // unwritten: every part is copied in below
  parallel_for(chunks, 0, [&](uint32_t c) {
    const RayBatch& part = parts[c].rays;
    std::copy(part.origin.begin(), part.origin.end(), next.origin.begin() + first[c]);
    std::copy(part.direction.begin(), part.direction.end(), next.direction.begin() + first[c]);
    std::copy(part.pixel.begin(), part.pixel.end(), next.pixel.begin() + first[c]);
    std::copy(part.weight.begin(), part.weight.end(), next.weight.begin() + first[c]);
  }, 1);
  if (stats) *stats = total;
  return next;
}

}  // namespace mobirt
