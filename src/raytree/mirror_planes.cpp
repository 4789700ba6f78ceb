#include "raytree/mirror_planes.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <tuple>
#include <unordered_map>

#include "core/error.h"
#include "core/parallel.h"

namespace mobirt {
namespace {

bool finite(const glm::vec3& p) { return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z); }

// The largest finite coordinate magnitude of `positions`, the scale of the planes' tolerances.
double largest_coordinate(std::span<const glm::vec3> positions) {
  double scale = 0.0;
  for (const glm::vec3& p : positions) {
    if (!finite(p)) continue;
    scale = std::max({scale, double(std::abs(p.x)), double(std::abs(p.y)), double(std::abs(p.z))});
  }
  return scale;
}

// Whether the unit vectors a and b agree within 1e-6 in every component.
bool same_direction(const glm::dvec3& a, const glm::dvec3& b) {
  const glm::dvec3 e = glm::abs(a - b);
  return e.x <= 1e-6 && e.y <= 1e-6 && e.z <= 1e-6;
}

}  // namespace

MirrorPlanes find_mirror_planes(const Scene& scene) {
  MirrorPlanes out;
  const TriangleMesh& mesh = scene.mesh;
  const size_t triangles = mesh.triangle_count();
  out.plane_of.assign(triangles, -1);
  const double tolerance = 1e-6 * std::max(largest_coordinate(mesh.positions), 1e-30);
  // Planes found so far, looked up by their normal on a 2^-16 grid and their offset on a grid of 64
  // tolerances (a triangle's own plane, rounded; the neighbouring offset cells are looked in too,
  // so that a plane near a cell's edge is still found).
  struct Key {
    int64_t nx, ny, nz, d;
    bool operator==(const Key&) const = default;
  };
  struct KeyHash {
    size_t operator()(const Key& k) const {
      uint64_t h = uint64_t(k.nx) * 0x9E3779B97F4A7C15ull;
      h ^= uint64_t(k.ny) + 0x7F4A7C159E3779B9ull + (h << 6) + (h >> 2);
      h ^= uint64_t(k.nz) + 0x94D049BB133111EBull + (h << 6) + (h >> 2);
      h ^= uint64_t(k.d) + 0xBF58476D1CE4E5B9ull + (h << 6) + (h >> 2);
      return size_t(h);
    }
  };
  std::unordered_map<Key, std::vector<int32_t>, KeyHash> lookup;
  const double cell = 64.0 * tolerance;
  for (size_t t = 0; t < triangles; ++t) {
    const uint32_t id = mesh.material_ids[t];
    if (id >= scene.materials.size()) continue;
    const Material& m = scene.materials[id];
    if (!(m.reflectance > 0.0f) || m.transmittance != 0.0f) continue;
    const glm::vec3* v = &mesh.positions[3 * t];
    if (!finite(v[0]) || !finite(v[1]) || !finite(v[2])) continue;
    const glm::dvec3 a(v[0]), b(v[1]), c(v[2]);
    const glm::dvec3 cross = glm::cross(b - a, c - a);
    const double length = glm::length(cross);
    if (!(length > 0.0)) continue;  // degenerate
    glm::dvec3 normal = cross / length;
    // The shading normals: all three the plane's, facing one way; the plane faces where they do.
    bool flat = mesh.normals.size() == mesh.positions.size();
    double side = 0.0;
    for (int k = 0; flat && k < 3; ++k) {
      const glm::dvec3 ns(mesh.normals[3 * t + k]);
      const double ns_length = glm::length(ns);
      if (!(ns_length > 0.0)) {
        flat = false;
        break;
      }
      const glm::dvec3 unit = ns / ns_length;
      if (side == 0.0) side = glm::dot(unit, normal) < 0.0 ? -1.0 : 1.0;
      flat = same_direction(unit, side * normal);
    }
    if (!flat) continue;
    normal *= side;
    const double offset = glm::dot(normal, a);
    const Key base{std::llround(normal.x * 65536.0), std::llround(normal.y * 65536.0), std::llround(normal.z * 65536.0),
                   std::llround(offset / cell)};
    auto on_plane = [&](const MirrorPlane& p) {
      return same_direction(p.normal, normal) && std::abs(glm::dot(p.normal, a) - p.offset) <= tolerance &&
             std::abs(glm::dot(p.normal, b) - p.offset) <= tolerance && std::abs(glm::dot(p.normal, c) - p.offset) <= tolerance;
    };
    int32_t found = -1;
    for (int64_t dd = -1; dd <= 1 && found < 0; ++dd) {
      const auto it = lookup.find(Key{base.nx, base.ny, base.nz, base.d + dd});
      if (it == lookup.end()) continue;
      for (const int32_t p : it->second) {
        if (on_plane(out.planes[size_t(p)])) {
          found = p;
          break;
        }
      }
    }
    if (found < 0) {
      found = int32_t(out.planes.size());
      MirrorPlane plane;
      plane.normal = normal;
      plane.offset = offset;
      out.planes.push_back(plane);
      lookup[base].push_back(found);
    }
    out.plane_of[t] = found;
    MirrorPlane& plane = out.planes[size_t(found)];
    ++plane.triangles;
    plane.area += 0.5 * length;
  }
  // The largest area first (ties: the plane found first), the triangles' indices renumbered.
  std::vector<int32_t> order(out.planes.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = int32_t(i);
  std::stable_sort(order.begin(), order.end(),
                   [&](int32_t x, int32_t y) { return out.planes[size_t(x)].area > out.planes[size_t(y)].area; });
  std::vector<int32_t> rank(order.size());
  std::vector<MirrorPlane> sorted(order.size());
  for (size_t i = 0; i < order.size(); ++i) {
    rank[size_t(order[i])] = int32_t(i);
    sorted[i] = out.planes[size_t(order[i])];
  }
  out.planes = std::move(sorted);
  for (int32_t& p : out.plane_of) {
    if (p >= 0) p = rank[size_t(p)];
  }
  return out;
}

namespace {

// Triangle t of `positions` mirrored in `plane` (mirrored_raster_vertices), appended to `out`.
void mirror_triangle(std::span<const glm::vec3> positions, size_t t, const MirrorPlane& plane, double margin,
                     std::vector<float>& out) {
  const glm::dvec3 n = plane.normal;
  auto emit = [&](const glm::dvec3& p, double s, float index) {
    // s = n . p - offset: the mirror image is p - 2 s n.
    const glm::dvec3 q = p - 2.0 * s * n;
    out.insert(out.end(), {float(q.x), float(q.y), float(q.z), index});
  };
  const glm::vec3* v = &positions[3 * t];
  if (!finite(v[0]) || !finite(v[1]) || !finite(v[2])) return;
  const float index = float(t + 1);
  glm::dvec3 p[3];
  double s[3];
  int front = 0;
  for (int k = 0; k < 3; ++k) {
    p[k] = glm::dvec3(v[k]);
    s[k] = glm::dot(n, p[k]) - plane.offset;
    front += s[k] > margin ? 1 : 0;
  }
  if (front == 0) return;  // behind the mirror, in it, or within the margin of it
  if (front == 3) {
    for (int k = 0; k < 3; ++k) emit(p[k], s[k], index);
    return;
  }
  // Cut at the margin's plane (Sutherland-Hodgman, one plane): the part in front, 3 or 4 corners.
  glm::dvec3 poly[4];
  double ps[4];
  int count = 0;
  for (int k = 0; k < 3; ++k) {
    const int j = (k + 1) % 3;
    const double sk = s[k] - margin, sj = s[j] - margin;
    if (sk > 0.0) {
      poly[count] = p[k];
      ps[count++] = s[k];
    }
    if ((sk > 0.0) != (sj > 0.0)) {
      // From the edge's lesser end (by coordinates), so that the two triangles sharing the edge
      // cut it at the same point, bit for bit: no crack between their parts.
      const bool forward = std::tie(p[k].x, p[k].y, p[k].z) < std::tie(p[j].x, p[j].y, p[j].z);
      const glm::dvec3& a = forward ? p[k] : p[j];
      const glm::dvec3& b = forward ? p[j] : p[k];
      const double sa = forward ? sk : sj, sb = forward ? sj : sk;
      const double f = sa / (sa - sb);
      poly[count] = a + f * (b - a);  // on the cut
      ps[count] = glm::dot(n, poly[count]) - plane.offset;
      ++count;
    }
  }
  for (int k = 1; k + 1 < count; ++k) {
    emit(poly[0], ps[0], index);
    emit(poly[k], ps[k], index);
    emit(poly[k + 1], ps[k + 1], index);
  }
}

}  // namespace

void mirrored_raster_vertices(std::span<const glm::vec3> positions, const MirrorPlane& plane, std::vector<float>& out,
                              std::span<const uint8_t> skip) {
  const double margin = 1e-6 * largest_coordinate(positions);
  const size_t triangles = positions.size() / 3;
  if (!skip.empty() && skip.size() != triangles) {
    throw Error(ErrorKind::Internal, "mirrored_raster_vertices: skip has " + std::to_string(skip.size()) +
                                         " entries for " + std::to_string(triangles) + " triangles");
  }
  // On all cores in chunks of triangles, each into its own array, then joined in order: the same
  // floats as one pass over the triangles (the toaster's 11,102 took 0.2 ms on one core).
  constexpr uint32_t kChunk = 2048;
  const uint32_t chunks = chunk_count(uint32_t(triangles), kChunk);
  std::vector<std::vector<float>> parts(chunks);
  parallel_for_chunks(uint32_t(triangles), kChunk, 0, [&](uint32_t c, uint32_t begin, uint32_t end) {
    std::vector<float>& part = parts[c];
    part.reserve(size_t(end - begin) * 12);
    for (uint32_t t = begin; t < end; ++t) {
      if (skip.empty() || !skip[t]) mirror_triangle(positions, t, plane, margin, part);
    }
  });
  std::vector<size_t> first(size_t(chunks) + 1, out.size());
  for (uint32_t c = 0; c < chunks; ++c) first[c + 1] = first[c] + parts[c].size();
  out.resize(first[chunks]);
  parallel_for(chunks, 0, [&](uint32_t c) { std::copy(parts[c].begin(), parts[c].end(), out.begin() + first[c]); }, 1);
}

}  // namespace mobirt
