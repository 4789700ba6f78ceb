#include "raytree/secondary.h"

#include <algorithm>
#include <cmath>

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
  RayBatch next;
  next.width = rays.width;
  const float absolute = absolute_offset(scene_bounds, settings.offset);
  SecondaryStats local;
  auto emit = [&](const glm::vec3& origin, const glm::vec3& direction, uint32_t pixel, const glm::vec3& w,
                  uint32_t& counter) {
    if (std::max(w.x, std::max(w.y, w.z)) < settings.min_weight) {
      ++local.culled;
      return;
    }
    next.push(Ray{origin, direction, 0.0f, kInfinity}, pixel, w);
    ++counter;
  };
  for (uint32_t i = 0; i < rays.count(); ++i) {
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
    const glm::vec3 above = offset_origin(p, ng, settings.offset.mode, absolute);
    const glm::vec3 below = offset_origin(p, -ng, settings.offset.mode, absolute);

    const WeightSplit<float> split = split_weight(m, d, ns, ng, h.entering);
    if (split.total_internal_reflection) ++local.total_internal_reflections;
    if (split.reflect > 0.0f) {
      emit(above, mirror_direction(d, ns, ng), rays.pixel[i], weight * split.reflect, local.reflected);
    }
    if (split.refract > 0.0f) {
      emit(below, split.refracted, rays.pixel[i], weight * split.refract, local.refracted);
    }
  }
  if (stats) *stats = local;
  return next;
}

}  // namespace mobirt
