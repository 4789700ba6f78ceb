#include "accel/closed_parts.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <unordered_map>
#include <utility>

#include "core/parallel.h"

namespace mobirt {

namespace {

uint32_t find_root(std::vector<uint32_t>& parent, uint32_t x) {
  while (parent[x] != x) {
    parent[x] = parent[parent[x]];
    x = parent[x];
  }
  return x;
}

bool finite(const glm::vec3& p) { return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z); }

float max_component(const glm::vec3& v) { return std::max({v.x, v.y, v.z}); }

// The weld's cell size against the largest coordinate, and the grid's offset that makes a cell's
// coordinates (within +-2^19 of 0) non-negative 21-bit numbers.
constexpr float kWeld = 1.0f / float(1 << 19);
constexpr int kWeldCells = 1 << 20;

// A part measured triangle by triangle: its box, and six times the signed volume its triangles
// enclose (tetrahedra from the part's first corner, in double). find_closed_parts and
// light_windings (the part as posed) both take its winding from it.
struct PartMeasure {
  glm::dvec3 anchor{0.0};
  bool anchored = false;
  double volume = 0.0;
  glm::vec3 lo{INFINITY}, hi{-INFINITY};
  void add(const glm::vec3* v) {
    if (!anchored) {
      anchor = glm::dvec3(v[0]);
      anchored = true;
    }
    const glm::dvec3 a = glm::dvec3(v[0]) - anchor, b = glm::dvec3(v[1]) - anchor, c = glm::dvec3(v[2]) - anchor;
    volume += glm::dot(a, glm::cross(b, c));
    for (int k = 0; k < 3; ++k) {
      lo = glm::min(lo, v[k]);
      hi = glm::max(hi, v[k]);
    }
  }
  // +1 wound outwards, -1 inwards; 0 where the volume is within a rounding of zero (a double-sided
  // sheet, every face met by its reverse, encloses nothing).
  int winding() const {
    const glm::dvec3 e = glm::dvec3(hi) - glm::dvec3(lo);
    const double scale = std::max({e.x, e.y, e.z});
    if (!(std::abs(volume) > 1e-9 * scale * scale * scale)) return 0;
    return volume > 0.0 ? 1 : -1;
  }
};

}  // namespace

