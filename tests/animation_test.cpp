// Animation: glTF node TRS channels (LINEAR with slerp, STEP, CUBICSPLINE, clamping), skins,
// morph targets, lights and cameras that follow animated parents, OBJ frame sequences (folder and
// printf pattern), the .mtl replacement, and the real animated samples when present.
#include <glm/gtc/quaternion.hpp>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
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

using test::expect_bad_input;
using test::expect_vec3;
using test::Gltf;
using test::kU8;

using nlohmann::json;
namespace fs = std::filesystem;

// One triangle (1,0,0), (0,1,0), (0,0,0) with +Z normals; returns the mesh index.
int triangle_mesh(Gltf& g) {
  const int pos = g.vec3s({{1, 0, 0}, {0, 1, 0}, {0, 0, 0}});
  const int nrm = g.vec3s({{0, 0, 1}, {0, 0, 1}, {0, 0, 1}});
  return g.mesh({{"attributes", {{"POSITION", pos}, {"NORMAL", nrm}}}});
}

const float kR = std::sqrt(0.5f);

// ---- glTF node animation -----------------------------------------------------------------------

// Four nodes share the triangle: translation LINEAR, rotation LINEAR (slerp), scale STEP,
// translation CUBICSPLINE. Triangle i of the scene is node i's; corner 3i is its vertex (1,0,0).
AnimatedScene trs_scene(const fs::path& dir) {
  Gltf g;
  const int m = triangle_mesh(g);
  const int lin = g.node({{"mesh", m}});
  const int rot = g.node({{"mesh", m}});
  const int step = g.node({{"mesh", m}});
  const int cubic = g.node({{"mesh", m}, {"translation", {9, 9, 9}}});
  g.scene({lin, rot, step, cubic});
  g.channel(0, lin, "translation", {1, 3}, {0, 0, 0, 4, 0, 0});
  // Identity to +90 degrees about Z, the second key written as the negated quaternion (the same
  // rotation): slerp must take the short way.
  g.channel(0, rot, "rotation", {0, 1}, {0, 0, 0, 1, 0, 0, -kR, -kR});
  g.channel(0, step, "scale", {0, 1, 2}, {1, 1, 1, 2, 2, 2, 3, 3, 3}, "STEP");
  // CUBICSPLINE: per key in-tangent, value, out-tangent.
  g.channel(0, cubic, "translation", {0, 2},
            {0, 0, 0, /*v0*/ 0, 0, 0, /*b0*/ 3, 0, 0,
             /*a1*/ -1, 0, 0, /*v1*/ 1, 0, 0, 0, 0, 0},
            "CUBICSPLINE");
  return load_animated_scene(g.write_gltf(dir / "trs.gltf"));
}

TEST(GltfAnimation, TranslationRotationScaleStepCubic) {
  const fs::path dir = test::temp_dir();
  const AnimatedScene a = trs_scene(dir);
  ASSERT_TRUE(a.animated());
  EXPECT_DOUBLE_EQ(a.duration(), 3.0);
  EXPECT_DOUBLE_EQ(a.fps(), 24.0);
  ASSERT_EQ(a.rest().mesh.triangle_count(), 4u);
  Scene s;
  auto vertex = [&](double t, size_t node) {
    a.evaluate(t, s);
    return s.mesh.positions[3 * node];  // the vertex (1,0,0) of node `node`
  };
  // LINEAR translation, keys at 1 s and 3 s: clamped before and after.
  expect_vec3(vertex(0.0, 0), {1, 0, 0});
  expect_vec3(vertex(1.0, 0), {1, 0, 0});
  expect_vec3(vertex(2.0, 0), {3, 0, 0});
  expect_vec3(vertex(2.5, 0), {4, 0, 0});
  expect_vec3(vertex(7.0, 0), {5, 0, 0});
  expect_vec3(vertex(std::numeric_limits<double>::infinity(), 0), {5, 0, 0});
  expect_vec3(vertex(-std::numeric_limits<double>::infinity(), 0), {1, 0, 0});
  expect_vec3(vertex(std::numeric_limits<double>::quiet_NaN(), 0), {1, 0, 0});  // NaN: t = 0
  // Rotation: slerp by the short way; 45 degrees at t = 0.5, 90 at t >= 1.
  expect_vec3(vertex(0.5, 1), {kR, kR, 0});
  expect_vec3(vertex(0.25, 1), {std::cos(glm::radians(22.5f)), std::sin(glm::radians(22.5f)), 0});
  expect_vec3(vertex(1.0, 1), {0, 1, 0});
  expect_vec3(vertex(9.0, 1), {0, 1, 0});
  expect_vec3(vertex(-1.0, 1), {1, 0, 0});
  // Rotated normals stay +Z (rotation about Z).
  a.evaluate(0.5, s);
  expect_vec3(s.mesh.normals[3], {0, 0, 1});
  // STEP scale: a key's value holds until the next key.
  expect_vec3(vertex(0.0, 2), {1, 0, 0});
  expect_vec3(vertex(0.99, 2), {1, 0, 0});
  expect_vec3(vertex(1.0, 2), {2, 0, 0});
  expect_vec3(vertex(1.99, 2), {2, 0, 0});
  expect_vec3(vertex(2.0, 2), {3, 0, 0});
  expect_vec3(vertex(5.0, 2), {3, 0, 0});
  // CUBICSPLINE (glTF 2.0 Appendix C), keys at 0 and 2 s: t = 1 is u = 0.5:
  // 0.5 v0 + 0.125 * 2 * b0 + 0.5 v1 - 0.125 * 2 * a1 = 0.75 + 0.5 + 0.25 = 1.5.
  expect_vec3(vertex(1.0, 3), {1 + 1.5f, 0, 0});
  // u = 0.25: h00 = 0.84375, h10 = 0.140625, h01 = 0.15625, h11 = -0.046875 (times td = 2).
  expect_vec3(vertex(0.5, 3), {1 + 0.140625f * 2 * 3 + 0.15625f + 0.046875f * 2, 0, 0});
  expect_vec3(vertex(-0.5, 3), {1, 0, 0});  // before: v0 (the node's own translation replaced)
  expect_vec3(vertex(2.0, 3), {2, 0, 0});
  expect_vec3(vertex(4.0, 3), {2, 0, 0});
}

