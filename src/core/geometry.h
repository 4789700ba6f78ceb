// Rays and boxes in single precision, as the GPU passes see them.
#pragma once

#include <glm/glm.hpp>

#include <algorithm>
#include <limits>

namespace mobirt {

constexpr float kInfinity = std::numeric_limits<float>::infinity();

struct Ray {
  glm::vec3 origin{0.0f};
  glm::vec3 direction{0.0f, 0.0f, -1.0f};
  float tmin = 0.0f;
  float tmax = kInfinity;
};

struct Aabb {
  glm::vec3 lo{kInfinity};
  glm::vec3 hi{-kInfinity};

  bool empty() const { return lo.x > hi.x || lo.y > hi.y || lo.z > hi.z; }
  void extend(const glm::vec3& p) {
    lo = glm::min(lo, p);
    hi = glm::max(hi, p);
  }
  void extend(const Aabb& b) {
    lo = glm::min(lo, b.lo);
    hi = glm::max(hi, b.hi);
  }
  glm::vec3 extent() const { return empty() ? glm::vec3(0.0f) : hi - lo; }
  glm::vec3 center() const { return 0.5f * (lo + hi); }
  float surface_area() const {
    const glm::vec3 d = extent();
    return 2.0f * (d.x * d.y + d.y * d.z + d.z * d.x);
  }
  int longest_axis() const {
    const glm::vec3 d = extent();
    return d.x >= d.y && d.x >= d.z ? 0 : (d.y >= d.z ? 1 : 2);
  }
};

// Slab test; returns the parametric interval of the ray inside the box, clipped to [tmin, tmax].
// Division by a zero direction component gives +-inf, which the min/max handle (NaN from 0*inf is
// avoided by the origin-inside check of each slab being implied by the ordered comparisons).
inline bool intersect_aabb(const Aabb& box, const Ray& ray, float& t0, float& t1) {
  t0 = ray.tmin;
  t1 = ray.tmax;
  for (int a = 0; a < 3; ++a) {
    const float inv = 1.0f / ray.direction[a];
    float tn = (box.lo[a] - ray.origin[a]) * inv;
    float tf = (box.hi[a] - ray.origin[a]) * inv;
    if (tn > tf) std::swap(tn, tf);
    // NaN (origin on a slab plane with a zero direction component) compares false: keep t0/t1.
    t0 = tn > t0 ? tn : t0;
    t1 = tf < t1 ? tf : t1;
    if (t0 > t1) return false;
  }
  return true;
}

}  // namespace mobirt
