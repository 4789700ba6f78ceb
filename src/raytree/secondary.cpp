#include "raytree/secondary.h"

#include <algorithm>
#include <cmath>

namespace mobirt {

float schlick_fresnel(float cos_i, float n1, float n2) {
  float r0 = (n1 - n2) / (n1 + n2);
  r0 *= r0;
  float c = cos_i;
  if (n1 > n2) {
    // Leaving the denser medium: Schlick must use the angle on the less dense side.
    const float eta = n1 / n2;
    const float sin2_t = eta * eta * (1.0f - cos_i * cos_i);
    if (sin2_t >= 1.0f) return 1.0f;
    c = std::sqrt(1.0f - sin2_t);
  }
  const float m = 1.0f - c;
  return r0 + (1.0f - r0) * m * m * m * m * m;
}

bool refract_direction(const glm::vec3& d, const glm::vec3& n, float eta, glm::vec3& out) {
  const float cos_i = -glm::dot(d, n);
  const float k = 1.0f - eta * eta * (1.0f - cos_i * cos_i);
  if (k < 0.0f) return false;
  out = glm::normalize(eta * d + (eta * cos_i - std::sqrt(k)) * n);
  return true;
}

bool scene_has_secondary_rays(const Scene& scene) {
  for (const Material& m : scene.materials) {
    if (m.reflectance > 0.0f || m.transmittance > 0.0f) return true;
  }
  return false;
}

RayBatch next_generation(const Scene& scene, const Aabb& scene_bounds, const RayBatch& rays,
                         std::span<const SurfaceHit> hits, const SecondarySettings& settings,
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
    if (settings.offset.mode == OffsetMode::NormalUlp) {
      const glm::vec3* v = &scene.mesh.positions[3 * size_t(h.prim)];
      p = v[0] + h.u * (v[1] - v[0]) + h.v * (v[2] - v[0]);
    }
    const glm::vec3 above = offset_origin(p, ng, settings.offset.mode, absolute);
    const glm::vec3 below = offset_origin(p, -ng, settings.offset.mode, absolute);

    float reflect_share = m.reflectance;
    float refract_share = m.transmittance;
    glm::vec3 refracted(0.0f);
    if (m.transmittance > 0.0f) {
      // Entering when the ray meets the front face; leaving, the ratio flips.
      const float n1 = h.entering ? 1.0f : m.ior;
      const float n2 = h.entering ? m.ior : 1.0f;
      if (!refract_direction(d, ns, n1 / n2, refracted) || glm::dot(refracted, ng) >= 0.0f) {
        // Total internal reflection (or a shading normal bending the ray back out): all to the mirror.
        ++local.total_internal_reflections;
        reflect_share += refract_share;
        refract_share = 0.0f;
      } else if (m.fresnel) {
        const float f = schlick_fresnel(std::clamp(-glm::dot(d, ns), 0.0f, 1.0f), n1, n2);
        reflect_share += refract_share * f;
        refract_share *= 1.0f - f;
      }
    }
    if (reflect_share > 0.0f) {
      glm::vec3 r = d - 2.0f * glm::dot(d, ns) * ns;
      // A shading normal can send the mirror ray under the surface: fall back to the geometric one.
      if (glm::dot(r, ng) <= 0.0f) r = d - 2.0f * glm::dot(d, ng) * ng;
      emit(above, r, rays.pixel[i], weight * reflect_share, local.reflected);
    }
    if (refract_share > 0.0f) {
      emit(below, refracted, rays.pixel[i], weight * refract_share, local.refracted);
    }
  }
  if (stats) *stats = local;
  return next;
}

}  // namespace mobirt
