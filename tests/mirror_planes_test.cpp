// Planar mirrors (src/raytree/mirror_planes.h): which reflective triangles form planes, and that
// the mirrored, clipped triangles a raster pass draws from the camera give every mirror ray's
// closest hit, against the mirror rays traced by brute force; then --mirrors raster in the
// renderer's frames against --mirrors trace on both backends.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "accel/closed_parts.h"
#include "core/image.h"
#include "raytree/mirror_planes.h"
#include "raytree/shading_math.h"
#include "render/renderer.h"
#include "scene/animation.h"
#include "scene/loader.h"
#include "scene/tessellate.h"
#include "test_scenes.h"
#include "test_support.h"
#include "vulkan_fixture.h"

namespace mobirt {
namespace {

Scene materials_scene() {
  Scene s;
  Material matte;
  matte.name = "matte";
  Material mirror;
  mirror.name = "mirror";
  mirror.reflectance = 0.5f;
  Material glass;
  glass.name = "glass";
  glass.reflectance = 0.1f;
  glass.transmittance = 0.9f;
  s.materials = {matte, mirror, glass};
  return s;
}

// Moller-Trumbore in double: t of the hit of o + t d on triangle (a, b, c) with t > tmin, else -1.
double hit_t(const glm::dvec3& o, const glm::dvec3& d, const glm::dvec3& a, const glm::dvec3& b, const glm::dvec3& c,
             double tmin) {
  const glm::dvec3 e1 = b - a, e2 = c - a, p = glm::cross(d, e2);
  const double det = glm::dot(e1, p);
  if (det == 0.0) return -1.0;
  const glm::dvec3 s = o - a;
  const double u = glm::dot(s, p) / det;
  if (u < 0.0 || u > 1.0) return -1.0;
  const glm::dvec3 q = glm::cross(s, e1);
  const double v = glm::dot(d, q) / det;
  if (v < 0.0 || u + v > 1.0) return -1.0;
  const double t = glm::dot(e2, q) / det;
  return t > tmin ? t : -1.0;
}

// The closest hit of o + t d (t > tmin) among the triangles of `vertices` (stride floats per
// vertex, xyz first), as (index, t); index -1 for a miss. skip(i) leaves triangle i out.
template <typename Skip>
std::pair<int, double> closest(const std::vector<glm::dvec3>& vertices, const glm::dvec3& o, const glm::dvec3& d,
                               double tmin, Skip skip) {
  std::pair<int, double> best{-1, INFINITY};
  for (size_t i = 0; i + 2 < vertices.size(); i += 3) {
    if (skip(int(i / 3))) continue;
    const double t = hit_t(o, d, vertices[i], vertices[i + 1], vertices[i + 2], tmin);
    if (t > 0.0 && t < best.second) best = {int(i / 3), t};
  }
  return best;
}

TEST(MirrorPlanes, FindsTheFlatReflectiveTrianglesByPlane) {
  Scene s = materials_scene();
  test::add_triangle(s, {-5, 0, -5}, {-5, 0, 5}, {5, 0, 5}, 1);  // 0, 1: a mirror floor (normal +y as wound)
  test::add_triangle(s, {-5, 0, -5}, {5, 0, 5}, {5, 0, -5}, 1);
  test::add_triangle(s, {-5, 0, 6}, {-5, 0, 9}, {5, 0, 9}, 1);   // 2: the same plane, apart
  test::add_triangle(s, {0, 3, 0}, {1, 3, 0}, {0, 3, 1}, 1);     // 3: a parallel plane above
  test::add_triangle(s, {0, 0, 0}, {0, 1, 0}, {0, 0, 1}, 1);     // 4: a wall x = 0
  test::add_triangle(s, {2, 0, 2}, {2, 1, 2}, {2, 0, 3}, 0);     // 5: matte
  test::add_triangle(s, {3, 0, 3}, {3, 1, 3}, {3, 0, 4}, 2);     // 6: glass (refracts)
  test::add_triangle(s, {4, 0, 4}, {4, 1, 4}, {4, 2, 4}, 1);     // 7: degenerate
  test::add_triangle(s, {-5, 0, 10}, {-5, 0, 12}, {5, 0, 12}, 1); // 8: on the floor's plane, bent normals
  s.mesh.normals[3 * 8 + 1] = glm::normalize(glm::vec3(0.1f, -1.0f, 0.0f));
  test::add_triangle(s, {-5, 1e-9f, 13}, {-5, 0, 14}, {5, 0, 14}, 1);  // 9: the floor within rounding
  const MirrorPlanes m = find_mirror_planes(s);
  ASSERT_EQ(m.plane_of.size(), 10u);
  ASSERT_EQ(m.planes.size(), 3u);
  const int floor = m.plane_of[0];
  ASSERT_GE(floor, 0);
  EXPECT_EQ(floor, 0) << "the largest area first";
  EXPECT_EQ(m.plane_of[1], floor);
  EXPECT_EQ(m.plane_of[2], floor);
  EXPECT_EQ(m.plane_of[9], floor);
  EXPECT_EQ(m.planes[0].triangles, 4u);
  EXPECT_NEAR(m.planes[0].area, 50.0 + 50.0 + 15.0 + 5.0, 1e-6);
  EXPECT_NEAR(m.planes[0].normal.y, 1.0, 1e-12) << "the side its shading normals face";
  EXPECT_NEAR(m.planes[0].offset, 0.0, 1e-12);
  EXPECT_GE(m.plane_of[3], 0);
  EXPECT_NE(m.plane_of[3], floor);
  EXPECT_GE(m.plane_of[4], 0);
  EXPECT_NE(m.plane_of[4], m.plane_of[3]);
  EXPECT_EQ(m.plane_of[5], -1) << "matte";
  EXPECT_EQ(m.plane_of[6], -1) << "refracts";
  EXPECT_EQ(m.plane_of[7], -1) << "degenerate";
  EXPECT_EQ(m.plane_of[8], -1) << "its shading normals bend the mirror ray";
  s.mesh.positions[3 * 3] = glm::vec3(NAN);
  EXPECT_EQ(find_mirror_planes(s).plane_of[3], -1) << "a NaN corner";
}

// The mirrored triangles, each clipped to its part in front of the plane, seen from a camera above
// a mirror floor: for every primary ray that meets the floor, the first of them along the ray past
// the floor is the mirror ray's closest hit (brute force over the scene's triangles from the
// floor point), triangle and distance. A wall stands behind, boxes stand on the floor, lean through
// it and hide under it (never seen), a sphere sinks into it, a plank leans through it, a random
// soup floats above.
TEST(MirrorPlanes, MirroredTrianglesGiveTheMirrorRaysHits) {
  Scene s = materials_scene();
  test::add_triangle(s, {-20, 0, -20}, {-20, 0, 20}, {20, 0, 20}, 1);
  test::add_triangle(s, {-20, 0, -20}, {20, 0, 20}, {20, 0, -20}, 1);
  for (size_t k = 0; k < 3; ++k) s.mesh.normals[k] = s.mesh.normals[3 + k] = glm::vec3(0, 1, 0);  // facing up
  test::add_triangle(s, {-20, 0, -10}, {20, 0, -10}, {20, 15, -10}, 0);  // a wall behind
  test::add_triangle(s, {-20, 0, -10}, {20, 15, -10}, {-20, 15, -10}, 0);
  test::add_box(s, {-3, 0, -3}, {-1, 2, -1}, 0);      // standing on it
  test::add_box(s, {2, -1, -4}, {4, 1.5f, -2}, 0);    // through it
  test::add_box(s, {-2, -3, 2}, {2, -1, 4}, 0);       // under it
  // A plank leaning through it: its part under the floor, mirrored whole, would stand in the open
  // above the floor and hide the reflection behind it; clipped, it is not drawn.
  test::add_triangle(s, {-7, -2, -7}, {-3, -2, -7}, {-5, 3, -1}, 0);
  test::add_triangle(s, {-7, -2, -7}, {-5, 3, -1}, {-3, -2, -7}, 0);
  Tessellation tess;
  tess.segments = 16;
  tessellate_sphere(s.mesh, {0.5f, 0.2f, 0.0f}, 1.0f, 0, tess);  // a sphere through the floor
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(-6.0f, 6.0f), h(0.5f, 5.0f);
  for (int i = 0; i < 60; ++i) {
    const glm::vec3 c(u(rng), h(rng), u(rng));
    test::add_triangle(s, c, c + glm::vec3(u(rng), u(rng), u(rng)) * 0.3f, c + glm::vec3(u(rng), u(rng), u(rng)) * 0.3f, 0);
  }
  const MirrorPlanes m = find_mirror_planes(s);
  ASSERT_EQ(m.planes.size(), 1u);
  ASSERT_EQ(m.plane_of[0], 0);
  const MirrorPlane& plane = m.planes[0];
  std::vector<float> raster;
  mirrored_raster_vertices(s.mesh.positions, plane, raster);
  ASSERT_EQ(raster.size() % 12, 0u);
  std::vector<glm::dvec3> mirrored, scene;
  std::vector<int> source;
  for (size_t i = 0; i < raster.size(); i += 4) {
    mirrored.emplace_back(raster[i], raster[i + 1], raster[i + 2]);
    if (i % 12 == 0) source.push_back(int(raster[i + 3]) - 1);
  }
  for (const glm::vec3& p : s.mesh.positions) scene.emplace_back(p);
  for (size_t i = 0; i < raster.size(); i += 4) EXPECT_EQ(raster[i + 3], raster[i - i % 12 + 3]) << "one index per triangle";
  for (const int t : source) ASSERT_NE(m.plane_of[size_t(t)], 0) << "the mirror itself is left out";
  const glm::dvec3 eye(1.0, 7.0, 12.0);
  int rays = 0, agree = 0, hits = 0;
  for (int i = 0; i < 6000; ++i) {
    const glm::dvec3 target(u(rng) * 2.0, 0.0, u(rng) * 2.0 - 2.0);
    const glm::dvec3 d = glm::normalize(target - eye);
    // The primary hit: the floor, unless something stands in front of it.
    const auto primary = closest(scene, eye, d, 0.0, [](int) { return false; });
    if (primary.first < 0 || m.plane_of[size_t(primary.first)] != 0) continue;
    ++rays;
    const glm::dvec3 x = eye + primary.second * d;
    const glm::dvec3 r = mirror_direction(d, plane.normal, plane.normal);
    const auto traced = closest(scene, x, r, 1e-9, [&](int t) { return m.plane_of[size_t(t)] == 0; });
    // Everything drawn counts, from the eye on, as in a raster pass with a depth test.
    const auto drawn = closest(mirrored, eye, d, 0.0, [](int) { return false; });
    const int drawn_source = drawn.first < 0 ? -1 : source[size_t(drawn.first)];
    if (traced.first >= 0) ++hits;
    if (drawn_source == traced.first &&
        (traced.first < 0 || std::abs((drawn.second - primary.second) - traced.second) <= 1e-4 * (1.0 + traced.second))) {
      ++agree;
    }
  }
  ASSERT_GT(rays, 3000);
  EXPECT_GT(hits, rays / 4) << "the mirror shows the scene";
  // Ties at shared edges can go either way in double; nothing else may differ.
  EXPECT_GE(agree, rays - rays / 1000) << agree << " of " << rays;
}

// mirrored_raster_vertices makes its triangles in chunks on all cores: over 6,000 triangles (three
// chunks and more), some skipped, some cut by the plane, some behind it, the output is each source
// triangle's part in front, in source order, appended after what `out` held: a triangle wholly in
// front is its mirror image exactly (p - 2 s n, s = n . p - offset, in double), one cut by the
// plane one or two triangles (one or two corners in front), each with its source index + 1.
TEST(MirrorPlanes, MirroredTrianglesComeInSourceOrderFromEveryChunk) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(-10.0f, 10.0f), h(-3.0f, 8.0f), e(-0.8f, 0.8f);
  std::vector<glm::vec3> positions;
  for (int i = 0; i < 6200; ++i) {
    const glm::vec3 c(u(rng), h(rng), u(rng));
    for (int k = 0; k < 3; ++k) positions.push_back(c + glm::vec3(e(rng), e(rng), e(rng)));
  }
  const size_t triangles = positions.size() / 3;
  std::vector<uint8_t> skip(triangles, 0);
  for (size_t t = 0; t < triangles; t += 7) skip[t] = 1;
  MirrorPlane plane;
  plane.normal = glm::normalize(glm::dvec3(0.1, 1.0, -0.05));
  plane.offset = 0.25;
  std::vector<float> out = {1.0f, 2.0f, 3.0f, 4.0f};  // kept in front of what is appended
  mirrored_raster_vertices(positions, plane, out, skip);
  ASSERT_EQ(out.size() % 4, 0u);
  EXPECT_EQ(out[0], 1.0f);
  EXPECT_EQ(out[3], 4.0f);
  double largest = 0.0;
  for (const glm::vec3& p : positions) largest = std::max({largest, double(std::abs(p.x)), double(std::abs(p.y)), double(std::abs(p.z))});
  const double margin = 1e-6 * largest;
  size_t at = 4, whole = 0, cut = 0;
  for (size_t t = 0; t < triangles; ++t) {
    if (skip[t]) continue;
    double side[3];
    int front = 0;
    for (int k = 0; k < 3; ++k) {
      side[k] = glm::dot(plane.normal, glm::dvec3(positions[3 * t + size_t(k)])) - plane.offset;
      front += side[k] > margin ? 1 : 0;
    }
    if (front == 0) continue;
    const size_t emitted = front == 3 ? 1 : size_t(front);  // a corner in front: one, two: two
    ASSERT_LE(at + emitted * 12, out.size()) << "triangle " << t;
    for (size_t v = 0; v < 3 * emitted; ++v) {
      ASSERT_EQ(out[at + 4 * v + 3], float(t + 1)) << "triangle " << t << ": its index, in source order";
    }
    if (front == 3) {
      for (int k = 0; k < 3; ++k) {
        const glm::dvec3 p(positions[3 * t + size_t(k)]);
        const glm::dvec3 q = p - 2.0 * side[k] * plane.normal;
        EXPECT_EQ(out[at + 4 * size_t(k)], float(q.x));
        EXPECT_EQ(out[at + 4 * size_t(k) + 1], float(q.y));
        EXPECT_EQ(out[at + 4 * size_t(k) + 2], float(q.z));
      }
      ++whole;
    } else {
      ++cut;
    }
    at += emitted * 12;
  }
  EXPECT_EQ(at, out.size()) << "nothing but the triangles' parts in front";
  EXPECT_GT(whole, 2048u);  // past the first chunk
  EXPECT_GT(cut, 100u);
}

// Which plane sent each mirror ray: the vector lanes (mirror_ray_planes, four rays at a time on
// AVX2 CPUs) give the reference's answer (mirror_ray_plane) for every ray: true mirror rays off a
// floor and a wall, the same rays nudged across each of the test's bounds (the origin off the plane
// by 0.5 to 1.5 of on_plane, the direction off by 0.5e-5 to 1.5e-5 of the image plane; each kind
// both passes and fails), rays into the plane, pixels outside the image and degenerate directions
// in the first group of four, random rays, and counts that leave one to three rays past the last
// group of four.
TEST(MirrorPlanes, VectorLanesFindTheReferencesPlanes) {
  if (!mirror_ray_lanes()) GTEST_SKIP() << "no AVX2: mirror_ray_planes runs the reference itself";
  Camera camera;
  camera.eye = glm::vec3(0.3f, 4.0f, 9.0f);
  camera.target = glm::vec3(0.0f, 0.5f, 0.0f);
  const uint32_t width = 61, height = 37;  // odd sizes: no lane pattern lines up with a row
  const CameraBasis basis(camera, int(width), int(height));
  std::vector<MirrorPlane> planes(2);
  planes[0].normal = glm::dvec3(0.0, 1.0, 0.0);  // a floor at y = 0.25, facing the eye
  planes[0].offset = 0.25;
  planes[1].normal = glm::normalize(glm::dvec3(0.0, 0.2, 1.0));  // a wall behind, leaning, facing the eye
  planes[1].offset = glm::dot(planes[1].normal, glm::dvec3(0.0, 0.0, -3.0));
  const double on_plane = 1e-4;
  const MirrorRayTest test{planes, basis, width, height, on_plane};
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
  RayBatch rays;
  rays.width = width;
  enum Kind { kTrue, kLifted, kNudged, kOther, kKinds };
  std::vector<Kind> kinds;
  const auto add = [&](glm::vec3 o, glm::vec3 d, uint32_t pixel, Kind kind) {
    Ray r;
    r.origin = o;
    r.direction = d;
    r.tmin = 0.0f;
    r.tmax = 1e30f;
    rays.push(r, pixel, glm::vec3(1.0f));
    kinds.push_back(kind);
  };
  // The first group of four: pixels outside the image, a NaN and a zero direction.
  add(glm::vec3(0.0f, 0.25f, 0.0f), glm::vec3(0.0f, 1.0f, 0.0f), width * height, kOther);
  add(glm::vec3(0.0f, 0.25f, 0.0f), glm::vec3(std::nanf(""), 1.0f, 0.0f), 5, kOther);
  add(glm::vec3(0.0f, 0.25f, 0.0f), glm::vec3(0.0f), 6, kOther);
  add(glm::vec3(0.0f, 0.25f, 0.0f), glm::vec3(0.0f, 1.0f, 0.0f), UINT32_MAX, kOther);
  for (uint32_t pixel = 0; pixel < width * height; ++pixel) {
    const Ray primary = basis.ray(float(pixel % width) + 0.5f, float(pixel / width) + 0.5f);
    for (const MirrorPlane& plane : planes) {
      const glm::dvec3 e(primary.origin), d(primary.direction);
      const double dn = glm::dot(d, plane.normal);
      if (!(dn < 0.0)) continue;
      const double t = (plane.offset - glm::dot(plane.normal, e)) / dn;
      if (!(t > 0.0)) continue;
      const glm::dvec3 x = e + t * d;
      const glm::vec3 mirror = glm::vec3(d - 2.0 * dn * plane.normal);
      add(glm::vec3(x), mirror, pixel, kTrue);
      const float lift = float((0.5 + std::abs(unit(rng))) * on_plane);  // across the origin's bound
      add(glm::vec3(x + double(lift) * plane.normal), mirror, pixel, kLifted);
      add(glm::vec3(x - double(lift) * plane.normal), mirror, pixel, kLifted);
      const float nudge = (0.5f + std::abs(unit(rng))) * 1e-5f;  // across the image plane's bounds
      add(glm::vec3(x), mirror + nudge * basis.right, pixel, kNudged);
      add(glm::vec3(x), mirror - nudge * basis.up, pixel, kNudged);
      add(glm::vec3(x), -mirror, pixel, kOther);  // into the plane
    }
    add(glm::vec3(unit(rng), unit(rng), unit(rng)), glm::vec3(unit(rng), unit(rng), unit(rng)), pixel, kOther);
  }
  size_t found[kKinds] = {}, missed[kKinds] = {};
  for (uint32_t tail = 0; tail < 4; ++tail) {
    const uint32_t n = rays.count() - tail;
    std::vector<uint8_t> lanes(n, 0x7E);
    mirror_ray_planes(test, rays, 0, n, lanes.data());
    size_t differ = 0;
    for (uint32_t i = 0; i < n; ++i) {
      const uint8_t reference = mirror_ray_plane(test, rays, i);
      differ += lanes[i] != reference ? 1u : 0u;
      if (tail == 0) ++(reference == kNoMirrorPlane ? missed : found)[kinds[i]];
    }
    EXPECT_EQ(differ, 0u) << "of " << n << " rays";
  }
  // The true mirror rays are found (a few at a grazing angle aside), the special rays are not, and
  // the rays nudged across a bound land on both sides of it.
  EXPECT_GT(found[kTrue], 9 * missed[kTrue]);
  for (const Kind kind : {kLifted, kNudged}) {
    EXPECT_GT(found[kind], found[kTrue] / 10) << "kind " << kind;
    EXPECT_GT(missed[kind], found[kTrue] / 10) << "kind " << kind;
  }
  EXPECT_EQ(found[kOther], 0u) << "rays into the plane, outside the image, degenerate or random";
}

// The project's scenes: the toaster's and the marbles' floors are found as one mirror plane each,
// holding every reflective triangle of the floor's material.
TEST(MirrorPlanes, TheProjectScenesFloorsAreMirrorPlanes) {
  for (const char* name : {"toaster", "marbles"}) {
    SCOPED_TRACE(name);
    const AnimatedScene animation = load_animated_scene(std::string(MOBIRT_SOURCE_DIR) + "/scenes/" + name + ".gltf");
    Scene posed;
    animation.evaluate(0.0, posed);
    const MirrorPlanes m = find_mirror_planes(posed);
    ASSERT_FALSE(m.planes.empty());
    size_t floor_triangles = 0;
    for (size_t t = 0; t < posed.mesh.triangle_count(); ++t) {
      if (posed.mesh.material_ids[t] == 0) {
        ++floor_triangles;
        EXPECT_EQ(m.plane_of[t], 0) << "floor triangle " << t;
      }
    }
    EXPECT_GT(floor_triangles, 0u);
    EXPECT_EQ(m.planes[0].triangles, floor_triangles);
    EXPECT_NEAR(std::abs(m.planes[0].normal.y), 1.0, 1e-9) << "a floor";
  }
}

using test::Api;
using test::api_name;

class MirrorRaster : public test::PerBackendTest {};

// The light, view and frame of the mirror tile scenes below: a floor at y = 0 seen from above.
Light tile_light() {
  Light light;
  light.position = glm::vec3(0, 10, 5);
  light.intensity = 100.0f;
  return light;
}
Camera tile_view() {
  Camera view;
  view.eye = glm::vec3(0, 8, 14);
  view.target = glm::vec3(0, 0, 0);
  return view;
}
RenderSettings tile_settings() {
  RenderSettings settings;
  settings.width = 80;
  settings.height = 48;
  settings.depth = 1;
  return settings;
}

// Frames with the floor's mirror rays rasterized against the same frames with every ray traced:
// the toaster and the marbles (their floors mirror 54 and 84 % of the pixels at the bench's view),
// one and two bounces, primaries rasterized and traced. Pixels may differ where a mirror ray's
// pixel centre lies on an edge (as with --primary raster); --mirrors raster must have found the
// hits (GenerationTimings::mirrored), trace none. Auto draws a plane's mirror rays only where they
// come from at least a quarter of the pixels (kMirrorRasterMinShare).
TEST_P(MirrorRaster, FramesMatchTracedMirrorRays) {
  for (const char* name : {"toaster", "marbles"}) {
    Scene scene = load_scene(std::string(MOBIRT_SOURCE_DIR "/scenes/") + name + ".gltf");
    ASSERT_TRUE(scene.camera);
    // Its closed parts, as an animated scene carries them: both raster passes leave out their
    // faces turned away (faces_turned_away; the mirrored one from the eye's image).
    scene.closed_parts = std::make_shared<const ClosedParts>(find_closed_parts(scene.mesh.positions));
    for (const auto& [depth, primary] : {std::pair{1, PrimaryHits::Raster}, std::pair{2, PrimaryHits::Trace}}) {
      const std::string what = std::string(api_name(GetParam())) + "-" + name + "-depth" + std::to_string(depth) +
                               "-primary-" + primary_hits_name(primary);
      SCOPED_TRACE(what);
      RenderSettings settings;
      settings.width = std::string(name) == "marbles" ? 72 : 120;
      settings.height = std::string(name) == "marbles" ? 120 : 72;
      settings.depth = depth;
      settings.primary = primary;
      settings.mirrors = MirrorHits::Trace;
      Renderer traced(*backend, settings);
      settings.mirrors = MirrorHits::Raster;
      Renderer rasterized(*backend, settings);
      FrameTimings ta, tb;
      const Image a = traced.render(scene, *scene.camera, &ta);
      const Image b = rasterized.render(scene, *scene.camera, &tb);
      ASSERT_GE(ta.generations.size(), 2u);
      ASSERT_GE(tb.generations.size(), 2u);
      EXPECT_EQ(ta.generations[1].mirrored, 0u);
      EXPECT_GT(tb.generations[1].mirrored, tb.generations[1].rays / 2) << "the floor's mirror rays rasterized";
      EXPECT_EQ(ta.generations[1].rays, tb.generations[1].rays);
      // The floor's raster started ahead, once the primary hits were shaded, and taken.
      EXPECT_EQ(traced.mirror_rasters_ahead().started, 0u);
      EXPECT_EQ(rasterized.mirror_rasters_ahead().started, 1u);
      EXPECT_EQ(rasterized.mirror_rasters_ahead().taken, 1u);
      const ImageDiff d = compare_images(a, b, 2.0f / 255.0f);
      EXPECT_GE(d.psnr, 40.0) << "share over 2/255 " << d.share_over << ", max error " << d.max_error;
      EXPECT_LE(d.share_over, 0.005) << "share of pixels that differ by more than 2/255";
      if (d.psnr < 40.0) write_image(test::output_path("mirrors-" + what + "-diff.png").string(), difference_image(a, b));
    }
  }
  // Auto: a small mirror tile on a matte floor sends mirror rays from far fewer than a quarter of
  // the pixels, so they are traced; the marbles' floor at its own view (84 % of the pixels) is drawn,
  // at a size where the raster pays (kRasterTrianglesPerPixel), and not at one where it does not.
  Scene tile = materials_scene();
  test::add_triangle(tile, {-10, 0, -10}, {-10, 0, 10}, {10, 0, 10}, 0);
  test::add_triangle(tile, {-10, 0, -10}, {10, 0, 10}, {10, 0, -10}, 0);
  test::add_triangle(tile, {-1, 0.5f, -1}, {-1, 0.5f, 1}, {1, 0.5f, 1}, 1);
  test::add_triangle(tile, {-1, 0.5f, -1}, {1, 0.5f, 1}, {1, 0.5f, -1}, 1);
  test::add_box(tile, {2, 0, -1}, {3, 3, 1}, 0);
  // A mirror of far more area under the floor, never seen: the plane drawn is the one whose mirror
  // rays there are (the Utah toasters' tray has such an underside), not the largest.
  test::add_triangle(tile, {-4, -2, -4}, {4, -2, 4}, {-4, -2, 4}, 1);
  test::add_triangle(tile, {-4, -2, -4}, {4, -2, -4}, {4, -2, 4}, 1);
  ASSERT_GT(find_mirror_planes(tile).planes.size(), 1u);
  tile.lights.push_back(tile_light());
  const Camera view = tile_view();
  RenderSettings settings = tile_settings();
  Renderer automatic(*backend, settings);
  FrameTimings t;
  automatic.render(tile, view, &t);
  ASSERT_GT(t.generations.size(), 1u);
  EXPECT_GT(t.generations[1].rays, 0u) << "the tile reflects";
  EXPECT_LT(t.generations[1].rays, uint32_t(settings.width * settings.height) / 8);
  EXPECT_EQ(t.generations[1].mirrored, 0u) << "too few mirror rays to draw";
  settings.mirrors = MirrorHits::Raster;
  Renderer forced(*backend, settings);
  FrameTimings tf;
  const Image drawn = forced.render(tile, view, &tf);
  EXPECT_EQ(tf.generations[1].mirrored, t.generations[1].rays) << "--mirrors raster draws them all";
  settings.mirrors = MirrorHits::Trace;
  Renderer walked(*backend, settings);
  const ImageDiff tile_diff = compare_images(walked.render(tile, view), drawn, 2.0f / 255.0f);
  EXPECT_LE(tile_diff.share_over, 0.005);
  const Scene marbles = load_scene(std::string(MOBIRT_SOURCE_DIR "/scenes/marbles.gltf"));
  settings.mirrors = MirrorHits::Auto;
  settings.width = 120;  // auto's triangle budget: at most half a triangle a pixel (8,000 here)
  settings.height = 200;
  Renderer automatic_marbles(*backend, settings);
  FrameTimings front;
  automatic_marbles.render(marbles, *marbles.camera, &front);
  ASSERT_GT(front.generations.size(), 1u);
  EXPECT_GT(front.generations[1].mirrored, front.generations[1].rays / 2) << "auto draws the floor's mirror rays";
  settings.width = 48;
  settings.height = 80;
  Renderer small_marbles(*backend, settings);
  FrameTimings small;
  small_marbles.render(marbles, *marbles.camera, &small);
  ASSERT_GT(small.generations.size(), 1u);
  EXPECT_EQ(small.generations[1].mirrored, 0u) << "8,000 triangles over 3,840 pixels: the raster does not pay";
}

// The mirror raster started ahead is the plane most primary hits lie on; where the mirror rays
// then choose another (a floor too faint to send any: its reflectance under --min-weight), it is
// dropped and the rays' own plane drawn, the image that of the traced mirror rays; where no mirror
// ray follows at all, it is dropped before the next frame, and the frames are those of --mirrors
// trace bit for bit.
TEST_P(MirrorRaster, StartedAheadAndDroppedWhereTheRaysChooseOtherwise) {
  Scene scene = materials_scene();
  Material faint;
  faint.name = "faint";
  faint.reflectance = 0.001f;  // under the default min_weight (1/512): no mirror ray
  scene.materials.push_back(faint);
  const uint32_t kFaint = 3;
  test::add_triangle(scene, {-10, 0, -10}, {-10, 0, 10}, {10, 0, 10}, kFaint);
  test::add_triangle(scene, {-10, 0, -10}, {10, 0, 10}, {10, 0, -10}, kFaint);
  test::add_box(scene, {2, 0, -1}, {3, 3, 1}, 0);
  scene.lights.push_back(tile_light());
  const Camera view = tile_view();
  RenderSettings settings = tile_settings();

  // Only the faint floor: a raster started ahead each frame, no mirror ray to take it.
  settings.mirrors = MirrorHits::Raster;
  Renderer drawn(*backend, settings);
  settings.mirrors = MirrorHits::Trace;
  Renderer walked(*backend, settings);
  for (int frame = 0; frame < 2; ++frame) {
    FrameTimings t;
    const Image a = drawn.render(scene, view, &t);
    const Image b = walked.render(scene, view);
    ASSERT_GT(t.generations.size(), 0u);
    EXPECT_TRUE(t.generations.size() == 1 || t.generations[1].rays == 0u) << "the faint floor sends no mirror ray";
    EXPECT_EQ(compare_images(a, b, 0.0f).share_over, 0.0) << "frame " << frame;
  }
  EXPECT_EQ(drawn.mirror_rasters_ahead().started, 2u);
  EXPECT_EQ(drawn.mirror_rasters_ahead().taken, 0u);

  // A mirror tile above the floor: fewer primary hits than the floor, yet the only mirror rays.
  test::add_triangle(scene, {-1, 0.5f, -1}, {-1, 0.5f, 1}, {1, 0.5f, 1}, 1);
  test::add_triangle(scene, {-1, 0.5f, -1}, {1, 0.5f, 1}, {1, 0.5f, -1}, 1);
  ASSERT_EQ(find_mirror_planes(scene).planes.size(), 2u);
  settings.mirrors = MirrorHits::Raster;
  Renderer tile(*backend, settings);
  FrameTimings t;
  const Image a = tile.render(scene, view, &t);
  ASSERT_GT(t.generations.size(), 1u);
  EXPECT_GT(t.generations[1].rays, 0u) << "the tile reflects";
  EXPECT_EQ(t.generations[1].mirrored, t.generations[1].rays) << "the tile's plane drawn, not the floor's";
  EXPECT_EQ(tile.mirror_rasters_ahead().started, 1u);
  EXPECT_EQ(tile.mirror_rasters_ahead().taken, 0u) << "the floor's raster started ahead and dropped";
  settings.mirrors = MirrorHits::Trace;
  Renderer traced(*backend, settings);
  const ImageDiff d = compare_images(traced.render(scene, view), a, 2.0f / 255.0f);
  EXPECT_LE(d.share_over, 0.005) << "max error " << d.max_error;
}

INSTANTIATE_TEST_SUITE_P(Backends, MirrorRaster, ::testing::Values(Api::Vulkan, Api::Gles), test::api_param_name);

}  // namespace
}  // namespace mobirt