TEST(GltfAnimation, StaticLoadIsTheSceneAtTimeZero) {
  const fs::path dir = test::temp_dir();
  const AnimatedScene a = trs_scene(dir);
  const Scene stat = load_scene((dir / "trs.gltf").string());
  const Scene at0 = a.at(0.0);
  ASSERT_EQ(stat.mesh.positions.size(), at0.mesh.positions.size());
  for (size_t i = 0; i < stat.mesh.positions.size(); ++i) {
    EXPECT_EQ(stat.mesh.positions[i], at0.mesh.positions[i]) << i;
    EXPECT_EQ(stat.mesh.positions[i], a.rest().mesh.positions[i]) << i;
    EXPECT_EQ(stat.mesh.normals[i], at0.mesh.normals[i]) << i;
  }
  EXPECT_EQ(stat.materials.size(), at0.materials.size());
  EXPECT_EQ(stat.mesh.material_ids, at0.mesh.material_ids);
}

TEST(GltfAnimation, EvaluateReusesTheScene) {
  const fs::path dir = test::temp_dir();
  const AnimatedScene a = trs_scene(dir);
  Scene s;
  a.evaluate(0.5, s);
  const glm::vec3* positions = s.mesh.positions.data();
  const glm::vec3* normals = s.mesh.normals.data();
  const Material* materials = s.materials.data();
  for (double t : {0.7, 1.4, 2.9}) {
    a.evaluate(t, s);
    EXPECT_EQ(s.mesh.positions.data(), positions);
    EXPECT_EQ(s.mesh.normals.data(), normals);
    EXPECT_EQ(s.materials.data(), materials);  // static parts are not copied again
  }
  EXPECT_EQ(s.source, a.rest().source);
  EXPECT_EQ(s.mesh.triangle_count(), 4u);
}

TEST(GltfAnimation, ChooseOneAnimationAndEarlierWins) {
  Gltf g;
  const int m = triangle_mesh(g);
  const int n = g.node({{"mesh", m}});
  g.scene({n});
  g.channel(0, n, "translation", {0, 1}, {0, 0, 0, 1, 0, 0});
  g.channel(1, n, "translation", {0, 4}, {0, 0, 0, 0, 8, 0});
  const std::string path = g.write_gltf(test::temp_dir() / "two.gltf");
  const AnimatedScene both = load_animated_scene(path);
  EXPECT_DOUBLE_EQ(both.duration(), 1.0);  // animations[1] drives what [0] drives: dropped
  expect_vec3(both.at(0.5).mesh.positions[0], {1.5f, 0, 0});
  LoadOptions second;
  second.animation = 1;
  second.fps = 30;
  const AnimatedScene one = load_animated_scene(path, second);
  EXPECT_DOUBLE_EQ(one.duration(), 4.0);
  EXPECT_DOUBLE_EQ(one.fps(), 30.0);
  expect_vec3(one.at(2.0).mesh.positions[0], {1, 4, 0});
  LoadOptions bad;
  bad.animation = 2;
  expect_bad_input([&] { load_animated_scene(path, bad); },
                   {"two.gltf", "animation 2 does not exist", "2 animations"});
}

TEST(GltfAnimation, StaticFileIsNotAnimated) {
  Gltf g;
  g.scene({g.node({{"mesh", triangle_mesh(g)}, {"translation", {0, 0, 2}}})});
  const AnimatedScene a = load_animated_scene(g.write_gltf(test::temp_dir() / "static.gltf"));
  EXPECT_FALSE(a.animated());
  EXPECT_DOUBLE_EQ(a.duration(), 0.0);
  const Scene s = a.at(3.0);
  expect_vec3(s.mesh.positions[0], {1, 0, 2});
  EXPECT_EQ(s.materials.size(), 1u);
}

