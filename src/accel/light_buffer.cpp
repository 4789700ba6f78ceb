#include "accel/light_buffer.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "accel/closed_parts.h"
#include "accel/kdtree.h"
#include "core/error.h"
#include "core/parallel.h"
#include "layout.h"

namespace mobirt {

static_assert(kLightBufferSubCells == MOBIRT_LIGHT_BUFFER_SUBCELLS);
// A part (LightBuffer::sub) travels as a float: exact below 2^24.
static_assert(uint64_t(kLightBufferSubCells) * kLightBufferSubCells * kLightBufferSubCells * kLightBufferSubCells <= (1u << 24));

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

// Direction d's cell, and its column and row of kLightBufferSubCells within the cell.
struct CellPosition {
  uint32_t cell = kLightBufferOutside;
  uint32_t sx = 0, sy = 0;
};

CellPosition cell_position(const LightBuffer& lb, glm::vec3 d) {
  // In float, as the shader computes it (glsl/traverse.glsl, light_buffer_occluded): x - floor(x)
  // and its product with 64 are exact.
  const int face = major_face(d);
  const glm::vec3 f = glm::vec3(face_coords(face, glm::dvec3(d)));
  const glm::vec4& w = lb.window[size_t(face)];
  const float x = (f.x / f.z - w.x) * w.z, y = (f.y / f.z - w.y) * w.w;
  const int r = lb.resolution;
  if (!(x >= 0.0f && y >= 0.0f && x < float(r) && y < float(r))) return {};
  const float cx = std::floor(x), cy = std::floor(y);
  constexpr float S = float(kLightBufferSubCells);
  return {uint32_t((face * r + int(cy)) * r + int(cx)), uint32_t((x - cx) * S), uint32_t((y - cy) * S)};
}

}  // namespace

