#include "raytree/mirror_planes.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <tuple>
#include <unordered_map>

#include "core/error.h"
#include "core/parallel.h"

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#define MOBIRT_MIRROR_AVX2 1
#include <immintrin.h>
#endif

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

uint8_t mirror_ray_plane(const MirrorRayTest& test, const RayBatch& rays, uint32_t i) {
  if (test.planes.size() >= kNoMirrorPlane) {
    throw Error(ErrorKind::Internal, "mirror_ray_plane: " + std::to_string(test.planes.size()) + " planes");
  }
  const uint32_t width = test.width;
  const uint32_t pixel = rays.pixel[i];
  if (pixel >= width * test.height) return kNoMirrorPlane;
  const CameraBasis& basis = test.basis;
  const glm::dvec3 forward(basis.forward), right(basis.right), up(basis.up);
  const double sx_scale = double(basis.tan_half) * double(basis.aspect);
  const glm::dvec3 o(rays.origin[i]), dir(rays.direction[i]);
  const double on_plane = test.on_plane;
  for (size_t p = 0; p < test.planes.size(); ++p) {
    const MirrorPlane& plane = test.planes[p];
    const double above = glm::dot(plane.normal, o) - plane.offset;
    if (!(above >= -on_plane && above <= on_plane)) continue;
    const double dn = glm::dot(dir, plane.normal);
    if (!(dn > 0.0)) continue;
    const glm::dvec3 back = dir - 2.0 * dn * plane.normal;  // the primary ray's direction, if a mirror ray
    const double f = glm::dot(back, forward);
    if (!(f > 0.0)) continue;
    const double sx = (2.0 * (double(pixel % width) + 0.5) / double(width) - 1.0) * sx_scale;
    const double sy = double(basis.row_offset(float(pixel / width) + 0.5f));
    if (std::abs(glm::dot(back, right) - sx * f) > 1e-5 * f || std::abs(glm::dot(back, up) - sy * f) > 1e-5 * f) {
      continue;
    }
    return uint8_t(p);
  }
  return kNoMirrorPlane;
}

#if defined(MOBIRT_MIRROR_AVX2)
namespace {
// Four doubles of glm's dot product, (a.x b.x + a.y b.y) + a.z b.z.
__attribute__((target("avx2"))) inline __m256d dot4(__m256d ax, __m256d ay, __m256d az, __m256d bx, __m256d by,
                                                    __m256d bz) {
  return _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(ax, bx), _mm256_mul_pd(ay, by)), _mm256_mul_pd(az, bz));
}

