// Scene loading: glTF (.gltf with data URIs, .glb) and OBJ files written by the tests themselves,
// broken files that must end in BadInput errors, and the shared real scenes when present.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include "core/error.h"
#include "gltf_builder.h"
#include "scene/animation.h"
#include "scene/loader.h"
#include "test_support.h"

namespace mobirt {
namespace {

using test::base64;
using test::expect_bad_input;
using test::expect_vec3;
using test::Gltf;
using test::kFloat;
using test::kU16;
using test::kU32;
using test::kU8;

using nlohmann::json;
namespace fs = std::filesystem;

// A unit quad in the XY plane facing +Z, indexed (4 vertices, 6 u16 indices), one node.
Gltf quad_gltf() {
  Gltf g;
  const int pos = g.vec3s({{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}});
  const int nrm = g.vec3s({{0, 0, 1}, {0, 0, 1}, {0, 0, 1}, {0, 0, 1}});
  const int uv = g.vec2s({{0, 1}, {1, 1}, {1, 0}, {0, 0}});
  const int idx = g.indices(std::vector<uint16_t>{0, 1, 2, 0, 2, 3});
  const int m = g.mesh({{"attributes", {{"POSITION", pos}, {"NORMAL", nrm}, {"TEXCOORD_0", uv}}},
                        {"indices", idx}});
  g.scene({g.node({{"mesh", m}})});
  return g;
}

// ---- glTF geometry -----------------------------------------------------------------------------

TEST(GltfLoader, IndexedQuad) {
  const std::string path = quad_gltf().write_gltf(test::temp_dir() / "quad.gltf");
  const Scene s = load_scene(path);
  EXPECT_EQ(s.source, path);
  ASSERT_EQ(s.mesh.triangle_count(), 2u);
  ASSERT_EQ(s.mesh.positions.size(), 6u);
  ASSERT_EQ(s.mesh.normals.size(), 6u);
  ASSERT_EQ(s.mesh.texcoords.size(), 6u);
  expect_vec3(s.mesh.positions[0], {0, 0, 0});
  expect_vec3(s.mesh.positions[1], {1, 0, 0});
  expect_vec3(s.mesh.positions[2], {1, 1, 0});
  expect_vec3(s.mesh.positions[5], {0, 1, 0});
  for (const glm::vec3& n : s.mesh.normals) expect_vec3(n, {0, 0, 1});
  EXPECT_FLOAT_EQ(s.mesh.texcoords[1].x, 1.0f);
  EXPECT_FLOAT_EQ(s.mesh.texcoords[1].y, 1.0f);
  ASSERT_EQ(s.materials.size(), 1u);  // the default material
  EXPECT_EQ(s.mesh.material_ids[0], 0u);
  EXPECT_TRUE(s.lights.empty());
  EXPECT_FALSE(s.camera.has_value());
  EXPECT_EQ(s.degenerate_triangles, 0u);
  const Aabb b = s.bounds();
  expect_vec3(b.lo, {0, 0, 0});
  expect_vec3(b.hi, {1, 1, 0});
}

TEST(GltfLoader, GlbBinaryAndUppercaseExtension) {
  const Gltf g = quad_gltf();
  const fs::path dir = test::temp_dir();
  const Scene s = load_scene(g.write_glb(dir / "quad.glb"));
  EXPECT_EQ(s.mesh.triangle_count(), 2u);
  const Scene upper = load_scene(g.write_glb(dir / "QUAD.GLB"));
  EXPECT_EQ(upper.mesh.triangle_count(), 2u);
  expect_vec3(upper.mesh.positions[2], {1, 1, 0});
}

TEST(GltfLoader, NonIndexedWithoutNormalsGetsFlatNormals) {
  Gltf g;
  const int pos = g.vec3s({{0, 0, 0}, {2, 0, 0}, {0, 2, 0}, {0, 0, 0}, {0, 0, 1}, {0, 1, 0}});
  const int m = g.mesh({{"attributes", {{"POSITION", pos}}}});
  g.scene({g.node({{"mesh", m}})});
  const Scene s = load_gltf(g.write_gltf(test::temp_dir() / "soup.gltf"));
  ASSERT_EQ(s.mesh.triangle_count(), 2u);
  for (int k = 0; k < 3; ++k) expect_vec3(s.mesh.normals[static_cast<size_t>(k)], {0, 0, 1});
  // (0,0,0), (0,0,1), (0,1,0): counter-clockwise seen from -X.
  for (int k = 3; k < 6; ++k) expect_vec3(s.mesh.normals[static_cast<size_t>(k)], {-1, 0, 0});
  EXPECT_TRUE(s.mesh.texcoords.empty());
}

TEST(GltfLoader, IndexTypesU8AndU32) {
  for (int type : {kU8, kU32}) {
    Gltf g;
    const int pos = g.vec3s({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}});
    const int idx = type == kU8 ? g.indices(std::vector<uint8_t>{0, 1, 2})
                                : g.indices(std::vector<uint32_t>{0, 1, 2});
    g.scene({g.node({{"mesh", g.mesh({{"attributes", {{"POSITION", pos}}}, {"indices", idx}})}})});
    const Scene s = load_gltf(g.write_gltf(test::temp_dir() / "tri.gltf"));
    ASSERT_EQ(s.mesh.triangle_count(), 1u) << type;
    expect_vec3(s.mesh.positions[2], {0, 1, 0});
  }
}

TEST(GltfLoader, InterleavedStrideAndNormalizedTexcoords) {
  Gltf g;
  // Interleaved position (12 bytes) + normal (12 bytes): stride 24.
  const std::vector<float> data = {0, 0, 0, 0, 0, 1, 1, 0, 0, 0, 0, 1, 0, 1, 0, 0, 0, 1};
  const int v = g.view(data.data(), data.size() * 4, 24);
  const int pos = g.accessor(v, kFloat, 3, "VEC3", 0);
  const int nrm = g.accessor(v, kFloat, 3, "VEC3", 12);
  const std::vector<uint16_t> uv16 = {0, 65535, 65535, 65535, 0, 0};
  const int uv = g.accessor(g.view(uv16.data(), uv16.size() * 2), kU16, 3, "VEC2", 0, true);
  g.scene({g.node({{"mesh", g.mesh({{"attributes",
                                       {{"POSITION", pos}, {"NORMAL", nrm}, {"TEXCOORD_0", uv}}}})}})});
  const Scene s = load_gltf(g.write_gltf(test::temp_dir() / "interleaved.gltf"));
  ASSERT_EQ(s.mesh.triangle_count(), 1u);
  expect_vec3(s.mesh.positions[1], {1, 0, 0});
  expect_vec3(s.mesh.normals[1], {0, 0, 1});
  EXPECT_FLOAT_EQ(s.mesh.texcoords[0].y, 1.0f);
  EXPECT_FLOAT_EQ(s.mesh.texcoords[2].x, 0.0f);
}

TEST(GltfLoader, NodeHierarchyTranslationRotationScale) {
  Gltf g;
  const float r = std::sqrt(0.5f);
  const int pos = g.vec3s({{1, 0, 0}, {0, 1, 0}, {0, 0, 0}});
  const int nrm = g.vec3s({{r, r, 0}, {r, r, 0}, {r, r, 0}});
  const int m = g.mesh({{"attributes", {{"POSITION", pos}, {"NORMAL", nrm}}}});
  // child: scale (2,1,1) then translate (0,0,1); parent: rotate +90 degrees about Y, then
  // translate (1,2,3).
  const int child = g.node({{"mesh", m}, {"scale", {2, 1, 1}}, {"translation", {0, 0, 1}}});
  const int parent = g.node({{"children", {child}}, {"translation", {1, 2, 3}},
                             {"rotation", {0, r, 0, r}}});
  g.scene({parent});
  const Scene s = load_gltf(g.write_gltf(test::temp_dir() / "trs.gltf"));
  ASSERT_EQ(s.mesh.triangle_count(), 1u);
  // (1,0,0) -> (2,0,0) -> (2,0,1) -> rotY90: (x,y,z) -> (z,y,-x) = (1,0,-2) -> (2,2,1)
  expect_vec3(s.mesh.positions[0], {2, 2, 1});
  // (0,1,0) -> (0,1,1) -> (1,1,0) -> (2,3,3)
  expect_vec3(s.mesh.positions[1], {2, 3, 3});
  // (0,0,0) -> (0,0,1) -> (1,0,0) -> (2,2,3)
  expect_vec3(s.mesh.positions[2], {2, 2, 3});
  // Normal (1,1,0)/sqrt2 by the inverse transpose of scale (2,1,1): (0.5,1,0) normalised, then
  // rotY90: (0, 2, -1)/sqrt5.
  const float s5 = std::sqrt(5.0f);
  expect_vec3(s.mesh.normals[0], {0, 2 / s5, -1 / s5});
}

TEST(GltfLoader, MatrixNodeAndMirrorFlipsWinding) {
  Gltf g;
  const int pos = g.vec3s({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}});
  const int m = g.mesh({{"attributes", {{"POSITION", pos}}}});
  // Column-major: mirror X, translate (5, 0, 0).
  g.scene({g.node({{"mesh", m},
                   {"matrix", {-1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 5, 0, 0, 1}}})});
  const Scene s = load_gltf(g.write_gltf(test::temp_dir() / "mirror.gltf"));
  ASSERT_EQ(s.mesh.triangle_count(), 1u);
  expect_vec3(s.mesh.positions[0], {5, 0, 0});
  expect_vec3(s.mesh.positions[1], {5, 1, 0});  // swapped: winding flipped
  expect_vec3(s.mesh.positions[2], {4, 0, 0});
  expect_vec3(s.mesh.normals[0], {0, 0, 1});  // still facing +Z
}