TEST(GltfAnimation, BrokenChannels) {
  const fs::path dir = test::temp_dir();
  {
    Gltf g;
    const int n = g.node({{"mesh", triangle_mesh(g)}});
    g.scene({n});
    g.channel(0, n, "translation", {0, 1}, {0, 0, 0});  // one value for two keys
    expect_bad_input([&] { load_animated_scene(g.write_gltf(dir / "count.gltf")); },
                     {"count.gltf", "animations[0].samplers[0].output", "expected 2"});
  }
  {
    Gltf g;
    const int n = g.node({{"mesh", triangle_mesh(g)}});
    g.scene({n});
    g.channel(0, n, "translation", {1, 0}, {0, 0, 0, 1, 1, 1});
    expect_bad_input([&] { load_scene(g.write_gltf(dir / "order.gltf")); },
                     {"order.gltf", "animations[0].samplers[0].input", "smaller than the one before"});
  }
  {
    Gltf g;
    const int n = g.node({{"mesh", triangle_mesh(g)}});
    g.scene({n});
    g.channel(0, n, "translation", {0, 1}, {0, 0, 0, 1, 1, 1}, "BEZIER");
    expect_bad_input([&] { load_scene(g.write_gltf(dir / "interp.gltf")); },
                     {"interp.gltf", "interpolation 'BEZIER'"});
  }
}

// ---- skins ----------------------------------------------------------------------------------

// A strip of two quads up the Y axis, x in {0, 1}, y in {0, 1, 2}; joint 0 at the origin, joint 1
// at (0,1,0) (its child), rotated about Z from 0 to 90 degrees over 1 s. Rows y = 0, 1, 2 have
// weights (1,0), (0.5,0.5), (0,1). The mesh node's own translation must be ignored.
AnimatedScene skinned_strip(const fs::path& dir) {
  Gltf g;
  const int pos = g.vec3s({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}, {0, 2, 0}, {1, 2, 0}});
  const int nrm = g.vec3s(std::vector<glm::vec3>(6, glm::vec3(0, 0, 1)));
  const std::vector<uint8_t> joints = {0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0,
                                       0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0};
  const int jnt = g.accessor(g.view(joints.data(), joints.size()), kU8, 6, "VEC4");
  const int wgt = g.floats({1, 0, 0, 0, 1, 0, 0, 0, 0.5f, 0.5f, 0, 0, 0.5f, 0.5f, 0, 0,
                            0, 1, 0, 0, 0, 1, 0, 0},
                           "VEC4", 4);
  const int idx = g.u16s({0, 1, 3, 0, 3, 2, 2, 3, 5, 2, 5, 4});
  const int m = g.mesh({{"attributes",
                         {{"POSITION", pos}, {"NORMAL", nrm}, {"JOINTS_0", jnt}, {"WEIGHTS_0", wgt}}},
                        {"indices", idx}});
  const std::vector<float> ibm = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1,
                                  1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, -1, 0, 1};
  const int ibm_acc = g.floats(ibm, "MAT4", 16);
  const int j1 = g.node({{"translation", {0, 1, 0}}});
  const int j0 = g.node({{"children", {j1}}});
  g.doc["skins"] = json::array({{{"joints", {j0, j1}}, {"inverseBindMatrices", ibm_acc}}});
  const int skinned = g.node({{"mesh", m}, {"skin", 0}, {"translation", {5, 5, 5}}});
  g.scene({j0, skinned});
  g.channel(0, j1, "rotation", {0, 1}, {0, 0, 0, 1, 0, 0, kR, kR});
  return load_animated_scene(g.write_gltf(dir / "strip.gltf"));
}

TEST(GltfSkin, TwoJointStripBends) {
  const AnimatedScene a = skinned_strip(test::temp_dir());
  ASSERT_TRUE(a.animated());
  ASSERT_EQ(a.rest().mesh.triangle_count(), 4u);
  // One corner per vertex: triangles (0,1,3) (0,3,2) (2,3,5) (2,5,4).
  const size_t corner_of[6] = {0, 1, 5, 2, 11, 8};
  Scene s;
  auto vertex = [&](size_t v) { return s.mesh.positions[corner_of[v]]; };
  // t = 0: the bind pose, where the file has it (the mesh node's translation is ignored).
  a.evaluate(0.0, s);
  expect_vec3(vertex(0), {0, 0, 0});
  expect_vec3(vertex(3), {1, 1, 0});
  expect_vec3(vertex(5), {1, 2, 0});
  // t = 1: joint 1 turned 90 degrees about Z around (0,1,0): (x, y) -> (1 - y, x + 1) there.
  a.evaluate(1.0, s);
  expect_vec3(vertex(0), {0, 0, 0});
  expect_vec3(vertex(1), {1, 0, 0});
  expect_vec3(vertex(2), {0, 1, 0});          // half/half of (0,1,0) and (0,1,0)
  expect_vec3(vertex(3), {0.5f, 1.5f, 0});    // half of (1,1,0), half of (0,2,0)
  expect_vec3(vertex(4), {-1, 1, 0});
  expect_vec3(vertex(5), {-1, 2, 0});
  for (const glm::vec3& n : s.mesh.normals) expect_vec3(n, {0, 0, 1});
  // t = 0.5: 45 degrees. Vertex (1,2,0) -> around (0,1,0): (1,1) rotated 45 = (0, sqrt2).
  a.evaluate(0.5, s);
  expect_vec3(vertex(5), {0, 1 + std::sqrt(2.0f), 0});
  expect_vec3(vertex(4), {-kR, 1 + kR, 0});
  // Before the first key and after the last: clamped.
  a.evaluate(-3.0, s);
  expect_vec3(vertex(5), {1, 2, 0});
  a.evaluate(3.0, s);
  expect_vec3(vertex(5), {-1, 2, 0});
}

