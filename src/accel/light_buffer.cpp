#include "accel/light_buffer.h"

#include <algorithm>
#include <cmath>
#include <numeric>

#include "accel/kdtree.h"

namespace mobirt {
namespace {

// Face f's coordinates of a direction: (u, v, w) with w along the face's axis (positive inside).
glm::dvec3 face_coords(int face, glm::dvec3 d) {
  switch (face) {
    case 0: return {-d.z, -d.y, d.x};
    case 1: return {d.z, -d.y, -d.x};
    case 2: return {d.x, d.z, d.y};
    case 3: return {d.x, -d.z, -d.y};
    case 4: return {d.x, -d.y, d.z};
    default: return {-d.x, -d.y, -d.z};
  }
}

int major_face(glm::vec3 d) {
  const glm::vec3 a = glm::abs(d);
  if (a.x >= a.y && a.x >= a.z) return d.x >= 0.0f ? 0 : 1;
  if (a.y >= a.z) return d.y >= 0.0f ? 2 : 3;
  return d.z >= 0.0f ? 4 : 5;
}

struct Bounds {
  double s0 = 1e300, t0 = 1e300, s1 = -1e300, t1 = -1e300;
};

// The directions of face `face` that triangle c (relative to the light) may cover, as a rectangle
// of the face's (u / w, v / w); false where none.
bool cover(int face, const glm::dvec3 (&c)[3], Bounds& b) {
  constexpr int kMax = 48;
  glm::dvec3 poly[2][kMax];
  int n = 3;
  for (int k = 0; k < 3; ++k) poly[0][k] = face_coords(face, c[k]);
  const double widen = 1.0 + kLightBufferFaceMargin;
  int cur = 0;
  // The pyramid |u| <= w widen, |v| <= w widen, clipped plane by plane (Sutherland-Hodgman).
  for (int plane = 0; plane < 4 && n > 0; ++plane) {
    auto dist = [&](const glm::dvec3& p) {
      switch (plane) {
        case 0: return p.z * widen - p.x;
        case 1: return p.z * widen + p.x;
        case 2: return p.z * widen - p.y;
        default: return p.z * widen + p.y;
      }
    };
    int m = 0;
    for (int i = 0; i < n; ++i) {
      const glm::dvec3& a = poly[cur][i];
      const glm::dvec3& b2 = poly[cur][(i + 1) % n];
      const double da = dist(a), db = dist(b2);
      if (da >= 0.0 && m < kMax) poly[1 - cur][m++] = a;
      if ((da < 0.0) != (db < 0.0) && m < kMax) poly[1 - cur][m++] = a + (b2 - a) * (da / (da - db));
    }
    n = m;
    cur = 1 - cur;
  }
  if (n == 0) return false;
  b = Bounds{};
  for (int i = 0; i < n; ++i) {
    const glm::dvec3& p = poly[cur][i];
    if (!(p.z > 1e-12 * (std::abs(p.x) + std::abs(p.y)))) {  // a point at the light: the whole face
      b = Bounds{-widen, -widen, widen, widen};
      return true;
    }
    b.s0 = std::min(b.s0, p.x / p.z);
    b.s1 = std::max(b.s1, p.x / p.z);
    b.t0 = std::min(b.t0, p.y / p.z);
    b.t1 = std::max(b.t1, p.y / p.z);
  }
  return true;
}

struct Rect {
  int face, x0, y0, x1, y1;
};

}  // namespace

uint32_t light_buffer_cell(const LightBuffer& lb, glm::vec3 d) {
  // In float, as the shader computes it (glsl/traverse.glsl, light_buffer_occluded).
  const int face = major_face(d);
  const glm::vec3 f = glm::vec3(face_coords(face, glm::dvec3(d)));
  const glm::vec4& w = lb.window[size_t(face)];
  const float x = (f.x / f.z - w.x) * w.z, y = (f.y / f.z - w.y) * w.w;
  const int r = lb.resolution;
  if (!(x >= 0.0f && y >= 0.0f && x < float(r) && y < float(r))) return kLightBufferOutside;
  return uint32_t((face * r + int(y)) * r + int(x));
}

double LightBuffer::mean_list() const {
  double sum = 0.0, squares = 0.0;
  for (size_t c = 0; c < cells(); ++c) {
    const double n = double(first[c + 1] - first[c]);
    sum += n;
    squares += n * n;
  }
  return sum > 0.0 ? squares / sum : 0.0;
}

bool light_buffer_occluded(const LightBuffer& lb, const FlatKdTree& tree, glm::vec3 origin, uint32_t* tests) {
  const Ray ray{origin, lb.light - origin, 0.0f, 1.0f};
  const uint32_t c = light_buffer_cell(lb, -ray.direction);
  if (tests) *tests = 0;
  if (c == kLightBufferOutside) return false;
  // Past the segment's end (a little beyond, for the rounding of the length): no triangle there
  // can meet it.
  const float end = glm::length(ray.direction) * (1.0f + 1e-4f);
  for (uint32_t k = lb.first[c]; k < lb.first[c + 1]; ++k) {
    if (lb.near[k] > end) break;
    if (tests) ++*tests;
    Hit h;
    if (intersect_triangle(tree, int32_t(lb.prims[k]), ray, h)) return true;
  }
  return false;
}

double point_triangle_distance(glm::dvec3 p, glm::dvec3 a, glm::dvec3 b, glm::dvec3 c) {
  const glm::dvec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = glm::dot(ab, ap), d2 = glm::dot(ac, ap);
  if (d1 <= 0.0 && d2 <= 0.0) return glm::length(p - a);
  const glm::dvec3 bp = p - b;
  const double d3 = glm::dot(ab, bp), d4 = glm::dot(ac, bp);
  if (d3 >= 0.0 && d4 <= d3) return glm::length(p - b);
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) return glm::length(p - (a + ab * (d1 / (d1 - d3))));
  const glm::dvec3 cp = p - c;
  const double d5 = glm::dot(ab, cp), d6 = glm::dot(ac, cp);
  if (d6 >= 0.0 && d5 <= d6) return glm::length(p - c);
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) return glm::length(p - (a + ac * (d2 / (d2 - d6))));
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) {
    return glm::length(p - (b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)))));
  }
  const double denom = va + vb + vc;
  if (!(std::abs(denom) > 0.0)) {  // degenerate: the nearest of its vertices and edges' ends
    return std::min({glm::length(p - a), glm::length(p - b), glm::length(p - c)});
  }
  const double v = vb / denom, w = vc / denom;
  return glm::length(p - (a + ab * v + ac * w));
}