TEST(GltfLoader, MirroredNormalsFollowTheInverseTranspose) {
  Gltf g;
  const int pos = g.vec3s({{0, 0, 0}, {0, 0, 1}, {0, 1, 0}});
  const int nrm = g.vec3s({{-1, 0, 0}, {-1, 0, 0}, {-1, 0, 0}});
  const int m = g.mesh({{"attributes", {{"POSITION", pos}, {"NORMAL", nrm}}}});
  g.scene({g.node({{"mesh", m}, {"scale", {-1, 1, 1}}})});
  const Scene s = load_gltf(g.write_gltf(test::temp_dir() / "mirror_n.gltf"));
  for (const glm::vec3& n : s.mesh.normals) expect_vec3(n, {1, 0, 0});
}

TEST(GltfLoader, TriangleStripAndFan) {
  Gltf g;
  const int strip_pos = g.vec3s({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}, {0, 2, 0}});
  const int fan_pos = g.vec3s({{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {-1, 0, 0}});
  const int strip = g.mesh({{"attributes", {{"POSITION", strip_pos}}}, {"mode", 5}});
  const int fan = g.mesh({{"attributes", {{"POSITION", fan_pos}}}, {"mode", 6}});
  g.scene({g.node({{"mesh", strip}}), g.node({{"mesh", fan}, {"translation", {0, 0, 1}}})});
  const Scene s = load_gltf(g.write_gltf(test::temp_dir() / "stripfan.gltf"));
  ASSERT_EQ(s.mesh.triangle_count(), 6u);
  for (const glm::vec3& n : s.mesh.normals) expect_vec3(n, {0, 0, 1});
  // Strip triangle 1 (odd) is (v1, v3, v2).
  expect_vec3(s.mesh.positions[3], {1, 0, 0});
  expect_vec3(s.mesh.positions[4], {1, 1, 0});
  expect_vec3(s.mesh.positions[5], {0, 1, 0});
  // Fan triangle 2 is (v0, v3, v4), moved to z = 1.
  expect_vec3(s.mesh.positions[15], {0, 0, 1});
  expect_vec3(s.mesh.positions[16], {0, 1, 1});
  expect_vec3(s.mesh.positions[17], {-1, 0, 1});
}