// ---- morph targets ----------------------------------------------------------------------------

// The triangle with two targets: target 0 lifts vertex 2 by (0,0,1) and tilts its normal,
// target 1 moves vertex 1 by (0,2,0). Mesh weights (0.25, 0).
Gltf morph_gltf(int& node) {
  Gltf g;
  const int pos = g.vec3s({{1, 0, 0}, {0, 1, 0}, {0, 0, 0}});
  const int nrm = g.vec3s({{0, 0, 1}, {0, 0, 1}, {0, 0, 1}});
  const int t0p = g.vec3s({{0, 0, 0}, {0, 0, 0}, {0, 0, 1}});
  const int t0n = g.vec3s({{0, 0, 0}, {0, 0, 0}, {1, 0, 0}});
  const int t1p = g.vec3s({{0, 0, 0}, {0, 2, 0}, {0, 0, 0}});
  const int m = g.mesh({{"attributes", {{"POSITION", pos}, {"NORMAL", nrm}}},
                        {"targets", {{{"POSITION", t0p}, {"NORMAL", t0n}}, {{"POSITION", t1p}}}}},
                       {{"weights", {0.25, 0.0}}});
  node = g.node({{"mesh", m}});
  g.scene({node});
  return g;
}

TEST(GltfMorph, MeshWeightsNodeWeightsAndWeightChannel) {
  const fs::path dir = test::temp_dir();
  int node = 0;
  {
    Gltf g = morph_gltf(node);
    const Scene s = load_scene(g.write_gltf(dir / "mesh_weights.gltf"));
    expect_vec3(s.mesh.positions[2], {0, 0, 0.25f});
    expect_vec3(s.mesh.positions[1], {0, 1, 0});
    expect_vec3(s.mesh.normals[2], glm::normalize(glm::vec3(0.25f, 0, 1)));
  }
  {
    Gltf g = morph_gltf(node);
    g.doc["nodes"][node]["weights"] = {0.5, 1.0};  // node weights win over the mesh's
    const Scene s = load_scene(g.write_gltf(dir / "node_weights.gltf"));
    expect_vec3(s.mesh.positions[2], {0, 0, 0.5f});
    expect_vec3(s.mesh.positions[1], {0, 3, 0});
  }
  {
    Gltf g = morph_gltf(node);
    // Two weights per key: (0, 0) at 0 s, (1, 0.5) at 1 s.
    g.channel(0, node, "weights", {0, 1}, {0, 0, 1, 0.5f});
    const AnimatedScene a = load_animated_scene(g.write_gltf(dir / "animated.gltf"));
    ASSERT_TRUE(a.animated());
    EXPECT_DOUBLE_EQ(a.duration(), 1.0);
    // t = 0: the channel's first key (0, 0), not the mesh's 0.25.
    expect_vec3(a.rest().mesh.positions[2], {0, 0, 0});
    const Scene s = a.at(0.5);
    expect_vec3(s.mesh.positions[2], {0, 0, 0.5f});
    expect_vec3(s.mesh.positions[1], {0, 1.5f, 0});
    expect_vec3(s.mesh.normals[2], glm::normalize(glm::vec3(0.5f, 0, 1)));
    expect_vec3(a.at(2.0).mesh.positions[1], {0, 2, 0});
  }
  {
    Gltf g = morph_gltf(node);
    g.channel(0, node, "weights", {0, 1}, {0, 0, 1});  // 3 values for 2 keys x 2 targets
    expect_bad_input([&] { load_scene(g.write_gltf(dir / "bad.gltf")); },
                     {"bad.gltf", "expected 4", "2 morph targets"});
  }
}

// ---- lights and cameras on animated nodes ------------------------------------------------------