ClosedParts find_closed_parts(std::span<const glm::vec3> positions) {
  ClosedParts r;
  const uint32_t triangles = uint32_t(positions.size() / 3);
  const uint32_t n = 3 * triangles;
  r.triangles = triangles;
  r.part.assign(triangles, kOpenPart);
  if (triangles == 0) return r;
  std::vector<uint8_t> open(triangles, 0);
  for (uint32_t t = 0; t < triangles; ++t) {
    if (!finite(positions[3 * t]) || !finite(positions[3 * t + 1]) || !finite(positions[3 * t + 2])) open[t] = 1;
  }
  // Weld: corners that differ by at most kWeld of their own largest coordinate, in each
  // coordinate, are one vertex (a generated sphere's seam and poles come out of sin and cos a
  // rounding apart), so that a small object far from the scene's largest coordinates keeps its
  // own small tolerance. Candidates through a grid of the largest such tolerance: every pair
  // falls in the same or neighbouring cells.
  float big = 0.0f;
  for (uint32_t t = 0; t < triangles; ++t) {
    if (open[t]) continue;
    for (int k = 0; k < 3; ++k) big = std::max(big, max_component(glm::abs(positions[3 * t + k])));
  }
  const float grid = big * kWeld;
  std::vector<uint32_t> weld(n);
  std::iota(weld.begin(), weld.end(), 0u);
  if (grid > 0.0f) {
    const auto cell = [&](const glm::vec3& p) {
      return glm::i64vec3(glm::ivec3(glm::floor(p / grid)) + kWeldCells);  // 0 .. 2^21
    };
    const auto key = [](glm::i64vec3 c) { return uint64_t(c.x) | uint64_t(c.y) << 21 | uint64_t(c.z) << 42; };
    // The corners by cell, and where each cell's run starts.
    std::vector<std::pair<uint64_t, uint32_t>> by_cell;
    by_cell.reserve(n);
    for (uint32_t i = 0; i < n; ++i) {
      if (!open[i / 3]) by_cell.emplace_back(key(cell(positions[i])), i);
    }
    std::sort(by_cell.begin(), by_cell.end());
    std::unordered_map<uint64_t, uint32_t> run;
    run.reserve(by_cell.size());
    for (uint32_t k = 0; k < by_cell.size(); ++k) run.emplace(by_cell[k].first, k);  // the first of each key stays
    for (const auto& [own, i] : by_cell) {
      const glm::vec3 p = positions[i];
      const float pi = max_component(glm::abs(p));
      const glm::i64vec3 c = cell(p);
      for (int dz = -1; dz <= 1; ++dz) {
        for (int dy = -1; dy <= 1; ++dy) {
          for (int dx = -1; dx <= 1; ++dx) {
            const uint64_t k = key(c + glm::i64vec3(dx, dy, dz));
            const auto it = run.find(k);
            if (it == run.end()) continue;
            for (uint32_t m = it->second; m < by_cell.size() && by_cell[m].first == k; ++m) {
              const uint32_t j = by_cell[m].second;
              if (j <= i) continue;  // each pair once
              const glm::vec3 q = positions[j];
              const float tolerance = kWeld * std::max(pi, max_component(glm::abs(q)));
              if (max_component(glm::abs(p - q)) > tolerance) continue;
              const uint32_t a = find_root(weld, i), b = find_root(weld, j);
              if (a != b) weld[std::max(a, b)] = std::min(a, b);
            }
          }
        }
      }
    }
  }
  // Vertices: the welds' roots, numbered; each group of two corners or more recorded.
  std::vector<uint32_t> vertex(n), number(n, kOpenPart);
  uint32_t vertices = 0;
  for (uint32_t i = 0; i < n; ++i) {
    const uint32_t root = find_root(weld, i);
    if (number[root] == kOpenPart) number[root] = vertices++;
    vertex[i] = number[root];
  }
  {
    std::vector<uint32_t> size(vertices, 0);
    for (uint32_t i = 0; i < n; ++i) ++size[vertex[i]];
    std::vector<uint32_t> start(vertices + 1, 0);
    for (uint32_t v = 0; v < vertices; ++v) start[v + 1] = start[v] + (size[v] > 1 ? size[v] : 0);
    r.corners.assign(start[vertices], 0);
    std::vector<uint32_t> fill(start.begin(), start.end() - 1);
    for (uint32_t i = 0; i < n; ++i) {
      if (size[vertex[i]] > 1) r.corners[fill[vertex[i]]++] = i;
    }
    for (uint32_t v = 0; v < vertices; ++v) {
      if (size[v] > 1) r.first.push_back(start[v]);
    }
    if (!r.first.empty()) r.first.push_back(start[vertices]);
    // Each group's spread: its corners' largest distance from its first, in each coordinate (up to
    // kWeld of their magnitude, more along a chain of welds).
    r.weld_tolerance.assign(r.first.empty() ? 0 : r.first.size() - 1, 0.0f);
    for (size_t g = 0; g < r.weld_tolerance.size(); ++g) {
      const glm::vec3 at = positions[r.corners[r.first[g]]];
      for (uint32_t c = r.first[g] + 1; c < r.first[g + 1]; ++c) {
        r.weld_tolerance[g] = std::max(r.weld_tolerance[g], max_component(glm::abs(positions[r.corners[c]] - at)));
      }
    }
  }
  // Directed edges (u, v) of each triangle, sorted. A triangle with a repeated vertex (no area, never
  // hit) is left out of the topology, in no part: the surface around it closes without it.
  std::vector<std::pair<uint64_t, uint32_t>> edges;
  edges.reserve(n);
  for (uint32_t t = 0; t < triangles; ++t) {
    if (open[t]) continue;
    const uint32_t v[3] = {vertex[3 * t], vertex[3 * t + 1], vertex[3 * t + 2]};
    if (v[0] == v[1] || v[1] == v[2] || v[2] == v[0]) {
      open[t] = 1;
      continue;
    }
    for (int k = 0; k < 3; ++k) edges.emplace_back((uint64_t(v[k]) << 32) | v[(k + 1) % 3], t);
  }
  std::sort(edges.begin(), edges.end());
  std::vector<uint32_t> parent(triangles);
  std::iota(parent.begin(), parent.end(), 0u);
  // A closed part wound one way meets each directed edge once, and its reverse once.
  const auto count = [&](uint64_t key) {
    const auto range = std::equal_range(edges.begin(), edges.end(), std::pair<uint64_t, uint32_t>(key, 0u),
                                        [](const auto& a, const auto& b) { return a.first < b.first; });
    return std::pair(size_t(range.second - range.first), range.first);
  };
  for (size_t i = 0; i < edges.size(); ++i) {
    const uint64_t key = edges[i].first;
    const uint32_t t = edges[i].second;
    const size_t same = count(key).first;
    const auto [reverse, at] = count((key << 32) | (key >> 32));
    if (same != 1 || reverse != 1) {
      open[t] = 1;
      continue;
    }
    const uint32_t a = find_root(parent, t), b = find_root(parent, at->second);
    if (a != b) parent[std::max(a, b)] = std::min(a, b);
  }
  // Parts: open if any of their triangles is; closed ones must enclose a volume.
  std::vector<uint8_t> root_open(triangles, 0);
  for (uint32_t t = 0; t < triangles; ++t) {
    if (open[t]) root_open[find_root(parent, t)] = 1;
  }
  std::vector<PartMeasure> measure(triangles);
  for (uint32_t t = 0; t < triangles; ++t) {
    const uint32_t root = find_root(parent, t);
    if (!root_open[root]) measure[root].add(&positions[3 * t]);
  }
  std::vector<uint32_t> index(triangles, kOpenPart);
  for (uint32_t t = 0; t < triangles; ++t) {
    const uint32_t root = find_root(parent, t);
    if (root_open[root]) continue;
    if (index[root] == kOpenPart) {
      const int winding = measure[root].winding();
      if (winding == 0) {  // encloses nothing: open
        root_open[root] = 1;
        continue;
      }
      index[root] = uint32_t(r.orientation.size());
      r.orientation.push_back(float(winding));
    }
    r.part[t] = index[root];
  }
  return r;
}