TEST(GltfLoader, SparseAccessor) {
  Gltf g;
  const std::vector<glm::vec3> base = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  const int pos = g.vec3s(base);
  const std::vector<uint8_t> sidx = {2};
  const std::vector<glm::vec3> svals = {{0, 5, 0}};
  const int iv = g.view(sidx.data(), 1);
  const int vv = g.view(svals.data(), sizeof(glm::vec3));
  g.doc["accessors"][static_cast<size_t>(pos)]["sparse"] = {
      {"count", 1},
      {"indices", {{"bufferView", iv}, {"componentType", kU8}}},
      {"values", {{"bufferView", vv}}}};
  g.scene({g.node({{"mesh", g.mesh({{"attributes", {{"POSITION", pos}}}})}})});
  const Scene s = load_gltf(g.write_gltf(test::temp_dir() / "sparse.gltf"));
  expect_vec3(s.mesh.positions[2], {0, 5, 0});
  expect_vec3(s.mesh.positions[1], {1, 0, 0});
}

TEST(GltfLoader, NoScenesUsesRootNodes) {
  Gltf g = quad_gltf();
  g.doc.erase("scenes");
  g.doc.erase("scene");
  const Scene s = load_gltf(g.write_gltf(test::temp_dir() / "noscene.gltf"));
  EXPECT_EQ(s.mesh.triangle_count(), 2u);
}

TEST(GltfLoader, DefaultSceneIsUsed) {
  Gltf g = quad_gltf();
  const int pos = g.vec3s({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}});
  const int other = g.node({{"mesh", g.mesh({{"attributes", {{"POSITION", pos}}}})}});
  g.doc["scenes"].push_back({{"nodes", {other}}});
  g.doc["scene"] = 1;
  const Scene s = load_gltf(g.write_gltf(test::temp_dir() / "scene1.gltf"));
  EXPECT_EQ(s.mesh.triangle_count(), 1u);
}

// ---- cameras, lights, materials ----------------------------------------------------------------

TEST(GltfLoader, FirstPerspectiveCamera) {
  Gltf g = quad_gltf();
  const float r = std::sqrt(0.5f);
  g.doc["cameras"] = json::array(
      {{{"type", "orthographic"},
        {"orthographic", {{"xmag", 1}, {"ymag", 1}, {"znear", 0.1}, {"zfar", 10}}}},
       {{"type", "perspective"}, {"perspective", {{"yfov", 0.5}, {"znear", 0.05}}}},
       {{"type", "perspective"}, {"perspective", {{"yfov", 0.9}, {"znear", 0.1}}}}});
  const int ortho = g.node({{"camera", 0}});
  // Rotated +90 degrees about Y: -Z becomes -X.
  const int cam = g.node({{"camera", 1}, {"translation", {0, 1, 5}}, {"rotation", {0, r, 0, r}}});
  const int later = g.node({{"camera", 2}});
  g.doc["scenes"][0]["nodes"].push_back(ortho);
  g.doc["scenes"][0]["nodes"].push_back(cam);
  g.doc["scenes"][0]["nodes"].push_back(later);
  const Scene s = load_gltf(g.write_gltf(test::temp_dir() / "camera.gltf"));
  ASSERT_TRUE(s.camera.has_value());
  expect_vec3(s.camera->eye, {0, 1, 5});
  expect_vec3(s.camera->target, {-1, 1, 5});
  expect_vec3(s.camera->up, {0, 1, 0});
  EXPECT_FLOAT_EQ(s.camera->yfov, 0.5f);
  EXPECT_FLOAT_EQ(s.camera->znear, 0.05f);
}

