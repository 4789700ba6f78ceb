#include "scene/validate.h"

#include <algorithm>
#include <cmath>
#include <iostream>
#include <string>
#include <vector>

#include "core/error.h"

namespace mobirt {

namespace {

bool finite3(const glm::vec3& v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

// Whether the triangle (a, b, c) has an area: check_corners' two passes count degenerate triangles
// with this one test.
bool has_area(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c) {
  const glm::vec3 cross = glm::cross(b - a, c - a);
  return glm::dot(cross, cross) > 0.0f;
}

// Whether normal n is of unit length as validation takes it: |n|^2 within 1e-5 of 1 puts |n|
// within 5.1e-6 of 1 and every component finite (a NaN or an infinity fails the comparison), so
// such a normal needs neither a square root nor a finiteness check. Both passes of check_corners
// test it.
bool unit_length(const glm::vec3& n) {
  const float length2 = glm::dot(n, n);  // what glm::length takes the root of
  return (length2 >= 1.0f - 1e-5f) & (length2 <= 1.0f + 1e-5f);
}

// The mesh's arrays in step: 3 corners a triangle (texture coordinates that or none). A loader's
// or the posing's bug otherwise.
void check_arrays(const Scene& scene) {
  const TriangleMesh& mesh = scene.mesh;
  const size_t tris = mesh.triangle_count();
  if (mesh.positions.size() != 3 * tris || mesh.normals.size() != 3 * tris ||
      (!mesh.texcoords.empty() && mesh.texcoords.size() != 3 * tris)) {
    throw Error(ErrorKind::Internal,
                scene.source + ": inconsistent mesh arrays (" + std::to_string(tris) +
                    " triangles, " + std::to_string(mesh.positions.size()) + " positions, " +
                    std::to_string(mesh.normals.size()) + " normals, " +
                    std::to_string(mesh.texcoords.size()) + " texture coordinates)");
  }
}

// One pass without branches over a mesh: whether every position is finite and every normal of
// unit length (unit_length), the degenerate triangles counted into `degenerate` as check_corners'
// loop counts them.
bool corners_clean(const TriangleMesh& mesh, size_t& degenerate) {
  bool clean = true;
  const glm::vec3* p = mesh.positions.data();
  const glm::vec3* n = mesh.normals.data();
  for (size_t t = 0, tris = mesh.triangle_count(); t < tris; ++t, p += 3, n += 3) {
    degenerate += !has_area(p[0], p[1], p[2]);
    // x - x is 0 for a finite x and NaN for a NaN or an infinity (a max would drop a NaN).
    const glm::vec3 zero = (p[0] - p[0]) + (p[1] - p[1]) + (p[2] - p[2]);
    clean &= (zero.x == 0.0f) & (zero.y == 0.0f) & (zero.z == 0.0f);
    for (int k = 0; k < 3; ++k) clean &= unit_length(n[k]);
  }
  return clean;
}

// Every corner's position finite, its normal unit length (renormalised, or the geometric normal
// for a zero one) and, with `texcoords`, its texture coordinates finite; the degenerate triangles
// counted. What posing changes is all of it but the texture coordinates.
void check_corners(Scene& scene, bool texcoords) {
  TriangleMesh& mesh = scene.mesh;
  const size_t tris = mesh.triangle_count();
  const bool uvs = texcoords && !mesh.texcoords.empty();
  // Without texture coordinates to check (a posed frame's, or a mesh without them) the pass
  // without branches comes first; where it finds nothing to fix or report, that is the whole check
  // (posing makes unit normals). Otherwise the loop below finds the corner, fixes it or names it.
  if (size_t clean_degenerate = 0; !uvs && corners_clean(mesh, clean_degenerate)) {
    scene.degenerate_triangles = clean_degenerate;
    return;
  }
  const auto check_texcoord = [&](size_t t, size_t k) {
    const glm::vec2& uv = mesh.texcoords[3 * t + k];
    if (!std::isfinite(uv.x) || !std::isfinite(uv.y)) {
      throw input_error(scene.source, "triangle " + std::to_string(t) + ": vertex " + std::to_string(k) +
                                          " has non-finite texture coordinates (NaN or infinity)");
    }
  };
  size_t degenerate = 0;
  for (size_t t = 0; t < tris; ++t) {
    for (size_t k = 0; k < 3; ++k) {
      const size_t i = 3 * t + k;
      if (!finite3(mesh.positions[i])) {
        throw input_error(scene.source, "triangle " + std::to_string(t) + ": vertex " +
                                            std::to_string(k) +
                                            " has a non-finite position (NaN or infinity)");
      }
    }
    const glm::vec3& a = mesh.positions[3 * t];
    const glm::vec3& b = mesh.positions[3 * t + 1];
    const glm::vec3& c = mesh.positions[3 * t + 2];
    if (!has_area(a, b, c)) ++degenerate;
    for (size_t k = 0; k < 3; ++k) {
      const size_t i = 3 * t + k;
      glm::vec3& n = mesh.normals[i];
      // A unit normal (what loaders and posing make) needs neither check below. The square root
      // of every corner's length was most of validation's cost when this loop ran on every posed
      // frame (perf: 1.4 % of a toaster frame's CPU); a posed frame now reaches it only where the
      // pass above found something.
      if (unit_length(n)) {
        if (uvs) check_texcoord(t, k);
        continue;
      }
      if (!finite3(n)) {
        throw input_error(scene.source, "triangle " + std::to_string(t) + ": vertex " +
                                            std::to_string(k) +
                                            " has a non-finite normal (NaN or infinity)");
      }
      const float len = glm::length(n);
      if (!(len > 0.0f) || !std::isfinite(len)) {
        n = geometric_normal(a, b, c);
      } else if (std::abs(len - 1.0f) > 1e-5f) {
        n /= len;
      }
      if (uvs) check_texcoord(t, k);
    }
  }
  scene.degenerate_triangles = degenerate;
}

}  // namespace

std::string library_message(const std::string& text) {
  std::vector<std::string> lines;
  std::vector<std::string> dropped_lines;
  size_t start = 0;
  while (start < text.size()) {
    size_t end = text.find('\n', start);
    if (end == std::string::npos) end = text.size();
    std::string line = text.substr(start, end - start);
    start = end + 1;
    while (!line.empty() && (line.back() == '\r' || line.back() == ' ')) line.pop_back();
    if (line.size() > 200) line = line.substr(0, 160) + "...";  // data URIs can be megabytes
    if (line.empty() || std::find(lines.begin(), lines.end(), line) != lines.end()) continue;
    if (lines.size() < 6) {
      lines.push_back(line);
    } else if (std::find(dropped_lines.begin(), dropped_lines.end(), line) ==
               dropped_lines.end()) {
      dropped_lines.push_back(line);
    }
  }
  std::string out;
  for (const std::string& line : lines) out += (out.empty() ? "" : "; ") + line;
  if (!dropped_lines.empty()) out += "; ... (" + std::to_string(dropped_lines.size()) + " more)";
  return out;
}

void scene_warning(const std::string& file, const std::string& message) {
  std::cerr << "mobirt: warning: " << (file.empty() ? "" : file + ": ") << message << '\n';
}

glm::vec3 geometric_normal(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c) {
  const glm::vec3 n = glm::cross(b - a, c - a);
  const float len = glm::length(n);
  if (!(len > 0.0f) || !std::isfinite(len)) return glm::vec3(0.0f, 0.0f, 1.0f);
  return n / len;
}

void validate_scene(Scene& scene) {
  TriangleMesh& mesh = scene.mesh;
  const size_t tris = mesh.triangle_count();
  check_arrays(scene);
  if (tris == 0 && scene.shapes.empty()) {
    throw input_error(scene.source,
                      "no triangles: the file has no triangle mesh in its scene (points and "
                      "lines are not rendered)");
  }
  if (scene.materials.empty()) {
    Material fallback;
    fallback.name = "default";
    scene.materials.push_back(fallback);
  }
  for (size_t t = 0; t < tris; ++t) {
    if (mesh.material_ids[t] >= scene.materials.size()) {
      throw Error(ErrorKind::Internal, scene.source + ": triangle " + std::to_string(t) +
                                           " has material " +
                                           std::to_string(mesh.material_ids[t]) + " of " +
                                           std::to_string(scene.materials.size()));
    }
  }
  for (size_t k = 0; k < scene.shapes.size(); ++k) {
    const Shape& s = scene.shapes[k];
    const bool finite = finite3(s.base) && finite3(s.apex) && std::isfinite(s.base_radius) &&
                        std::isfinite(s.apex_radius);
    const bool sphere_ok = s.kind == ShapeKind::Sphere && s.base_radius > 0.0f;
    const bool cone_ok = s.kind == ShapeKind::Cone && s.base != s.apex && s.base_radius >= 0.0f &&
                         s.apex_radius >= 0.0f && (s.base_radius > 0.0f || s.apex_radius > 0.0f);
    if (!finite || !(sphere_ok || cone_ok) || s.material >= scene.materials.size()) {
      throw Error(ErrorKind::Internal, scene.source + ": shape " + std::to_string(k) +
                                           " is malformed (radii, axis or material out of range)");
    }
  }
  for (const Material& m : scene.materials) {
    if (m.texture >= static_cast<int>(scene.textures.size())) {
      throw Error(ErrorKind::Internal,
                  scene.source + ": material '" + m.name + "' has an out-of-range texture");
    }
  }

  check_corners(scene, true);
}

void validate_posed(Scene& scene) {
  check_arrays(scene);
  check_corners(scene, false);
}

}  // namespace mobirt