PosedParts pose_closed_parts(const ClosedParts& parts, std::span<const glm::vec3> positions) {
  PosedParts posed;
  const size_t triangles = positions.size() / 3;
  if (parts.triangles != triangles || parts.parts() == 0) return posed;
  posed.of = &parts;
  // Each part as posed now: its box, its signed volume (the pose may have mirrored it: the winding
  // is the volume's sign now), whether its corners are finite and its welds still hold.
  const size_t count = parts.parts();
  std::vector<uint8_t> valid(count, 1);
  std::vector<PartMeasure> measure(count);
  for (size_t t = 0; t < triangles; ++t) {
    const uint32_t p = parts.part[t];
    if (p == kOpenPart) continue;
    const glm::vec3* v = &positions[3 * t];
    if (!finite(v[0]) || !finite(v[1]) || !finite(v[2])) {
      valid[p] = 0;
      continue;
    }
    measure[p].add(v);
  }
  for (size_t v = 0; v + 1 < parts.first.size(); ++v) {
    // Within four times the weld's tolerance at analysis (a turn stretches the largest coordinate
    // of a difference by up to sqrt(3)), or of the corner's magnitude now where the pose moved it.
    const glm::vec3 at = positions[parts.corners[parts.first[v]]];
    const float tolerance = 4.0f * std::max(parts.weld_tolerance[v], kWeld * max_component(glm::abs(at)));
    bool holds = true;
    for (uint32_t c = parts.first[v] + 1; c < parts.first[v + 1]; ++c) {
      holds = holds && max_component(glm::abs(positions[parts.corners[c]] - at)) <= tolerance;  // false for NaN
    }
    if (holds) continue;
    for (uint32_t c = parts.first[v]; c < parts.first[v + 1]; ++c) {
      const uint32_t p = parts.part[parts.corners[c] / 3];
      if (p != kOpenPart) valid[p] = 0;
    }
  }
  posed.lo.resize(count);
  posed.hi.resize(count);
  posed.winding.resize(count);
  for (size_t p = 0; p < count; ++p) {
    const PartMeasure& part = measure[p];
    posed.lo[p] = part.lo;
    posed.hi[p] = part.hi;
    posed.winding[p] = valid[p] ? int8_t(part.winding()) : int8_t(0);
    // Every measured part's box, valid or not, as light_windings measured it before the split.
    if (part.anchored) {
      posed.largest = std::max({posed.largest, max_component(glm::abs(part.lo)), max_component(glm::abs(part.hi))});
    }
  }
  return posed;
}