TEST(GltfLoader, PunctualLights) {
  Gltf g = quad_gltf();
  const float r = std::sqrt(0.5f);
  g.doc["extensionsUsed"] = {"KHR_lights_punctual"};
  g.doc["extensions"]["KHR_lights_punctual"]["lights"] = json::array(
      {{{"type", "point"}, {"color", {1, 0.5, 0.25}}, {"intensity", 20}, {"range", 7}},
       {{"type", "spot"},
        {"intensity", 5},
        {"spot", {{"innerConeAngle", 0.1}, {"outerConeAngle", 0.6}}}},
       {{"type", "directional"}, {"intensity", 3}}});
  auto light_node = [](int light, json extra) {
    extra["extensions"] = {{"KHR_lights_punctual", {{"light", light}}}};
    return extra;
  };
  const int point = g.node(light_node(0, {{"translation", {1, 2, 3}}}));
  // Rotated -90 degrees about X: -Z becomes -Y.
  const int spot = g.node(light_node(1, {{"translation", {0, 4, 0}}, {"rotation", {-r, 0, 0, r}}}));
  const int sun = g.node(light_node(2, json::object()));
  const int group = g.node({{"children", {spot, sun}}, {"translation", {10, 0, 0}}});
  g.doc["scenes"][0]["nodes"].push_back(point);
  g.doc["scenes"][0]["nodes"].push_back(group);
  const Scene s = load_gltf(g.write_gltf(test::temp_dir() / "lights.gltf"));
  ASSERT_EQ(s.lights.size(), 3u);
  const Light& p = s.lights[0];
  EXPECT_EQ(p.type, LightType::Point);
  expect_vec3(p.position, {1, 2, 3});
  expect_vec3(p.color, {1, 0.5f, 0.25f});
  EXPECT_FLOAT_EQ(p.intensity, 20.0f);
  EXPECT_FLOAT_EQ(p.range, 7.0f);
  const Light& sp = s.lights[1];
  EXPECT_EQ(sp.type, LightType::Spot);
  expect_vec3(sp.position, {10, 4, 0});
  expect_vec3(sp.direction, {0, -1, 0});
  EXPECT_FLOAT_EQ(sp.inner_cone, 0.1f);
  EXPECT_FLOAT_EQ(sp.outer_cone, 0.6f);
  EXPECT_FLOAT_EQ(sp.range, 0.0f);
  const Light& d = s.lights[2];
  EXPECT_EQ(d.type, LightType::Directional);
  expect_vec3(d.direction, {0, 0, -1});
  EXPECT_FLOAT_EQ(d.intensity, 3.0f);
}

TEST(GltfLoader, MaterialsAndTextures) {
  Gltf g = quad_gltf();
  const std::vector<uint8_t> png = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n', 1, 2, 3};
  g.doc["images"] = json::array({{{"uri", "data:image/png;base64," + base64(png)}},
                                 {{"uri", "tex%20file.png"}}});
  g.doc["samplers"] = json::array({{{"wrapS", 33071}, {"wrapT", 33648}}});
  g.doc["textures"] = json::array({{{"source", 0}, {"sampler", 0}}, {{"source", 1}}});
  g.doc["extensionsUsed"] = {"KHR_materials_transmission", "KHR_materials_ior"};
  g.doc["materials"] = json::array(
      {{{"name", "plastic"},
        {"pbrMetallicRoughness",
         {{"baseColorFactor", {0.8, 0.2, 0.1, 1.0}},
          {"metallicFactor", 0.0},
          {"roughnessFactor", 0.5},
          {"baseColorTexture", {{"index", 0}}}}}},
       {{"name", "mirror"},
        {"pbrMetallicRoughness",
         {{"baseColorFactor", {0.9, 0.9, 0.9, 1.0}},
          {"metallicFactor", 1.0},
          {"roughnessFactor", 0.0},
          {"baseColorTexture", {{"index", 1}}}}}},
       {{"name", "glass"},
        {"pbrMetallicRoughness", {{"metallicFactor", 0.0}, {"roughnessFactor", 0.0}}},
        {"extensions",
         {{"KHR_materials_transmission", {{"transmissionFactor", 0.9}}},
          {"KHR_materials_ior", {{"ior", 1.33}}}}}},
       json::object()});
  g.doc["meshes"][0]["primitives"][0]["material"] = 2;
  const Scene s = load_gltf(g.write_gltf(test::temp_dir() / "materials.gltf"));
  ASSERT_EQ(s.materials.size(), 4u);  // every material of the file, no default needed
  EXPECT_EQ(s.mesh.material_ids[0], 2u);

  const Material& plastic = s.materials[0];
  EXPECT_EQ(plastic.name, "plastic");
  expect_vec3(plastic.diffuse, {0.8f, 0.2f, 0.1f});
  expect_vec3(plastic.specular, {0.04f, 0.04f, 0.04f});
  EXPECT_NEAR(plastic.shininess, 30.0f, 1e-3f);  // 2 / 0.5^4 - 2
  EXPECT_FLOAT_EQ(plastic.reflectance, 0.0f);
  EXPECT_FLOAT_EQ(plastic.transmittance, 0.0f);
  EXPECT_FLOAT_EQ(plastic.ior, 1.5f);
  ASSERT_EQ(plastic.texture, 0);

  const Material& mirror = s.materials[1];
  expect_vec3(mirror.specular, {0.9f, 0.9f, 0.9f});
  EXPECT_FLOAT_EQ(mirror.reflectance, 1.0f);
  EXPECT_FLOAT_EQ(mirror.shininess, 1024.0f);
  expect_vec3(mirror.diffuse, {0, 0, 0});
  ASSERT_EQ(mirror.texture, 1);

  const Material& glass = s.materials[2];
  EXPECT_FLOAT_EQ(glass.transmittance, 0.9f);
  EXPECT_FLOAT_EQ(glass.ior, 1.33f);
  EXPECT_FLOAT_EQ(glass.reflectance, 0.0f);

  const Material& fallback = s.materials[3];  // glTF defaults: metallic 1, roughness 1
  expect_vec3(fallback.diffuse, {1, 1, 1});
  EXPECT_FLOAT_EQ(fallback.reflectance, 0.0f);
  EXPECT_FLOAT_EQ(fallback.shininess, 1.0f);
  EXPECT_EQ(fallback.texture, -1);

  ASSERT_EQ(s.textures.size(), 2u);
  EXPECT_EQ(s.textures[0].data, png);
  EXPECT_EQ(s.textures[0].mime_type, "image/png");
  EXPECT_TRUE(s.textures[0].path.empty());
  EXPECT_EQ(s.textures[0].wrap_s, TextureWrap::ClampToEdge);
  EXPECT_EQ(s.textures[0].wrap_t, TextureWrap::MirroredRepeat);
  EXPECT_TRUE(s.textures[1].data.empty());
  EXPECT_EQ(fs::path(s.textures[1].path).filename().string(), "tex file.png");
  EXPECT_EQ(s.textures[1].wrap_s, TextureWrap::Repeat);
}

