// Triangle meshes for tools/make_scenes.cpp: positions, normals, texture coordinates (glTF
// convention: (0, 0) is the top-left of the image) and the shapes the scenes are made of.
#pragma once

#include <glm/glm.hpp>

#include <cstdint>
#include <vector>

namespace mobirt::scenes {

constexpr float kPi = 3.14159265358979f;

struct Mesh {
  std::vector<glm::vec3> positions;
  std::vector<glm::vec3> normals;
  std::vector<glm::vec2> uvs;  // one per vertex
  std::vector<uint32_t> indices;

  uint32_t vertex(const glm::vec3& p, const glm::vec3& n, const glm::vec2& uv = glm::vec2(0.0f)) {
    positions.push_back(p);
    normals.push_back(n);
    uvs.push_back(uv);
    return uint32_t(positions.size() - 1);
  }
  void quad(uint32_t a, uint32_t b, uint32_t c, uint32_t d) {
    indices.insert(indices.end(), {a, b, c, a, c, d});
  }
  size_t triangles() const { return indices.size() / 3; }
};

// An axis-aligned box centred on the origin, flat normals; each face maps the whole texture.
Mesh box(const glm::vec3& size);
// A UV sphere centred on the origin, smooth normals; u runs around (equirectangular), v = 0 at +Y.
Mesh sphere(float radius, int segments, int rings);
// A closed cylinder standing on the origin, smooth sides, flat caps; u around, v down the side.
Mesh cylinder(float radius, float height, int segments);
// A square floor in the XZ plane, facing +Y, split into n x n quads; uv spans [0, tiles].
Mesh floor_plane(float size, int n, float tiles = 1.0f);
// A rectangle in the XY plane facing +Z, w x h, split into nx x ny quads; the image's top at +Y.
Mesh panel(float w, float h, int nx, int ny);
// A box with rounded edges (a superellipsoid, exponent e: 1 = ellipsoid, towards 0 = box), centred
// on the origin, parameterised like sphere().
Mesh rounded_box(const glm::vec3& size, float e, int segments, int rings);
// A torus around the Y axis (ring radius R, tube radius r); u around the ring, v around the tube.
Mesh torus(float R, float r, int segments, int sides);
// A flat-shaded prism: the triangle (a, b, c) in the XY plane extruded by depth along Z, centred.
Mesh prism(const glm::vec2& a, const glm::vec2& b, const glm::vec2& c, float depth);

// Appends b to a.
void append(Mesh& a, const Mesh& b);
// Scales every vertex by s (normals follow the inverse transpose).
void scale(Mesh& m, const glm::vec3& s);

}  // namespace mobirt::scenes