uint32_t light_buffer_cell(const LightBuffer& lb, glm::vec3 d, uint32_t* sx, uint32_t* sy) {
  const CellPosition p = cell_position(lb, d);
  if (sx) *sx = p.sx;
  if (sy) *sy = p.sy;
  return p.cell;
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

bool light_buffer_occluded(const LightBuffer& lb, const FlatKdTree& tree, glm::vec3 origin, uint32_t* tests,
                           uint32_t* entries, const RayTest* test) {
  const Ray ray{origin, lb.light - origin, 0.0f, 1.0f};
  const CellPosition p = cell_position(lb, -ray.direction);
  if (tests) *tests = 0;
  if (entries) *entries = 0;
  if (p.cell == kLightBufferOutside) return false;
  // Past the segment's end (a little beyond, for the rounding of the length): no triangle there
  // can meet it.
  const float end = glm::length(ray.direction) * (1.0f + 1e-4f);
  for (uint32_t k = lb.first[p.cell]; k < lb.first[p.cell + 1]; ++k) {
    if (lb.near[k] > end) break;
    if (entries) ++*entries;
    if (!light_buffer_sub_contains(lb.sub[k], p.sx, p.sy)) continue;
    if (tests) ++*tests;
    Hit h;
    if (intersect_triangle(tree, int32_t(lb.prims[k]), ray, h, test ? *test : RayTest{})) return true;
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

namespace {

// What pass 1 found for one triangle: its rectangle on one face (0-5: every vertex well inside that
// face's pyramid), kClipped (it straddles faces: clipped to each), or kEverywhere (through the light).
constexpr uint8_t kClipped = 6;
constexpr uint8_t kEverywhere = 7;
constexpr uint8_t kLeftOut = 8;  // in no list (build_light_buffer's keep)

// A build's working arrays.
struct BuildScratch {
  std::vector<float> near;        // per triangle
  std::vector<uint8_t> kind;      // per triangle: its face, kClipped, kEverywhere or kLeftOut
  std::vector<Bounds> bounds;     // per triangle: its rectangle where kind is a face
  std::vector<uint64_t> keys[2];  // (near's bits, triangle) for the radix sort
  std::vector<std::pair<int, Bounds>> rects;  // in the order of their triangles' near
  std::vector<uint32_t> rect_tri;
  std::vector<Rect> cell_rects;
  std::vector<std::array<uint32_t, 4>> edge_subs;  // per rect: its first column's x0, first row's y0, last column's x1, last row's y1
  std::vector<uint32_t> fill;
};

// A rectangle's edge v (face coordinates, the window's origin and cells per unit) widened outwards
// (sign) by kLightBufferCellMargin of a cell and the float look-up's error in cells (a few ulps of
// v and of the origin, times the cells per unit, and of the product), in kLightBufferSubCells of a
// cell from the window's corner, clamped to the face (as a double: far outside the window the
// product passes an int).
inline int widened_subcell(double v, double origin, double scale, double sign, int resolution) {
  const double slack = 5e-7 * ((std::abs(v) + std::abs(origin)) * scale + resolution);
  const double g = std::floor(((v - origin) * scale + sign * (kLightBufferCellMargin + slack)) * kLightBufferSubCells);
  return g > 0.0 ? int(std::min(g, double(resolution * int(kLightBufferSubCells) - 1))) : 0;
}

// keys sorted by their upper 32 bits (a non-negative float's bits: the same order as the floats),
// stably: LSD radix sort, 8 bits a pass, passes whose digit every key shares skipped. Keys start
// in triangle order (the lower 32 bits), so equal distances stay in triangle order.
void radix_sort_upper(std::vector<uint64_t>& keys, std::vector<uint64_t>& tmp) {
  tmp.resize(keys.size());
  for (int shift = 32; shift < 64; shift += 8) {
    uint32_t count[257] = {};
    for (uint64_t k : keys) ++count[((k >> shift) & 0xFF) + 1];
    if (std::any_of(count + 1, count + 257, [&](uint32_t c) { return c == keys.size(); })) continue;
    for (int i = 0; i < 256; ++i) count[i + 1] += count[i];
    for (uint64_t k : keys) tmp[count[(k >> shift) & 0xFF]++] = k;
    keys.swap(tmp);
  }
}

}  // namespace

void build_light_buffer(std::span<const glm::vec3> positions, glm::vec3 light, int resolution, LightBuffer& lb,
                        unsigned threads, std::span<const int8_t> winding) {
  // Made per build, not kept per thread: the frame pipeline's worker is a new thread each frame
  // (std::async), and a thread's copy would keep a large mesh's arrays for the process's life.
  BuildScratch s;
  lb.light = light;
  lb.resolution = resolution;
  const uint32_t triangles = uint32_t(positions.size() / 3);
  if (!winding.empty() && winding.size() != triangles) {
    throw Error(ErrorKind::Internal, "build_light_buffer: " + std::to_string(winding.size()) + " windings for " +
                                         std::to_string(triangles) + " triangles");
  }
  const size_t cells = size_t(6) * resolution * resolution;
  const glm::dvec3 l(light);
  const double inner = 1.0 - kLightBufferFaceMargin;
  // Pass 1, on all cores: each triangle's nearest distance to the light, and its rectangle where
  // it lies well inside one face (the pyramid is convex, so the triangle is too, away from the
  // other faces' widened pyramids): its vertices' projections.
  s.near.resize(triangles);
  s.kind.resize(triangles);
  s.bounds.resize(triangles);
  s.keys[0].resize(triangles);
  parallel_for_chunks(triangles, 1024, threads, [&](uint32_t, uint32_t begin, uint32_t end) {
    for (uint32_t t = begin; t < end; ++t) {
      const glm::dvec3 c[3] = {glm::dvec3(positions[3 * t]) - l, glm::dvec3(positions[3 * t + 1]) - l,
                               glm::dvec3(positions[3 * t + 2]) - l};
      if (!winding.empty() && winding[t] != 0 && faces_away(c, winding[t])) {
        s.kind[t] = kLeftOut;
        s.keys[0][t] = ~uint64_t(0);  // sorted last, then skipped
        continue;
      }
      const double d = point_triangle_distance(glm::dvec3(0.0), c[0], c[1], c[2]);
      float df = float(d);  // rounded down: a lower bound stays one
      if (double(df) > d) df = std::nextafter(df, 0.0f);
      s.near[t] = df;
      s.keys[0][t] = (uint64_t(std::bit_cast<uint32_t>(df)) << 32) | t;
      // A triangle through the light (or all but): a segment ending at the light may touch it
      // from any direction, so it goes into every cell of every face.
      const double extent = std::max({glm::length(c[1] - c[0]), glm::length(c[2] - c[0]), glm::length(c[2] - c[1])});
      if (!(double(df) > 1e-6 * extent)) {
        s.kind[t] = kEverywhere;
        continue;
      }
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
      s.kind[t] = inside ? uint8_t(face) : kClipped;
      s.bounds[t] = b;
    }
  });
  lb.left_out = size_t(std::count(s.kind.begin(), s.kind.end(), kLeftOut));
  // Triangles in the order of their nearest distance: each cell's list is filled in that order.
  radix_sort_upper(s.keys[0], s.keys[1]);
  // Their rectangles in that order, and each face's window (the union of its rectangles: the cells
  // cover only the directions where triangles are). Triangles that straddle faces are clipped to
  // each face's pyramid here (few: those near a cube edge as seen from the light).
  s.rects.clear();
  s.rect_tri.clear();
  Bounds window[6];
  for (const uint64_t key : s.keys[0]) {
    if (key == ~uint64_t(0)) break;  // the triangles left out, sorted last (no real key is all ones)
    const uint32_t t = uint32_t(key);
    auto add = [&](int face, const Bounds& b) {
      s.rects.emplace_back(face, b);
      s.rect_tri.push_back(t);
      Bounds& w = window[face];
      w = {std::min(w.s0, b.s0), std::min(w.t0, b.t0), std::max(w.s1, b.s1), std::max(w.t1, b.t1)};
    };
    const uint8_t kind = s.kind[t];
    if (kind < kClipped) {
      add(kind, s.bounds[t]);
    } else if (kind == kEverywhere) {
      for (int f = 0; f < 6; ++f) add(f, Bounds{-2.0, -2.0, 2.0, 2.0});
    } else {
      const glm::dvec3 c[3] = {glm::dvec3(positions[3 * t]) - l, glm::dvec3(positions[3 * t + 1]) - l,
                               glm::dvec3(positions[3 * t + 2]) - l};
      Bounds b;
      for (int f = 0; f < 6; ++f) {
        if (cover(f, c, b)) add(f, b);
      }
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
  // Pass 2, on all cores: the rectangles as cell ranges, widened by kLightBufferCellMargin of a cell.
  const uint32_t rect_count = uint32_t(s.rects.size());
  s.cell_rects.resize(rect_count);
  s.edge_subs.resize(rect_count);
  parallel_for_chunks(rect_count, 2048, threads, [&](uint32_t, uint32_t begin, uint32_t end) {
    for (uint32_t i = begin; i < end; ++i) {
      const auto& [face, b] = s.rects[i];
      const glm::vec4& w = lb.window[size_t(face)];
      // Each widened edge (widened_subcell) gives its cell (the product with a power of two is
      // exact, so g / S is floor(v) clamped) and its column or row within that cell, rounded
      // outwards (the look-up's floor((x - floor(x)) * S) is monotonic in x).
      const int x0 = widened_subcell(b.s0, w.x, w.z, -1.0, resolution), y0 = widened_subcell(b.t0, w.y, w.w, -1.0, resolution),
                x1 = widened_subcell(b.s1, w.x, w.z, 1.0, resolution), y1 = widened_subcell(b.t1, w.y, w.w, 1.0, resolution);
      constexpr int S = int(kLightBufferSubCells);
      s.cell_rects[i] = {face, x0 / S, y0 / S, x1 / S, y1 / S};
      s.edge_subs[i] = {uint32_t(x0 % S), uint32_t(y0 % S), uint32_t(x1 % S), uint32_t(y1 % S)};
    }
  });
  // Each cell's count, its list's start, and the lists filled in near order: each comes out sorted.
  lb.first.assign(cells + 1, 0);
  uint32_t* count = lb.first.data() + 1;
  for (const Rect& r : s.cell_rects) {
    for (int y = r.y0; y <= r.y1; ++y) {
      uint32_t* row = count + (size_t(r.face) * resolution + y) * resolution;
      for (int x = r.x0; x <= r.x1; ++x) ++row[x];
    }
  }
  for (size_t c = 0; c < cells; ++c) lb.first[c + 1] += lb.first[c];
  lb.prims.resize(lb.first[cells]);
  lb.sub.resize(lb.first[cells]);
  s.fill.assign(lb.first.begin(), lb.first.end() - 1);
  constexpr uint32_t kLast = kLightBufferSubCells - 1;
  uint32_t* const prims = lb.prims.data();
  uint32_t* const subs = lb.sub.data();
  for (uint32_t i = 0; i < rect_count; ++i) {
    // Copies in locals: the stores below are uint32_t, which the compiler must assume alias these.
    const Rect r = s.cell_rects[i];
    const uint32_t t = s.rect_tri[i];
    const std::array<uint32_t, 4> e = s.edge_subs[i];
    for (int y = r.y0; y <= r.y1; ++y) {
      uint32_t* row = s.fill.data() + (size_t(r.face) * resolution + y) * resolution;
      const uint32_t sy0 = y == r.y0 ? e[1] : 0, sy1 = y == r.y1 ? e[3] : kLast;
      // The row's parts: its first column's, the middle columns' and its last column's.
      const uint32_t first = light_buffer_sub(e[0], sy0, r.x0 == r.x1 ? e[2] : kLast, sy1);
      const uint32_t middle = light_buffer_sub(0, sy0, kLast, sy1);
      const uint32_t last = light_buffer_sub(0, sy0, e[2], sy1);
      for (int x = r.x0; x <= r.x1; ++x) {
        const uint32_t k = row[x]++;
        prims[k] = t;
        subs[k] = x == r.x0 ? first : (x == r.x1 ? last : middle);
      }
    }
  }
  lb.near.resize(lb.prims.size());
  parallel_for_chunks(uint32_t(lb.prims.size()), 16384, threads, [&](uint32_t, uint32_t begin, uint32_t end) {
    for (uint32_t k = begin; k < end; ++k) lb.near[k] = s.near[lb.prims[k]];
  });
}

}  // namespace mobirt