TEST(GltfLoader, GlbEmbeddedImage) {
  Gltf g = quad_gltf();
  const std::vector<uint8_t> png = {0x89, 'P', 'N', 'G', 9, 8, 7};
  const int view = g.view(png.data(), png.size());
  g.doc["images"] = json::array({{{"bufferView", view}, {"mimeType", "image/png"}}});
  g.doc["textures"] = json::array({{{"source", 0}}});
  g.doc["materials"] = json::array({{{"pbrMetallicRoughness", {{"baseColorTexture", {{"index", 0}}}}}}});
  g.doc["meshes"][0]["primitives"][0]["material"] = 0;
  const Scene s = load_gltf(g.write_glb(test::temp_dir() / "image.glb"));
  ASSERT_EQ(s.textures.size(), 1u);
  EXPECT_EQ(s.textures[0].data, png);
  EXPECT_EQ(s.materials[0].texture, 0);
}

// ---- broken glTF -------------------------------------------------------------------------------

TEST(GltfErrors, LinesPrimitiveNamesTheElement) {
  Gltf g = quad_gltf();
  const int pos = g.vec3s({{0, 0, 0}, {1, 0, 0}});
  g.doc["meshes"].push_back({{"primitives", json::array({{{"attributes", {{"POSITION", pos}}}},
                                                         {{"attributes", {{"POSITION", pos}}},
                                                          {"mode", 1}}})}});
  g.doc["nodes"][0]["children"] = {g.node({{"mesh", 1}})};
  const std::string path = g.write_gltf(test::temp_dir() / "lines.gltf");
  expect_bad_input([&] { load_scene(path); },
                   {"lines.gltf", "meshes[1].primitives[1]: mode LINES (1) is not supported",
                    "triangles only"});
}

TEST(GltfErrors, PointsAndLineStripAreRejected) {
  for (int mode : {0, 2, 3}) {
    Gltf g = quad_gltf();
    g.doc["meshes"][0]["primitives"][0]["mode"] = mode;
    const std::string path = g.write_gltf(test::temp_dir() / "points.gltf");
    std::string mode_text = std::to_string(mode);  // appended: GCC 12 warns falsely on "(" + s
    mode_text.insert(0, 1, '(').push_back(')');
    expect_bad_input([&] { load_scene(path); }, {"meshes[0].primitives[0]: mode", mode_text});
  }
}

TEST(GltfErrors, BufferViewBeyondBuffer) {
  Gltf g = quad_gltf();
  g.doc["bufferViews"][0]["byteLength"] = 4096;  // the buffer holds far less
  const std::string path = g.write_gltf(test::temp_dir() / "truncated.gltf");
  expect_bad_input([&] { load_scene(path); }, {"truncated.gltf", "bufferViews[0]", "buffers[0]"});
}

TEST(GltfErrors, TruncatedGlbBinChunk) {
  Gltf g = quad_gltf();
  const fs::path dir = test::temp_dir();
  const std::string path = g.write_glb(dir / "cut.glb");
  const auto size = fs::file_size(path);
  fs::resize_file(path, size - 40);
  expect_bad_input([&] { load_scene(path); }, {"cut.glb"});
}

TEST(GltfErrors, AccessorBeyondBufferView) {
  Gltf g = quad_gltf();
  g.doc["accessors"][0]["count"] = 5;  // the view holds 4 VEC3
  const std::string path = g.write_gltf(test::temp_dir() / "count.gltf");
  expect_bad_input([&] { load_scene(path); }, {"count.gltf", "accessors[0]", "bufferViews[0]"});
  g.doc["accessors"][0]["count"] = 4;
  g.doc["accessors"][0]["byteOffset"] = 8;
  const std::string path2 = g.write_gltf(test::temp_dir() / "offset.gltf");
  expect_bad_input([&] { load_scene(path2); }, {"accessors[0]", "from byte 8"});
}

TEST(GltfErrors, BadByteStride) {
  Gltf g = quad_gltf();
  g.doc["bufferViews"][0]["byteStride"] = 8;  // smaller than a VEC3 of floats
  const std::string path = g.write_gltf(test::temp_dir() / "stride.gltf");
  expect_bad_input([&] { load_scene(path); }, {"accessors[0]", "byteStride 8"});
}

TEST(GltfErrors, IndexOutOfRange) {
  Gltf g;
  const int pos = g.vec3s({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}});
  const int idx = g.indices(std::vector<uint16_t>{0, 1, 7});
  g.scene({g.node({{"mesh", g.mesh({{"attributes", {{"POSITION", pos}}}, {"indices", idx}})}})});
  const std::string path = g.write_gltf(test::temp_dir() / "index.gltf");
  expect_bad_input([&] { load_scene(path); },
                   {"index.gltf", "accessors[1]", "index 7", "3 vertices"});
}