TEST(GltfAnimation, ChildLightAndCameraFollowTheParent) {
  Gltf g;
  const int m = triangle_mesh(g);
  g.doc["extensionsUsed"] = {"KHR_lights_punctual"};
  g.doc["extensions"]["KHR_lights_punctual"]["lights"] = json::array(
      {{{"type", "spot"}, {"intensity", 5}, {"spot", {{"innerConeAngle", 0.1}, {"outerConeAngle", 0.6}}}}});
  g.doc["cameras"] = json::array({{{"type", "perspective"}, {"perspective", {{"yfov", 0.5}, {"znear", 0.1}}}}});
  const int lamp = g.node({{"translation", {0, 0, 5}},
                           {"extensions", {{"KHR_lights_punctual", {{"light", 0}}}}}});
  const int cam = g.node({{"translation", {0, 0, 5}}, {"camera", 0}});
  const int parent = g.node({{"children", {lamp, cam}}});
  g.scene({g.node({{"mesh", m}}), parent});
  g.channel(0, parent, "translation", {0, 1}, {0, 0, 0, 10, 0, 0});
  // +90 degrees about Y from t = 1 on (STEP).
  g.channel(0, parent, "rotation", {0, 1}, {0, 0, 0, 1, 0, kR, 0, kR}, "STEP");
  const AnimatedScene a = load_animated_scene(g.write_gltf(test::temp_dir() / "follow.gltf"));
  Scene s;
  a.evaluate(0.0, s);
  ASSERT_EQ(s.lights.size(), 1u);
  ASSERT_TRUE(s.camera.has_value());
  expect_vec3(s.lights[0].position, {0, 0, 5});
  expect_vec3(s.lights[0].direction, {0, 0, -1});
  expect_vec3(s.camera->eye, {0, 0, 5});
  a.evaluate(0.5, s);
  expect_vec3(s.lights[0].position, {5, 0, 5});
  expect_vec3(s.camera->eye, {5, 0, 5});
  expect_vec3(s.camera->target, {5, 0, 4});
  // t = 1.5: translation (10,0,0), rotation Y 90: the child's (0,0,5) -> (5,0,0); -Z -> -X.
  a.evaluate(1.5, s);
  expect_vec3(s.lights[0].position, {15, 0, 0});
  expect_vec3(s.lights[0].direction, {-1, 0, 0});
  EXPECT_EQ(s.lights[0].type, LightType::Spot);
  EXPECT_FLOAT_EQ(s.lights[0].outer_cone, 0.6f);
  expect_vec3(s.camera->eye, {15, 0, 0});
  expect_vec3(s.camera->target, {14, 0, 0});
  expect_vec3(s.camera->up, {0, 1, 0});
  EXPECT_FLOAT_EQ(s.camera->yfov, 0.5f);
}

TEST(GltfAnimation, CameraScaledToZeroIsAnError) {
  Gltf g;
  g.doc["cameras"] = json::array({{{"type", "perspective"}, {"perspective", {{"yfov", 0.5}, {"znear", 0.1}}}}});
  const int cam = g.node({{"camera", 0}});
  g.scene({g.node({{"mesh", triangle_mesh(g)}}), cam});
  g.channel(0, cam, "scale", {0, 1}, {1, 1, 1, 0, 0, 0});
  const AnimatedScene a = load_animated_scene(g.write_gltf(test::temp_dir() / "zero.gltf"));
  EXPECT_TRUE(a.at(0.5).camera.has_value());
  expect_bad_input([&] { a.at(1.0); }, {"zero.gltf", "nodes[0]", "singular", "t = 1"});
}

// ---- OBJ sequences ----------------------------------------------------------------------------

// Frame k: one triangle shifted by k along X (and a quad when `quad` is true).
void write_frame(const fs::path& path, int k, bool quad = false) {
  std::ofstream out(path);
  out << "v " << k << " 0 0\nv " << k + 1 << " 0 0\nv " << k << " 1 0\n";
  if (quad) out << "v " << k + 1 << " 1 0\nf 1 2 4 3\n";
  else out << "f 1 2 3\n";
}

float frame_x(const Scene& s) { return s.mesh.positions[0].x; }

TEST(ObjSequence, FolderSortedByNameAndFramePicking) {
  const fs::path dir = test::temp_dir();
  const fs::path seq = dir / "seq";
  fs::create_directories(seq);
  // Written out of order; a file of another type is ignored.
  write_frame(seq / "f_02.obj", 2);
  write_frame(seq / "f_00.obj", 0);
  write_frame(seq / "f_01.OBJ", 1);
  std::ofstream(seq / "notes.txt") << "not a frame\n";
  EXPECT_EQ(sequence_files(seq.string()).size(), 3u);
  const AnimatedScene a = load_animated_scene(seq.string());
  ASSERT_TRUE(a.animated());
  EXPECT_EQ(a.frame_count(), 3u);
  EXPECT_DOUBLE_EQ(a.fps(), 24.0);
  EXPECT_DOUBLE_EQ(a.duration(), 3.0 / 24.0);
  EXPECT_FLOAT_EQ(frame_x(a.rest()), 0.0f);
  Scene s;
  // frame = floor(t * fps), clamped; no interpolation.
  const std::vector<std::pair<double, float>> expect = {
      {-1.0, 0.f}, {0.0, 0.f}, {0.99 / 24, 0.f}, {1.0 / 24, 1.f}, {1.5 / 24, 1.f},
      {2.0 / 24, 2.f}, {3.0 / 24, 2.f}, {100.0, 2.f}};
  for (const auto& [t, x] : expect) {
    a.evaluate(t, s);
    EXPECT_FLOAT_EQ(frame_x(s), x) << "t = " << t;
    EXPECT_EQ(s.mesh.triangle_count(), 1u);
  }
  EXPECT_EQ(s.source, seq.string());
  EXPECT_FALSE(s.camera.has_value());
}

