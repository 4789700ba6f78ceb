// The CPU's shading and ray-tree maths, once for float (the CPU renderer, the ray tree) and double
// (the reference renderer): glsl/shade.glsl's Phong with its light falloff and spot cones,
// Schlick's Fresnel, Snell's refraction, the mirror direction and the split of a hit's weight
// between its mirror and refracted rays. The shaders keep their own copy, step for step.
#pragma once

#include <glm/glm.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <span>

#include "scene/scene.h"

namespace mobirt {

// The float instantiations must use the very constants the single-precision code always used.
static_assert(float(1e-4) == 1e-4f && float(1e-8) == 1e-8f);

// A point light's falloff at squared distance distance2: inverse square, windowed to 0 at `range`
// (glTF's KHR_lights_punctual; range 0 = unbounded).
template <typename T>
T light_falloff(T distance2, T range) {
  T window = T(1);
  if (range > T(0)) {
    const T r = distance2 / (range * range);
    window = std::clamp(T(1) - r * r, T(0), T(1));
    window *= window;
  }
  return window / std::max(distance2, T(1e-8));
}

// Phong with the shadow mask, as glsl/shade.glsl's shade_hit() computes it: ambient, then each
// light whose bit is set in mask. `view` is unit and points towards the viewer; `diffuse` is the
// material's, textured where it has a texture.
template <typename T>
glm::vec<3, T> phong(std::span<const Light> lights, const Material& m, const glm::vec<3, T>& diffuse,
                     const glm::vec<3, T>& position, const glm::vec<3, T>& normal, const glm::vec<3, T>& view,
                     uint32_t mask) {
  using V = glm::vec<3, T>;
  V color = T(m.ambient) * diffuse;
  for (size_t l = 0; l < lights.size(); ++l) {
    if (!(mask & (1u << l))) continue;
    const Light& light = lights[l];
    V to_light = -V(light.direction);
    T falloff = T(1);
    if (light.type != LightType::Directional) {
      to_light = V(light.position) - position;
      falloff = light_falloff(glm::dot(to_light, to_light), T(light.range));
    }
    const V l_dir = glm::normalize(to_light);
    if (light.type == LightType::Spot) {
      const T cos_outer = std::cos(T(light.outer_cone));
      const T cos_inner = std::cos(T(light.inner_cone));
      const T cone = std::clamp((glm::dot(-l_dir, V(light.direction)) - cos_outer) /
                                    std::max(cos_inner - cos_outer, T(1e-4)),
                                T(0), T(1));
      falloff *= cone * cone;
    }
    const T n_dot_l = glm::dot(normal, l_dir);
    if (n_dot_l <= T(0)) continue;
    const V r = T(2) * n_dot_l * normal - l_dir;
    const T spec = m.shininess > 0.0f ? std::pow(std::max(glm::dot(r, view), T(0)), T(m.shininess)) : T(0);
    color += falloff * V(light.color) * T(light.intensity) * (diffuse * n_dot_l + V(m.specular) * spec);
  }
  return color;
}

// Schlick's approximation of the Fresnel reflectance for a ray meeting a surface at cos_i, going
// from a medium of index n1 into one of n2.
template <typename T>
T schlick_fresnel(T cos_i, T n1, T n2) {
  T r0 = (n1 - n2) / (n1 + n2);
  r0 *= r0;
  T c = cos_i;
  if (n1 > n2) {
    // Leaving the denser medium: Schlick must use the angle on the less dense side.
    const T eta = n1 / n2;
    const T sin2_t = eta * eta * (T(1) - cos_i * cos_i);
    if (sin2_t >= T(1)) return T(1);
    c = std::sqrt(T(1) - sin2_t);
  }
  const T m = T(1) - c;
  return r0 + (T(1) - r0) * m * m * m * m * m;
}

// Refraction of unit direction d at unit normal n (facing against d), eta = n1 / n2. Returns false
// on total internal reflection (out untouched).
template <typename T>
bool refract_direction(const glm::vec<3, T>& d, const glm::vec<3, T>& n, T eta, glm::vec<3, T>& out) {
  const T cos_i = -glm::dot(d, n);
  const T k = T(1) - eta * eta * (T(1) - cos_i * cos_i);
  if (k < T(0)) return false;
  out = glm::normalize(eta * d + (eta * cos_i - std::sqrt(k)) * n);
  return true;
}

// The mirror direction of d about the shading normal ns; where that would go under the surface, about
// the geometric normal ng instead (both facing the incoming ray).
template <typename T>
glm::vec<3, T> mirror_direction(const glm::vec<3, T>& d, const glm::vec<3, T>& ns, const glm::vec<3, T>& ng) {
  glm::vec<3, T> r = d - T(2) * glm::dot(d, ns) * ns;
  if (glm::dot(r, ng) <= T(0)) r = d - T(2) * glm::dot(d, ng) * ng;
  return r;
}

// How a hit splits its ray's weight between the mirror ray and the refracted one (and its direction).
template <typename T>
struct WeightSplit {
  T reflect = T(0);
  T refract = T(0);
  glm::vec<3, T> refracted{T(0)};
  bool total_internal_reflection = false;
};

// The split on material m for unit direction d at shading normal ns and geometric normal ng (both
// facing the ray). Entering and leaving a medium are told apart by the geometric normal
// (`entering`); total internal reflection, or a shading normal bending the refracted ray back out,
// sends the refracted share into the mirror ray; with m.fresnel, Schlick moves part of it there.
template <typename T>
WeightSplit<T> split_weight(const Material& m, const glm::vec<3, T>& d, const glm::vec<3, T>& ns,
                            const glm::vec<3, T>& ng, bool entering) {
  WeightSplit<T> s;
  s.reflect = T(m.reflectance);
  s.refract = T(m.transmittance);
  if (m.transmittance > 0.0f) {
    const T n1 = entering ? T(1) : T(m.ior);
    const T n2 = entering ? T(m.ior) : T(1);
    if (!refract_direction(d, ns, n1 / n2, s.refracted) || glm::dot(s.refracted, ng) >= T(0)) {
      s.total_internal_reflection = true;
      s.reflect += s.refract;
      s.refract = T(0);
    } else if (m.fresnel) {
      const T f = schlick_fresnel(std::clamp(-glm::dot(d, ns), T(0), T(1)), n1, n2);
      s.reflect += s.refract * f;
      s.refract *= T(1) - f;
    }
  }
  return s;
}

}  // namespace mobirt
