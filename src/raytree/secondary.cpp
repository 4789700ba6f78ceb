#include "raytree/secondary.h"

#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

#include "core/parallel.h"

namespace mobirt {

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
    // each ray about twice more) and unwritten (RayBatch::resize): each ray is written at `made`
    // and the arrays cut to the rays made at the end (push_back's four capacity checks a ray cost
    // more than the stores).
    RayBatch out;
    out.resize(2 * (end - begin));
    uint32_t made = 0;
    SecondaryStats local;
    // A new ray leaving p on the side `side` (+1: along the geometric normal ng, -1: against
    // it), its origin offset_origin's, made only for a ray that is not culled.
    auto emit = [&](const glm::vec3& p, const glm::vec3& ng, float side, const glm::vec3& direction, uint32_t pixel,
                    const glm::vec3& w, uint32_t& counter) {
      if (std::max(w.x, std::max(w.y, w.z)) < settings.min_weight) {
        ++local.culled;
        return;
      }
      out.origin[made] = glm::vec4(offset_origin(p, side * ng, settings.offset.mode, absolute), 0.0f);
      out.direction[made] = glm::vec4(direction, kInfinity);
      out.pixel[made] = pixel;
      out.weight[made] = w;
      ++made;
      ++counter;
    };
    for (uint32_t i = begin; i < end; ++i) {
      const SurfaceHit& h = hits[i];
      if (!h.valid()) continue;
      const Material& m = scene.materials[h.material];
      if (m.reflectance <= 0.0f && m.transmittance <= 0.0f) continue;
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
      if (split.total_internal_reflection) ++local.total_internal_reflections;
      if (split.reflect > 0.0f) {
        emit(p, ng, 1.0f, mirror_direction(d, ns, ng), rays.pixel[i], weight * split.reflect, local.reflected);
      }
      if (split.refract > 0.0f) {
        emit(p, ng, -1.0f, split.refracted, rays.pixel[i], weight * split.refract, local.refracted);
      }
    }
    out.resize(made);  // shrinks: nothing moves
    parts[c].rays = std::move(out);
    parts[c].stats = local;
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
