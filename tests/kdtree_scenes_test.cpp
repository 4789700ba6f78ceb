// kd-tree on real data (../shared/scenes): the Utah toasters and SPD scenes, read with
// tinyobjloader directly so that this test does not depend on the scene loader. Every traversal
// variant must agree with brute force on camera-like and random rays; skips when the data is absent.
#include <gtest/gtest.h>
#include <tiny_obj_loader.h>

#include <glm/glm.hpp>

#include <chrono>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "accel/kdtree.h"
#include "test_support.h"

namespace mobirt {
namespace {

using test::random_direction;

std::vector<glm::vec3> load_obj_triangles(const std::filesystem::path& path) {
  tinyobj::ObjReader reader;
  tinyobj::ObjReaderConfig config;
  config.triangulate = true;
  config.mtl_search_path = path.parent_path().string();
  EXPECT_TRUE(reader.ParseFromFile(path.string(), config)) << reader.Error();
  std::vector<glm::vec3> positions;
  const std::vector<tinyobj::real_t>& v = reader.GetAttrib().vertices;
  for (const tinyobj::shape_t& shape : reader.GetShapes()) {
    size_t index = 0;
    for (const unsigned char count : shape.mesh.num_face_vertices) {
      if (count == 3) {
        for (size_t k = 0; k < 3; ++k) {
          const size_t i = size_t(shape.mesh.indices[index + k].vertex_index);
          positions.emplace_back(v[3 * i], v[3 * i + 1], v[3 * i + 2]);
        }
      }
      index += count;
    }
  }
  return positions;
}

bool same_hit(const Hit& a, const Hit& b) {
  if (a.prim == b.prim) return !a.valid() || a.t == b.t;
  if (!a.valid() || !b.valid()) return false;
  return std::abs(a.t - b.t) <= 1e-4f * std::max(1.0f, std::abs(a.t));  // a near-tie
}

// Half camera rays (a pinhole outside the scene looking at its centre, 100 x 100 jittered
// pixels, from 4 viewpoints), half random rays from inside the scene box and from its surfaces.
std::vector<Ray> scene_rays(const FlatKdTree& tree, const std::vector<glm::vec3>& positions,
                            unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  const Aabb& box = tree.bounds;
  const glm::vec3 c = box.center();
  const float radius = 0.5f * glm::length(box.extent());
  std::vector<Ray> rays;
  for (int view = 0; view < 4; ++view) {
    const glm::vec3 eye = c + 1.6f * radius * random_direction(rng);
    const glm::vec3 forward = glm::normalize(c - eye);
    const glm::vec3 helper = std::abs(forward.y) < 0.9f ? glm::vec3(0, 1, 0) : glm::vec3(1, 0, 0);
    const glm::vec3 right = glm::normalize(glm::cross(forward, helper));
    const glm::vec3 up = glm::cross(right, forward);
    for (int y = 0; y < 50; ++y) {
      for (int x = 0; x < 50; ++x) {
        const float sx = (float(x) + u(rng)) / 50.0f * 2.0f - 1.0f;
        const float sy = (float(y) + u(rng)) / 50.0f * 2.0f - 1.0f;
        Ray ray;
        ray.origin = eye;
        ray.direction = glm::normalize(forward + 0.7f * (sx * right + sy * up));
        rays.push_back(ray);
      }
    }
  }
  const size_t prims = positions.size() / 3;
  for (int i = 0; i < 10000; ++i) {
    Ray ray;
    if (i % 2 == 0) {
      ray.origin = box.lo + box.extent() * glm::vec3(u(rng), u(rng), u(rng));
    } else {  // from a surface (secondary rays)
      const glm::vec3* v = &positions[3 * (size_t(u(rng) * float(prims)) % prims)];
      float a = u(rng), b = u(rng);
      if (a + b > 1.0f) {
        a = 1.0f - a;
        b = 1.0f - b;
      }
      ray.origin = v[0] + a * (v[1] - v[0]) + b * (v[2] - v[0]);
      ray.tmin = 1e-4f * radius;
    }
    ray.direction = random_direction(rng);
    if (i % 7 == 0) {  // axis-aligned
      ray.direction = glm::vec3(0.0f);
      ray.direction[i % 3] = i % 2 ? 1.0f : -1.0f;
    }
    rays.push_back(ray);
  }
  return rays;
}

void check_scene(const std::filesystem::path& path, size_t expected_triangles, const KdBuildOptions& options = {}) {
  const std::vector<glm::vec3> positions = load_obj_triangles(path);
  ASSERT_EQ(positions.size() / 3, expected_triangles) << path;
  const auto start = std::chrono::steady_clock::now();
  const FlatKdTree tree = build_kdtree(positions, options);
  const double ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  const KdBuildStats& s = tree.stats;
  std::printf("%s, %s build: %zu triangles, build %.1f ms, %zu nodes, %zu leaves (%zu empty), "
              "%.2f refs/triangle, depth %d/%d, largest leaf %zu, SAH %.1f\n",
              path.filename().c_str(), kd_build_mode_name(options.build), expected_triangles, ms, s.nodes, s.leaves, s.empty_leaves,
              double(s.prim_references) / double(expected_triangles), s.max_depth_reached,
              tree.max_depth, s.max_leaf_size, s.sah_cost);

  const std::vector<Ray> rays = scene_rays(tree, positions, 1234);
  ASSERT_GE(rays.size(), 10000u);
  int failures = 0;
  size_t hits = 0;
  size_t checked = 0;
  for (size_t i = 0; i < rays.size(); i += test::sanitizer_stride(8)) {
    const Ray& ray = rays[i];
    ++checked;
    const Hit expected = brute_force(tree, ray);
    hits += expected.valid();
    for (int depth : {-1, 0, 1, 2, 4, 8}) {
      const Hit got = traverse(tree, ray, depth);
      if (!same_hit(got, expected) && ++failures <= 5) {
        ADD_FAILURE() << "stack " << depth << ": o=(" << ray.origin.x << "," << ray.origin.y << ","
                      << ray.origin.z << ") d=(" << ray.direction.x << "," << ray.direction.y
                      << "," << ray.direction.z << ") kd " << got.prim << " t " << got.t
                      << ", brute force " << expected.prim << " t " << expected.t;
      }
    }
    Ray segment = ray;
    if (expected.valid()) segment.tmax = ray.tmin + (expected.t - ray.tmin) * (ray.tmin > 0 ? 0.5f : 2.0f);
    const bool blocked = brute_force(tree, segment).valid();
    for (int depth : {-1, 0, 4}) {
      if (occluded(tree, segment, depth) != blocked && ++failures <= 5) {
        ADD_FAILURE() << "occluded, stack " << depth << " disagrees with brute force";
      }
    }
  }
  EXPECT_EQ(failures, 0);
  EXPECT_GT(hits, checked / 10) << "the rays should hit the scene";
}

TEST(KdTreeScenes, UtahToasters) {
  MOBIRT_REQUIRE_SHARED(path, "utah-toasters/Toasters004.obj");
  check_scene(path, 11141);
  KdBuildOptions quality;
  quality.build = KdBuildMode::Quality;
  check_scene(path, 11141, quality);
}

TEST(KdTreeScenes, FastBuildKeepsTheSahCost) {
  // --build fast clips more loosely than quality; on real data the looser clip must cost about the
  // same (measured 897.3 against 893.0 with leaves of 1 and no cluster rule: fast's leaf size of 3
  // and cluster rule trade SAH cost for build time by design,
  // KdTree.FastLeafSizeMakesFewerNodesAndStaysExact, KdTree.ClusterRuleKeepsVertexFans...).
  MOBIRT_REQUIRE_SHARED(path, "utah-toasters/Toasters004.obj");
  const std::vector<glm::vec3> positions = load_obj_triangles(path);
  KdBuildOptions quality;
  quality.build = KdBuildMode::Quality;
  KdBuildOptions fast;
  fast.build = KdBuildMode::Fast;
  fast.max_leaf_prims = 1;
  fast.cluster_refs = 0;
  const double quality_cost = build_kdtree(positions, quality).stats.sah_cost;
  const double fast_cost = build_kdtree(positions, fast).stats.sah_cost;
  std::printf("toasters SAH: quality %.1f, fast %.1f\n", quality_cost, fast_cost);
  EXPECT_LE(fast_cost, 1.05 * quality_cost);
}

TEST(KdTreeScenes, SpdTeapot) {
  MOBIRT_REQUIRE_SHARED(path, "spd/teapot_s2.obj");
  check_scene(path, 248);  // 244 faces, some of them quads
}

TEST(KdTreeScenes, SpdGears) {
  // Concave 144-gons, triangulated by tinyobjloader: coplanar, axis-aligned geometry.
  MOBIRT_REQUIRE_SHARED(path, "spd/gears_s1.obj");
  const std::vector<glm::vec3> positions = load_obj_triangles(path);
  ASSERT_GT(positions.size(), 0u);
  check_scene(path, positions.size() / 3);
}

TEST(KdTreeScenes, SahWithMoreBinsIsNotWorse) {
  MOBIRT_REQUIRE_SHARED(path, "utah-toasters/Toasters004.obj");
  const std::vector<glm::vec3> positions = load_obj_triangles(path);
  // pbrt's empty bonus (any empty slab) makes the greedy SAH cut thin empty slabs off walls until
  // the depth limit, so with it more bins can score worse (measured 893 at 32 bins, 725 at 4).
  // With the bonus kept for slabs of at least 5% of the node, more bins must not be worse.
  for (float min_width : {0.0f, 0.05f}) {
    KdBuildOptions four;
    four.bins = 4;
    four.empty_bonus_min_width = min_width;
    KdBuildOptions many = four;
    many.bins = 32;
    const double cost4 = build_kdtree(positions, four).stats.sah_cost;
    const double cost32 = build_kdtree(positions, many).stats.sah_cost;
    std::printf("toasters SAH, empty bonus min width %.2f: 4 bins %.1f, 32 bins %.1f\n",
                double(min_width), cost4, cost32);
    if (min_width > 0.0f) {
      EXPECT_LE(cost32, cost4);
    }
  }
  // Split clipping makes a tighter tree: fewer references, lower cost.
  KdBuildOptions no_clip;
  no_clip.split_clipping = false;
  const FlatKdTree plain = build_kdtree(positions, no_clip);
  const FlatKdTree clipped = build_kdtree(positions);
  EXPECT_LT(clipped.stats.prim_references, plain.stats.prim_references);
  EXPECT_LT(clipped.stats.sah_cost, plain.stats.sah_cost);
}

}  // namespace
}  // namespace mobirt