TEST(ObjSequence, PrintfPatternAndFrameRate) {
  const fs::path dir = test::temp_dir();
  for (int k = 0; k < 3; ++k) {
    char name[32];
    std::snprintf(name, sizeof name, "doll_%02d.obj", k);
    write_frame(dir / name, k);
    write_frame(dir / ("one_" + std::to_string(k + 1) + ".obj"), k);  // counted from 1
  }
  LoadOptions options;
  options.fps = 10.0;
  const AnimatedScene a = load_animated_scene((dir / "doll_%02d.obj").string(), options);
  EXPECT_EQ(a.frame_count(), 3u);
  EXPECT_DOUBLE_EQ(a.duration(), 0.3);
  EXPECT_DOUBLE_EQ(a.fps(), 10.0);
  EXPECT_FLOAT_EQ(frame_x(a.at(0.1)), 1.0f);
  EXPECT_FLOAT_EQ(frame_x(a.at(0.25)), 2.0f);
  const AnimatedScene b = load_animated_scene((dir / "one_%d.obj").string());
  EXPECT_EQ(b.frame_count(), 3u);
  EXPECT_FLOAT_EQ(frame_x(b.at(1.0 / 24)), 1.0f);

  expect_bad_input([&] { load_animated_scene((dir / "none_%03d.obj").string()); },
                   {"none_%03d.obj", "no frame files", "none_000.obj"});
  expect_bad_input([&] { load_animated_scene((dir / "doll_%s.obj").string()); },
                   {"doll_%s.obj", "%d"});
  expect_bad_input([&] { load_animated_scene((dir / "doll_%d_%d.obj").string()); },
                   {"exactly one %d"});
  LoadOptions zero;
  zero.fps = 0.0;
  expect_bad_input([&] { load_animated_scene((dir / "doll_%02d.obj").string(), zero); },
                   {"frame rate"});
  // A single OBJ file is a static scene.
  const AnimatedScene single = load_animated_scene((dir / "doll_01.obj").string());
  EXPECT_FALSE(single.animated());
  EXPECT_FLOAT_EQ(frame_x(single.at(1.0)), 1.0f);
}

TEST(ObjSequence, TopologyMismatchNamesTheFrame) {
  const fs::path dir = test::temp_dir();
  write_frame(dir / "a_0.obj", 0);
  write_frame(dir / "a_1.obj", 1);
  write_frame(dir / "a_2.obj", 2, /*quad=*/true);
  expect_bad_input([&] { load_animated_scene((dir / "a_%d.obj").string()); },
                   {"a_2.obj", "frame 2 has 2 triangles", "same topology", "a_0.obj"});
  const fs::path empty = dir / "empty";
  fs::create_directories(empty);
  expect_bad_input([&] { load_animated_scene(empty.string()); }, {"no .obj files"});
}

TEST(ObjLoader, ReplacementMtl) {
  const fs::path dir = test::temp_dir();
  fs::create_directories(dir / "obj");
  fs::create_directories(dir / "look");
  std::ofstream(dir / "look" / "mine.mtl") << "newmtl body\nKd 0.2 0.4 0.6\nmap_Kd wood.png\n"
                                              "newmtl eyes\nKd 1 1 1\n";
  std::ofstream(dir / "obj" / "toy.mtl") << "newmtl body\nKd 1 0 0\n";
  const std::string obj_text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\n"
                               "usemtl body\nf 1/1 2/2 3/3\nusemtl eyes\nf 1 3 2\n";
  std::ofstream(dir / "obj" / "toy.obj") << "mtllib toy.mtl\n" << obj_text;
  std::ofstream(dir / "obj" / "bare.obj") << obj_text;  // names no .mtl at all
  LoadOptions options;
  options.mtl = (dir / "look" / "mine.mtl").string();
  for (const char* name : {"toy.obj", "bare.obj"}) {
    const Scene s = load_scene((dir / "obj" / name).string(), options);
    ASSERT_EQ(s.mesh.triangle_count(), 2u) << name;
    ASSERT_EQ(s.materials.size(), 2u) << name;
    const Material& body = s.materials[s.mesh.material_ids[0]];
    EXPECT_EQ(body.name, "body");
    expect_vec3(body.diffuse, {0.2f, 0.4f, 0.6f});
    ASSERT_EQ(body.texture, 0);
    // map_Kd is relative to the replacement .mtl's folder.
    EXPECT_EQ(fs::path(s.textures[0].path), (dir / "look" / "wood.png").lexically_normal());
    EXPECT_EQ(s.materials[s.mesh.material_ids[1]].name, "eyes");
  }
  // Without the option the OBJ's own .mtl is used.
  const Scene own = load_scene((dir / "obj" / "toy.obj").string());
  expect_vec3(own.materials[own.mesh.material_ids[0]].diffuse, {1, 0, 0});
  // Through a sequence too.
  const AnimatedScene seq = load_animated_scene((dir / "obj").string(), options);
  EXPECT_EQ(seq.frame_count(), 2u);
  expect_vec3(seq.rest().materials[seq.rest().mesh.material_ids[0]].diffuse, {0.2f, 0.4f, 0.6f});
  options.mtl = (dir / "look" / "absent.mtl").string();
  expect_bad_input([&] { load_scene((dir / "obj" / "toy.obj").string(), options); },
                   {"absent.mtl", "file not found"});
}

// ---- real animated scenes (skipped when ../shared/scenes is absent) -----------------------------

void expect_sane(const Scene& s) {
  const Aabb b = s.bounds();
  ASSERT_FALSE(b.empty());
  for (int k = 0; k < 3; ++k) ASSERT_TRUE(std::isfinite(b.lo[k]) && std::isfinite(b.hi[k]));
  for (const glm::vec3& n : s.mesh.normals) ASSERT_NEAR(glm::length(n), 1.0f, 1e-4f);
}

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

