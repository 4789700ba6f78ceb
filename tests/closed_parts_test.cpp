// Closed parts of a triangle soup (src/accel/closed_parts.h) and the light-buffer faces they let a
// shadow ray do without: which surfaces count as closed and which way they are wound; per light and
// pose, which faces may go; and that no shadow answer changes when they go, on the CPU (against
// brute force over every triangle) and in the renderer's frames (the image with the parts and
// without, per backend).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "accel/closed_parts.h"
#include "accel/kdtree.h"
#include "accel/light_buffer.h"
#include "render/renderer.h"
#include "scene/animation.h"
#include "scene/tessellate.h"
#include "test_scenes.h"
#include "test_support.h"
#include "vulkan_fixture.h"

namespace mobirt {
namespace {

size_t closed_triangles(const ClosedParts& p) {
  return size_t(std::count_if(p.part.begin(), p.part.end(), [](uint32_t x) { return x != kOpenPart; }));
}

TEST(ClosedParts, BoxesAndSpheresAreClosedFloorsAndSheetsAreNot) {
  Scene s;
  test::add_box(s, {0, 0, 0}, {1, 1, 1}, 0);   // triangles 0-11, wound outwards
  test::add_box(s, {3, 0, 0}, {4, 2, 1}, 0);   // 12-23
  test::add_triangle(s, {-5, 0, -5}, {-5, 0, 5}, {5, 0, 5}, 0);  // a floor: open
  test::add_triangle(s, {-5, 0, -5}, {5, 0, 5}, {5, 0, -5}, 0);
  Tessellation t;
  t.segments = 24;
  tessellate_sphere(s.mesh, {0, 5, 0}, 1.5f, 0, t);
  tessellate_sphere(s.mesh, {6, 5, 0}, -1.0f, 0, t);  // inside out: wound inwards
  const size_t sphere = sphere_triangle_count(t);
  const ClosedParts p = find_closed_parts(s.mesh.positions);
  ASSERT_EQ(p.triangles, s.mesh.triangle_count());
  ASSERT_EQ(p.parts(), 4u);
  EXPECT_EQ(closed_triangles(p), 24 + 2 * sphere);
  EXPECT_EQ(p.part[24], kOpenPart);
  EXPECT_EQ(p.part[25], kOpenPart);
  EXPECT_EQ(p.orientation[p.part[0]], 1.0f);
  EXPECT_EQ(p.orientation[p.part[12]], 1.0f);
  EXPECT_NE(p.part[0], p.part[12]);
  EXPECT_EQ(p.orientation[p.part[26]], 1.0f) << "the sphere";
  EXPECT_EQ(p.orientation[p.part[26 + sphere]], -1.0f) << "the inside-out sphere";
  for (size_t k = 0; k < 12; ++k) EXPECT_EQ(p.part[k], p.part[0]);
  EXPECT_FALSE(p.first.empty()) << "welds recorded";
  ASSERT_EQ(p.weld_tolerance.size() + 1, p.first.size());

  // A box without one triangle, a box with a face twice (three triangles on an edge), a sheet
  // whose two sides are the same triangles wound both ways (no volume), a triangle with a NaN, a
  // box and a copy sharing a face: all open.
  const auto open_all = [](const Scene& scene, const char* what) {
    const ClosedParts q = find_closed_parts(scene.mesh.positions);
    EXPECT_EQ(q.parts(), 0u) << what;
    EXPECT_EQ(closed_triangles(q), 0u) << what;
  };
  Scene holed;
  test::add_box(holed, {0, 0, 0}, {1, 1, 1}, 0);
  holed.mesh.positions.resize(33);
  holed.mesh.normals.resize(33);
  holed.mesh.material_ids.resize(11);
  open_all(holed, "a box with a hole");
  Scene twice;
  test::add_box(twice, {0, 0, 0}, {1, 1, 1}, 0);
  test::add_triangle(twice, twice.mesh.positions[0], twice.mesh.positions[1], twice.mesh.positions[2], 0);
  open_all(twice, "a box with a triangle twice");
  Scene sheet;
  test::add_triangle(sheet, {0, 0, 0}, {1, 0, 0}, {0, 1, 0}, 0);
  test::add_triangle(sheet, {0, 0, 0}, {0, 1, 0}, {1, 0, 0}, 0);
  open_all(sheet, "a two-sided sheet");
  Scene stacked;
  test::add_box(stacked, {0, 0, 0}, {1, 1, 1}, 0);
  test::add_box(stacked, {0, 1, 0}, {1, 2, 1}, 0);
  open_all(stacked, "two boxes sharing a face");
  Scene nan;
  test::add_box(nan, {0, 0, 0}, {1, 1, 1}, 0);
  nan.mesh.positions[4].y = NAN;
  open_all(nan, "a box with a NaN corner");
  // The weld's tolerance is each corner's own: a crack of 0.003 in a unit box stays open beside a
  // floor 1,000 wide (whose coordinates would allow 0.002 apiece), one of a rounding closes.
  Scene cracked;
  test::add_triangle(cracked, {-1000, 0, -1000}, {-1000, 0, 1000}, {1000, 0, 1000}, 0);
  test::add_box(cracked, {0, 1, 0}, {1, 2, 1}, 0);
  Scene sealed = cracked;
  cracked.mesh.positions[3 + 4].x += 0.003f;  // one corner of the box's second triangle
  open_all(cracked, "a box with a crack");
  sealed.mesh.positions[3 + 4].x = std::nextafter(sealed.mesh.positions[3 + 4].x, 2.0f);
  EXPECT_EQ(find_closed_parts(sealed.mesh.positions).parts(), 1u) << "a crack of one ulp is welded";
  EXPECT_EQ(find_closed_parts({}).parts(), 0u);
}

// Degenerate triangles (two corners welded) are left out of the topology: the box around them
// stays closed, they stay listed.
TEST(ClosedParts, DegenerateTrianglesDoNotOpenTheirSurface) {
  Scene s;
  test::add_box(s, {0, 0, 0}, {1, 1, 1}, 0);
  s.mesh.positions.push_back({0, 0, 0});
  s.mesh.positions.push_back({0, 0, 0});
  s.mesh.positions.push_back({1, 0, 0});
  s.mesh.normals.resize(s.mesh.positions.size());
  s.mesh.material_ids.push_back(0);
  const ClosedParts p = find_closed_parts(s.mesh.positions);
  ASSERT_EQ(p.parts(), 1u);
  EXPECT_EQ(closed_triangles(p), 12u);
  EXPECT_EQ(p.part[12], kOpenPart);
}

// Per light: a part's winding where the light is outside its box, 0 where inside it; 0 for a part
// whose welded corners no longer meet (a pose that tore it); and faces_away leaves out exactly the
// faces with the light behind their plane.
TEST(ClosedParts, WindingsPerLightAndPose) {
  Scene s;
  test::add_box(s, {0, 0, 0}, {1, 1, 1}, 0);
  test::add_box(s, {3, 0, 0}, {4, 1, 1}, 0);
  const ClosedParts p = find_closed_parts(s.mesh.positions);
  ASSERT_EQ(p.parts(), 2u);
  std::vector<int8_t> w;
  light_windings(p, s.mesh.positions, {10.0f, 0.5f, 0.5f}, w);
  ASSERT_EQ(w.size(), 24u);
  EXPECT_TRUE(std::all_of(w.begin(), w.end(), [](int8_t x) { return x == 1; }));
  // Seen from +x beside both boxes: only the +x faces (two triangles each) face the light.
  size_t away = 0;
  for (size_t t = 0; t < 24; ++t) {
    const glm::dvec3 l(10.0, 0.5, 0.5);
    const glm::dvec3 c[3] = {glm::dvec3(s.mesh.positions[3 * t]) - l, glm::dvec3(s.mesh.positions[3 * t + 1]) - l,
                             glm::dvec3(s.mesh.positions[3 * t + 2]) - l};
    const bool out = faces_away(c, w[t]);
    away += out ? 1 : 0;
    const glm::vec3 n = glm::cross(s.mesh.positions[3 * t + 1] - s.mesh.positions[3 * t],
                                   s.mesh.positions[3 * t + 2] - s.mesh.positions[3 * t]);
    EXPECT_EQ(out, !(n.x > 0.0f)) << "triangle " << t;
  }
  EXPECT_EQ(away, 20u);
  light_windings(p, s.mesh.positions, {0.5f, 0.5f, 0.5f}, w);  // inside the first box
  for (size_t t = 0; t < 24; ++t) EXPECT_EQ(w[t], t < 12 ? 0 : 1) << t;
  std::vector<glm::vec3> torn = s.mesh.positions;
  torn[0].x += 0.25f;  // one corner of the first box moves away from its welded neighbours
  light_windings(p, torn, {10.0f, 0.5f, 0.5f}, w);
  for (size_t t = 0; t < 24; ++t) EXPECT_EQ(w[t], t < 12 ? 0 : 1) << t;
  std::vector<glm::vec3> nan = s.mesh.positions;
  nan[40].z = NAN;  // a corner of the second box (triangles 12-23)
  light_windings(p, nan, {10.0f, 0.5f, 0.5f}, w);
  for (size_t t = 0; t < 24; ++t) EXPECT_EQ(w[t], t < 12 ? 1 : 0) << t;
  // Mirrored (x -> -x, the light too): the windings turn with the volume's sign, and the faces
  // left out are again those turned away from the light.
  std::vector<glm::vec3> mirrored = s.mesh.positions;
  for (glm::vec3& v : mirrored) v.x = -v.x;
  light_windings(p, mirrored, {-10.0f, 0.5f, 0.5f}, w);
  EXPECT_TRUE(std::all_of(w.begin(), w.end(), [](int8_t x) { return x == -1; }));
  away = 0;
  for (size_t t = 0; t < 24; ++t) {
    const glm::dvec3 l(-10.0, 0.5, 0.5);
    const glm::dvec3 c[3] = {glm::dvec3(mirrored[3 * t]) - l, glm::dvec3(mirrored[3 * t + 1]) - l,
                             glm::dvec3(mirrored[3 * t + 2]) - l};
    const bool out = faces_away(c, w[t]);
    away += out ? 1 : 0;
    const glm::vec3 outward = -glm::cross(mirrored[3 * t + 1] - mirrored[3 * t], mirrored[3 * t + 2] - mirrored[3 * t]);
    EXPECT_EQ(out, !(outward.x < 0.0f)) << "triangle " << t;
  }
  EXPECT_EQ(away, 20u);
  std::vector<glm::vec3> moved = s.mesh.positions;
  for (glm::vec3& v : moved) v = glm::vec3(v.z, v.x, v.y) + glm::vec3(100.0f, -50.0f, 7.0f);  // turned and moved
  light_windings(p, moved, {0.0f, 0.0f, 0.0f}, w);
  EXPECT_TRUE(std::all_of(w.begin(), w.end(), [](int8_t x) { return x == 1; })) << "a rigid pose keeps the welds";
  light_windings(p, std::vector<glm::vec3>(30), {0, 0, 0}, w);
  EXPECT_TRUE(std::all_of(w.begin(), w.end(), [](int8_t x) { return x == 0; })) << "another soup";
}

// One pose measured for a frame serves each of its lights: the windings equal the one-light call's
// for lights outside, inside and beside the parts, far away and near, on a mesh posed anew
// (turned, scaled, one part torn); and a pose of another soup leaves every face in.
TEST(ClosedParts, OnePoseServesEveryLight) {
  Scene s;
  test::add_box(s, {0, 0, 0}, {1, 1, 1}, 0);
  test::add_box(s, {3, 0, 0}, {4, 1, 1}, 0);
  Tessellation t;
  t.segments = 12;
  tessellate_sphere(s.mesh, {1.5f, 3.0f, 0.5f}, -0.7f, 0, t);
  const ClosedParts parts = find_closed_parts(s.mesh.positions);
  ASSERT_EQ(parts.parts(), 3u);
  std::vector<glm::vec3> posed = s.mesh.positions;
  for (glm::vec3& v : posed) v = glm::vec3(-v.z, 2.0f * v.y, v.x) + glm::vec3(0.0f, 0.0f, -5.0f);
  std::vector<glm::vec3> torn = posed;
  torn[5].y += 0.5f;  // a corner of the first box
  const glm::vec3 lights[] = {{20, 3, 1}, {-0.5f, 1, -4.5f}, {-0.5f, 6, -3.5f}, {1e5f, -3e4f, 2e5f}, {0, 0, -5}};
  for (const std::vector<glm::vec3>* positions : {&posed, &torn}) {
    const PosedParts pose = pose_closed_parts(parts, *positions);
    ASSERT_EQ(pose.winding.size(), 3u);
    int differs = 0, nonzero = 0;
    for (const glm::vec3& light : lights) {
      std::vector<int8_t> once, each;
      light_windings(pose, *positions, light, once);
      light_windings(parts, *positions, light, each);
      differs += once == each ? 0 : 1;
      nonzero += int(std::count_if(once.begin(), once.end(), [](int8_t x) { return x != 0; }));
    }
    EXPECT_EQ(differs, 0);
    EXPECT_GT(nonzero, 0);
  }
  EXPECT_EQ(pose_closed_parts(parts, torn).winding[0], 0) << "the torn box counts as open";
  EXPECT_NE(pose_closed_parts(parts, posed).winding[0], 0);
  const PosedParts other = pose_closed_parts(parts, std::vector<glm::vec3>(30));
  EXPECT_EQ(other.of, nullptr);
  std::vector<int8_t> w;
  light_windings(other, posed, lights[0], w);
  EXPECT_TRUE(std::all_of(w.begin(), w.end(), [](int8_t x) { return x == 0; }));
}

// The faces a raster pass from a viewpoint leaves out (faces_turned_away): a box's three faces
// turned away from an eye outside it, none from an eye inside it, none of an open sheet; with
// rays_from, only the parts that point is outside of too.
TEST(ClosedParts, FacesTurnedAwayFromAnEye) {
  Scene s;
  test::add_box(s, {0, 0, 0}, {1, 1, 1}, 0);  // triangles 0-11
  test::add_box(s, {3, 0, 0}, {4, 1, 1}, 0);  // 12-23
  test::add_triangle(s, {-5, -1, -5}, {5, -1, -5}, {0, -1, 5}, 0);  // 24, open
  const ClosedParts parts = find_closed_parts(s.mesh.positions);
  ASSERT_EQ(parts.parts(), 2u);
  const PosedParts posed = pose_closed_parts(parts, s.mesh.positions);
  const auto count = [](const std::vector<uint8_t>& away, size_t first, size_t last) {
    return size_t(std::count(away.begin() + std::ptrdiff_t(first), away.begin() + std::ptrdiff_t(last), uint8_t(1)));
  };
  const glm::vec3 eye(2.0f, 5.0f, 9.0f);  // above and in front of both boxes: three faces of each seen
  std::vector<uint8_t> away;
  faces_turned_away(posed, s.mesh.positions, eye, away);
  ASSERT_EQ(away.size(), 25u);
  EXPECT_EQ(count(away, 0, 12), 6u);
  EXPECT_EQ(count(away, 12, 24), 6u);
  EXPECT_EQ(away[24], 0) << "an open sheet keeps both sides";
  for (size_t t = 0; t < 24; ++t) {
    if (!away[t]) continue;
    const glm::vec3* c = &s.mesh.positions[3 * t];
    EXPECT_LT(glm::dot(glm::cross(c[1] - c[0], c[2] - c[0]), eye - c[0]), 0.0f) << "triangle " << t << " faces the eye";
  }
  faces_turned_away(posed, s.mesh.positions, glm::vec3(0.5f, 0.5f, 0.5f), away);  // inside the first box
  EXPECT_EQ(count(away, 0, 12), 0u);
  EXPECT_EQ(count(away, 12, 24), 10u) << "the second box seen from within its height and depth: all but its near face";
  const glm::vec3 inside_second(3.5f, 0.5f, 0.5f);
  faces_turned_away(posed, s.mesh.positions, eye, away, &inside_second);
  EXPECT_EQ(count(away, 0, 12), 6u);
  EXPECT_EQ(count(away, 12, 24), 0u) << "rays that start inside the second box's bounds";
  // An eye 0.05 outside the first box whose rays start 0.1 along themselves (a near distance):
  // they may start inside it, so it keeps every face; with no reach its back is left out.
  const glm::vec3 near_box(0.5f, 0.5f, 1.05f);
  faces_turned_away(posed, s.mesh.positions, near_box, away, nullptr, 0.1f);
  EXPECT_EQ(count(away, 0, 12), 0u);
  EXPECT_EQ(count(away, 12, 24), 8u) << "the second box, far from it: all but its two faces towards it";
  faces_turned_away(posed, s.mesh.positions, near_box, away, nullptr, 0.0f);
  EXPECT_EQ(count(away, 0, 12), 10u) << "seen from within its height and width: all but its near face";
  faces_turned_away(pose_closed_parts(parts, std::vector<glm::vec3>(30)), s.mesh.positions, eye, away);
  EXPECT_EQ(count(away, 0, away.size()), 0u) << "a pose of another soup leaves nothing out";
}

// Closed boxes and spheres (wound both ways) among open triangles: with their faces turned away
// from the light left out, every segment's answer is still brute force's over all triangles, from
// origins anywhere (inside the closed parts too, and just off their surfaces on both sides), for
// lights outside every part and inside one.
TEST(ClosedParts, LeftOutFacesChangeNoShadowAnswer) {
  Scene s = test::random_soup_scene(300, 13);
  for (int i = 0; i < 4; ++i) test::add_box(s, glm::vec3(-4.0f + 2.5f * float(i), -1.0f, 1.0f), glm::vec3(-3.0f + 2.5f * float(i), 0.5f, 2.2f), 0);
  Tessellation t;
  t.segments = 20;
  tessellate_sphere(s.mesh, {1.0f, 2.0f, -2.0f}, 1.2f, 0, t);
  tessellate_sphere(s.mesh, {-2.0f, -2.0f, -1.0f}, -0.9f, 0, t);
  const ClosedParts parts = find_closed_parts(s.mesh.positions);
  ASSERT_EQ(parts.parts(), 6u);
  const FlatKdTree tree = build_kdtree(s.mesh.positions);
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(-6.0f, 6.0f), w(0.0f, 1.0f);
  std::vector<glm::vec3> origins;
  for (int i = 0; i < 2000; ++i) origins.push_back({u(rng), u(rng), u(rng)});
  const size_t n = s.mesh.triangle_count();
  for (int i = 0; i < 2000; ++i) {  // just off a surface point, on either side
    const size_t tri = size_t(rng() % n);
    const glm::vec3* v = &s.mesh.positions[3 * tri];
    const float a = w(rng), b = w(rng) * (1.0f - a);
    const glm::vec3 q = v[0] + a * (v[1] - v[0]) + b * (v[2] - v[0]);
    const glm::vec3 normal = glm::normalize(glm::cross(v[1] - v[0], v[2] - v[0]));
    origins.push_back(q + (i % 2 ? 1e-3f : -1e-3f) * normal);
  }
  // Two lights outside every part, one inside the first sphere (whose faces then all stay).
  for (const glm::vec3 light : {glm::vec3(0, 9, 3), glm::vec3(-8, 1, -7), glm::vec3(1.0f, 2.3f, -2.1f)}) {
    SCOPED_TRACE("light (" + std::to_string(light.x) + ", " + std::to_string(light.y) + ", " + std::to_string(light.z) + ")");
    std::vector<int8_t> winding;
    light_windings(parts, s.mesh.positions, light, winding);
    for (int res : {8, 64}) {
      LightBuffer all, culled;
      build_light_buffer(s.mesh.positions, light, res, all);
      build_light_buffer(s.mesh.positions, light, res, culled, 0, winding);
      EXPECT_EQ(all.left_out, 0u);
      EXPECT_GT(culled.left_out, 100u) << "faces left out";
      EXPECT_LT(culled.prims.size(), all.prims.size());
      size_t occluded = 0;
      for (const glm::vec3& o : origins) {
        const bool expected = test::occluded_by_any(tree, o, light);
        occluded += expected ? 1 : 0;
        ASSERT_EQ(light_buffer_occluded(culled, tree, o), expected) << "origin (" << o.x << ", " << o.y << ", " << o.z << ")";
      }
      EXPECT_GT(occluded, origins.size() / 10);
      if (light.y > 5.0f || light.x < -5.0f) {  // not in the sphere
        EXPECT_LT(occluded, origins.size() * 9 / 10);
      }
    }
  }
}

// AnimatedScene finds the closed parts once and hands them to every pose.
TEST(ClosedParts, EveryPoseOfAnAnimatedSceneCarriesThem) {
  Scene rest = test::box_grid_scene();
  const AnimatedScene animation(rest, nullptr, 0.0, 24.0);
  ASSERT_TRUE(animation.rest().closed_parts);
  // 48 of its 49 boxes: one has height 0 (a sheet, both sides the same faces), the floor is open.
  EXPECT_EQ(animation.rest().closed_parts->parts(), 48u);
  const Scene posed = animation.at(0.5);
  EXPECT_EQ(posed.closed_parts, animation.rest().closed_parts);
}

// ---- In the renderer's frames, per backend ---------------------------------------------------

using test::Api;

class ClosedPartsFrame : public test::PerBackendTest {};

// The box grid and two tessellated spheres under a point light, shadow rays through light buffers:
// the frame with the closed parts' back faces left out is the frame with every face listed, pixel
// for pixel, with reflections and refractions too (their shadow rays use the buffers as well).
TEST_P(ClosedPartsFrame, TheImageIsTheOneWithEveryFaceListed) {
  Scene scene = test::box_grid_scene();
  scene.lights.resize(1);  // the point light (the sun would walk the tree)
  ASSERT_NE(scene.lights[0].type, LightType::Directional);
  Tessellation t;
  t.segments = 32;
  Material glass;  // refracted rays through a closed part, their shadow rays from inside it
  glass.name = "glass";
  glass.diffuse = glm::vec3(0.1f);
  glass.transmittance = 0.8f;
  glass.ior = 1.5f;
  scene.materials.push_back(glass);
  tessellate_sphere(scene.mesh, {0.0f, 2.5f, 0.0f}, 1.0f, uint32_t(scene.materials.size() - 1), t);
  tessellate_sphere(scene.mesh, {-3.0f, 1.5f, 2.0f}, 0.8f, 1, t);
  scene.mesh.normals.resize(scene.mesh.positions.size(), glm::vec3(0, 1, 0));
  RenderSettings settings;
  settings.width = 120;
  settings.height = 80;
  settings.depth = 2;
  settings.shadow_cells = 64;
  const ClosedParts parts = find_closed_parts(scene.mesh.positions);
  ASSERT_EQ(parts.parts(), 50u);  // the grid's 48 closed boxes and the spheres
  Scene listed = scene;
  listed.closed_parts = nullptr;
  scene.closed_parts = std::make_shared<const ClosedParts>(parts);
  Renderer with(*backend, settings), without(*backend, settings);
  const Image a = with.render(scene, *scene.camera);
  const Image b = without.render(listed, *listed.camera);
  EXPECT_GE(with.light_buffers_used(), 1);
  EXPECT_GT(with.light_buffer_faces_left_out(), scene.mesh.triangle_count() / 4) << "faces were left out";
  EXPECT_EQ(without.light_buffer_faces_left_out(), 0u);
  EXPECT_EQ(compare_images(a, b).max_error, 0.0f);
}

INSTANTIATE_TEST_SUITE_P(Backends, ClosedPartsFrame, ::testing::Values(Api::Vulkan, Api::Gles), test::api_param_name);

}  // namespace
}  // namespace mobirt
