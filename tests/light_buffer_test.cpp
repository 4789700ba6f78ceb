// The light buffer (src/accel/light_buffer.h) against brute force: every shadow segment's answer
// is the one testing every triangle gives, wherever the light is (outside the scene, inside it, on
// a triangle's plane, inside a triangle) and wherever the segment starts (on a cube edge's
// direction from the light too), at every resolution.
#include <gtest/gtest.h>

#include <random>

#include "accel/kdtree.h"
#include "accel/light_buffer.h"
#include "test_scenes.h"

namespace mobirt {
namespace {

// Any triangle of `tree` that the segment origin -> light meets (the light buffer's predicate,
// intersect_triangle, on every triangle).
bool occluded_by_any(const FlatKdTree& tree, glm::vec3 origin, glm::vec3 light) {
  const Ray ray{origin, light - origin, 0.0f, 1.0f};
  const int32_t n = int32_t(tree.triangles.size() / MOBIRT_TEXELS_PER_TRIANGLE);
  for (int32_t t = 0; t < n; ++t) {
    Hit h;
    if (intersect_triangle(tree, t, ray, h)) return true;
  }
  return false;
}

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
    const bool expected = occluded_by_any(tree, o, light);
    occluded += expected ? 1 : 0;
    ASSERT_EQ(light_buffer_occluded(lb, tree, o), expected)
        << "origin (" << o.x << ", " << o.y << ", " << o.z << ")";
  }
  EXPECT_GT(occluded, origins.size() / 20) << "the segments meet triangles";
  if (some_lit) EXPECT_LT(occluded, origins.size()) << "and miss them";
}

std::vector<glm::vec3> random_points(int count, float extent, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-extent, extent);
  std::vector<glm::vec3> points;
  for (int i = 0; i < count; ++i) points.push_back({u(rng), u(rng), u(rng)});
  return points;
}

TEST(LightBuffer, EveryAnswerIsBruteForcesWhereverTheLightIs) {
  const Scene soup = test::random_soup_scene(600, 3);
  const std::vector<glm::vec3> origins = random_points(3000, 6.0f, 11);
  for (const glm::vec3 light : {glm::vec3(0, 0, 0), glm::vec3(2, 1, -1), glm::vec3(0, 40, 0), glm::vec3(30, 30, 30)}) {
    for (int res : {1, 8, 64}) expect_exact(soup, light, origins, res);
  }
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