TEST(RealAnimations, FoxSkinned) {
  MOBIRT_REQUIRE_SHARED(path, "gltf/Fox/Fox.glb");
  const AnimatedScene a = load_animated_scene(path.string());
  ASSERT_TRUE(a.animated());
  EXPECT_EQ(a.rest().mesh.triangle_count(), 576u);
  // Survey (animations[0], 3.4167 s) plays; Walk and Run drive the same joints and are dropped.
  EXPECT_NEAR(a.duration(), 3.41667, 1e-4);
  Scene s0;
  Scene s1;
  a.evaluate(0.0, s0);
  a.evaluate(0.5, s1);
  expect_sane(s0);
  expect_sane(s1);
  const Aabb b0 = s0.bounds();
  const Aabb b1 = s1.bounds();
  EXPECT_GT(glm::length(b0.lo - b1.lo) + glm::length(b0.hi - b1.hi), 0.1f);
  // The bind pose spans about 25 x 79 x 155 units: a posed fox stays that size.
  for (const Aabb& b : {b0, b1}) {
    EXPECT_GT(b.extent().y, 40.0f);
    EXPECT_LT(b.extent().y, 120.0f);
    EXPECT_GT(b.extent().z, 80.0f);
    EXPECT_LT(b.extent().z, 240.0f);
    EXPECT_LT(b.extent().x, 80.0f);
  }
  LoadOptions run;
  run.animation = 2;
  const AnimatedScene r = load_animated_scene(path.string(), run);
  EXPECT_NEAR(r.duration(), 1.15833, 1e-4);

  // Cost of one evaluation (skinning 1,728 vertices, 24 joints) with the Scene reused.
  Scene s;
  a.evaluate(0.0, s);
  const int n = 200;
  const auto start = std::chrono::steady_clock::now();
  for (int i = 0; i < n; ++i) a.evaluate(a.duration() * i / n, s);
  const double ms = seconds_since(start) * 1000.0 / n;
  std::cout << "Fox: evaluate " << ms << " ms per frame (" << s.mesh.triangle_count()
            << " triangles), bounds at t=0: " << b0.extent().x << " x " << b0.extent().y << " x "
            << b0.extent().z << ", at t=0.5: " << b1.extent().x << " x " << b1.extent().y << " x "
            << b1.extent().z << "\n";
  // No bound on the time: tests assert no times (a loaded machine is not a wrong result); the line
  // above is for whoever reads the log.
}

// Reads accessor `index` of a glTF with one external .bin (tightly packed floats), independently
// of the loader.
std::vector<float> read_floats(const json& doc, const std::vector<char>& bin, int index) {
  const json& a = doc["accessors"][index];
  const json& v = doc["bufferViews"][a["bufferView"].get<int>()];
  const size_t per = a["type"] == "SCALAR" ? 1 : a["type"] == "VEC3" ? 3 : 4;
  const size_t offset = v.value("byteOffset", 0) + a.value("byteOffset", 0);
  std::vector<float> out(a["count"].get<size_t>() * per);
  std::memcpy(out.data(), bin.data() + offset, out.size() * 4);
  return out;
}

TEST(RealAnimations, AnimatedMorphCube) {
  MOBIRT_REQUIRE_SHARED(path, "gltf/assimp-testmodels/AnimatedMorphCube-glTF/AnimatedMorphCube.gltf");
  const AnimatedScene a = load_animated_scene(path.string());
  ASSERT_TRUE(a.animated());
  EXPECT_EQ(a.rest().mesh.triangle_count(), 12u);

  // Expected bounds from the file's own data: base + w0 * target0 + w1 * target1, then the node's
  // rotation and scale (100).
  json doc;
  std::ifstream(path) >> doc;
  std::ifstream bin_file(path.parent_path() / doc["buffers"][0]["uri"].get<std::string>(),
                         std::ios::binary);
  const std::vector<char> bin((std::istreambuf_iterator<char>(bin_file)),
                              std::istreambuf_iterator<char>());
  const json& prim = doc["meshes"][0]["primitives"][0];
  const std::vector<float> base = read_floats(doc, bin, prim["attributes"]["POSITION"]);
  const std::vector<float> t0 = read_floats(doc, bin, prim["targets"][0]["POSITION"]);
  const std::vector<float> t1 = read_floats(doc, bin, prim["targets"][1]["POSITION"]);
  const json& sampler = doc["animations"][0]["samplers"][0];
  const std::vector<float> times = read_floats(doc, bin, sampler["input"]);
  const std::vector<float> weights = read_floats(doc, bin, sampler["output"]);
  ASSERT_EQ(weights.size(), 2 * times.size());
  EXPECT_NEAR(a.duration(), times.back(), 1e-6);
  const json& node = doc["nodes"][0];
  const glm::quat rot(node["rotation"][3].get<float>(), node["rotation"][0].get<float>(),
                      node["rotation"][1].get<float>(), node["rotation"][2].get<float>());
  const float scale = node["scale"][0].get<float>();
  auto expected_bounds = [&](float w0, float w1) {
    Aabb box;
    for (size_t v = 0; v < base.size() / 3; ++v) {
      glm::vec3 p(base[3 * v], base[3 * v + 1], base[3 * v + 2]);
      p += w0 * glm::vec3(t0[3 * v], t0[3 * v + 1], t0[3 * v + 2]);
      p += w1 * glm::vec3(t1[3 * v], t1[3 * v + 1], t1[3 * v + 2]);
      box.extend(glm::normalize(rot) * (scale * p));
    }
    return box;
  };
  auto check = [&](double t, float w0, float w1) {
    const Aabb want = expected_bounds(w0, w1);
    const Aabb got = a.at(t).bounds();
    expect_vec3(got.lo, want.lo, 1e-3f);
    expect_vec3(got.hi, want.hi, 1e-3f);
  };
  // At key times, and halfway between two keys (LINEAR weights).
  for (size_t k : {size_t(0), size_t(30), size_t(63), size_t(100), times.size() - 1}) {
    check(times[k], weights[2 * k], weights[2 * k + 1]);
  }
  const size_t k = 45;
  check(0.5 * (times[k] + times[k + 1]), 0.5f * (weights[2 * k] + weights[2 * k + 2]),
        0.5f * (weights[2 * k + 1] + weights[2 * k + 3]));
  // The animation does change the cube.
  float max_w = 0.0f;
  size_t at = 0;
  for (size_t i = 0; i < weights.size(); ++i) {
    if (weights[i] > max_w) max_w = weights[i], at = i / 2;
  }
  const Scene rest = a.rest();
  const Scene moved = a.at(times[at]);
  float largest = 0.0f;
  for (size_t i = 0; i < rest.mesh.positions.size(); ++i) {
    largest = std::max(largest, glm::length(moved.mesh.positions[i] - rest.mesh.positions[i]));
  }
  EXPECT_GT(largest, 1.0f) << "weight " << max_w << " at t = " << times[at];
}