LightBuffer build_light_buffer(std::span<const glm::vec3> positions, glm::vec3 light, int resolution) {
  LightBuffer lb;
  lb.light = light;
  lb.resolution = resolution;
  const size_t triangles = positions.size() / 3;
  const size_t cells = size_t(6) * resolution * resolution;
  const glm::dvec3 l(light);
  // Pass 1: each triangle's nearest distance to the light, its rectangle per face, and each face's
  // window (the union of its rectangles: the cells cover only the directions where triangles are).
  std::vector<float> tri_near(triangles);
  std::vector<std::pair<int, Bounds>> rects;
  std::vector<uint32_t> rect_tri;
  Bounds window[6];
  for (size_t t = 0; t < triangles; ++t) {
    const glm::dvec3 c[3] = {glm::dvec3(positions[3 * t]) - l, glm::dvec3(positions[3 * t + 1]) - l,
                             glm::dvec3(positions[3 * t + 2]) - l};
    const double d = point_triangle_distance(glm::dvec3(0.0), c[0], c[1], c[2]);
    float df = float(d);  // rounded down: a lower bound stays one
    if (double(df) > d) df = std::nextafter(df, 0.0f);
    tri_near[t] = df;
  }
  // Triangles in the order of their nearest distance: each cell's list is filled in that order.
  std::vector<uint32_t> order(triangles);
  std::iota(order.begin(), order.end(), 0u);
  std::sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return tri_near[a] < tri_near[b] || (tri_near[a] == tri_near[b] && a < b); });
  const double inner = 1.0 - kLightBufferFaceMargin;
  for (uint32_t t : order) {
    const glm::dvec3 c[3] = {glm::dvec3(positions[3 * t]) - l, glm::dvec3(positions[3 * t + 1]) - l,
                             glm::dvec3(positions[3 * t + 2]) - l};
    auto add = [&](int face, const Bounds& b) {
      rects.emplace_back(face, b);
      rect_tri.push_back(t);
      Bounds& w = window[face];
      w = {std::min(w.s0, b.s0), std::min(w.t0, b.t0), std::max(w.s1, b.s1), std::max(w.t1, b.t1)};
    };
    // A triangle through the light (or all but): a segment ending at the light may touch it from
    // any direction, so it goes into every cell of every face.
    const double extent = std::max({glm::length(c[1] - c[0]), glm::length(c[2] - c[0]), glm::length(c[2] - c[1])});
    if (!(double(tri_near[t]) > 1e-6 * extent)) {
      for (int f = 0; f < 6; ++f) add(f, Bounds{-2.0, -2.0, 2.0, 2.0});
      continue;
    }
    // Fast path: every vertex well inside one face's pyramid (the pyramid is convex, so the
    // triangle is too, away from the other faces' widened pyramids): its vertices' projections.
    const int face = major_face(glm::vec3(c[0]));
    Bounds b;
    bool inside = true;
    for (int k = 0; k < 3 && inside; ++k) {
      const glm::dvec3 f = face_coords(face, c[k]);
      if (!(f.z > 0.0) || std::abs(f.x) > inner * f.z || std::abs(f.y) > inner * f.z) {
        inside = false;
        break;
      }
      b.s0 = std::min(b.s0, f.x / f.z);
      b.s1 = std::max(b.s1, f.x / f.z);
      b.t0 = std::min(b.t0, f.y / f.z);
      b.t1 = std::max(b.t1, f.y / f.z);
    }
    if (inside) {
      add(face, b);
      continue;
    }
    for (int f = 0; f < 6; ++f) {
      if (cover(f, c, b)) add(f, b);
    }
  }
  for (int face = 0; face < 6; ++face) {
    const Bounds& w = window[face];
    if (w.s1 < w.s0) {
      lb.window[size_t(face)] = glm::vec4(0.0f);  // no triangle: every direction outside
      continue;
    }
    // Widened by a thousandth of its width, and by what the look-up's float arithmetic (the
    // shader's: s = u / w in float) may stray from the exact direction: a few ulps of |s|.
    const double ms = (w.s1 - w.s0) * 1e-3 + 1e-6 * (1.0 + std::max(std::abs(w.s0), std::abs(w.s1)));
    const double mt = (w.t1 - w.t0) * 1e-3 + 1e-6 * (1.0 + std::max(std::abs(w.t0), std::abs(w.t1)));
    const double s0 = w.s0 - ms, t0 = w.t0 - mt;
    lb.window[size_t(face)] = glm::vec4(float(s0), float(t0), float(resolution / (w.s1 + ms - s0)),
                                        float(resolution / (w.t1 + mt - t0)));
  }
  // Pass 2: the rectangles as cell ranges, widened by kLightBufferCellMargin of a cell.
  std::vector<Rect> cell_rects(rects.size());
  std::vector<uint32_t> count(cells, 0);
  for (size_t i = 0; i < rects.size(); ++i) {
    const auto& [face, b] = rects[i];
    const glm::vec4& w = lb.window[size_t(face)];
    // The margin: kLightBufferCellMargin of a cell, and the float look-up's error in cells (a few
    // ulps of s and of the window's origin, times the cells per unit, and of the product).
    auto cell = [&](double s, double origin, double scale, double sign) {
      const double slack = 5e-7 * ((std::abs(s) + std::abs(origin)) * scale + resolution);
      return std::clamp(int(std::floor((s - origin) * scale + sign * (kLightBufferCellMargin + slack))), 0,
                        resolution - 1);
    };
    Rect& r = cell_rects[i];
    r = {face, cell(b.s0, w.x, w.z, -1.0), cell(b.t0, w.y, w.w, -1.0), cell(b.s1, w.x, w.z, 1.0),
         cell(b.t1, w.y, w.w, 1.0)};
    for (int y = r.y0; y <= r.y1; ++y) {
      for (int x = r.x0; x <= r.x1; ++x) ++count[(size_t(face) * resolution + y) * resolution + x];
    }
  }
  lb.first.assign(cells + 1, 0);
  for (size_t c = 0; c < cells; ++c) lb.first[c + 1] = lb.first[c] + count[c];
  lb.prims.resize(lb.first[cells]);
  // The rectangles came in the order of their triangles' nearest distance: each list comes out sorted.
  std::vector<uint32_t> fill(lb.first.begin(), lb.first.end() - 1);
  for (size_t i = 0; i < cell_rects.size(); ++i) {
    const Rect& r = cell_rects[i];
    for (int y = r.y0; y <= r.y1; ++y) {
      for (int x = r.x0; x <= r.x1; ++x) lb.prims[fill[(size_t(r.face) * resolution + y) * resolution + x]++] = rect_tri[i];
    }
  }
  lb.near.resize(lb.prims.size());
  for (size_t k = 0; k < lb.prims.size(); ++k) lb.near[k] = tri_near[lb.prims[k]];
  return lb;
}

}  // namespace mobirt