TEST(GltfErrors, WrongComponentTypes) {
  {
    Gltf g;
    const std::vector<uint16_t> p = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    const int pos = g.accessor(g.view(p.data(), p.size() * 2), kU16, 3, "VEC3");
    g.scene({g.node({{"mesh", g.mesh({{"attributes", {{"POSITION", pos}}}})}})});
    const std::string path = g.write_gltf(test::temp_dir() / "u16pos.gltf");
    expect_bad_input([&] { load_scene(path); }, {"accessors[0]", "POSITION", "UNSIGNED_SHORT"});
  }
  {
    Gltf g;
    const int pos = g.vec3s({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}});
    const std::vector<float> idx = {0, 1, 2};
    const int ia = g.accessor(g.view(idx.data(), 12), kFloat, 3, "SCALAR");
    g.scene({g.node({{"mesh", g.mesh({{"attributes", {{"POSITION", pos}}}, {"indices", ia}})}})});
    const std::string path = g.write_gltf(test::temp_dir() / "floatidx.gltf");
    expect_bad_input([&] { load_scene(path); }, {"accessors[1]", "indices", "FLOAT"});
  }
  {
    Gltf g = quad_gltf();
    g.doc["accessors"][2]["componentType"] = kU8;  // TEXCOORD_0, not normalized
    const std::string path = g.write_gltf(test::temp_dir() / "uv.gltf");
    expect_bad_input([&] { load_scene(path); }, {"accessors[2]", "TEXCOORD_0"});
  }
}

TEST(GltfErrors, AttributeCountMismatch) {
  Gltf g = quad_gltf();
  g.doc["accessors"][1]["count"] = 3;
  const std::string path = g.write_gltf(test::temp_dir() / "normals.gltf");
  expect_bad_input([&] { load_scene(path); }, {"accessors[1]", "NORMAL", "3 elements"});
}

TEST(GltfErrors, MissingAccessorAndMaterial) {
  {
    Gltf g = quad_gltf();
    g.doc["meshes"][0]["primitives"][0]["attributes"]["NORMAL"] = 42;
    const std::string path = g.write_gltf(test::temp_dir() / "acc.gltf");
    expect_bad_input([&] { load_scene(path); }, {"accessor 42 does not exist"});
  }
  {
    Gltf g = quad_gltf();
    g.doc["meshes"][0]["primitives"][0]["material"] = 3;
    const std::string path = g.write_gltf(test::temp_dir() / "mat.gltf");
    expect_bad_input([&] { load_scene(path); }, {"meshes[0].primitives[0]", "material 3"});
  }
}

TEST(GltfErrors, BadJsonAndBadBuffers) {
  const fs::path dir = test::temp_dir();
  {
    const fs::path path = dir / "broken.gltf";
    std::ofstream(path) << "{ \"asset\": { \"version\": \"2.0\" }, \"meshes\": [ ";
    expect_bad_input([&] { load_scene(path.string()); }, {"broken.gltf", "not a valid glTF"});
  }
  {
    Gltf g = quad_gltf();
    json d = g.finished(true);
    d["buffers"][0]["byteLength"] = g.bin.size() + 100;  // the data URI is shorter
    const fs::path path = dir / "short.gltf";
    std::ofstream(path) << d.dump();
    expect_bad_input([&] { load_scene(path.string()); }, {"short.gltf"});
  }
  {
    Gltf g = quad_gltf();
    json d = g.finished(false);
    d["buffers"][0]["uri"] = "missing.bin";
    const fs::path path = dir / "external.gltf";
    std::ofstream(path) << d.dump();
    expect_bad_input([&] { load_scene(path.string()); }, {"external.gltf"});
  }
  {
    const fs::path path = dir / "garbage.glb";
    std::ofstream(path, std::ios::binary) << "glTF\x02\0\0\0garbage";
    expect_bad_input([&] { load_scene(path.string()); }, {"garbage.glb"});
  }
}

TEST(GltfErrors, NonFinitePositionNamesTriangle) {
  Gltf g;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const int pos = g.vec3s({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 0}, {1, 0, 0}, {nan, 1, 0}});
  g.scene({g.node({{"mesh", g.mesh({{"attributes", {{"POSITION", pos}}}})}})});
  const std::string path = g.write_gltf(test::temp_dir() / "nan.gltf");
  expect_bad_input([&] { load_scene(path); }, {"nan.gltf", "triangle 1", "non-finite position"});
}

// Posing re-validates only what it changes (validate_posed): the loader's validate_scene after the
// first pose is what refuses a non-finite texture coordinate, for a still scene and an animated one.
TEST(GltfErrors, NonFiniteTexcoordNamesTriangle) {
  Gltf g;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const int pos = g.vec3s({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 0}, {1, 0, 0}, {0, 1, 0}});
  const int uv = g.vec2s({{0, 0}, {1, 0}, {0, 1}, {0, 0}, {1, nan}, {0, 1}});
  g.scene({g.node({{"mesh", g.mesh({{"attributes", {{"POSITION", pos}, {"TEXCOORD_0", uv}}}})}})});
  const std::string path = g.write_gltf(test::temp_dir() / "nan_uv.gltf");
  const std::vector<std::string> parts = {"nan_uv.gltf", "triangle 1", "vertex 1", "non-finite texture coordinates"};
  expect_bad_input([&] { load_scene(path); }, parts);
  expect_bad_input([&] { load_animated_scene(path); }, parts);
}