TEST(RealAnimations, SimpleSkin) {
  MOBIRT_REQUIRE_SHARED(path, "gltf/assimp-testmodels/simple_skin/simple_skin.gltf");
  const AnimatedScene a = load_animated_scene(path.string());
  ASSERT_TRUE(a.animated());
  EXPECT_EQ(a.rest().mesh.triangle_count(), 8u);
  EXPECT_DOUBLE_EQ(a.duration(), 5.5);
  // Both joints' inverse bind matrices are translate(-0.5, -1, 0) and joint 0 sits at (0,1,0):
  // at rest the strip (x in [0,1], y in [0,2]) is shifted by -0.5 in x.
  const Aabb rest = a.rest().bounds();
  expect_vec3(rest.lo, {-0.5f, 0, 0});
  expect_vec3(rest.hi, {0.5f, 2, 0});
  // t = 1.5: joint 1 turned 90 degrees about Z; the top row (weights (0, 1)) swings to x = -1,
  // y in {0.5, 1.5}.
  const Aabb bent = a.at(1.5).bounds();
  expect_vec3(bent.lo, {-1, 0, 0}, 2e-3f);
  expect_vec3(bent.hi, {0.5f, 1.5f, 0}, 2e-3f);
  // Back to rest at 2.5 s and at the end.
  expect_vec3(a.at(2.5).bounds().hi, {0.5f, 2, 0});
  expect_vec3(a.at(5.5).bounds().hi, {0.5f, 2, 0});
}

TEST(RealAnimations, UtahWoodDoll) {
  MOBIRT_REQUIRE_SHARED(dir, "utah-wooddoll");
  const auto start = std::chrono::steady_clock::now();
  const AnimatedScene a = load_animated_scene((dir / "wooddoll_%02d.obj").string());
  const double load_s = seconds_since(start);
  EXPECT_EQ(a.frame_count(), 29u);
  EXPECT_DOUBLE_EQ(a.duration(), 29.0 / 24.0);
  const Scene f0 = a.at(0.0);
  const Scene f14 = a.at(14.0 / 24.0);
  expect_sane(f0);
  expect_sane(f14);
  ASSERT_EQ(f0.mesh.triangle_count(), f14.mesh.triangle_count());
  size_t moved = 0;
  for (size_t i = 0; i < f0.mesh.positions.size(); ++i) {
    moved += glm::length(f0.mesh.positions[i] - f14.mesh.positions[i]) > 1e-4f;
  }
  EXPECT_GT(moved, f0.mesh.positions.size() / 10);
  // The folder form gives the same frames.
  const AnimatedScene b = load_animated_scene(dir.string());
  EXPECT_EQ(b.frame_count(), 29u);
  EXPECT_EQ(b.at(14.0 / 24.0).mesh.positions, f14.mesh.positions);

  Scene s;
  a.evaluate(0.0, s);
  const int n = 290;
  const auto t0 = std::chrono::steady_clock::now();
  for (int i = 0; i < n; ++i) a.evaluate(a.duration() * i / n, s);
  const double ms = seconds_since(t0) * 1000.0 / n;
  const size_t corners = f0.mesh.positions.size();
  const double mib = 29.0 * corners * 2 * sizeof(glm::vec3) / (1024.0 * 1024.0);
  std::cout << "wood doll: 29 frames of " << f0.mesh.triangle_count() << " triangles loaded in "
            << load_s * 1000.0 << " ms, " << mib << " MiB of frame positions and normals; evaluate "
            << ms << " ms per frame\n";
}

}  // namespace
}  // namespace mobirt
