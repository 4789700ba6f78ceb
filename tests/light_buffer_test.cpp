// The light buffer (src/accel/light_buffer.h) against brute force: every shadow segment's answer
// is the one testing every triangle gives, wherever the light is (outside the scene, inside it, on
// a triangle's plane, inside a triangle) and wherever the segment starts (on a cube edge's
// direction from the light too), at every resolution.
#include <gtest/gtest.h>

#include <algorithm>
#include <memory>
#include <random>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "accel/kdtree.h"
#include "accel/light_buffer.h"
#include "backend/backend.h"
#include "raytree/packing.h"
#include "raytree/rays.h"
#include "render/renderer.h"
#include "scene/loader.h"
#include "test_scenes.h"
#include "test_support.h"
#include "vulkan_fixture.h"

namespace mobirt {
namespace {

// some_lit: some segments must miss every triangle (not so with the light inside one: each segment
// ends on it, and intersect_triangle takes t = 1).
void expect_exact(const Scene& scene, glm::vec3 light, const std::vector<glm::vec3>& origins, int resolution,
                  bool some_lit = true) {
  SCOPED_TRACE("light (" + std::to_string(light.x) + ", " + std::to_string(light.y) + ", " + std::to_string(light.z) +
               "), resolution " + std::to_string(resolution));
  const FlatKdTree tree = build_kdtree(scene.mesh.positions);
  const LightBuffer lb = build_light_buffer(scene.mesh.positions, light, resolution);
  ASSERT_EQ(lb.cells(), size_t(6) * resolution * resolution);
  ASSERT_EQ(lb.first.back(), lb.prims.size());
  for (size_t c = 0; c < lb.cells(); ++c) {  // each list sorted by nearest distance
    for (uint32_t k = lb.first[c] + 1; k < lb.first[c + 1]; ++k) ASSERT_LE(lb.near[k - 1], lb.near[k]);
  }
  size_t occluded = 0;
  for (const glm::vec3& o : origins) {
    const bool expected = test::occluded_by_any(tree, o, light);
    occluded += expected ? 1 : 0;
    ASSERT_EQ(light_buffer_occluded(lb, tree, o), expected)
        << "origin (" << o.x << ", " << o.y << ", " << o.z << ")";
  }
  EXPECT_GT(occluded, origins.size() / 20) << "the segments meet triangles";
  if (some_lit) {
    EXPECT_LT(occluded, origins.size()) << "and miss them";
  }
}

std::vector<glm::vec3> random_points(int count, float extent, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-extent, extent);
  std::vector<glm::vec3> points;
  for (int i = 0; i < count; ++i) points.push_back({u(rng), u(rng), u(rng)});
  return points;
}

// Each entry's part of its cell (LightBuffer::sub) holds every direction of its triangle that falls
// in the cell: the vertices, edge points and inner points of every triangle, from lights outside,
// inside and far from the soup, land in a cell whose list has the triangle, and in its part. And
// the parts skip tests: at 64 cells the segments that end on the triangles read more entries than
// they test.
TEST(LightBuffer, EveryTrianglesDirectionsLieInItsPartOfTheirCell) {
  const Scene soup = test::random_soup_scene(400, 5);
  const std::span<const glm::vec3> p = soup.mesh.positions;
  const FlatKdTree tree = build_kdtree(p);
  const float weights[][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {0.5f, 0.5f, 0}, {0, 0.5f, 0.5f}, {0.5f, 0, 0.5f},
                              {1.0f / 3, 1.0f / 3, 1.0f / 3}, {0.8f, 0.1f, 0.1f}, {0.1f, 0.8f, 0.1f}, {0.1f, 0.1f, 0.8f},
                              {0.999f, 0.001f, 0}, {0, 0.001f, 0.999f}};
  for (const glm::vec3 light : {glm::vec3(0, 0, 0), glm::vec3(2, 1, -1), glm::vec3(0, 40, 0), glm::vec3(30, 30, 30)}) {
    for (int res : {1, 8, 64}) {
      SCOPED_TRACE("light (" + std::to_string(light.x) + ", " + std::to_string(light.y) + ", " +
                   std::to_string(light.z) + "), resolution " + std::to_string(res));
      const LightBuffer lb = build_light_buffer(p, light, res);
      ASSERT_EQ(lb.sub.size(), lb.prims.size());
      constexpr uint32_t S = kLightBufferSubCells;
      size_t full = 0;
      for (const uint32_t part : lb.sub) {
        full += part == light_buffer_sub(0, 0, S - 1, S - 1) ? 1 : 0;
        const uint32_t lo = part % (S * S), hi = part / (S * S);
        ASSERT_LT(hi, S * S);
        ASSERT_LE(lo % S, hi % S);
        ASSERT_LE(lo / S, hi / S);
      }
      if (res == 64) {  // the soup's triangles span several cells: the cells at their edges hold parts
        EXPECT_GT(lb.sub.size() - full, lb.sub.size() / 10) << "entries cover part of their cell";
      }
      uint64_t entries = 0, tests = 0;
      for (uint32_t t = 0; t < p.size() / 3; ++t) {
        for (const auto& w : weights) {
          const glm::vec3 q = w[0] * p[3 * t] + w[1] * p[3 * t + 1] + w[2] * p[3 * t + 2];
          if (glm::length(q - light) < 1e-3f) continue;
          uint32_t sx = 0, sy = 0;
          const uint32_t c = light_buffer_cell(lb, q - light, &sx, &sy);
          ASSERT_NE(c, kLightBufferOutside) << "triangle " << t;
          bool listed = false;
          for (uint32_t k = lb.first[c]; k < lb.first[c + 1] && !listed; ++k) {
            if (lb.prims[k] != t) continue;
            listed = true;
            ASSERT_TRUE(light_buffer_sub_contains(lb.sub[k], sx, sy))
                << "triangle " << t << " point (" << q.x << ", " << q.y << ", " << q.z << ") at " << sx << ", " << sy
                << " outside its part " << lb.sub[k];
          }
          ASSERT_TRUE(listed) << "triangle " << t << " not in the cell of its point";
          // A shadow segment from just in front of the point (towards the light).
          uint32_t e = 0, n = 0;
          light_buffer_occluded(lb, tree, q + 1e-3f * (light - q), &n, &e);
          entries += e;
          tests += n;
        }
      }
      if (res == 64) {
        EXPECT_LT(tests, entries) << "the parts skip tests";
      }
    }
  }
}

TEST(LightBuffer, EveryAnswerIsBruteForcesWhereverTheLightIs) {
  const Scene soup = test::random_soup_scene(600, 3);
  const std::vector<glm::vec3> origins = random_points(3000, 6.0f, 11);
  for (const glm::vec3 light : {glm::vec3(0, 0, 0), glm::vec3(2, 1, -1), glm::vec3(0, 40, 0), glm::vec3(30, 30, 30)}) {
    for (int res : {1, 8, 64}) expect_exact(soup, light, origins, res);
  }
}

// The build on all cores is the serial build's, bit for bit, and each cell's list is in the order of
// nearest distance, ties by triangle index: checked on 12K triangles (past the parallel loops'
// chunks) with every tenth triangle duplicated (equal distances), against lists made here with a
// stable sort.
TEST(LightBuffer, TheSameBufferOnAnyThreadCount) {
  Scene soup = test::random_soup_scene(12000, 21);
  const size_t n = soup.mesh.triangle_count();
  for (size_t t = 0; t < n; t += 10) {
    test::add_triangle(soup, soup.mesh.positions[3 * t], soup.mesh.positions[3 * t + 1], soup.mesh.positions[3 * t + 2], 0);
  }
  const glm::vec3 light(0.5f, 2.0f, -0.25f);
  LightBuffer serial, parallel;
  build_light_buffer(soup.mesh.positions, light, 32, serial, 1);
  build_light_buffer(soup.mesh.positions, light, 32, parallel, 0);
  build_light_buffer(soup.mesh.positions, light, 32, parallel, 0);  // into its own memory again
  for (size_t f = 0; f < 6; ++f) EXPECT_EQ(serial.window[f], parallel.window[f]) << f;
  EXPECT_EQ(serial.first, parallel.first);
  EXPECT_EQ(serial.prims, parallel.prims);
  EXPECT_EQ(serial.near, parallel.near);
  EXPECT_EQ(serial.sub, parallel.sub);
  size_t ties = 0;
  for (size_t c = 0; c < serial.cells(); ++c) {
    std::vector<std::pair<float, uint32_t>> list;
    for (uint32_t k = serial.first[c]; k < serial.first[c + 1]; ++k) list.emplace_back(serial.near[k], serial.prims[k]);
    std::vector<std::pair<float, uint32_t>> sorted = list;
    std::stable_sort(sorted.begin(), sorted.end());  // by distance, then index
    ASSERT_EQ(list, sorted) << "cell " << c;
    for (size_t k = 1; k < list.size(); ++k) ties += list[k].first == list[k - 1].first ? 1 : 0;
  }
  EXPECT_GT(ties, 100u) << "the duplicates give equal distances";
}

// Segments along the cube's edges and corners seen from the light (|x| = |y| and the like), where
// the face the look-up takes and the faces a triangle covers meet.
TEST(LightBuffer, DirectionsOnTheCubesEdgesAndCorners) {
  const Scene soup = test::random_soup_scene(600, 5);
  const glm::vec3 light(0.25f, 0.5f, -0.125f);
  std::vector<glm::vec3> origins;
  for (float a = -6.0f; a <= 6.0f; a += 0.37f) {
    for (float b = -6.0f; b <= 6.0f; b += 1.13f) {
      origins.push_back(light + glm::vec3(a, a, b));
      origins.push_back(light + glm::vec3(a, b, -a));
      origins.push_back(light + glm::vec3(b, a, a));
      origins.push_back(light + glm::vec3(a, a, a));
      origins.push_back(light + glm::vec3(a, -a, a));
    }
  }
  for (int res : {2, 16, 64}) expect_exact(soup, light, origins, res);
}

// ---- In the traversal pass (--shadow-cells), per backend ---------------------------------------

using test::Api;

class LightBufferPass : public test::PerBackendTest {};

// The traversal pass's texels with --shadow-cells N against the walk's on the same rays: the same
// hits, and the same shadow masks on all but a few rays in 10^4 (a triangle that the walk, at a
// leaf's boundary, and the cell's list, decide differently in float). Specialised and general
// passes, every project scene, and two scenes with spot and several lights.
void expect_same_texels(Backend& backend, const Scene& scene, int cells, bool specialize, const std::string& what) {
  SCOPED_TRACE(what + ", " + std::to_string(cells) + " cells" + (specialize ? "" : ", general pass"));
  ASSERT_TRUE(scene.camera);
  RenderSettings settings;
  settings.width = 160;
  settings.height = 96;
  settings.specialize = specialize;
  settings.primary = PrimaryHits::Trace;
  settings.shadow_cells = 0;
  Renderer walk(backend, settings);
  settings.shadow_cells = cells;
  Renderer buffered(backend, settings);
  const FlatKdTree tree = build_kdtree(scene.mesh.positions);
  const RayBatch rays = primary_rays(*scene.camera, settings.width, settings.height);
  const TraceResult a = walk.trace(scene, tree, rays);
  const TraceResult b = buffered.trace(scene, tree, rays);
  EXPECT_EQ(walk.light_buffers_used(), 0);
  const int used = buffered.light_buffers_used();
  ASSERT_EQ(a.packing, b.packing);
  size_t differing = 0, lit = 0, capped = 0;
  for (size_t i = 0; i < rays.count(); ++i) {
    const TraceTexel walked = unpack_trace(a.packing, a.texels[i]), listed = unpack_trace(b.packing, b.texels[i]);
    ASSERT_FALSE(walked.capped) << i;
    // A list longer than the loop cap reports the ray as capped (the CPU traces it): time, not pixels.
    if (listed.capped) {
      ++capped;
      continue;
    }
    differing += a.texels[i] != b.texels[i] ? 1 : 0;
    lit += walked.mask != 0 ? 1 : 0;
  }
  std::printf("[ light buffer ] %s, %d cells, %d lights with one: %zu of %u texels differ, %zu capped, %zu lit\n",
              what.c_str(), cells, used, differing, rays.count(), capped, lit);
  if (cells >= 32) {
    EXPECT_GE(used, 1) << "the buffers were used, not the walk compared with itself";
    EXPECT_GT(lit, rays.count() / 10) << "lights that reach the surfaces";
    EXPECT_EQ(capped, 0u);
  }
  EXPECT_LE(double(differing), 1e-4 * rays.count() + 1.0);
}

TEST_P(LightBufferPass, ShadowMasksAreTheWalks) {
  for (const char* name : {"default", "toaster", "marbles", "fish"}) {
    const Scene scene = load_scene(std::string(MOBIRT_SOURCE_DIR "/scenes/") + name + ".gltf");
    // One cell a face: lists of every triangle a face sees, mostly too long (kLightBufferMaxMeanList):
    // those lights walk; where one is kept, rays past the loop cap go to the CPU as capped.
    // From 64 cells on every scene's light keeps its buffer (the toaster's lists at 32: 108 > 100).
    for (int cells : {1, 64, 96}) expect_same_texels(*backend, scene, cells, true, name);
  }
  expect_same_texels(*backend, test::random_soup_scene(3000, 7), 32, true, "soup with a spot and a point light");
  expect_same_texels(*backend, test::nine_lights_scene(), 32, false, "nine lights");
}

// A directional light walks the tree beside a point light's buffer; a still scene whose light moves
// gets new buffers (the tree kept): the frame equals a fresh renderer's.
TEST_P(LightBufferPass, DirectionalLightsWalkAndMovedLightsRebuild) {
  Scene scene = test::box_grid_scene();
  Light sun;
  sun.type = LightType::Directional;
  sun.direction = glm::normalize(glm::vec3(-0.3f, -1.0f, -0.2f));
  sun.intensity = 0.5f;
  scene.lights.push_back(sun);
  RenderSettings settings;
  settings.width = 96;
  settings.height = 64;
  settings.depth = 0;
  settings.shadow_cells = 32;
  Renderer kept(*backend, settings);
  RenderSettings walking = settings;
  walking.shadow_cells = 0;
  EXPECT_EQ(RenderSettings{}.shadow_cells, -1) << "auto, the default";
  EXPECT_LE(compare_images(kept.render(scene, *scene.camera), Renderer(*backend, walking).render(scene, *scene.camera))
                .share_over,
            0.001);
  ASSERT_NE(scene.lights[0].type, LightType::Directional);
  scene.lights[0].position += glm::vec3(3.0f, 1.0f, -2.0f);
  FrameTimings t;
  const Image moved = kept.render(scene, *scene.camera, &t);
  EXPECT_FALSE(t.tree_rebuilt) << "the triangles did not move";
  const Image fresh = Renderer(*backend, settings).render(scene, *scene.camera);
  EXPECT_EQ(compare_images(moved, fresh).max_error, 0.0f);
}

// With rasterized primaries, no secondary rays and a buffer for every light, the frame builds no
// kd-tree: its image is the walking frame's but for pixels whose centre sits on an edge (the
// rasterizer's triangle stands there, README *Primary hits rasterized*). A directional light
// walks, so its frame has a tree.
TEST_P(LightBufferPass, ShadowFramesWithoutAKdTree) {
  for (const char* name : {"toaster", "marbles", "fish"}) {
    SCOPED_TRACE(name);
    const Scene scene = load_scene(std::string(MOBIRT_SOURCE_DIR "/scenes/") + name + ".gltf");
    RenderSettings settings;
    settings.width = 120;
    settings.height = 72;
    settings.depth = 0;
    settings.primary = PrimaryHits::Raster;
    ASSERT_FALSE(frame_walks_tree(scene, settings));
    Renderer buffered(*backend, settings);
    const Image a = buffered.render(scene, *scene.camera);
    EXPECT_FALSE(buffered.frame_had_kd_tree());
    EXPECT_EQ(buffered.light_buffers_used(), int(scene.lights.size()));
    settings.primary = PrimaryHits::Trace;
    settings.shadow_cells = 0;
    Renderer walk(*backend, settings);
    const ImageDiff d = compare_images(a, walk.render(scene, *scene.camera), 2.0f / 255.0f);
    EXPECT_TRUE(walk.frame_had_kd_tree());
    EXPECT_LE(d.share_over, 0.005);
    EXPECT_GE(d.psnr, 38.0);
  }
  Scene boxes = test::box_grid_scene();  // a point light and the sun
  RenderSettings settings;
  settings.width = 96;
  settings.height = 64;
  settings.depth = 0;
  settings.primary = PrimaryHits::Raster;
  Renderer renderer(*backend, settings);
  renderer.render(boxes, *boxes.camera);
  EXPECT_TRUE(renderer.frame_had_kd_tree()) << "the sun's rays walk";
  EXPECT_EQ(renderer.light_buffers_used(), 1);
}

// A frame planned without a tree builds it after all where a light's buffer is not used (lists
// past kLightBufferMaxMeanList: wide quads stacked over the light, each in every cell of its
// face), and where a list stops a ray at the loop cap (thin slivers whose bounding rectangles
// cover the face: every list holds them all, the rays pass between them), so that the CPU retraces
// it. Each image is the walking frame's.
TEST_P(LightBufferPass, FramesWithoutATreeBuildOneWhereTheyNeedIt) {
  for (const bool slivers : {false, true}) {
    SCOPED_TRACE(slivers ? "slivers, loop cap 16" : "stacked quads");
    Scene s = test::box_grid_scene();
    s.lights.resize(1);  // the point light at (-4, 9, 6)
    const int layers = slivers ? 40 : 120;
    for (int i = 0; i < layers; ++i) {
      const float y = 7.0f + 0.01f * float(i);
      if (slivers) {
        const float x = -9.0f + 0.45f * float(i);
        test::add_triangle(s, {x, y, -4.0f}, {x + 0.02f, y, -4.0f}, {x + 6.0f, y, 15.0f}, 0);
      } else {
        // Above the light (out of the camera's view, shading nothing below): each in every cell
        // of the light's upward face.
        const float above = y + 3.0f;
        test::add_triangle(s, {-30, above, -30}, {30, above, -30}, {30, above, 30}, 0);
        test::add_triangle(s, {-30, above, -30}, {30, above, 30}, {-30, above, 30}, 0);
      }
    }
    RenderSettings settings;
    settings.width = 96;
    settings.height = 64;
    settings.depth = 0;
    settings.primary = PrimaryHits::Raster;
    settings.shadow_cells = 64;
    if (slivers) settings.max_steps = 16;
    ASSERT_FALSE(frame_walks_tree(s, settings));
    Renderer renderer(*backend, settings);
    FrameTimings t;
    const Image a = renderer.render(s, *s.camera, &t);
    EXPECT_TRUE(renderer.frame_had_kd_tree());
    if (slivers) {
      EXPECT_EQ(renderer.light_buffers_used(), 1);
      EXPECT_GT(t.sum.capped, 0u);
    } else {
      EXPECT_EQ(renderer.light_buffers_used(), 0);
    }
    settings.primary = PrimaryHits::Trace;
    settings.shadow_cells = 0;
    settings.max_steps = RenderSettings{}.max_steps;
    const ImageDiff d = compare_images(a, Renderer(*backend, settings).render(s, *s.camera), 2.0f / 255.0f);
    EXPECT_LE(d.share_over, 0.005);
    // The next frame of the still scene keeps the tree it built (uploaded again where a capped ray
    // made it after the upload; its edge misses then walk it), and gives the same image but for
    // those edge pixels.
    FrameTimings next;
    const Image b = renderer.render(s, *s.camera, &next);
    EXPECT_FALSE(next.tree_rebuilt);
    EXPECT_TRUE(renderer.frame_had_kd_tree());
    EXPECT_LE(compare_images(a, b, 2.0f / 255.0f).share_over, 0.005);
  }
}

INSTANTIATE_TEST_SUITE_P(Backends, LightBufferPass, ::testing::Values(Api::Vulkan, Api::Gles), test::api_param_name);

// A light in a triangle's plane, and one inside a triangle: the triangles through the light cover
// whole faces.
TEST(LightBuffer, LightOnATrianglesPlaneAndInsideATriangle) {
  Scene s = test::random_soup_scene(300, 9);
  test::add_triangle(s, {-5, 1, -5}, {5, 1, -5}, {0, 1, 5}, 0);  // the plane y = 1
  const std::vector<glm::vec3> origins = random_points(2000, 6.0f, 13);
  for (int res : {4, 32}) {
    expect_exact(s, {7, 1, 0}, origins, res);    // in the plane, outside the triangle
    expect_exact(s, {0, 1, 0}, origins, res, false);  // inside the triangle: every segment ends on it
  }
}

// The nearest distance is a lower bound of every point's, and reached: checked against points
// sampled on triangles.
TEST(LightBuffer, PointTriangleDistance) {
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> u(-3.0, 3.0), w(0.0, 1.0);
  for (int i = 0; i < 2000; ++i) {
    const glm::dvec3 p(u(rng), u(rng), u(rng)), a(u(rng), u(rng), u(rng)), b(u(rng), u(rng), u(rng)),
        c(u(rng), u(rng), u(rng));
    const double d = point_triangle_distance(p, a, b, c);
    double sampled = 1e300;
    for (int k = 0; k < 400; ++k) {
      double x = w(rng), y = w(rng);
      if (x + y > 1.0) x = 1.0 - x, y = 1.0 - y;
      sampled = std::min(sampled, glm::length(p - (a + (b - a) * x + (c - a) * y)));
    }
    for (const glm::dvec3& v : {a, b, c}) sampled = std::min(sampled, glm::length(p - v));
    ASSERT_LE(d, sampled + 1e-9) << i;
    ASSERT_GE(d, sampled - 0.35) << i << ": a loose check that it is reached, from 400 samples";
  }
  EXPECT_DOUBLE_EQ(point_triangle_distance({0, 1, 0}, {-1, 0, -1}, {1, 0, -1}, {0, 0, 1}), 1.0);  // above the inside
  EXPECT_DOUBLE_EQ(point_triangle_distance({0, 0, 2}, {-1, 0, -1}, {1, 0, -1}, {0, 0, 1}), 1.0);  // past a vertex
}

}  // namespace
}  // namespace mobirt
