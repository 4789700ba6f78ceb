#include "scene/tessellate.h"

#include <algorithm>
#include <cmath>

#include <glm/gtc/constants.hpp>

namespace mobirt {

namespace {

int rings_of(const Tessellation& t) { return std::max(2, t.segments / 2); }
int segments_of(const Tessellation& t) { return std::max(3, t.segments); }

// One triangle of the soup; texture coordinates stay in step when the mesh has them.
void push_triangle(TriangleMesh& mesh, const glm::vec3 (&p)[3], const glm::vec3 (&n)[3], uint32_t material) {
  for (int k = 0; k < 3; ++k) {
    mesh.positions.push_back(p[k]);
    mesh.normals.push_back(n[k]);
  }
  if (!mesh.texcoords.empty()) mesh.texcoords.resize(mesh.positions.size(), glm::vec2(0.0f));
  mesh.material_ids.push_back(material);
}

// Pushes (a, b, c), or (a, c, b) when `flip` (inside visible).
void push_oriented(TriangleMesh& mesh, bool flip, const glm::vec3& pa, const glm::vec3& na, const glm::vec3& pb,
                   const glm::vec3& nb, const glm::vec3& pc, const glm::vec3& nc, uint32_t material) {
  if (flip) {
    push_triangle(mesh, {pa, pc, pb}, {na, nc, nb}, material);
  } else {
    push_triangle(mesh, {pa, pb, pc}, {na, nb, nc}, material);
  }
}

}  // namespace

size_t sphere_triangle_count(const Tessellation& t) {
  return size_t(2) * size_t(segments_of(t)) * size_t(rings_of(t) - 1);
}

size_t cone_triangle_count(const Tessellation& t) { return size_t(2) * size_t(segments_of(t)); }

void tessellate_sphere(TriangleMesh& mesh, const glm::vec3& center, float radius, uint32_t material,
                       const Tessellation& t) {
  const int segments = segments_of(t);
  const int rings = rings_of(t);
  const bool inside = radius < 0.0f;
  const float r = std::abs(radius);
  const float sign = inside ? -1.0f : 1.0f;
  // Unit direction of grid point (ring i from the +Y pole, segment j).
  auto dir = [&](int i, int j) {
    if (i == 0) return glm::vec3(0.0f, 1.0f, 0.0f);
    if (i == rings) return glm::vec3(0.0f, -1.0f, 0.0f);
    const float theta = glm::pi<float>() * float(i) / float(rings);
    const float phi = glm::two_pi<float>() * float(j % segments) / float(segments);
    return glm::vec3(std::sin(theta) * std::cos(phi), std::cos(theta), std::sin(theta) * std::sin(phi));
  };
  for (int i = 0; i < rings; ++i) {
    for (int j = 0; j < segments; ++j) {
      const glm::vec3 da = dir(i, j), db = dir(i, j + 1), dc = dir(i + 1, j), dd = dir(i + 1, j + 1);
      // (a, b, c) and (b, d, c) face outwards; the first collapses at the north pole, the second
      // at the south pole.
      if (i > 0) {
        push_oriented(mesh, inside, center + r * da, sign * da, center + r * db, sign * db, center + r * dc,
                      sign * dc, material);
      }
      if (i + 1 < rings) {
        push_oriented(mesh, inside, center + r * db, sign * db, center + r * dd, sign * dd, center + r * dc,
                      sign * dc, material);
      }
    }
  }
}

void tessellate_cone(TriangleMesh& mesh, const glm::vec3& base, float base_radius, const glm::vec3& apex,
                     float apex_radius, uint32_t material, const Tessellation& t) {
  const int segments = segments_of(t);
  const glm::vec3 axis = apex - base;
  const float h = glm::length(axis);
  if (!(h > 0.0f)) return;
  const glm::vec3 a = axis / h;
  const bool inside = base_radius < 0.0f && apex_radius < 0.0f;
  const float rb = std::abs(base_radius), ra = std::abs(apex_radius);
  const float sign = inside ? -1.0f : 1.0f;
  // u, v, a right-handed, so that increasing phi turns counter-clockwise about the axis.
  const glm::vec3 u = glm::normalize(glm::cross(a, std::abs(a.x) < 0.9f ? glm::vec3(1, 0, 0) : glm::vec3(0, 1, 0)));
  const glm::vec3 v = glm::cross(a, u);
  auto radial = [&](int j) {
    const float phi = glm::two_pi<float>() * float(j % segments) / float(segments);
    return std::cos(phi) * u + std::sin(phi) * v;
  };
  // The side's normal is perpendicular to the slant a * h + radial * (ra - rb).
  auto normal = [&](const glm::vec3& d) { return sign * glm::normalize(d * h - a * (ra - rb)); };
  for (int j = 0; j < segments; ++j) {
    const glm::vec3 d0 = radial(j), d1 = radial(j + 1);
    const glm::vec3 n0 = normal(d0), n1 = normal(d1);
    const glm::vec3 b0 = base + rb * d0, b1 = base + rb * d1;
    const glm::vec3 a0 = apex + ra * d0, a1 = apex + ra * d1;
    if (rb > 0.0f) push_oriented(mesh, inside, b0, n0, b1, n1, a0, n0, material);
    if (ra > 0.0f) push_oriented(mesh, inside, b1, n1, a1, n1, a0, n0, material);
  }
}

void tessellate_shapes(Scene& scene, const Tessellation& t) {
  for (const Shape& s : scene.shapes) {
    const float sign = s.inside ? -1.0f : 1.0f;
    if (s.kind == ShapeKind::Sphere) {
      tessellate_sphere(scene.mesh, s.base, sign * s.base_radius, s.material, t);
    } else {
      tessellate_cone(scene.mesh, s.base, sign * s.base_radius, s.apex, sign * s.apex_radius, s.material, t);
    }
  }
  scene.shapes.clear();
}

glm::vec3 polygon_normal(const std::vector<glm::vec3>& polygon) {
  glm::dvec3 n(0.0);
  for (size_t i = 0; i < polygon.size(); ++i) {
    const glm::dvec3 p(polygon[i]), q(polygon[(i + 1) % polygon.size()]);
    n += glm::dvec3((p.y - q.y) * (p.z + q.z), (p.z - q.z) * (p.x + q.x), (p.x - q.x) * (p.y + q.y));
  }
  const double len = glm::length(n);
  return len > 0.0 && std::isfinite(len) ? glm::vec3(n / len) : glm::vec3(0.0f);
}

std::vector<uint32_t> triangulate_polygon(const std::vector<glm::vec3>& polygon) {
  std::vector<uint32_t> out;
  const size_t n = polygon.size();
  if (n < 3) return out;
  const glm::vec3 normal = polygon_normal(polygon);
  if (normal == glm::vec3(0.0f)) return out;
  // Project onto the plane of the two axes other than the normal's largest component, in the
  // order that keeps the polygon counter-clockwise when the normal points along +k.
  const glm::vec3 an = glm::abs(normal);
  const int k = an.x >= an.y && an.x >= an.z ? 0 : an.y >= an.z ? 1 : 2;
  const int ax = (k + 1) % 3, ay = (k + 2) % 3;
  const double orient = normal[k] > 0.0f ? 1.0 : -1.0;
  std::vector<glm::dvec2> p(n);
  for (size_t i = 0; i < n; ++i) p[i] = glm::dvec2(polygon[i][ax], orient * double(polygon[i][ay]));
  auto cross = [&](size_t a, size_t b, size_t c) {
    return (p[b].x - p[a].x) * (p[c].y - p[a].y) - (p[b].y - p[a].y) * (p[c].x - p[a].x);
  };

  // Convex (every turn left, one full turn): a fan, no search.
  bool convex = true;
  double turning = 0.0;
  for (size_t i = 0; i < n && convex; ++i) {
    const size_t a = (i + n - 1) % n, b = i, c = (i + 1) % n;
    if (cross(a, b, c) < 0.0) convex = false;
    const glm::dvec2 e0 = p[b] - p[a], e1 = p[c] - p[b];
    turning += std::atan2(e0.x * e1.y - e0.y * e1.x, glm::dot(e0, e1));
  }
  if (convex && std::abs(turning - glm::two_pi<double>()) < 1e-3) {
    for (uint32_t i = 1; i + 1 < n; ++i) out.insert(out.end(), {0u, i, i + 1});
    return out;
  }

  // Ear clipping over the remaining ring of vertices.
  std::vector<uint32_t> ring(n);
  for (uint32_t i = 0; i < n; ++i) ring[i] = i;
  auto inside = [&](size_t q, size_t a, size_t b, size_t c) {
    if (p[q] == p[a] || p[q] == p[b] || p[q] == p[c]) return false;
    return cross(a, b, q) >= 0.0 && cross(b, c, q) >= 0.0 && cross(c, a, q) >= 0.0;
  };
  size_t cursor = 0;
  size_t misses = 0;  // vertices tried since the last clip
  while (ring.size() > 3) {
    const size_t m = ring.size();
    const size_t i0 = (cursor + m - 1) % m, i1 = cursor % m, i2 = (cursor + 1) % m;
    const uint32_t a = ring[i0], b = ring[i1], c = ring[i2];
    const double turn = cross(a, b, c);
    bool ear = turn > 0.0;
    for (size_t j = 0; ear && j < m; ++j) {
      const uint32_t q = ring[j];
      if (q == a || q == b || q == c) continue;
      // Only a reflex (or straight) vertex can lie inside a candidate ear of a simple polygon.
      const uint32_t qa = ring[(j + m - 1) % m], qc = ring[(j + 1) % m];
      if (cross(qa, q, qc) > 0.0) continue;
      if (inside(q, a, b, c)) ear = false;
    }
    const bool stuck = misses >= m;
    if (ear || stuck) {
      // Stuck: a self-intersecting or numerically degenerate rest; a straight vertex goes without
      // a triangle, anything else is clipped anyway.
      if (!(stuck && !ear && std::abs(turn) <= 0.0)) out.insert(out.end(), {a, b, c});
      ring.erase(ring.begin() + std::ptrdiff_t(i1));
      cursor = i1 % ring.size();
      misses = 0;
    } else {
      cursor = i2;
      ++misses;
    }
  }
  out.insert(out.end(), {ring[0], ring[1], ring[2]});
  return out;
}

}  // namespace mobirt