TEST(GltfErrors, NoTriangles) {
  Gltf g;
  g.doc["nodes"] = json::array({json::object()});
  g.scene({0});
  const std::string path = g.write_gltf(test::temp_dir() / "empty.gltf");
  expect_bad_input([&] { load_scene(path); }, {"empty.gltf", "no triangles"});
}

TEST(GltfErrors, NodeCycle) {
  Gltf g = quad_gltf();
  g.doc["nodes"][0]["children"] = {1};
  g.node({{"children", {0}}});
  const std::string path = g.write_gltf(test::temp_dir() / "cycle.gltf");
  expect_bad_input([&] { load_scene(path); }, {"cycle.gltf", "cycle"});
}

TEST(GltfLoader, DegenerateTrianglesAreKeptAndCounted) {
  Gltf g;
  const int pos = g.vec3s({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 0}, {1, 1, 1}, {2, 2, 2}});
  g.scene({g.node({{"mesh", g.mesh({{"attributes", {{"POSITION", pos}}}})}})});
  const Scene s = load_gltf(g.write_gltf(test::temp_dir() / "degenerate.gltf"));
  EXPECT_EQ(s.mesh.triangle_count(), 2u);
  EXPECT_EQ(s.degenerate_triangles, 1u);
  for (const glm::vec3& n : s.mesh.normals) EXPECT_NEAR(glm::length(n), 1.0f, 1e-5f);
}

// ---- load_scene dispatch -----------------------------------------------------------------------

TEST(SceneLoader, MissingFileAndUnknownExtension) {
  const fs::path dir = test::temp_dir();
  expect_bad_input([&] { load_scene((dir / "nope.gltf").string()); }, {"nope.gltf", "file not found"});
  expect_bad_input([&] { load_obj((dir / "nope.obj").string()); }, {"nope.obj", "file not found"});
  const fs::path xyz = dir / "cloud.xyz";
  std::ofstream(xyz) << "1 2 3\n";
  expect_bad_input([&] { load_scene(xyz.string()); },
                   {"cloud.xyz", "unsupported scene format '.xyz': mobirt reads .gltf, .glb, .obj, .nff and .ply"});
  expect_bad_input([&] { load_scene(dir.string()); }, {"folder"});
}

// ---- OBJ ---------------------------------------------------------------------------------------

TEST(ObjLoader, WithMtl) {
  const fs::path dir = test::temp_dir();
  std::ofstream(dir / "box.mtl") << "newmtl red\nKd 0.8 0.1 0.1\nKs 0.5 0.5 0.5\nNs 64\nillum 2\n"
                                    "map_Kd red.png\n"
                                    "newmtl chrome\nKd 0.1 0.1 0.1\nKs 0.9 0.8 0.7\nNs 500\nillum 3\n"
                                    "newmtl glass\nKd 0 0 0\nKs 1 1 1\nd 0.25\nNi 1.45\nillum 7\n";
  std::ofstream(dir / "box.obj") << "mtllib box.mtl\n"
                                    "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
                                    "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
                                    "vn 0 0 1\n"
                                    "usemtl red\nf 1/1/1 2/2/1 3/3/1 4/4/1\n"
                                    "usemtl chrome\nf 1 2 3\n"
                                    "usemtl glass\nf 1 3 4\n";
  const Scene s = load_scene((dir / "box.obj").string());
  ASSERT_EQ(s.mesh.triangle_count(), 4u);  // the quad triangulated, + 2
  ASSERT_EQ(s.materials.size(), 3u);
  EXPECT_EQ(s.mesh.material_ids[0], 0u);
  EXPECT_EQ(s.mesh.material_ids[2], 1u);
  EXPECT_EQ(s.mesh.material_ids[3], 2u);
  const Material& red = s.materials[0];
  expect_vec3(red.diffuse, {0.8f, 0.1f, 0.1f});
  expect_vec3(red.specular, {0.5f, 0.5f, 0.5f});
  EXPECT_FLOAT_EQ(red.shininess, 64.0f);
  EXPECT_FLOAT_EQ(red.reflectance, 0.0f);
  ASSERT_EQ(red.texture, 0);
  ASSERT_EQ(s.textures.size(), 1u);
  EXPECT_EQ(fs::path(s.textures[0].path).filename().string(), "red.png");
  const Material& chrome = s.materials[1];
  EXPECT_FLOAT_EQ(chrome.reflectance, 0.9f);
  const Material& glass = s.materials[2];
  EXPECT_FLOAT_EQ(glass.transmittance, 0.75f);
  EXPECT_FLOAT_EQ(glass.ior, 1.45f);
  EXPECT_FLOAT_EQ(glass.reflectance, 1.0f);
  // normals: from the file for the quad, flat (also +Z) for the others
  for (const glm::vec3& n : s.mesh.normals) expect_vec3(n, {0, 0, 1});
  // texcoords: v flipped to the glTF convention (the quad's vt equal its xy); faces without vt
  // get zeros
  ASSERT_EQ(s.mesh.texcoords.size(), 12u);
  for (size_t i = 0; i < 6; ++i) {
    EXPECT_FLOAT_EQ(s.mesh.texcoords[i].x, s.mesh.positions[i].x) << i;
    EXPECT_FLOAT_EQ(s.mesh.texcoords[i].y, 1.0f - s.mesh.positions[i].y) << i;
  }
  EXPECT_FLOAT_EQ(s.mesh.texcoords[7].x, 0.0f);
}

