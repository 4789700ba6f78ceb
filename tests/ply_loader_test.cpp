// PLY: files written by the test in ASCII and binary of both byte orders round-trip their
// triangles, normals, texture coordinates and colours; broken and over-limit files end in
// BadInput errors naming the file and the element.
#include <gtest/gtest.h>

#include <bit>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "core/error.h"
#include "scene/loader.h"
#include "test_support.h"

namespace mobirt {
namespace {

namespace fs = std::filesystem;
using test::expect_bad_input;
using test::expect_vec3;

struct Vertex {
  glm::vec3 p, n;
  glm::vec2 uv;
  uint8_t rgb[3];
};

// Two faces: a quad (red) and a triangle (green) sharing an edge, plus a two-vertex "face" (a
// line, not rendered).
const std::vector<Vertex> kVertices = {
    {{0, 0, 0}, {0, 0, 1}, {0, 0}, {255, 0, 0}},     {{1, 0, 0}, {0, 0, 1}, {1, 0}, {255, 0, 0}},
    {{1, 1, 0}, {0, 0, 1}, {1, 1}, {255, 0, 0}},     {{0, 1, 0}, {0, 0, 1}, {0, 1}, {255, 0, 0}},
    {{1, 0, 0}, {0.6f, 0, 0.8f}, {0.5f, 0.25f}, {0, 255, 0}},
    {{2, 0, 1}, {0.6f, 0, 0.8f}, {1, 0.25f}, {0, 255, 0}},
    {{1, 1, 0}, {0.6f, 0, 0.8f}, {0.5f, 1}, {0, 255, 0}}};
const std::vector<std::vector<uint32_t>> kFaces = {{0, 1, 2, 3}, {4, 5, 6}, {0, 1}};

enum class Kind { Ascii, Little, Big };

template <class T>
void put(std::string& out, T v, bool big) {
  unsigned char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  if (big == (std::endian::native == std::endian::little)) std::reverse(b, b + sizeof(T));
  out.append(reinterpret_cast<const char*>(b), sizeof(T));
}

// The test mesh as a PLY file. Texture coordinates are named as `uv_names` says; an element
// mobirt does not read ("edge") and a face property before the index list ("flags") are
// included so that the reader must step over them.
std::string write_ply(const std::string& name, Kind kind, const char* uv_names[2]) {
  std::ostringstream h;
  h << "ply\r\nformat " << (kind == Kind::Ascii ? "ascii" : kind == Kind::Little ? "binary_little_endian" : "binary_big_endian")
    << " 1.0\ncomment written by ply_loader_test\n"
    << "element vertex " << kVertices.size() << "\n"
    << "property float x\nproperty float y\nproperty double z\n"
    << "property float nx\nproperty float ny\nproperty float nz\n"
    << "property float " << uv_names[0] << "\nproperty float " << uv_names[1] << "\n"
    << "property uchar red\nproperty uchar green\nproperty uchar blue\n"
    << "element edge 1\nproperty int vertex1\nproperty int vertex2\n"
    << "element face " << kFaces.size() << "\n"
    << "property short flags\nproperty list uchar int vertex_indices\n"
    << "end_header\n";
  std::string body;
  const bool big = kind == Kind::Big;
  for (const Vertex& v : kVertices) {
    if (kind == Kind::Ascii) {
      std::ostringstream line;
      line << v.p.x << " " << v.p.y << " " << v.p.z << " " << v.n.x << " " << v.n.y << " " << v.n.z << " " << v.uv.x
           << " " << v.uv.y << " " << int(v.rgb[0]) << " " << int(v.rgb[1]) << " " << int(v.rgb[2]) << "\n";
      body += line.str();
    } else {
      put(body, v.p.x, big);
      put(body, v.p.y, big);
      put(body, double(v.p.z), big);
      for (int k = 0; k < 3; ++k) put(body, v.n[k], big);
      put(body, v.uv.x, big);
      put(body, v.uv.y, big);
      for (int k = 0; k < 3; ++k) put(body, v.rgb[k], big);
    }
  }
  if (kind == Kind::Ascii) {
    body += "0 1\n";
  } else {
    put(body, int32_t(0), big);
    put(body, int32_t(1), big);
  }
  for (const auto& f : kFaces) {
    if (kind == Kind::Ascii) {
      body += "7 " + std::to_string(f.size());
      for (uint32_t i : f) body += " " + std::to_string(i);
      body += "\n";
    } else {
      put(body, int16_t(7), big);
      put(body, uint8_t(f.size()), big);
      for (uint32_t i : f) put(body, int32_t(i), big);
    }
  }
  const fs::path path = test::temp_dir() / name;
  std::ofstream(path, std::ios::binary) << h.str() << body;
  return path.string();
}

TEST(PlyLoader, AsciiAndBinaryOfBothByteOrdersRoundTripTheirTriangles) {
  const char* names[3][2] = {{"u", "v"}, {"s", "t"}, {"texture_u", "texture_v"}};
  const Kind kinds[3] = {Kind::Ascii, Kind::Little, Kind::Big};
  for (int k = 0; k < 3; ++k) {
    SCOPED_TRACE(k);
    const Scene s = load_scene(write_ply("mesh" + std::to_string(k) + ".ply", kinds[k], names[k]));
    // The quad fans from its first vertex: (0 1 2) (0 2 3); then the triangle; the line is dropped.
    const std::vector<uint32_t> expected = {0, 1, 2, 0, 2, 3, 4, 5, 6};
    ASSERT_EQ(s.mesh.triangle_count(), 3u);
    ASSERT_EQ(s.mesh.positions.size(), expected.size());
    ASSERT_EQ(s.mesh.texcoords.size(), expected.size());
    for (size_t i = 0; i < expected.size(); ++i) {
      const Vertex& v = kVertices[expected[i]];
      expect_vec3(s.mesh.positions[i], v.p);
      expect_vec3(s.mesh.normals[i], v.n);
      EXPECT_FLOAT_EQ(s.mesh.texcoords[i].x, v.uv.x);
      EXPECT_FLOAT_EQ(s.mesh.texcoords[i].y, 1.0f - v.uv.y);  // flipped to glTF's convention
    }
    // The colour groups: the red quad and the green triangle, one material each.
    ASSERT_EQ(s.materials.size(), 2u);
    expect_vec3(s.materials[s.mesh.material_ids[0]].diffuse, {1, 0, 0});
    EXPECT_EQ(s.mesh.material_ids[0], s.mesh.material_ids[1]);
    expect_vec3(s.materials[s.mesh.material_ids[2]].diffuse, {0, 1, 0});
    EXPECT_FALSE(s.camera);
    EXPECT_TRUE(s.lights.empty());
  }
}

TEST(PlyLoader, MinimalFileGetsFlatNormalsAndTheDefaultMaterial) {
  const fs::path path = test::temp_dir() / "min.ply";
  // A concave face (an L of 6 vertices): ear clipping, 4 triangles, area 3.
  std::ofstream(path) << "ply\nformat ascii 1.0\nelement vertex 6\nproperty float x\nproperty float y\n"
                         "property float z\nelement face 1\nproperty list uchar uint vertex_index\nend_header\n"
                         "0 0 0\n2 0 0\n2 1 0\n1 1 0\n1 2 0\n0 2 0\n6 0 1 2 3 4 5\n";
  const Scene s = load_scene(path.string());
  ASSERT_EQ(s.mesh.triangle_count(), 4u);
  EXPECT_TRUE(s.mesh.texcoords.empty());
  ASSERT_EQ(s.materials.size(), 1u);
  expect_vec3(s.materials[0].diffuse, Material{}.diffuse);
  double area = 0.0;
  for (size_t t = 0; t < 4; ++t) {
    const glm::vec3* p = &s.mesh.positions[3 * t];
    const glm::vec3 c = glm::cross(p[1] - p[0], p[2] - p[0]);
    EXPECT_GT(c.z, 0.0f) << "wound like the face";
    area += 0.5 * double(c.z);
    for (int k = 0; k < 3; ++k) expect_vec3(s.mesh.normals[3 * t + size_t(k)], {0, 0, 1});
  }
  EXPECT_NEAR(area, 3.0, 1e-6);
}

TEST(PlyLoader, BadFilesNameTheFileAndTheElement) {
  const std::string header = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                             "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
  std::vector<std::pair<std::string, std::vector<std::string>>> cases = {
      {"", {"bad.ply", "not a PLY file"}},
      {"solid cube\n", {"bad.ply", "not a PLY file"}},
      {"ply\nformat ascii 1.0\nelement vertex 3\n", {"bad.ply", "header line 4", "end_header"}},
      {"ply\nformat utf16 1.0\nend_header\n", {"bad.ply", "header line 2", "unknown format 'utf16'"}},
      {"ply\nformat ascii 1.0\nproperty float x\nend_header\n", {"bad.ply", "header line 3", "before any element"}},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty quad x\nend_header\n", {"header line 4", "property TYPE NAME"}},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty list float int x\nend_header\n", {"header line 4", "integer COUNT_TYPE"}},
      {"ply\nelement vertex 0\nend_header\n", {"bad.ply", "no 'format' line"}},
      {"ply\nformat ascii 1.0\nbogus\nend_header\n", {"header line 3", "unknown header keyword 'bogus'"}},
      {header + "0 0 0\n1 0 0\n", {"bad.ply", "element 'vertex': 3 records do not fit", "truncated"}},
      {header + "0 0 0\n1 0 0\n0 1 0\n3 0 1 9\n", {"bad.ply", "element 'face' 0", "vertex index 9", "3 vertices"}},
      {header + "0 0 0\n1 0 0\n0 1 0\n3 0 1\n", {"bad.ply", "element 'face' 0 property 'vertex_indices'", "end of file"}},
      {header + "0 0 0\n1 0 x\n0 1 0\n3 0 1 2\n", {"bad.ply", "element 'vertex' 1 property 'z'", "'x' is not a number"}},
      {header + "0 0 0\n1 0 0\n0 1 0\n-3 0 1 2\n", {"bad.ply", "element 'face' 0", "list length"}},
      {header + "0 0 0\n1 0 nan\n0 1 0\n3 0 1 2\n", {"bad.ply", "non-finite position"}},
      {"ply\nformat ascii 1.0\nelement vertex 4000000000\nproperty float x\nend_header\n1\n", {"element 'vertex'", "4000000000 records"}},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty float y\nend_header\n1\n", {"element 'vertex'", "x, y and z"}},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
       "element face 1\nproperty int a\nend_header\n0 0 0\n1\n", {"element 'face'", "vertex_indices"}},
      {"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
       "0 0 0\n1 0 0\n0 1 0\n", {"bad.ply", "no triangles"}},
      // A second vertex list after the faces would leave their indices pointing past it.
      {"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
       "element face 1\nproperty list uchar int vertex_indices\nelement vertex 1\nproperty float x\n"
       "property float y\nproperty float z\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n5 5 5\n",
       {"bad.ply", "element 'vertex' appears twice"}},
  };
  std::string big_face = header + "0 0 0\n1 0 0\n0 1 0\n16385";
  for (int i = 0; i < 16385; ++i) big_face += " 0";
  cases.push_back({big_face + "\n", {"bad.ply", "element 'face' 0: 16385 vertices, more than the 16384"}});
  for (const auto& [text, parts] : cases) {
    SCOPED_TRACE(text.substr(0, 400));
    const fs::path path = test::temp_dir() / "bad.ply";
    std::ofstream(path, std::ios::binary) << text;
    expect_bad_input([&] { load_scene(path.string()); }, parts);
  }
  // A binary file cut short inside its face list: the element and record are named.
  const char* names[2] = {"u", "v"};
  const std::string good = write_ply("cut.ply", Kind::Little, names);
  std::string bytes;
  {
    std::ifstream in(good, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  std::ofstream(good, std::ios::binary | std::ios::trunc) << bytes.substr(0, bytes.size() - 5);
  expect_bad_input([&] { load_scene(good); }, {"cut.ply", "element 'face' 2", "end of file"});
}

}  // namespace
}  // namespace mobirt
