// Light buffer (Haines and Greenberg 1986): for a point light, a cube of direction cells around it,
// each listing every triangle that a ray from the light through the cell can meet. A shadow ray
// from a point p to the light lies on one direction from the light, so only the triangles of p's
// cell can occlude it: one cell look-up and a short list instead of a walk through the kd-tree.
// Exact where the cells are conservative: each triangle is clipped to each face's view pyramid
// (widened by kLightBufferFaceMargin so that directions on a cube edge belong to both faces) and
// its projection's bounding rectangle widened by kLightBufferCellMargin of a cell. Measured against
// the kd-tree walk by tools/profile/light_buffer_probe.cpp (docs/performance-history.md,
// *Session 28: a light buffer*); the renderer's shadow rays test them under --shadow-cells (auto,
// the default: under highp, up to 32,768 triangles, without analytic shapes).
#pragma once

#include <glm/glm.hpp>

#include <array>
#include <cstdint>
#include <span>
#include <vector>

namespace mobirt {

inline constexpr float kLightBufferFaceMargin = 1e-3f;   // of the face's half-width, at z = 1
inline constexpr float kLightBufferCellMargin = 1e-2f;   // of a cell
inline constexpr uint32_t kLightBufferOutside = 0xFFFFFFFFu;  // a direction no triangle covers
inline constexpr uint32_t kLightBufferSubCells = 64;  // glsl/layout.h MOBIRT_LIGHT_BUFFER_SUBCELLS

// A triangle's part of a cell (LightBuffer::sub): columns x0..x1, rows y0..y1, each 0..63.
constexpr uint32_t light_buffer_sub(uint32_t x0, uint32_t y0, uint32_t x1, uint32_t y1) {
  return x0 + kLightBufferSubCells * y0 + kLightBufferSubCells * kLightBufferSubCells * (x1 + kLightBufferSubCells * y1);
}
// Whether column sx, row sy of a cell lies in the part `sub`.
constexpr bool light_buffer_sub_contains(uint32_t sub, uint32_t sx, uint32_t sy) {
  constexpr uint32_t S = kLightBufferSubCells;
  const uint32_t lo = sub % (S * S), hi = sub / (S * S);
  return sx >= lo % S && sy >= lo / S && sx <= hi % S && sy <= hi / S;
}

struct LightBuffer {
  glm::vec3 light{0.0f};
  int resolution = 0;                 // cells per face edge
  // Per face, the directions its cells cover (the union of its triangles' projections, a little
  // wider): (s0, t0, columns per unit of s, rows per unit of t); the face's (u / w, v / w) at s0,
  // t0 is the corner of cell 0.
  std::array<glm::vec4, 6> window{};
  // Cell c's triangles are prims[first[c] .. first[c + 1]), sorted by near (their nearest distance
  // to the light, ascending). Cell index: (face * resolution + row) * resolution + column; face
  // 0..5 = +x, -x, +y, -y, +z, -z (light_buffer_cell).
  std::vector<uint32_t> first;
  std::vector<uint32_t> prims;
  std::vector<float> near;            // per entry of prims
  // Per entry of prims: the part of its cell the triangle's rectangle covers (widened as the
  // cells are), in kLightBufferSubCells columns and rows: x0 + S y0 + S^2 (x1 + S y1), S =
  // kLightBufferSubCells. A ray whose direction lies outside it cannot meet the triangle: its test
  // is skipped (light_buffer_occluded, glsl/traverse.glsl). Measured at 64 cells, the default:
  // 33-62 % of the triangle tests of the paper's scenes and the Utah models skipped (README,
  // *Shadow rays through light buffers*).
  std::vector<uint32_t> sub;
  // Triangles left out of every list (faces of closed parts turned away from the light:
  // build_light_buffer's winding, src/accel/closed_parts.h).
  size_t left_out = 0;
  size_t cells() const { return first.empty() ? 0 : first.size() - 1; }
  // The list a reference finds itself in, on average (sum of count^2 / sum of count): about what a
  // shadow ray that ends on a surface tests, where rays fall as the triangles do.
  double mean_list() const;
};

// Past this mean_list() a light's shadow rays walk the kd-tree instead (--shadow-cells): the
// tessellated sphereflake's lights, 19-123x the toaster's lists, took 3x the walk's pass.
inline constexpr double kLightBufferMaxMeanList = 100.0;

// Whether a light's shadow rays test `lb` rather than walk: built (resolution > 0), lists not long.
inline bool light_buffer_pays(const LightBuffer& lb) {
  return lb.resolution > 0 && lb.mean_list() <= kLightBufferMaxMeanList;
}

// The light buffer of the triangles `positions` (three vertices each) around `light`, into `out`
// (its arrays' memory reused), on `threads` threads (0 = all cores). The same buffer for any
// thread count. winding (one per triangle, or empty: all 0): where not 0, the triangle is a face of
// a closed part with the light outside (light_windings() in src/accel/closed_parts.h) and goes into
// no list if it faces away from the light (faces_away): a shadow ray does not need it.
void build_light_buffer(std::span<const glm::vec3> positions, glm::vec3 light, int resolution, LightBuffer& out,
                        unsigned threads = 0, std::span<const int8_t> winding = {});
inline LightBuffer build_light_buffer(std::span<const glm::vec3> positions, glm::vec3 light, int resolution) {
  LightBuffer lb;
  build_light_buffer(positions, light, resolution, lb);
  return lb;
}

// The cell of direction d (from the light; not zero), or kLightBufferOutside where no triangle is;
// sx, sy (where given): d's column and row of kLightBufferSubCells within the cell.
uint32_t light_buffer_cell(const LightBuffer& lb, glm::vec3 d, uint32_t* sx = nullptr, uint32_t* sy = nullptr);

// Whether the segment from `origin` to the light meets one of the triangles (`tree` holds their
// texels: intersect_triangle, the traversal pass's test), testing only origin's cell up to the
// first triangle whose nearest distance to the light is past the segment's end, and skipping the
// triangles whose part of the cell (LightBuffer::sub) the segment's direction misses. tests: how
// many triangles it tested; entries: how many entries of the list it read, skipped ones included
// (either may be null).
struct FlatKdTree;
// `test`: the ray/triangle test (the pass's INTERSECT; single precision only).
struct RayTest;
bool light_buffer_occluded(const LightBuffer& lb, const FlatKdTree& tree, glm::vec3 origin, uint32_t* tests = nullptr,
                           uint32_t* entries = nullptr, const RayTest* test = nullptr);

// The nearest distance from `p` to the triangle a, b, c (Ericson, Real-Time Collision Detection,
// 5.1.5), in double.
double point_triangle_distance(glm::dvec3 p, glm::dvec3 a, glm::dvec3 b, glm::dvec3 c);

}  // namespace mobirt