TEST(ObjLoader, WithoutMtlUsesDefaultMaterial) {
  const fs::path dir = test::temp_dir();
  std::ofstream(dir / "tri.OBJ") << "mtllib absent.mtl\nv 0 0 0\nv 0 0 1\nv 0 1 0\nusemtl x\nf 1 2 3\n";
  const Scene s = load_scene((dir / "tri.OBJ").string());
  ASSERT_EQ(s.mesh.triangle_count(), 1u);
  ASSERT_EQ(s.materials.size(), 1u);
  EXPECT_EQ(s.materials[0].name, "default");
  expect_vec3(s.mesh.normals[0], {-1, 0, 0});
  EXPECT_TRUE(s.mesh.texcoords.empty());
}

TEST(ObjLoader, NegativeIndices) {
  const fs::path dir = test::temp_dir();
  std::ofstream(dir / "neg.obj") << "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\n";
  const Scene s = load_obj((dir / "neg.obj").string());
  ASSERT_EQ(s.mesh.triangle_count(), 1u);
  expect_vec3(s.mesh.positions[1], {1, 0, 0});
}

TEST(ObjErrors, BrokenFiles) {
  const fs::path dir = test::temp_dir();
  std::ofstream(dir / "nofaces.obj") << "v 0 0 0\nv 1 0 0\n";
  expect_bad_input([&] { load_scene((dir / "nofaces.obj").string()); },
                   {"nofaces.obj", "no triangles"});
  std::ofstream(dir / "range.obj") << "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n";
  expect_bad_input([&] { load_scene((dir / "range.obj").string()); }, {"range.obj"});
  std::ofstream(dir / "nan.obj") << "v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n";
  try {
    load_scene((dir / "nan.obj").string());  // tinyobjloader may read "nan" as 0
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::BadInput);
    EXPECT_NE(std::string(e.what()).find("triangle 0"), std::string::npos) << e.what();
  }
}

// ---- real scenes (skipped when ../shared/scenes is absent) -------------------------------------

void expect_sane(const Scene& s) {
  EXPECT_GT(s.mesh.triangle_count(), 0u);
  EXPECT_FALSE(s.materials.empty());
  const Aabb b = s.bounds();
  ASSERT_FALSE(b.empty());
  for (int a = 0; a < 3; ++a) {
    EXPECT_TRUE(std::isfinite(b.lo[a]) && std::isfinite(b.hi[a]));
  }
  EXPECT_GT(glm::length(b.extent()), 0.0f);
  for (const glm::vec3& n : s.mesh.normals) ASSERT_NEAR(glm::length(n), 1.0f, 1e-4f);
}

TEST(RealScenes, UtahToasters) {
  MOBIRT_REQUIRE_SHARED(path, "utah-toasters/Toasters004.obj");
  const Scene s = load_scene(path.string());
  EXPECT_EQ(s.mesh.triangle_count(), 11141u);
  expect_sane(s);
}

TEST(RealScenes, CornellBox) {
  MOBIRT_REQUIRE_SHARED(path, "gltf/CornellBox/CornellBox.glb");
  const Scene s = load_scene(path.string());
  expect_sane(s);
  std::cout << "CornellBox: " << s.mesh.triangle_count() << " triangles, " << s.materials.size()
            << " materials, " << s.lights.size() << " lights, camera "
            << (s.camera ? "yes" : "no") << "\n";
}

TEST(RealScenes, Fox) {
  MOBIRT_REQUIRE_SHARED(path, "gltf/Fox/Fox.glb");
  const Scene s = load_scene(path.string());
  expect_sane(s);
  EXPECT_FALSE(s.mesh.texcoords.empty());
  EXPECT_EQ(s.textures.size(), 1u);
  std::cout << "Fox: " << s.mesh.triangle_count() << " triangles, extent "
            << s.bounds().extent().x << " x " << s.bounds().extent().y << " x "
            << s.bounds().extent().z << "\n";
}

TEST(RealScenes, BoxTextured) {
  MOBIRT_REQUIRE_SHARED(path, "gltf/assimp-testmodels/BoxTextured-glTF/BoxTextured.gltf");
  const Scene s = load_scene(path.string());
  EXPECT_EQ(s.mesh.triangle_count(), 12u);
  expect_sane(s);
  ASSERT_EQ(s.textures.size(), 1u);
  EXPECT_TRUE(fs::exists(s.textures[0].path)) << s.textures[0].path;
  EXPECT_EQ(s.materials[s.mesh.material_ids[0]].texture, 0);
  EXPECT_EQ(s.mesh.texcoords.size(), 36u);
}

TEST(RealScenes, Cameras) {
  MOBIRT_REQUIRE_SHARED(path, "gltf/assimp-testmodels/cameras/Cameras.gltf");
  const Scene s = load_scene(path.string());
  EXPECT_EQ(s.mesh.triangle_count(), 2u);
  expect_sane(s);
  ASSERT_TRUE(s.camera.has_value());
  expect_vec3(s.camera->eye, {0.5f, 0.5f, 3.0f});
  expect_vec3(s.camera->target, {0.5f, 0.5f, 2.0f});
  EXPECT_FLOAT_EQ(s.camera->yfov, 0.7f);
}

}  // namespace
}  // namespace mobirt