// mirror_ray_plane of rays [i, i + 4), every operation mirror_ray_plane's (the file is built with
// -ffp-contract=off: no product is fused into a sum here or there).
__attribute__((target("avx2"))) void mirror_ray_planes_x4(const MirrorRayTest& test, const RayBatch& rays, uint32_t i,
                                                          uint8_t* plane_of) {
  const uint32_t width = test.width, pixels = test.width * test.height;
  const CameraBasis& basis = test.basis;
  // The rays' origins and directions, transposed into x, y and z of the four, widened to double.
  __m128 o0 = _mm_loadu_ps(&rays.origin[i].x), o1 = _mm_loadu_ps(&rays.origin[i + 1].x);
  __m128 o2 = _mm_loadu_ps(&rays.origin[i + 2].x), o3 = _mm_loadu_ps(&rays.origin[i + 3].x);
  _MM_TRANSPOSE4_PS(o0, o1, o2, o3);
  __m128 d0 = _mm_loadu_ps(&rays.direction[i].x), d1 = _mm_loadu_ps(&rays.direction[i + 1].x);
  __m128 d2 = _mm_loadu_ps(&rays.direction[i + 2].x), d3 = _mm_loadu_ps(&rays.direction[i + 3].x);
  _MM_TRANSPOSE4_PS(d0, d1, d2, d3);
  const __m256d ox = _mm256_cvtps_pd(o0), oy = _mm256_cvtps_pd(o1), oz = _mm256_cvtps_pd(o2);
  const __m256d dx = _mm256_cvtps_pd(d0), dy = _mm256_cvtps_pd(d1), dz = _mm256_cvtps_pd(d2);
  // Each lane's pixel column and row; sx in double and sy in float, as mirror_ray_plane makes them.
  alignas(32) double column[4];
  alignas(16) float row[4];
  alignas(32) int64_t inside[4];
  for (int k = 0; k < 4; ++k) {
    const uint32_t pixel = rays.pixel[i + uint32_t(k)];
    const bool in = pixel < pixels;
    column[k] = in ? double(pixel % width) : 0.0;
    row[k] = in ? float(pixel / width) : 0.0f;
    inside[k] = in ? -1 : 0;  // all bits set where the pixel is in the image
  }
  const __m256d sx_scale = _mm256_set1_pd(double(basis.tan_half) * double(basis.aspect));
  const __m256d sx = _mm256_mul_pd(
      _mm256_sub_pd(_mm256_div_pd(_mm256_mul_pd(_mm256_set1_pd(2.0), _mm256_add_pd(_mm256_load_pd(column), _mm256_set1_pd(0.5))),
                                  _mm256_set1_pd(double(width))),
                    _mm256_set1_pd(1.0)),
      sx_scale);
  // CameraBasis::row_offset(y + 0.5f): (1 - 2 y / height) tan_half, in float.
  const __m128 y = _mm_add_ps(_mm_load_ps(row), _mm_set1_ps(0.5f));
  const __m128 sy_f = _mm_mul_ps(
      _mm_sub_ps(_mm_set1_ps(1.0f), _mm_div_ps(_mm_mul_ps(_mm_set1_ps(2.0f), y), _mm_set1_ps(basis.height))),
      _mm_set1_ps(basis.tan_half));
  const __m256d sy = _mm256_cvtps_pd(sy_f);
  const __m256d fx = _mm256_set1_pd(double(basis.forward.x)), fy = _mm256_set1_pd(double(basis.forward.y)),
                fz = _mm256_set1_pd(double(basis.forward.z));
  const __m256d rx = _mm256_set1_pd(double(basis.right.x)), ry = _mm256_set1_pd(double(basis.right.y)),
                rz = _mm256_set1_pd(double(basis.right.z));
  const __m256d ux = _mm256_set1_pd(double(basis.up.x)), uy = _mm256_set1_pd(double(basis.up.y)),
                uz = _mm256_set1_pd(double(basis.up.z));
  const __m256d on = _mm256_set1_pd(test.on_plane), minus_on = _mm256_set1_pd(-test.on_plane);
  const __m256d zero = _mm256_setzero_pd(), two = _mm256_set1_pd(2.0), tolerance = _mm256_set1_pd(1e-5);
  const __m256d abs_mask = _mm256_castsi256_pd(_mm256_set1_epi64x(0x7fffffffffffffffLL));
  __m256d open = _mm256_castsi256_pd(_mm256_load_si256(reinterpret_cast<const __m256i*>(inside)));  // without a plane yet
  alignas(32) double chosen[4] = {double(kNoMirrorPlane), double(kNoMirrorPlane), double(kNoMirrorPlane),
                                  double(kNoMirrorPlane)};
  __m256d result = _mm256_load_pd(chosen);
  for (size_t p = 0; p < test.planes.size() && _mm256_movemask_pd(open) != 0; ++p) {
    const MirrorPlane& plane = test.planes[p];
    const __m256d nx = _mm256_set1_pd(plane.normal.x), ny = _mm256_set1_pd(plane.normal.y),
                  nz = _mm256_set1_pd(plane.normal.z);
    const __m256d above = _mm256_sub_pd(dot4(nx, ny, nz, ox, oy, oz), _mm256_set1_pd(plane.offset));
    __m256d pass = _mm256_and_pd(_mm256_cmp_pd(above, minus_on, _CMP_GE_OQ), _mm256_cmp_pd(above, on, _CMP_LE_OQ));
    const __m256d dn = dot4(dx, dy, dz, nx, ny, nz);
    pass = _mm256_and_pd(pass, _mm256_cmp_pd(dn, zero, _CMP_GT_OQ));
    const __m256d twice = _mm256_mul_pd(two, dn);
    const __m256d bx = _mm256_sub_pd(dx, _mm256_mul_pd(twice, nx)), by = _mm256_sub_pd(dy, _mm256_mul_pd(twice, ny)),
                  bz = _mm256_sub_pd(dz, _mm256_mul_pd(twice, nz));
    const __m256d f = dot4(bx, by, bz, fx, fy, fz);
    pass = _mm256_and_pd(pass, _mm256_cmp_pd(f, zero, _CMP_GT_OQ));
    const __m256d bound = _mm256_mul_pd(tolerance, f);
    const __m256d off_x = _mm256_and_pd(_mm256_sub_pd(dot4(bx, by, bz, rx, ry, rz), _mm256_mul_pd(sx, f)), abs_mask);
    const __m256d off_y = _mm256_and_pd(_mm256_sub_pd(dot4(bx, by, bz, ux, uy, uz), _mm256_mul_pd(sy, f)), abs_mask);
    // !(off > bound): a NaN passes, as the reference's `>` lets it.
    pass = _mm256_and_pd(pass, _mm256_cmp_pd(off_x, bound, _CMP_NGT_UQ));
    pass = _mm256_and_pd(pass, _mm256_cmp_pd(off_y, bound, _CMP_NGT_UQ));
    pass = _mm256_and_pd(pass, open);
    result = _mm256_blendv_pd(result, _mm256_set1_pd(double(p)), pass);
    open = _mm256_andnot_pd(pass, open);
  }
  _mm256_store_pd(chosen, result);
  for (int k = 0; k < 4; ++k) plane_of[i + uint32_t(k)] = uint8_t(chosen[k]);
}
}  // namespace
#endif

bool mirror_ray_lanes() {
#if defined(MOBIRT_MIRROR_AVX2)
  static const bool avx2 = __builtin_cpu_supports("avx2");
  return avx2;
#else
  return false;
#endif
}

void mirror_ray_planes(const MirrorRayTest& test, const RayBatch& rays, uint32_t begin, uint32_t end, uint8_t* plane_of) {
  if (test.planes.size() >= kNoMirrorPlane) {
    throw Error(ErrorKind::Internal, "mirror_ray_planes: " + std::to_string(test.planes.size()) + " planes");
  }
  uint32_t i = begin;
#if defined(MOBIRT_MIRROR_AVX2)
  if (mirror_ray_lanes()) {
    for (; i + 4 <= end; i += 4) mirror_ray_planes_x4(test, rays, i, plane_of);
  }
#endif
  for (; i < end; ++i) plane_of[i] = mirror_ray_plane(test, rays, i);
}

}  // namespace mobirt