void light_windings(const PosedParts& posed, std::span<const glm::vec3> positions, glm::vec3 light,
                    std::vector<int8_t>& winding) {
  const size_t triangles = positions.size() / 3;
  winding.assign(triangles, 0);
  if (!posed.of || posed.of->triangles != triangles || posed.winding.size() != posed.of->parts()) return;
  const ClosedParts& parts = *posed.of;
  // The light outside the part's box by a ten-thousandth of the scene's largest coordinate (the
  // light's included): a segment's last crossing of the part, through a face turned towards the
  // light, then lies at t <= 1 - 1e-5 or so, well inside the shadow test's t <= 1 in float.
  const float m = 1e-4f * std::max(posed.largest, max_component(glm::abs(light)));
  const size_t count = posed.winding.size();
  std::vector<int8_t> sign(count, 0);
  for (size_t p = 0; p < count; ++p) {
    const bool outside = glm::any(glm::lessThan(light, posed.lo[p] - m)) || glm::any(glm::greaterThan(light, posed.hi[p] + m));
    sign[p] = outside ? posed.winding[p] : int8_t(0);
  }
  for (size_t t = 0; t < triangles; ++t) {
    if (parts.part[t] != kOpenPart) winding[t] = sign[parts.part[t]];
  }
}

void light_windings(const ClosedParts& parts, std::span<const glm::vec3> positions, glm::vec3 light,
                    std::vector<int8_t>& winding) {
  light_windings(pose_closed_parts(parts, positions), positions, light, winding);
}

void faces_turned_away(const PosedParts& posed, std::span<const glm::vec3> positions, glm::vec3 eye,
                       std::vector<uint8_t>& away, const glm::vec3* rays_from, float reach) {
  const size_t triangles = positions.size() / 3;
  away.assign(triangles, 0);
  if (!posed.of || posed.of->triangles != triangles || posed.winding.size() != posed.of->parts()) return;
  // The parts' boxes grown by the reach: an eye within it of a box counts as inside.
  const PosedParts* boxes = &posed;
  PosedParts grown;
  if (reach > 0.0f) {
    grown = posed;
    for (glm::vec3& lo : grown.lo) lo -= glm::vec3(reach);
    for (glm::vec3& hi : grown.hi) hi += glm::vec3(reach);
    boxes = &grown;
  }
  std::vector<int8_t> winding, from;
  light_windings(*boxes, positions, eye, winding);
  if (rays_from) {
    light_windings(*boxes, positions, *rays_from, from);
    for (size_t t = 0; t < triangles; ++t) {
      if (from[t] == 0) winding[t] = 0;
    }
  }
  const glm::dvec3 e(eye);
  parallel_for_chunks(uint32_t(triangles), 4096, 0, [&](uint32_t, uint32_t begin, uint32_t end) {
    for (uint32_t t = begin; t < end; ++t) {
      if (winding[t] == 0) continue;
      const glm::dvec3 c[3] = {glm::dvec3(positions[3 * size_t(t)]) - e, glm::dvec3(positions[3 * size_t(t) + 1]) - e,
                               glm::dvec3(positions[3 * size_t(t) + 2]) - e};
      away[t] = faces_away(c, winding[t]) ? 1 : 0;
    }
  });
}

}  // namespace mobirt
