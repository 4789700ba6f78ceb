// Analytic primitives beside triangles: spheres and open truncated cones (a cylinder when both
// radii are equal), as Haines' NFF describes them. They share the kd-tree's 24-bit primitive index
// space with the triangles (a scene's shape k is primitive triangle_count + k) and its texel
// array (glsl/layout.h, MOBIRT_PRIM_*); this header holds what every stage derives from a shape
// alone: its texels, its bounds, its normal and its texture coordinates, in float or double.
#pragma once

#include <glm/glm.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "core/geometry.h"
#include "layout.h"

namespace mobirt {

enum class ShapeKind : uint8_t { Sphere, Cone };

struct Shape {
  ShapeKind kind = ShapeKind::Sphere;
  glm::vec3 base{0.0f};     // sphere: the centre; cone: the centre of the base circle
  float base_radius = 1.0f; // sphere: the radius (> 0); cone: the radius at `base` (>= 0)
  glm::vec3 apex{0.0f};     // cone: the centre of the apex circle (!= base); sphere: unused
  float apex_radius = 0.0f; // cone: the radius at `apex` (>= 0, not both 0)
  bool inside = false;      // the surface faces inwards (NFF's negative radii: "only the inside
                            // is visible"): decides which side a ray enters from (refraction)
  uint32_t material = 0;
  bool operator==(const Shape&) const = default;
};

// The frame of a cone, in float (its texels) or double (the reference): unit axis from base to
// apex, height, and the slope of the radius along the axis (radius(z) = base_radius + slope * z
// for z in [0, height]).
template <class T>
struct ConeFrame {
  glm::vec<3, T> axis{0, 0, 1};
  T height = 0;
  T slope = 0;
};
template <class T = float>
ConeFrame<T> cone_frame(const Shape& s) {
  ConeFrame<T> f;
  const glm::vec<3, T> d = glm::vec<3, T>(s.apex) - glm::vec<3, T>(s.base);
  f.height = glm::length(d);
  if (f.height > T(0)) {
    f.axis = d / f.height;
    f.slope = (T(s.apex_radius) - T(s.base_radius)) / f.height;
  }
  return f;
}

// The shape's MOBIRT_TEXELS_PER_TRIANGLE texels in the primitive array (glsl/layout.h).
static_assert(MOBIRT_PRIM_KIND == 3, "the kind is the w of the first texel");
inline void shape_texels(const Shape& s, glm::vec4* out) {
  if (s.kind == ShapeKind::Sphere) {
    out[0] = glm::vec4(s.base, float(MOBIRT_PRIM_SPHERE));
    out[1] = glm::vec4(s.base_radius, 0.0f, 0.0f, 0.0f);
    out[2] = glm::vec4(0.0f);
    return;
  }
  const ConeFrame<float> f = cone_frame(s);
  out[0] = glm::vec4(s.base, float(MOBIRT_PRIM_CONE));
  out[1] = glm::vec4(f.axis, f.height);
  out[2] = glm::vec4(s.base_radius, f.slope, 0.0f, 0.0f);
}

// A box holding the whole surface, padded by a few ulps of its size so that float rounding of
// the box (or of the hit point) never leaves a piece of the surface outside it.
inline Aabb shape_bounds(const Shape& s) {
  Aabb box;
  if (s.kind == ShapeKind::Sphere) {
    box.extend(s.base - glm::vec3(s.base_radius));
    box.extend(s.base + glm::vec3(s.base_radius));
  } else {
    // A circle of radius r about axis a reaches r sqrt(1 - a_i^2) along axis i.
    const glm::vec3 a = cone_frame(s).axis;
    const glm::vec3 reach = glm::sqrt(glm::max(glm::vec3(1.0f) - a * a, glm::vec3(0.0f)));
    box.extend(s.base - s.base_radius * reach);
    box.extend(s.base + s.base_radius * reach);
    box.extend(s.apex - s.apex_radius * reach);
    box.extend(s.apex + s.apex_radius * reach);
  }
  const glm::vec3 size = glm::max(glm::abs(box.lo), glm::abs(box.hi));
  const glm::vec3 pad = glm::vec3(std::max({size.x, size.y, size.z}) * 4.0f * 1.1920929e-7f);
  box.lo -= pad;
  box.hi += pad;
  return box;
}

// The unit normal at a point p on (or next to) the surface, outwards (inwards for `inside`).
// A cone's normal is the radial direction tilted against the slope; on the axis of a pointed
// apex, where the radial direction vanishes, the axis itself (turned against the slope).
template <class T>
glm::vec<3, T> shape_normal(const Shape& s, const glm::vec<3, T>& p) {
  using V = glm::vec<3, T>;
  V n(0.0);
  if (s.kind == ShapeKind::Sphere) {
    n = p - V(s.base);
  } else {
    const ConeFrame<T> f = cone_frame<T>(s);
    const V w = p - V(s.base);
    const V radial = w - glm::dot(w, f.axis) * f.axis;
    const T rl = glm::length(radial);
    n = rl > T(0) ? radial / rl - f.slope * f.axis : (f.slope > T(0) ? -f.axis : f.axis);
  }
  const T len = glm::length(n);
  n = len > T(0) && std::isfinite(len) ? n / len : V(0, 0, 1);
  return s.inside ? -n : n;
}

// Texture coordinates (glTF convention, v = 0 at the top): a sphere's longitude u in [0, 1) about
// +Y from +X towards +Z and its polar angle v = theta / pi from the +Y pole, as tessellate_sphere
// lays out its grid; a cone's angle u about its axis and v = 1 - z / height (v = 0 at the apex).
template <class T>
glm::vec<2, T> shape_texcoord(const Shape& s, const glm::vec<3, T>& p) {
  using V = glm::vec<3, T>;
  const T two_pi = T(6.283185307179586);
  if (s.kind == ShapeKind::Sphere) {
    const V d = p - V(s.base);
    const T len = glm::length(d);
    if (!(len > T(0))) return glm::vec<2, T>(0);
    T u = std::atan2(d.z, d.x) / two_pi;
    if (u < T(0)) u += T(1);
    const T v = std::acos(std::clamp(d.y / len, T(-1), T(1))) / T(3.141592653589793);
    return glm::vec<2, T>(u, v);
  }
  const ConeFrame<T> f = cone_frame<T>(s);
  const V a = f.axis;
  // The same (u, v, a) frame as tessellate_cone.
  const V e1 = glm::normalize(glm::cross(a, std::abs(a.x) < T(0.9) ? V(1, 0, 0) : V(0, 1, 0)));
  const V e2 = glm::cross(a, e1);
  const V w = p - V(s.base);
  T u = std::atan2(glm::dot(w, e2), glm::dot(w, e1)) / two_pi;
  if (u < T(0)) u += T(1);
  return glm::vec<2, T>(u, T(1) - glm::dot(w, a) / f.height);
}

}  // namespace mobirt
