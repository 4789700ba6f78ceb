// kd-tree build, flattening and CPU traversal on generated scenes: every traversal variant
// (full stack, kd-restart, short stacks) must agree with brute force, for every build option.
#include <gtest/gtest.h>

#include <glm/glm.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <functional>
#include <limits>
#include <random>
#include <span>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "accel/kdtree.h"
#include "accel/kdtree_clip.h"
#include "core/camera.h"
#include "test_scenes.h"
#include "test_support.h"
#include "core/error.h"
#include "layout.h"
#include "texels.h"

namespace mobirt {
namespace {

using test::random_direction;

using Positions = std::vector<glm::vec3>;

// ---- Scenes ------------------------------------------------------------------------------------

void add_triangle(Positions& p, glm::vec3 a, glm::vec3 b, glm::vec3 c) {
  p.push_back(a);
  p.push_back(b);
  p.push_back(c);
}

void add_quad(Positions& p, glm::vec3 a, glm::vec3 b, glm::vec3 c, glm::vec3 d) {
  add_triangle(p, a, b, c);
  add_triangle(p, a, c, d);
}

void add_box(Positions& p, glm::vec3 lo, glm::vec3 hi) {
  const glm::vec3 v[8] = {{lo.x, lo.y, lo.z}, {hi.x, lo.y, lo.z}, {hi.x, hi.y, lo.z},
                          {lo.x, hi.y, lo.z}, {lo.x, lo.y, hi.z}, {hi.x, lo.y, hi.z},
                          {hi.x, hi.y, hi.z}, {lo.x, hi.y, hi.z}};
  add_quad(p, v[0], v[1], v[2], v[3]);
  add_quad(p, v[4], v[5], v[6], v[7]);
  add_quad(p, v[0], v[1], v[5], v[4]);
  add_quad(p, v[3], v[2], v[6], v[7]);
  add_quad(p, v[0], v[3], v[7], v[4]);
  add_quad(p, v[1], v[2], v[6], v[5]);
}

Positions random_soup(int n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  Positions p;
  for (int i = 0; i < n; ++i) {
    const glm::vec3 c(u(rng) * 10.0f, u(rng) * 10.0f, u(rng) * 10.0f);
    const float size = 0.1f + 1.5f * u(rng) * u(rng);
    for (int k = 0; k < 3; ++k) {
      p.push_back(c + size * glm::vec3(u(rng) - 0.5f, u(rng) - 0.5f, u(rng) - 0.5f));
    }
  }
  return p;
}

// A floor of unit quads at integer coordinates with axis-aligned boxes on it (integer corners):
// split planes land exactly on the geometry, and axis-aligned rays run along faces.
Positions grid_with_boxes() {
  Positions p;
  for (int x = 0; x < 16; ++x) {
    for (int z = 0; z < 16; ++z) {
      const float fx = float(x), fz = float(z);
      add_quad(p, {fx, 0, fz}, {fx + 1, 0, fz}, {fx + 1, 0, fz + 1}, {fx, 0, fz + 1});
    }
  }
  for (int i = 0; i < 12; ++i) {
    const float x = float((i * 5) % 14), z = float((i * 7) % 13);
    add_box(p, {x, 0, z}, {x + 1 + float(i % 3), 1 + float(i % 4), z + 1 + float(i % 2)});
  }
  add_box(p, {4, 2, 4}, {8, 3, 8});  // floating box
  return p;
}

Positions long_thin(unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  Positions p;
  for (int i = 0; i < 600; ++i) {
    const int axis = i % 3;
    glm::vec3 a(u(rng) * 10.0f, u(rng) * 10.0f, u(rng) * 10.0f);
    glm::vec3 b = a;
    a[axis] = 0.0f;
    b[axis] = 10.0f;
    const glm::vec3 c = a + 0.02f * glm::vec3(u(rng), u(rng), u(rng));
    add_triangle(p, a, b, c);
  }
  return p;
}

// Everything in the plane z = 1 (the scene box is flat).
Positions planar(unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  Positions p;
  for (int i = 0; i < 800; ++i) {
    const glm::vec3 c(u(rng) * 10.0f, u(rng) * 10.0f, 1.0f);
    add_triangle(p, c, c + glm::vec3(u(rng), u(rng) * 0.5f, 0.0f),
                 c + glm::vec3(-0.5f * u(rng), u(rng), 0.0f));
  }
  return p;
}

// Many coincident triangles (the same triangle 200 times, a quad 50 times), overlapping coplanar
// ones and some degenerate (zero-area) ones.
Positions duplicates(unsigned seed) {
  Positions p;
  for (int i = 0; i < 200; ++i) add_triangle(p, {0, 0, 0}, {2, 0, 0}, {0, 2, 1});
  for (int i = 0; i < 50; ++i) add_quad(p, {-1, -1, 3}, {3, -1, 3}, {3, 3, 3}, {-1, 3, 3});
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (int i = 0; i < 100; ++i) {
    const glm::vec3 c(u(rng) * 3.0f, u(rng) * 3.0f, 2.0f);
    add_triangle(p, c, c + glm::vec3(1, 0, 0), c + glm::vec3(0, 1, 0));
  }
  for (int i = 0; i < 20; ++i) {
    const glm::vec3 c(u(rng) * 3.0f, u(rng) * 3.0f, u(rng) * 3.0f);
    add_triangle(p, c, c, c + glm::vec3(1, 1, 1));           // a segment
    add_triangle(p, c, c + glm::vec3(1, 0, 0), c + glm::vec3(2, 0, 0));  // collinear
  }
  return p;
}

Positions one_triangle() { return {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}; }

// A height field of n x n quads, two triangles each, every inner vertex shared by 6 triangles as
// in most real meshes (a vertex's fan is what cluster_refs keeps together).
Positions terrain(int n) {
  const auto vertex = [n](int i, int j) {
    const float x = float(i) / float(n) * 10.0f, z = float(j) / float(n) * 10.0f;
    return glm::vec3(x, std::sin(x) * std::cos(0.7f * z) + 0.3f * std::sin(2.3f * x + z), z);
  };
  Positions p;
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      add_triangle(p, vertex(i, j), vertex(i + 1, j), vertex(i + 1, j + 1));
      add_triangle(p, vertex(i, j), vertex(i + 1, j + 1), vertex(i, j + 1));
    }
  }
  return p;
}

struct NamedScene {
  std::string name;
  Positions positions;
};

std::vector<NamedScene> all_scenes() {
  return {{"soup", random_soup(2000, 1)},   {"grid_boxes", grid_with_boxes()},
          {"long_thin", long_thin(2)},      {"planar", planar(3)},
          {"duplicates", duplicates(4)},    {"one_triangle", one_triangle()},
          {"empty", {}}};
}

// ---- Rays --------------------------------------------------------------------------------------

// Split planes of the tree, to start rays on them.
struct Plane {
  int axis;
  float s;
};
std::vector<Plane> split_planes(const FlatKdTree& tree) {
  std::vector<Plane> planes;
  for (const glm::vec4& n : tree.nodes) {
    if (n.z != float(MOBIRT_NODE_LEAF)) planes.push_back({int(n.z), n.x});
  }
  return planes;
}

// A mix: random rays from around and inside the scene, rays aimed at triangles, axis-aligned
// rays (also from integer coordinates), rays starting on split planes, rays lying in split
// planes, directions with zero (and negative-zero) components, finite [tmin, tmax] intervals.
std::vector<Ray> make_rays(const FlatKdTree& tree, const Positions& positions, int count,
                           unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  Aabb box = tree.bounds;
  if (box.empty()) box = Aabb{glm::vec3(-1.0f), glm::vec3(1.0f)};
  const glm::vec3 lo = box.lo - 0.1f * (box.extent() + glm::vec3(1.0f));
  const glm::vec3 hi = box.hi + 0.1f * (box.extent() + glm::vec3(1.0f));
  const float radius = glm::length(box.extent()) + 1.0f;
  const auto inside = [&] { return lo + (hi - lo) * glm::vec3(u(rng), u(rng), u(rng)); };
  const auto target = [&]() -> glm::vec3 {
    if (!positions.empty() && u(rng) < 0.7f) {
      const size_t tri = size_t(u(rng) * float(positions.size() / 3)) % (positions.size() / 3);
      float a = u(rng), b = u(rng);
      if (a + b > 1.0f) {
        a = 1.0f - a;
        b = 1.0f - b;
      }
      const glm::vec3* v = &positions[3 * tri];
      return v[0] + a * (v[1] - v[0]) + b * (v[2] - v[0]);
    }
    return inside();
  };
  const std::vector<Plane> planes = split_planes(tree);
  std::vector<Ray> rays;
  rays.reserve(size_t(count));
  for (int i = 0; i < count; ++i) {
    Ray ray;
    const int kind = i % 10;
    if (kind <= 2) {  // from outside, aimed at the scene
      ray.origin = box.center() + radius * random_direction(rng);
      ray.direction = glm::normalize(target() - ray.origin);
    } else if (kind == 3) {  // from inside, any direction
      ray.origin = inside();
      ray.direction = random_direction(rng);
    } else if (kind == 4) {  // axis-aligned, origin on integers half of the time
      ray.origin = inside();
      if (i % 20 == 4) ray.origin = glm::floor(ray.origin);
      ray.direction = glm::vec3(0.0f);
      ray.direction[int(u(rng) * 3.0f) % 3] = u(rng) < 0.5f ? 1.0f : -1.0f;
    } else if (kind == 5) {  // zero components (one or two), signed zeros
      ray.origin = inside();
      ray.direction = glm::normalize(target() - ray.origin);
      const int a = int(u(rng) * 3.0f) % 3;
      ray.direction[a] = u(rng) < 0.5f ? 0.0f : -0.0f;
      if (u(rng) < 0.3f) ray.direction[(a + 1) % 3] = -0.0f;
      if (glm::length(ray.direction) == 0.0f) ray.direction[(a + 2) % 3] = 1.0f;
    } else if (kind == 6 && !planes.empty()) {  // starting on a split plane
      const Plane pl = planes[size_t(u(rng) * float(planes.size())) % planes.size()];
      ray.origin = target();
      ray.origin[pl.axis] = pl.s;
      ray.direction = random_direction(rng);
    } else if (kind == 7 && !planes.empty()) {  // lying in a split plane
      const Plane pl = planes[size_t(u(rng) * float(planes.size())) % planes.size()];
      ray.origin = inside();
      ray.origin[pl.axis] = pl.s;
      ray.direction = random_direction(rng);
      ray.direction[pl.axis] = u(rng) < 0.5f ? 0.0f : -0.0f;
      if (u(rng) < 0.3f) {  // and axis-aligned
        ray.direction = glm::vec3(0.0f);
        ray.direction[(pl.axis + 1) % 3] = u(rng) < 0.5f ? 1.0f : -1.0f;
      }
    } else if (kind == 8) {  // a finite interval, possibly starting inside the scene
      ray.origin = box.center() + radius * random_direction(rng);
      ray.direction = target() - ray.origin;  // not normalised: t in [0, 1] reaches the target
      ray.tmin = 0.5f * u(rng);
      ray.tmax = ray.tmin + 1.5f * u(rng);
    } else {  // from a triangle's surface outwards (secondary rays)
      ray.origin = target();
      ray.direction = random_direction(rng);
      ray.tmin = 1e-4f;
    }
    rays.push_back(ray);
  }
  return rays;
}

// ---- Comparison --------------------------------------------------------------------------------

bool same_hit(const Hit& a, const Hit& b) {
  if (a.prim == b.prim) return !a.valid() || a.t == b.t;
  if (!a.valid() || !b.valid()) return false;
  return std::abs(a.t - b.t) <= 1e-4f * std::max(1.0f, std::abs(a.t));  // a near-tie
}

std::string describe(const Ray& r) {
  std::ostringstream s;
  s.precision(9);
  s << "o=(" << r.origin.x << "," << r.origin.y << "," << r.origin.z << ") d=(" << r.direction.x
    << "," << r.direction.y << "," << r.direction.z << ") t=[" << r.tmin << "," << r.tmax << "]";
  return s.str();
}

constexpr int kStackDepths[] = {-1, 0, 1, 2, 4, 8};

// Traversal with every stack depth against brute force; occlusion on segments.
// Returns the number of disagreements (and reports the first few).
int check_rays(const FlatKdTree& tree, const std::vector<Ray>& rays, const std::string& what) {
  int failures = 0;
  for (const Ray& ray : rays) {
    const Hit expected = brute_force(tree, ray);
    for (int depth : kStackDepths) {
      TraversalStats stats;
      const Hit got = traverse(tree, ray, depth, stats);
      EXPECT_EQ(stats.capped, 0u);
      if (!same_hit(got, expected)) {
        if (++failures <= 5) {
          ADD_FAILURE() << what << " stack " << depth << ": " << describe(ray) << " kd prim "
                        << got.prim << " t " << got.t << ", brute force prim " << expected.prim
                        << " t " << expected.t;
        }
      }
    }
    // Shadow segments: the same ray, cut short before, across or after the closest hit.
    Ray segment = ray;
    if (expected.valid()) {
      const float span = expected.t - ray.tmin;
      static const float kFractions[] = {0.5f, 0.999f, 1.001f, 2.0f};
      segment.tmax = ray.tmin + span * kFractions[size_t(std::abs(expected.prim)) % 4];
    }
    const bool blocked = brute_force(tree, segment).valid();
    for (int depth : {-1, 0, 2}) {
      if (occluded(tree, segment, depth) != blocked) {
        if (++failures <= 5) {
          ADD_FAILURE() << what << " occluded, stack " << depth << ": " << describe(segment)
                        << " expected " << blocked;
        }
      }
    }
  }
  return failures;
}

// ---- Layout checks -----------------------------------------------------------------------------

bool boxes_touch(const Aabb& a, const Aabb& b) {
  return a.lo.x <= b.hi.x && b.lo.x <= a.hi.x && a.lo.y <= b.hi.y && b.lo.y <= a.hi.y &&
         a.lo.z <= b.hi.z && b.lo.z <= a.hi.z;
}

// Walks the flattened tree from the root box and checks every texel.
void check_layout(const FlatKdTree& tree, const Positions& positions,
                  const KdBuildOptions& options = {}) {
  const size_t prims = positions.size() / 3;
  ASSERT_EQ(tree.triangles.size(), prims * MOBIRT_TEXELS_PER_TRIANGLE);
  for (size_t i = 0; i < positions.size(); ++i) {
    ASSERT_EQ(glm::vec3(tree.triangles[i]), positions[i]);
    ASSERT_EQ(tree.triangles[i].w, 0.0f);
  }
  ASSERT_FALSE(tree.nodes.empty());
  ASSERT_LE(tree.nodes.size(), kKdIndexLimit);
  ASSERT_EQ(tree.leaf_prims.size() % MOBIRT_TEXELS_PER_TRIANGLE, 0u);
  ASSERT_LE(tree.leaf_prims.size(), kKdIndexLimit);
  std::vector<int> visits(tree.nodes.size(), 0);
  std::vector<int> referenced(prims, 0);
  size_t leaves = 0, empty_leaves = 0, references = 0, max_leaf = 0, list_entries = 0;
  int max_depth = 0;
  double cost = 0.0;
  struct Item {
    size_t node;
    Aabb box;
    int depth;
  };
  std::vector<Item> todo = {{0, tree.bounds, 0}};
  while (!todo.empty()) {
    const Item item = todo.back();
    todo.pop_back();
    ASSERT_LT(item.node, tree.nodes.size());
    ++visits[item.node];
    const glm::vec4 n = tree.nodes[item.node];
    max_depth = std::max(max_depth, item.depth);
    const double area = item.box.surface_area();
    if (n.z == float(MOBIRT_NODE_LEAF)) {
      EXPECT_EQ(n.w, 0.0f);
      ++leaves;
      const size_t count = size_t(n.y);
      ASSERT_EQ(float(count), n.y);
      references += count;
      max_leaf = std::max(max_leaf, count);
      cost += options.intersection_cost * double(count) * area;
      if (count == 0) {
        ++empty_leaves;
        EXPECT_EQ(n.x, 0.0f);
      }
      std::vector<size_t> leaf;
      if (count > 0) {
        // Every leaf's entries: a copy of each primitive's texels with its index in them.
        ASSERT_EQ(float(size_t(n.x)), n.x);
        ASSERT_LE(size_t(n.x) + count, tree.leaf_entries());
        list_entries += count;
        for (size_t i = 0; i < count; ++i) {
          const size_t entry = size_t(n.x) + i;
          const int32_t prim = tree.leaf_prim(entry);
          ASSERT_GE(prim, 0);
          ASSERT_LT(size_t(prim), prims);
          const glm::vec4* copy = leaf_prim_texel::of(tree.leaf_prims, entry);
          const glm::vec4* original = triangle_texel::of(tree.triangles, prim);
          for (int k = 0; k < MOBIRT_TEXELS_PER_TRIANGLE; ++k) {
            ASSERT_EQ(glm::vec3(copy[k]), glm::vec3(original[k])) << "entry " << entry << " texel " << k;
          }
          ASSERT_EQ(copy[0].w, original[0].w) << "entry " << entry << ": the primitive's kind";
          leaf.push_back(size_t(prim));
        }
      }
      for (size_t i = 0; i < leaf.size(); ++i) {
        ASSERT_LT(leaf[i], prims);
        if (i > 0) {
          EXPECT_LT(leaf[i - 1], leaf[i]) << "leaf lists are sorted and unique";
        }
        ++referenced[leaf[i]];
        Aabb tri;
        for (int k = 0; k < 3; ++k) tri.extend(positions[3 * leaf[i] + k]);
        EXPECT_TRUE(boxes_touch(tri, item.box)) << "prim " << leaf[i] << " in a leaf it misses";
      }
      continue;
    }
    cost += options.traversal_cost * area;
    const int axis = int(n.z);
    ASSERT_TRUE(axis >= 0 && axis <= 2);
    const size_t above = size_t(n.y);
    ASSERT_EQ(float(above), n.y);
    ASSERT_GT(above, item.node + 1);
    ASSERT_LT(above, tree.nodes.size());
    // Empty-child flags: exactly the children that are leaves without primitives.
    auto empty_leaf = [&](size_t i) { return tree.nodes[i].z == float(MOBIRT_NODE_LEAF) && tree.nodes[i].y == 0.0f; };
    EXPECT_EQ(n.w, (empty_leaf(item.node + 1) ? MOBIRT_NODE_BELOW_EMPTY : 0.0f) +
                       (empty_leaf(above) ? MOBIRT_NODE_ABOVE_EMPTY : 0.0f));
    EXPECT_GT(n.x, item.box.lo[axis]);
    EXPECT_LT(n.x, item.box.hi[axis]);
    Aabb below_box = item.box, above_box = item.box;
    below_box.hi[axis] = n.x;
    above_box.lo[axis] = n.x;
    todo.push_back({above, above_box, item.depth + 1});
    todo.push_back({item.node + 1, below_box, item.depth + 1});
  }
  for (size_t i = 0; i < visits.size(); ++i) ASSERT_EQ(visits[i], 1) << "node " << i;
  const KdBuildStats& s = tree.stats;
  EXPECT_EQ(s.nodes, tree.nodes.size());
  EXPECT_EQ(s.leaves, leaves);
  EXPECT_EQ(s.empty_leaves, empty_leaves);
  EXPECT_EQ(s.prim_references, references);
  EXPECT_EQ(s.max_leaf_size, max_leaf);
  EXPECT_EQ(s.max_depth_reached, max_depth);
  EXPECT_LE(max_depth, tree.max_depth);
  EXPECT_EQ(tree.leaf_entries(), list_entries);  // nothing but the leaves' entries
  const double root_area = tree.bounds.surface_area();
  if (root_area > 0.0) {
    EXPECT_NEAR(s.sah_cost, cost / root_area, 1e-3 * (1.0 + s.sah_cost));
  }
  // Every triangle with an area is referenced somewhere.
  for (size_t i = 0; i < prims; ++i) {
    const glm::vec3* v = &positions[3 * i];
    if (glm::length(glm::cross(v[1] - v[0], v[2] - v[0])) > 0.0f) {
      EXPECT_GT(referenced[i], 0) << "prim " << i << " is in no leaf";
    }
  }
}

// ---- Tests -------------------------------------------------------------------------------------

TEST(KdTree, TraversalMatchesBruteForceOnGeneratedScenes) {
  unsigned seed = 100;
  for (const NamedScene& scene : all_scenes()) {
    SCOPED_TRACE(scene.name);
    const FlatKdTree tree = build_kdtree(scene.positions);
    check_layout(tree, scene.positions);
    const std::vector<Ray> rays = make_rays(tree, scene.positions, 10000 / test::sanitizer_stride(8), seed++);
    EXPECT_EQ(check_rays(tree, rays, scene.name), 0);
  }
}

// Nodes of 8,192 references or more choose their plane from a sample of them: the 40,000-triangle
// soup's top levels do, and the tree must still hold every triangle and traverse exactly. In the
// clustered soup, 2,000 triangles far from a cluster of 30,000 make a child much smaller than its
// sample's stride expected, which is binned again in full; the tree is the same for any thread
// count.
TEST(KdTree, SampledBinningOfLargeNodesTraversesCorrectly) {
  Positions clustered = random_soup(30000, 45);
  for (const glm::vec3& p : random_soup(2000, 46)) {
    clustered.push_back(p * glm::vec3(1.0f, 1.0f, 0.1f) + glm::vec3(0.0f, 0.0f, 40.0f));
  }
  const std::vector<NamedScene> scenes = {{"soup 40000", random_soup(40000, 41)}, {"clustered", clustered}};
  for (const NamedScene& scene : scenes) {
    for (KdBuildMode mode : {KdBuildMode::Quality, KdBuildMode::Fast}) {
      SCOPED_TRACE(scene.name + " " + kd_build_mode_name(mode));
      KdBuildOptions o;
      o.build = mode;
      o.threads = 1;
      const FlatKdTree tree = build_kdtree(scene.positions, o);
      check_layout(tree, scene.positions, o);
      // Few rays: the brute-force oracle tests every triangle for each.
      EXPECT_EQ(check_rays(tree, make_rays(tree, scene.positions, 300, 77), scene.name), 0);
      o.threads = 2;
      const FlatKdTree parallel = build_kdtree(scene.positions, o);
      ASSERT_EQ(parallel.nodes.size(), tree.nodes.size());
      EXPECT_EQ(std::memcmp(parallel.nodes.data(), tree.nodes.data(), tree.nodes.size() * sizeof(glm::vec4)), 0);
      EXPECT_EQ(parallel.leaf_prims, tree.leaf_prims);
    }
  }
}

TEST(KdTree, EveryBuildOptionTraversesCorrectly) {
  const std::vector<NamedScene> scenes = {{"soup", random_soup(600, 7)},
                                          {"grid_boxes", grid_with_boxes()},
                                          {"planar", planar(8)},
                                          {"duplicates", duplicates(9)}};
  unsigned seed = 200;
  for (const NamedScene& scene : scenes) {
    const FlatKdTree reference = build_kdtree(scene.positions);
    const std::vector<Ray> rays = make_rays(reference, scene.positions, 600 / test::sanitizer_stride(8), seed++);
    for (int bins : {4, 8, 32, 128}) {
      for (int leaf : {1, 4, 16}) {
        for (int depth : {0, 3, -1}) {
          for (bool clip : {false, true}) {
            KdBuildOptions o;
            o.bins = bins;
            o.max_leaf_prims = leaf;
            o.max_depth = depth;
            o.deep_levels = 0;  // the limit exactly (levels past it: DeepLevelsSplitOnly...)
            o.split_clipping = clip;
            const std::string what = scene.name + " bins " + std::to_string(bins) + " leaf " +
                                     std::to_string(leaf) + " depth " + std::to_string(depth) +
                                     (clip ? " clip" : " noclip");
            SCOPED_TRACE(what);
            const FlatKdTree tree = build_kdtree(scene.positions, o);
            check_layout(tree, scene.positions, o);
            if (depth == 0) {
              EXPECT_EQ(tree.nodes.size(), 1u);
            }
            if (depth >= 0) {
              EXPECT_LE(tree.stats.max_depth_reached, depth);
            }
            ASSERT_EQ(check_rays(tree, rays, what), 0);
          }
        }
      }
    }
  }
}

TEST(KdTree, CostOptionsStillTraverseCorrectly) {
  const Positions soup = random_soup(800, 11);
  const FlatKdTree reference = build_kdtree(soup);
  const std::vector<Ray> rays = make_rays(reference, soup, 1000, 12);
  for (float isect : {1.0f, 5.0f, 80.0f, 1000.0f}) {
    for (float bonus : {0.0f, 0.3f, 0.5f, 0.9f}) {
      KdBuildOptions o;
      o.intersection_cost = isect;
      o.empty_bonus = bonus;
      o.empty_bonus_min_width = bonus > 0.6f ? 0.1f : 0.0f;
      const FlatKdTree tree = build_kdtree(soup, o);
      check_layout(tree, soup, o);
      EXPECT_EQ(check_rays(tree, rays, "isect " + std::to_string(isect)), 0);
    }
  }
}

TEST(KdTree, EmptySceneIsOneEmptyLeaf) {
  const FlatKdTree tree = build_kdtree({});
  EXPECT_TRUE(tree.bounds.empty());
  ASSERT_EQ(tree.nodes.size(), 1u);
  EXPECT_EQ(tree.nodes[0], glm::vec4(0.0f, 0.0f, float(MOBIRT_NODE_LEAF), 0.0f));
  EXPECT_TRUE(tree.leaf_prims.empty());
  EXPECT_TRUE(tree.triangles.empty());
  EXPECT_EQ(tree.stats.leaves, 1u);
  EXPECT_EQ(tree.stats.empty_leaves, 1u);
  Ray ray;
  ray.origin = glm::vec3(0.0f, 0.0f, 5.0f);
  for (int depth : kStackDepths) {
    EXPECT_FALSE(traverse(tree, ray, depth).valid());
    EXPECT_FALSE(occluded(tree, ray, depth));
  }
  EXPECT_FALSE(brute_force(tree, ray).valid());
}

TEST(KdTree, OneTriangleIsASingleLeafWithOneEntry) {
  const FlatKdTree tree = build_kdtree(one_triangle());
  ASSERT_EQ(tree.nodes.size(), 1u);
  EXPECT_EQ(tree.nodes[0], glm::vec4(0.0f, 1.0f, float(MOBIRT_NODE_LEAF), 0.0f));
  ASSERT_EQ(tree.leaf_entries(), 1u);
  EXPECT_EQ(tree.leaf_prim(0), 0);
  for (int k = 0; k < MOBIRT_TEXELS_PER_TRIANGLE; ++k) {
    EXPECT_EQ(glm::vec3(tree.leaf_prims[size_t(k)]), glm::vec3(tree.triangles[size_t(k)]));
  }
  Ray ray;
  ray.origin = glm::vec3(0.25f, 0.25f, 1.0f);
  const Hit hit = traverse(tree, ray);
  ASSERT_TRUE(hit.valid());
  EXPECT_EQ(hit.prim, 0);
  EXPECT_FLOAT_EQ(hit.t, 1.0f);
  EXPECT_FLOAT_EQ(hit.u, 0.25f);
  EXPECT_FLOAT_EQ(hit.v, 0.25f);
}

TEST(KdTree, FlattenIsDepthFirstWithBelowChildNext) {
  // Two clusters far apart on x: the root splits on x.
  Positions p;
  for (int i = 0; i < 8; ++i) {
    const float y = float(i);
    add_triangle(p, {0, y, 0}, {1, y, 0}, {0, y + 0.5f, 1});
    add_triangle(p, {100, y, 0}, {101, y, 0}, {100, y + 0.5f, 1});
  }
  const FlatKdTree tree = build_kdtree(p);
  check_layout(tree, p);
  const glm::vec4 root = tree.nodes[0];
  ASSERT_NE(root.z, float(MOBIRT_NODE_LEAF));
  EXPECT_EQ(root.z, 0.0f);
  EXPECT_GT(root.x, 1.0f);
  EXPECT_LT(root.x, 100.0f);
  // Rays down each cluster hit its own triangles.
  for (float x : {0.2f, 100.2f}) {
    Ray ray;
    ray.origin = glm::vec3(x, 3.2f, -1.0f);
    ray.direction = glm::vec3(0, 0, 1);
    const Hit hit = traverse(tree, ray);
    ASSERT_TRUE(hit.valid());
    EXPECT_EQ(hit.prim % 2, x < 50.0f ? 0 : 1);
  }
}

// ---- Split clipping (accel/kdtree_clip.h) ------------------------------------------------------

TEST(KdClip, SplitsATriangleInsideTheBoxExactly) {
  const glm::vec3 v[3] = {{0, 0, 0}, {2, 0, 0}, {0, 2, 0}};
  const kdclip::Box box{{-1, -1, -1}, {3, 3, 1}};
  kdclip::Box below;
  kdclip::Box above;
  ASSERT_EQ(kdclip::clip_and_split(v, box, 0, 1.0f, below, above), 3);
  // Below x = 1: the vertices (0,0) and (0,2) and the crossings (1,0) and (1,1).
  EXPECT_EQ(below.lo[0], 0.0f);
  EXPECT_EQ(below.hi[0], 1.0f);
  EXPECT_EQ(below.lo[1], 0.0f);
  EXPECT_EQ(below.hi[1], 2.0f);
  // Above: (2,0) and the crossings.
  EXPECT_EQ(above.lo[0], 1.0f);
  EXPECT_EQ(above.hi[0], 2.0f);
  EXPECT_EQ(above.lo[1], 0.0f);
  EXPECT_EQ(above.hi[1], 1.0f);
  EXPECT_EQ(above.lo[2], 0.0f);
  EXPECT_EQ(above.hi[2], 0.0f);
}

TEST(KdClip, ASideTheTriangleMissesGetsNothing) {
  // Inside y >= 1.2 the triangle x + y <= 2 has x <= 0.8: nothing above x = 1.5, although the
  // triangle's box reaches past it.
  const glm::vec3 v[3] = {{0, 0, 0}, {2, 0, 0}, {0, 2, 0}};
  const kdclip::Box box{{-1, 1.2f, -1}, {3, 3, 1}};
  kdclip::Box below;
  kdclip::Box above;
  EXPECT_EQ(kdclip::clip_and_split(v, box, 0, 1.5f, below, above), 1);
  EXPECT_LE(below.hi[0], 0.8f + 1e-6f);
  EXPECT_GE(below.lo[1], 1.2f);
  // A box the triangle misses entirely.
  const kdclip::Box away{{1.5f, 1.5f, -1}, {3, 3, 1}};
  EXPECT_EQ(kdclip::clip_and_split(v, away, 0, 2.0f, below, above), 0);
}

// A random triangle and box in [-5, 5]^3 and a split plane on `axis` inside the box (returned).
float random_clip_case(std::mt19937& rng, int axis, glm::vec3 (&v)[3], kdclip::Box& box) {
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (glm::vec3& p : v) p = glm::vec3(u(rng), u(rng), u(rng)) * 10.0f - 5.0f;
  for (int a = 0; a < 3; ++a) {
    const float x = u(rng) * 10.0f - 5.0f;
    const float y = u(rng) * 10.0f - 5.0f;
    box.lo[a] = std::min(x, y);
    box.hi[a] = std::max(x, y);
  }
  return box.lo[axis] + (box.hi[axis] - box.lo[axis]) * u(rng);
}

TEST(KdClip, BoundsContainEveryPointOfTheClippedParts) {
  std::mt19937 rng(77);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  int parts = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    glm::vec3 v[3];
    kdclip::Box box;
    const int axis = trial % 3;
    const float split = random_clip_case(rng, axis, v, box);
    kdclip::Box sides[2];
    const int result = kdclip::clip_and_split(v, box, axis, split, sides[0], sides[1]);
    // Points of the triangle inside the box must lie in the bounds of their side(s).
    for (int sample = 0; sample < 200; ++sample) {
      double a = u(rng), b = u(rng);
      if (a + b > 1.0) {
        a = 1.0 - a;
        b = 1.0 - b;
      }
      double p[3];
      bool inside = true;
      for (int k = 0; k < 3; ++k) {
        p[k] = double(v[0][k]) + a * (double(v[1][k]) - double(v[0][k])) + b * (double(v[2][k]) - double(v[0][k]));
        inside = inside && p[k] >= box.lo[k] && p[k] <= box.hi[k];
      }
      if (!inside) continue;
      for (int side = 0; side < 2; ++side) {
        if (side == 0 ? p[axis] > split : p[axis] < split) continue;
        ASSERT_TRUE(result & (1 << side)) << "trial " << trial << ": a part with points was reported empty";
        for (int k = 0; k < 3; ++k) {
          // The sample itself is rounded in double: allow its own rounding error.
          const double slack = 1e-12 * (1.0 + std::abs(p[k]));
          ASSERT_LE(double(sides[side].lo[k]), p[k] + slack) << "trial " << trial;
          ASSERT_GE(double(sides[side].hi[k]), p[k] - slack) << "trial " << trial;
        }
        ++parts;
      }
    }
    // The bounds never leave the box or the triangle's box.
    for (int side = 0; side < 2; ++side) {
      if (!(result & (1 << side))) continue;
      for (int k = 0; k < 3; ++k) {
        const float tri_lo = std::min({v[0][k], v[1][k], v[2][k]});
        const float tri_hi = std::max({v[0][k], v[1][k], v[2][k]});
        EXPECT_GE(sides[side].lo[k], std::nextafter(std::max(box.lo[k], tri_lo), -kInfinity));
        EXPECT_LE(sides[side].hi[k], std::nextafter(std::min(box.hi[k], tri_hi), kInfinity));
      }
    }
  }
  EXPECT_GT(parts, 10000);
}

// --build fast's clip: the whole triangle split by the plane. Its bounds must contain the exact
// clip's (so that, cut to the reference's box, they stay conservative), and a side it calls empty
// must be one the exact clip calls empty too.
TEST(KdClip, SplitTriangleContainsTheExactClip) {
  std::mt19937 rng(78);
  int compared = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    glm::vec3 v[3];
    kdclip::Box box;
    const int axis = trial % 3;
    const float split = random_clip_case(rng, axis, v, box);
    kdclip::Box exact[2];
    kdclip::Box loose[2];
    const int exact_sides = kdclip::clip_and_split(v, box, axis, split, exact[0], exact[1]);
    const int loose_sides = kdclip::split_triangle(v, axis, split, loose[0], loose[1]);
    ASSERT_EQ(exact_sides & ~loose_sides, 0) << "trial " << trial << ": a side with a part was reported empty";
    for (int side = 0; side < 2; ++side) {
      if (!(exact_sides & (1 << side))) continue;
      for (int k = 0; k < 3; ++k) {
        EXPECT_LE(loose[side].lo[k], exact[side].lo[k]) << "trial " << trial;
        EXPECT_GE(loose[side].hi[k], exact[side].hi[k]) << "trial " << trial;
      }
      ++compared;
    }
  }
  EXPECT_GT(compared, 1000);
}

// The fast build's float split (crossings padded by a few ulps) holds the exact split's bounds
// (crossings in double, rounded outwards) from subnormal coordinates (where only the pad's floor
// covers the rounding) to coordinates past 2^126 (which take the exact split), off-centre
// triangles, and planes an ulp from a vertex; it reports the sides the exact split does.
TEST(KdClip, FloatSplitHoldsTheExactSplit) {
  std::mt19937 rng(80);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  int compared = 0;
  for (int trial = 0; trial < 42000; ++trial) {
    glm::vec3 v[3];
    const float scales[] = {1e-42f, 1e-30f, 1e-3f, 1.0f, 1e6f, 1e30f, 3e38f};
    const float scale = scales[trial % 7];
    // Off-centre triangles (an offset far larger than the triangle) where that stays finite.
    const bool off_centre = (trial / 7) % 3 == 0 && scale <= 1e30f;
    const glm::vec3 offset = off_centre ? glm::vec3(u(rng), u(rng), u(rng)) * scale * 1000.0f : glm::vec3(0.0f);
    for (glm::vec3& p : v) p = glm::vec3(u(rng), u(rng), u(rng)) * scale + offset;
    const int axis = trial % 3;
    float split = v[0][axis] + (v[1][axis] - v[0][axis]) * (0.5f + 0.5f * u(rng));
    if ((trial / 7) % 5 == 0) split = std::nextafter(v[2][axis], trial % 2 ? kInfinity : -kInfinity);  // an ulp off a vertex
    kdclip::Box exact[2];
    kdclip::Box loose[2];
    const int exact_sides = kdclip::split_triangle_exact(v, axis, split, exact[0], exact[1]);
    const int loose_sides = kdclip::split_triangle(v, axis, split, loose[0], loose[1]);
    ASSERT_EQ(exact_sides, loose_sides) << "trial " << trial;
    for (int side = 0; side < 2; ++side) {
      if (!(exact_sides & (1 << side))) continue;
      for (int k = 0; k < 3; ++k) {
        ASSERT_LE(loose[side].lo[k], exact[side].lo[k]) << "trial " << trial << " side " << side << " axis " << k;
        ASSERT_GE(loose[side].hi[k], exact[side].hi[k]) << "trial " << trial << " side " << side << " axis " << k;
        // A few ulps looser at most: the pad is 2^-19 of the edge's largest coordinate.
        const float m = std::max({std::fabs(v[0][k]), std::fabs(v[1][k]), std::fabs(v[2][k])});
        if (scale > 1e38f) {  // past 2^126: the exact split itself
          ASSERT_EQ(loose[side].lo[k], exact[side].lo[k]) << "trial " << trial;
          ASSERT_EQ(loose[side].hi[k], exact[side].hi[k]) << "trial " << trial;
          continue;
        }
        ASSERT_LE(double(exact[side].lo[k]) - double(loose[side].lo[k]), double(m) * 0x1p-18 + 1e-37) << "trial " << trial;
        ASSERT_LE(double(loose[side].hi[k]) - double(exact[side].hi[k]), double(m) * 0x1p-18 + 1e-37) << "trial " << trial;
      }
      ++compared;
    }
  }
  EXPECT_GT(compared, 50000);
}

// The SIMD split_triangle against the scalar one, bit for bit, including planes through a vertex,
// on the box's faces, and at negative and zero coordinates (the outward rounding's sign cases).
// Both pairs: the fast build's float split and the exact split that clip_and_split uses.
void expect_simd_split_is_scalar(int (*simd_split)(const glm::vec3*, int, float, kdclip::Box&, kdclip::Box&),
                                 int (*scalar_split)(const glm::vec3*, int, float, kdclip::Box&, kdclip::Box&)) {
  std::mt19937 rng(79);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  int both_sides = 0;
  for (int trial = 0; trial < 20000; ++trial) {
    glm::vec3 v[3];
    // Subnormal and past-2^126 coordinates too (the float split's floor and its exact fallback).
    const float scales[] = {1e-30f, 1e6f, 1.0f, 1.0f, 1e-42f, 3e38f};
    const float scale = scales[trial % 6];
    for (glm::vec3& p : v) p = glm::vec3(u(rng), u(rng), u(rng)) * scale;
    if (trial % 5 == 0) v[1][trial % 3] = 0.0f;  // zeros next to the plane
    const int axis = trial % 3;
    float split = v[0][axis] + (v[1][axis] - v[0][axis]) * (0.5f + 0.5f * u(rng));
    if (trial % 7 == 0) split = v[2][axis];  // a plane through a vertex
    if (trial % 11 == 0) split = 0.0f;
    kdclip::Box simd[2];
    kdclip::Box scalar[2];
    const int simd_sides = simd_split(v, axis, split, simd[0], simd[1]);
    const int scalar_sides = scalar_split(v, axis, split, scalar[0], scalar[1]);
    ASSERT_EQ(simd_sides, scalar_sides) << "trial " << trial;
    for (int side = 0; side < 2; ++side) {
      if (!(scalar_sides & (1 << side))) continue;
      ASSERT_EQ(std::memcmp(&simd[side], &scalar[side], sizeof(kdclip::Box)), 0) << "trial " << trial << " side " << side;
    }
    both_sides += scalar_sides == 3 ? 1 : 0;
  }
  EXPECT_GT(both_sides, 10000);
}

TEST(KdClip, SplitTriangleIsTheScalarSplitBitForBit) {
  {
    SCOPED_TRACE("the fast build's float split");
    expect_simd_split_is_scalar(kdclip::split_triangle, kdclip::split_triangle_scalar);
  }
  {
    SCOPED_TRACE("the exact split");
    expect_simd_split_is_scalar(kdclip::split_triangle_exact, kdclip::split_triangle_exact_scalar);
  }
}

TEST(KdTree, BuildModesParseAndNameEachOther) {
  for (KdBuildMode m : {KdBuildMode::Quality, KdBuildMode::Fast}) {
    KdBuildMode parsed = m == KdBuildMode::Fast ? KdBuildMode::Quality : KdBuildMode::Fast;
    ASSERT_TRUE(parse_kd_build_mode(kd_build_mode_name(m), parsed));
    EXPECT_EQ(parsed, m);
  }
  KdBuildMode unchanged = KdBuildMode::Fast;
  EXPECT_FALSE(parse_kd_build_mode("sah", unchanged));
  EXPECT_EQ(unchanged, KdBuildMode::Fast);
}

// Every build mode, on every generated scene and with the options that change its work: the same
// hits as brute force, and SAH costs near each other's (fast clips more loosely).
TEST(KdTree, EveryBuildModeTraversesCorrectly) {
  unsigned seed = 300;
  for (const NamedScene& scene : all_scenes()) {
    SCOPED_TRACE(scene.name);
    KdBuildOptions quality;
    quality.build = KdBuildMode::Quality;
    KdBuildOptions fast = quality;
    fast.build = KdBuildMode::Fast;
    // The looser clip alone (fast's leaf size, small-node gain and cluster rule raise the cost of
    // these small scenes' trees further, by design: FastLeafSize..., SmallSplitGain... and
    // ClusterRule... below).
    fast.small_split_gain = 0.0f;
    fast.max_leaf_prims = 1;
    fast.cluster_refs = 0;
    const FlatKdTree quality_tree = build_kdtree(scene.positions, quality);
    const FlatKdTree fast_tree = build_kdtree(scene.positions, fast);
    EXPECT_LE(fast_tree.stats.sah_cost, 1.10 * quality_tree.stats.sah_cost + 1e-6);
    EXPECT_LE(quality_tree.stats.sah_cost, 1.10 * fast_tree.stats.sah_cost + 1e-6);
    const std::vector<Ray> rays = make_rays(quality_tree, scene.positions, 3000 / test::sanitizer_stride(8), seed++);
    for (KdBuildMode mode : {KdBuildMode::Quality, KdBuildMode::Fast}) {
      for (bool clip : {true, false}) {
        for (int leaf : {1, 4}) {
          KdBuildOptions o;
          o.build = mode;
          o.split_clipping = clip;
          o.max_leaf_prims = leaf;
          const std::string what = scene.name + " " + kd_build_mode_name(mode) + (clip ? " clip" : " noclip") +
                                   " leaf " + std::to_string(leaf);
          SCOPED_TRACE(what);
          const FlatKdTree tree = build_kdtree(scene.positions, o);
          check_layout(tree, scene.positions, o);
          ASSERT_EQ(check_rays(tree, rays, what), 0);
        }
      }
    }
  }
}

// The GPU and the CPU read the same arrays, and tests compare images across machines: the tree
// must not depend on how many threads built it, nor on how their tasks were scheduled.
TEST(KdTree, SameTreeForAnyThreadCount) {
  // The 40,000-triangle soup has top nodes large enough to partition in parallel blocks; the
  // others are built by a handful of tasks or one.
  const std::vector<NamedScene> scenes = {{"soup 40000", random_soup(40000, 41)},
                                          {"soup 3000", random_soup(3000, 42)},
                                          {"grid_boxes", grid_with_boxes()},
                                          {"duplicates", duplicates(43)},
                                          {"planar", planar(44)}};
  for (const NamedScene& scene : scenes) {
    for (int bins : {32, 128}) {
      for (KdBuildMode mode : {KdBuildMode::Quality, KdBuildMode::Fast}) {
        if (bins != 32 && scene.name != "soup 3000") continue;  // the sweep of more than 64 bins
        SCOPED_TRACE(scene.name + " bins " + std::to_string(bins) + " " + kd_build_mode_name(mode));
        KdBuildOptions serial;
        serial.bins = bins;
        serial.build = mode;
        serial.threads = 1;
        const FlatKdTree reference = build_kdtree(scene.positions, serial);
        check_layout(reference, scene.positions, serial);
        for (int threads : {2, 3, 0}) {
          KdBuildOptions o = serial;
          o.threads = threads;
          for (int repeat = 0; repeat < 2; ++repeat) {  // different schedules
            const FlatKdTree tree = build_kdtree(scene.positions, o);
            ASSERT_EQ(tree.nodes.size(), reference.nodes.size()) << threads << " threads";
            ASSERT_EQ(tree.leaf_prims.size(), reference.leaf_prims.size()) << threads << " threads";
            ASSERT_EQ(tree.triangles.size(), reference.triangles.size()) << threads << " threads";
            EXPECT_EQ(std::memcmp(tree.nodes.data(), reference.nodes.data(), tree.nodes.size() * sizeof(glm::vec4)), 0)
                << threads << " threads";
            EXPECT_EQ(std::memcmp(tree.leaf_prims.data(), reference.leaf_prims.data(),
                                  tree.leaf_prims.size() * sizeof(glm::vec4)),
                      0)
                << threads << " threads";
            EXPECT_EQ(std::memcmp(tree.triangles.data(), reference.triangles.data(),
                                  tree.triangles.size() * sizeof(glm::vec4)),
                      0)
                << threads << " threads";
            EXPECT_EQ(std::memcmp(&tree.bounds, &reference.bounds, sizeof(Aabb)), 0);
            EXPECT_EQ(tree.max_depth, reference.max_depth);
            EXPECT_EQ(tree.stats.sah_cost, reference.stats.sah_cost);  // summed in the same order too
            EXPECT_EQ(tree.stats.leaves, reference.stats.leaves);
            EXPECT_EQ(tree.stats.prim_references, reference.stats.prim_references);
            EXPECT_EQ(tree.stats.max_depth_reached, reference.stats.max_depth_reached);
          }
        }
      }
    }
  }
}

// A trace (tools/profile/simd_stats.cpp) walks on past the hit that ended the walk, to measure
// what a speculative lane would spend: the hit, the steps and every counter stay those of the walk
// without a trace, and the trace says which walks ended at a hit in a leaf.
TEST(KdTree, TraceLeavesTheWalkUnchanged) {
  const Positions positions = random_soup(3000, 61);
  const FlatKdTree tree = build_kdtree(positions);
  const std::vector<Ray> rays = make_rays(tree, positions, 2000 / test::sanitizer_stride(8), 62);
  auto same_stats = [](const TraversalStats& a, const TraversalStats& b) {
    return a.nodes_visited == b.nodes_visited && a.leaves_visited == b.leaves_visited &&
           a.triangles_tested == b.triangles_tested && a.steps == b.steps && a.pops == b.pops &&
           a.dropped == b.dropped && a.restarts == b.restarts && a.capped == b.capped;
  };
  size_t walks = 0, ended_at_hit = 0, walked_on = 0, walked_far = 0;
  uint64_t node_iterations = 0, two_level_iterations = 0;
  // Two levels a fetch (an estimate for simd_stats): a segment's descents pair up, so it takes at
  // least half its iterations and never more than all of them.
  auto count_two_levels = [&](const TraversalTrace& t) {
    for (const TraversalTrace::Segment& seg : t.segments) {
      ASSERT_LE(seg.two_level_iterations, seg.node_iterations);
      ASSERT_GE(2 * seg.two_level_iterations, seg.node_iterations);
      node_iterations += seg.node_iterations;
      two_level_iterations += seg.two_level_iterations;
    }
  };
  for (int stack : {-1, 0, 4}) {
    for (const Ray& ray : rays) {
      TraversalStats plain;
      const Hit a = traverse(tree, ray, stack, plain);
      // Unlimited, then capped at the walk's own steps (it completes) and one fewer (it is capped):
      // the walk on past the hit must neither count against the cap nor be stopped by it.
      for (int64_t cap : {int64_t(-1), int64_t(plain.steps), int64_t(plain.steps) - 1}) {
        SCOPED_TRACE("stack " + std::to_string(stack) + ", cap " + std::to_string(cap));
        TraversalStats untraced, traced;
        TraversalTrace trace;
        const Hit u = traverse(tree, ray, stack, untraced, cap);
        const Hit b = traverse(tree, ray, stack, traced, cap, RayTest{}, &trace);
        ASSERT_EQ(u.prim, b.prim);
        ASSERT_EQ(std::memcmp(&u.t, &b.t, sizeof(float)), 0);
        ASSERT_TRUE(same_stats(untraced, traced)) << traced.steps << " steps against " << untraced.steps;
        ASSERT_EQ(traced.capped, uint64_t(cap >= 0 && cap < int64_t(plain.steps)));
        if (cap >= 0) continue;
        ASSERT_EQ(u.prim, a.prim);
        // A walk that ended at a hit in a leaf has no closing segment; one that did not ends with it.
        ASSERT_TRUE(!trace.ended_at_hit || a.valid());
        ASSERT_EQ(trace.ended_at_hit, !trace.segments.empty() && trace.segments.back().triangle_tests > 0);
        ++walks;
        count_two_levels(trace);
        ended_at_hit += trace.ended_at_hit;
        walked_on += trace.past_hit_iterations > 0;
        walked_far += trace.past_hit_iterations > 1;
      }
      // Shadow rays: the walk ends at the first hit found, always in a leaf.
      TraversalStats shadow_plain, shadow_traced;
      TraversalTrace shadow_trace;
      const bool blocked = occluded(tree, ray, stack, shadow_plain);
      ASSERT_EQ(occluded(tree, ray, stack, shadow_traced, -1, RayTest{}, &shadow_trace), blocked);
      ASSERT_TRUE(same_stats(shadow_plain, shadow_traced));
      ASSERT_EQ(shadow_trace.ended_at_hit, blocked);
      count_two_levels(shadow_trace);
    }
  }
  EXPECT_GT(4 * ended_at_hit, walks);  // a third of these walks end at a hit in a leaf
  EXPECT_EQ(walked_on, ended_at_hit);  // each walk on fetches at least the node it goes on to
  EXPECT_GT(walked_far, ended_at_hit / 4);  // and many go on past a pop to another node
  // The walks down from the root and from popped nodes are long enough to pair most steps.
  EXPECT_LT(4 * two_level_iterations, 3 * node_iterations);
}

// rebuild_kdtree replaces whatever tree it is given (larger, smaller, with shapes or not) by the
// very tree build_kdtree makes, and leaves none behind when the input is refused.
TEST(KdTree, RebuildIntoAnotherTreeGivesTheSameArrays) {
  const std::vector<glm::vec3> big = random_soup(20000, 51);
  const std::vector<glm::vec3> small = random_soup(700, 52);
  const std::vector<glm::vec3> planes = planar(53);
  Shape sphere;
  sphere.base = glm::vec3(0.2f);
  sphere.base_radius = 0.3f;
  const std::vector<Shape> shapes = {sphere};
  auto same = [](const FlatKdTree& a, const FlatKdTree& b) {
    auto bytes = [](const TexelArray& x, const TexelArray& y) {
      return x.size() == y.size() && std::memcmp(x.data(), y.data(), x.size() * sizeof(glm::vec4)) == 0;
    };
    EXPECT_TRUE(bytes(a.nodes, b.nodes));
    EXPECT_TRUE(bytes(a.leaf_prims, b.leaf_prims));
    EXPECT_TRUE(bytes(a.triangles, b.triangles));
    EXPECT_EQ(std::memcmp(&a.bounds, &b.bounds, sizeof(Aabb)), 0);
    EXPECT_EQ(a.max_depth, b.max_depth);
    EXPECT_EQ(a.stats.nodes, b.stats.nodes);
    EXPECT_EQ(a.stats.leaves, b.stats.leaves);
    EXPECT_EQ(a.stats.empty_leaves, b.stats.empty_leaves);
    EXPECT_EQ(a.stats.prim_references, b.stats.prim_references);
    EXPECT_EQ(a.stats.max_leaf_size, b.stats.max_leaf_size);
    EXPECT_EQ(a.stats.max_depth_reached, b.stats.max_depth_reached);
    EXPECT_EQ(a.stats.sah_cost, b.stats.sah_cost);
  };
  for (int threads : {1, 0}) {
    SCOPED_TRACE(std::to_string(threads) + " threads");
    KdBuildOptions o;
    o.threads = threads;
    FlatKdTree tree;
    // Big, then small (arrays shrink, memory kept), then big again (they grow back), then a
    // planar scene with a shape (other bounds, other texels after the triangles).
    const std::vector<std::pair<const std::vector<glm::vec3>*, std::span<const Shape>>> sequence = {
        {&big, {}}, {&small, {}}, {&big, {}}, {&planes, shapes}, {&small, {}}};
    for (const auto& [positions, with] : sequence) {
      rebuild_kdtree(tree, *positions, with, o);
      same(tree, build_kdtree(*positions, with, o));
    }
    std::vector<glm::vec3> broken = small;
    broken[301].y = std::numeric_limits<float>::quiet_NaN();
    test::expect_bad_input([&] { rebuild_kdtree(tree, broken, {}, o); }, {"triangle 100 vertex 1", "non-finite"});
    EXPECT_TRUE(tree.nodes.empty() && tree.leaf_prims.empty() && tree.triangles.empty());
    rebuild_kdtree(tree, small, {}, o);  // and the tree is usable again
    same(tree, build_kdtree(small, {}, o));
    // Options refused before the build begins leave no tree either.
    KdBuildOptions one_bin = o;
    one_bin.bins = 1;
    test::expect_bad_input([&] { rebuild_kdtree(tree, small, {}, one_bin); }, {"bins"});
    EXPECT_TRUE(tree.nodes.empty() && tree.leaf_prims.empty() && tree.triangles.empty());
    rebuild_kdtree(tree, small, {}, o);
    tree.clear();  // no tree, its memory kept
    EXPECT_TRUE(tree.nodes.empty() && tree.leaf_prims.empty() && tree.triangles.empty());
    EXPECT_GT(tree.nodes.capacity(), 0u);
    rebuild_kdtree(tree, big, {}, o);
    same(tree, build_kdtree(big, {}, o));
  }
}

TEST(KdTree, NegativeThreadCountIsBadInput) {
  KdBuildOptions o;
  o.threads = -1;
  test::expect_bad_input([&] { build_kdtree(random_soup(10, 3), o); }, {"threads", "-1"});
}

// The same nodes and leaf entries, byte for byte.
void expect_same_nodes(const FlatKdTree& a, const FlatKdTree& b) {
  ASSERT_EQ(a.nodes.size(), b.nodes.size());
  ASSERT_EQ(a.leaf_prims.size(), b.leaf_prims.size());
  EXPECT_EQ(std::memcmp(a.nodes.data(), b.nodes.data(), a.nodes.size() * sizeof(glm::vec4)), 0);
  EXPECT_EQ(std::memcmp(a.leaf_prims.data(), b.leaf_prims.data(), a.leaf_prims.size() * sizeof(glm::vec4)), 0);
}

// The traversal statistics of all the rays (stack 4), summed.
TraversalStats traversal_totals(const FlatKdTree& tree, const std::vector<Ray>& rays) {
  TraversalStats total;
  for (const Ray& ray : rays) {
    TraversalStats s;
    traverse(tree, ray, 4, s);
    total += s;
  }
  return total;
}

// Fast's leaf size (kd_leaf_size): nodes of up to 3 references stay leaves. On every generated
// scene: the same hits as brute force, fewer nodes than with leaves of 1, and at most 10 % more
// steps of the GPU's loop per ray (one per node, one per triangle test; measured: fewer on every
// scene, e.g. long_thin 85.2 -> 61.8 with 8.5 -> 21.1 triangle tests), where pbrt's SAH, pricing
// a test at 80 node steps, rises. Quality keeps leaves of 1.
TEST(KdTree, FastLeafSizeMakesFewerNodesAndStaysExact) {
  KdBuildOptions fast;
  EXPECT_EQ(kd_leaf_size(fast), 3);
  KdBuildOptions quality;
  quality.build = KdBuildMode::Quality;
  EXPECT_EQ(kd_leaf_size(quality), 1);
  KdBuildOptions leaf1;
  leaf1.max_leaf_prims = 1;
  EXPECT_EQ(kd_leaf_size(leaf1), 1);
  unsigned seed = 700;
  for (const NamedScene& scene : all_scenes()) {
    SCOPED_TRACE(scene.name);
    const FlatKdTree small = build_kdtree(scene.positions, leaf1);
    const FlatKdTree tree = build_kdtree(scene.positions, fast);
    check_layout(tree, scene.positions, fast);
    EXPECT_LE(tree.stats.nodes, small.stats.nodes);
    const std::vector<Ray> rays = make_rays(small, scene.positions, 2000 / test::sanitizer_stride(8), seed++);
    ASSERT_EQ(check_rays(tree, rays, scene.name), 0);
    const TraversalStats with_small = traversal_totals(small, rays);
    const TraversalStats with_fast = traversal_totals(tree, rays);
    std::printf("%s: nodes %zu -> %zu, steps per ray %.2f -> %.2f, triangle tests %.2f -> %.2f\n",
                scene.name.c_str(), small.stats.nodes, tree.stats.nodes, double(with_small.steps) / rays.size(),
                double(with_fast.steps) / rays.size(), double(with_small.triangles_tested) / rays.size(),
                double(with_fast.triangles_tested) / rays.size());
    EXPECT_LE(double(with_fast.steps), 1.10 * double(with_small.steps));
  }
}

// The cluster rule: fast's default keeps vertex fans together, for far fewer nodes and leaf
// references on a mesh and steps per ray within a few percent; every setting traverses as brute
// force does; quality's default is the first builder's rule (none) bit for bit.
TEST(KdTree, ClusterRuleKeepsVertexFansTogetherAndStaysExact) {
  KdBuildOptions fast, quality, none;
  quality.build = KdBuildMode::Quality;
  none.cluster_refs = 0;
  EXPECT_EQ(std::vector<int>({kd_cluster_refs(fast), kd_cluster_refs(quality), kd_cluster_refs(none)}),
            std::vector<int>({6, 0, 0}));

  const Positions mesh = terrain(48);
  const FlatKdTree plain = build_kdtree(mesh, none);
  const FlatKdTree tree = build_kdtree(mesh, fast);
  check_layout(tree, mesh, fast);
  // (this smooth height field: 10 % and 8 % fewer; the toaster's meshes: 33 % and 27 %)
  EXPECT_LT(double(tree.stats.nodes), 0.95 * double(plain.stats.nodes));
  EXPECT_LT(double(tree.stats.prim_references), 0.95 * double(plain.stats.prim_references));
  const std::vector<Ray> rays = make_rays(plain, mesh, 2000 / test::sanitizer_stride(8), 31);
  const TraversalStats with_plain = traversal_totals(plain, rays);
  const TraversalStats with_rule = traversal_totals(tree, rays);
  std::printf("terrain: nodes %zu -> %zu, references %zu -> %zu, steps per ray %.2f -> %.2f\n",
              plain.stats.nodes, tree.stats.nodes, plain.stats.prim_references, tree.stats.prim_references,
              double(with_plain.steps) / rays.size(), double(with_rule.steps) / rays.size());
  EXPECT_LE(double(with_rule.steps), 1.05 * double(with_plain.steps));

  const Positions soup = random_soup(1500, 32);
  const std::vector<Ray> soup_rays = make_rays(build_kdtree(soup, none), soup, 800, 33);
  for (int refs : {0, 4, 6, 12, 64}) {
    for (KdBuildMode mode : {KdBuildMode::Fast, KdBuildMode::Quality}) {
      KdBuildOptions o;
      o.build = mode;
      o.cluster_refs = refs;
      const std::string what = std::string(kd_build_mode_name(mode)) + " cluster " + std::to_string(refs);
      SCOPED_TRACE(what);
      const FlatKdTree t = build_kdtree(mesh, o);
      check_layout(t, mesh, o);
      ASSERT_EQ(check_rays(t, rays, what), 0);
      const FlatKdTree u = build_kdtree(soup, o);
      check_layout(u, soup, o);
      ASSERT_EQ(check_rays(u, soup_rays, what), 0);
    }
  }
  KdBuildOptions quality_none = quality;
  quality_none.cluster_refs = 0;
  expect_same_nodes(build_kdtree(mesh, quality), build_kdtree(mesh, quality_none));
  test::expect_bad_input(
      [&] {
        KdBuildOptions o;
        o.cluster_refs = -2;
        build_kdtree(soup, o);
      },
      {"cluster_refs"});
  for (float bonus : {-0.1f, -2.0f, 1.0f, std::numeric_limits<float>::quiet_NaN()}) {
    KdBuildOptions o;
    o.empty_bonus = bonus;
    test::expect_bad_input([&] { build_kdtree(soup, o); }, {"empty_bonus"});
  }
}

// Past the depth limit only nodes of more than deep_refs references split: deep_refs beyond any
// node's count gives the tree of the limit alone, deep_refs at the leaf size the tree of the limit
// raised by deep_levels; either way the walks stay exact, and fewer triangle tests are left.
TEST(KdTree, DeepLevelsSplitOnlyLargeNodesPastTheDepthLimit) {
  KdBuildOptions fast, quality, none;
  quality.build = KdBuildMode::Quality;
  none.deep_levels = 0;
  EXPECT_EQ(std::vector<int>({kd_deep_levels(fast), kd_deep_levels(quality), kd_deep_levels(none)}),
            std::vector<int>({4, 0, 0}));
  const Positions mesh = terrain(48);
  const Positions soup = random_soup(1500, 41);
  for (const Positions* p : {&mesh, &soup}) {
    SCOPED_TRACE(p == &mesh ? "terrain" : "soup");
    const int limit = kdtree_depth_limit(p->size() / 3, -1);
    KdBuildOptions huge = fast;
    huge.deep_refs = 1 << 20;
    const FlatKdTree plain = build_kdtree(*p, none);
    EXPECT_EQ(plain.max_depth, limit);
    const FlatKdTree same = build_kdtree(*p, huge);
    expect_same_nodes(plain, same);
    EXPECT_EQ(same.max_depth, limit + 4);

    KdBuildOptions every = fast;  // every node the leaf size lets split may split past the limit
    every.deep_refs = kd_leaf_size(fast);
    KdBuildOptions raised = none;
    raised.max_depth = limit + 4;
    expect_same_nodes(build_kdtree(*p, every), build_kdtree(*p, raised));

    const FlatKdTree deep = build_kdtree(*p, fast);
    check_layout(deep, *p, fast);
    EXPECT_LE(deep.stats.max_depth_reached, limit + 4);
    const std::vector<Ray> rays = make_rays(plain, *p, 1500 / test::sanitizer_stride(8), 43);
    ASSERT_EQ(check_rays(deep, rays, "deep"), 0);
    const TraversalStats a = traversal_totals(plain, rays);
    const TraversalStats b = traversal_totals(deep, rays);
    std::printf("deep levels: nodes %zu -> %zu, triangle tests per ray %.2f -> %.2f\n", plain.stats.nodes,
                deep.stats.nodes, double(a.triangles_tested) / rays.size(), double(b.triangles_tested) / rays.size());
    EXPECT_GE(deep.stats.nodes, plain.stats.nodes);
    EXPECT_LE(b.triangles_tested, a.triangles_tested);
  }
  expect_same_nodes(build_kdtree(mesh, quality), [&] {
    KdBuildOptions q = quality;
    q.deep_levels = 0;
    return build_kdtree(mesh, q);
  }());
  for (int bad : {-2, 33}) {
    KdBuildOptions o;
    o.deep_levels = bad;
    test::expect_bad_input([&] { build_kdtree(soup, o); }, {"deep_levels"});
  }
  KdBuildOptions o;
  o.deep_refs = -1;
  test::expect_bad_input([&] { build_kdtree(soup, o); }, {"deep_refs"});
}

// The plane sweeps (SSE2, and AVX2 where the CPU has it; the sparse sweep of small nodes, which
// SSE2 takes for more of them) choose the same planes, and the binning (SSE2, or a reference in
// one AVX2 register) counts the same bins: the same tree on any CPU.
TEST(KdTree, SameTreeForEverySweep) {
  const std::vector<NamedScene> scenes = {{"soup 3000", random_soup(3000, 42)}, {"terrain", terrain(40)},
                                          {"grid_boxes", grid_with_boxes()},    {"duplicates", duplicates(43)},
                                          {"planar", planar(44)}};
  for (const NamedScene& scene : scenes) {
    for (KdBuildMode mode : {KdBuildMode::Quality, KdBuildMode::Fast}) {
      SCOPED_TRACE(scene.name + " " + kd_build_mode_name(mode));
      KdBuildOptions best;
      best.build = mode;
      KdBuildOptions sse2 = best;
      sse2.sweep_simd = KdSweepSimd::Sse2;
      expect_same_nodes(build_kdtree(scene.positions, best), build_kdtree(scene.positions, sse2));
    }
  }
}

TEST(KdTree, SmallSplitGainOutsideItsRangeIsBadInput) {
  for (float gain : {1.0f, -0.5f, std::numeric_limits<float>::quiet_NaN()}) {
    KdBuildOptions o;
    o.small_split_gain = gain;
    test::expect_bad_input([&] { build_kdtree(random_soup(10, 3), o); }, {"small_split_gain"});
  }
}

// Fast's gain on small nodes: fewer nodes than gain 0 for a little more SAH cost, hits as brute
// force's for any gain, and quality's default is the first builder's rule (gain 0) bit for bit.
TEST(KdTree, SmallSplitGainMakesFewerNodesAndStaysExact) {
  const Positions soup = random_soup(1500, 21);
  KdBuildOptions leaf1;  // fast's gain applies to the nodes of up to 3 references its leaf size 3 keeps
  leaf1.max_leaf_prims = 1;
  const FlatKdTree reference = build_kdtree(soup, leaf1);
  const std::vector<Ray> rays = make_rays(reference, soup, 800, 22);
  KdBuildOptions none = leaf1;
  none.small_split_gain = 0.0f;
  const FlatKdTree plain = build_kdtree(soup, none);
  EXPECT_LT(reference.stats.nodes, plain.stats.nodes);
  EXPECT_GE(reference.stats.sah_cost, plain.stats.sah_cost);
  EXPECT_LE(reference.stats.sah_cost, 1.05 * plain.stats.sah_cost);
  for (float gain : {0.0f, 0.15f, 0.5f, 0.99f}) {
    for (int refs : {2, 3, 8}) {
      KdBuildOptions o = leaf1;
      o.small_split_gain = gain;
      o.small_node_refs = refs;
      const std::string what = "gain " + std::to_string(gain) + " refs " + std::to_string(refs);
      SCOPED_TRACE(what);
      const FlatKdTree tree = build_kdtree(soup, o);
      check_layout(tree, soup, o);
      ASSERT_EQ(check_rays(tree, rays, what), 0);
    }
  }
  KdBuildOptions quality;
  quality.build = KdBuildMode::Quality;
  KdBuildOptions quality_none = quality;
  quality_none.small_split_gain = 0.0f;
  expect_same_nodes(build_kdtree(soup, quality), build_kdtree(soup, quality_none));
}

// The empty bonus a build takes (kd_empty_bonus): the option where set, else pbrt's 0.5, and
// kKdWalksEmptyBonus for a fast tree built for walks (rays > 0); the quality build keeps pbrt's.
// A walks tree built by default is the one built with that bonus set, node for node.
TEST(KdTree, TreesForWalksTakeTheWalksEmptyBonus) {
  EXPECT_EQ(kd_empty_bonus(KdBuildOptions{}), 0.5f);
  EXPECT_EQ(kd_empty_bonus(KdBuildOptions{.rays = 1000.0}), kKdWalksEmptyBonus);
  EXPECT_EQ(kd_empty_bonus(KdBuildOptions{.build = KdBuildMode::Quality, .rays = 1000.0}), 0.5f);
  EXPECT_EQ(kd_empty_bonus(KdBuildOptions{.empty_bonus = 0.3f, .rays = 1000.0}), 0.3f);
  EXPECT_EQ(kd_empty_bonus(KdBuildOptions{.empty_bonus = 0.0f}), 0.0f);
  const Positions mesh = terrain(40);
  for (double rays : {2000.0, 1e30}) {
    SCOPED_TRACE("rays " + std::to_string(rays));
    const FlatKdTree walks = build_kdtree(mesh, KdBuildOptions{.rays = rays});
    expect_same_nodes(walks, build_kdtree(mesh, KdBuildOptions{.empty_bonus = kKdWalksEmptyBonus, .rays = rays}));
    // pbrt's bonus builds another tree for the same rays (fewer nodes: fewer cuts of empty space).
    const FlatKdTree pbrt = build_kdtree(mesh, KdBuildOptions{.empty_bonus = 0.5f, .rays = rays});
    EXPECT_NE(walks.stats.nodes, pbrt.stats.nodes);
  }
  expect_same_nodes(build_kdtree(mesh, KdBuildOptions{}), build_kdtree(mesh, KdBuildOptions{.empty_bonus = 0.5f}));
}

// KdBuildOptions::rays: a tree built for fewer rays has fewer nodes (a split must save those rays
// more walking than it costs to build), never a leaf of more than rays_leaf_limit references that
// the full tree does not have, the same nodes for any thread count, and every walk exact; 0 and
// a count past any node's price give the full tree (of the same empty bonus: a tree built for
// walks takes kKdWalksEmptyBonus by default, kd_empty_bonus).
TEST(KdTree, TreesForFewerRaysHaveFewerNodesAndStayExact) {
  const Positions mesh = terrain(48);
  const Positions soup = random_soup(3000, 51);
  for (const Positions* p : {&mesh, &soup}) {
    SCOPED_TRACE(p == &mesh ? "terrain" : "soup");
    const FlatKdTree full = build_kdtree(*p, KdBuildOptions{.empty_bonus = kKdWalksEmptyBonus});
    const std::vector<Ray> rays = make_rays(full, *p, 600 / test::sanitizer_stride(4), 52);
    KdBuildOptions unbounded;
    unbounded.rays = 1e30;
    expect_same_nodes(full, build_kdtree(*p, unbounded));
    size_t last_nodes = 0;
    for (double count : {1.0, 100.0, 10000.0, 1000000.0}) {
      const std::string what = "rays " + std::to_string(count);
      SCOPED_TRACE(what);
      KdBuildOptions o;
      o.rays = count;
      const FlatKdTree tree = build_kdtree(*p, o);
      check_layout(tree, *p, o);
      ASSERT_EQ(check_rays(tree, rays, what), 0);
      EXPECT_GE(tree.stats.nodes, last_nodes);
      EXPECT_LE(tree.stats.nodes, full.stats.nodes);
      EXPECT_GE(tree.stats.sah_cost, full.stats.sah_cost * 0.999);
      EXPECT_LE(tree.stats.max_leaf_size, std::max(size_t(o.rays_leaf_limit), full.stats.max_leaf_size));
      last_nodes = tree.stats.nodes;
      KdBuildOptions one_thread = o;
      one_thread.threads = 1;
      expect_same_nodes(tree, build_kdtree(*p, one_thread));
    }
    KdBuildOptions few;
    few.rays = 1.0;
    EXPECT_LT(build_kdtree(*p, few).stats.nodes, full.stats.nodes / 4);
    few.rays_leaf_limit = 8;  // a lower limit: more nodes, leaves of 8 where the rule made them
    const FlatKdTree limited = build_kdtree(*p, few);
    EXPECT_LE(limited.stats.max_leaf_size, std::max(size_t(8), full.stats.max_leaf_size));
    EXPECT_GT(limited.stats.nodes, build_kdtree(*p, KdBuildOptions{.rays = 1.0}).stats.nodes);
  }
  for (double bad : {-1.0, std::numeric_limits<double>::infinity(), std::numeric_limits<double>::quiet_NaN()}) {
    KdBuildOptions o;
    o.rays = bad;
    test::expect_bad_input([&] { build_kdtree(soup, o); }, {"rays"});
    o = KdBuildOptions{};
    o.build_ref_cost = bad == -1.0 ? -2.0 : bad;
    test::expect_bad_input([&] { build_kdtree(soup, o); }, {"build_ref_cost"});
  }
  KdBuildOptions o;
  o.rays_leaf_limit = -1;
  test::expect_bad_input([&] { build_kdtree(soup, o); }, {"rays_leaf_limit"});
}

TEST(KdTree, NonFiniteAndMalformedInputIsBadInput) {
  Positions p = random_soup(10, 3);
  p[7].y = std::numeric_limits<float>::quiet_NaN();
  try {
    build_kdtree(p);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::BadInput);
    EXPECT_NE(std::string(e.what()).find("triangle 2"), std::string::npos) << e.what();
  }
  p[7].y = kInfinity;
  EXPECT_THROW(build_kdtree(p), Error);
  // The build checks blocks of triangles in parallel: the first bad vertex is named all the same.
  Positions large = random_soup(20000, 4);
  large[3 * 17000].x = kInfinity;
  large[3 * 9000 + 1].z = std::numeric_limits<float>::quiet_NaN();
  KdBuildOptions two;
  two.threads = 2;
  test::expect_bad_input([&] { build_kdtree(large, two); }, {"triangle 9000 vertex 1", "non-finite"});
  p[7].y = 0.0f;
  p.pop_back();
  EXPECT_THROW(build_kdtree(p), Error);  // not whole triangles
  KdBuildOptions o;
  o.bins = 1;
  EXPECT_THROW(build_kdtree(random_soup(10, 3), o), Error);
  o.bins = kKdMaxBins + 1;
  test::expect_bad_input([&] { build_kdtree(random_soup(10, 3), o); }, {"bins", "1024"});
  o.bins = kKdMaxBins;
  EXPECT_NO_THROW(build_kdtree(random_soup(100, 3), o));
}

TEST(KdTree, TooManyTrianglesForExactFloatIndicesIsBadInput) {
  const Positions p((kKdMaxTriangles + 1) * 3, glm::vec3(0.0f));
  try {
    build_kdtree(p);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::BadInput);
    EXPECT_NE(std::string(e.what()).find("5,592,406 triangles"), std::string::npos) << e.what();
  }
}

TEST(KdTree, DepthLimitFollowsPbrt) {
  EXPECT_EQ(kdtree_depth_limit(0, -1), 8);
  EXPECT_EQ(kdtree_depth_limit(1, -1), 8);
  EXPECT_EQ(kdtree_depth_limit(1024, -1), 21);       // 8 + 1.3 * 10
  EXPECT_EQ(kdtree_depth_limit(11141, -1), 25);      // 8 + 1.3 * 13 = 24.9
  EXPECT_EQ(kdtree_depth_limit(1000000, -1), 33);    // 8 + 1.3 * 19 = 32.7
  EXPECT_EQ(kdtree_depth_limit(1000, 5), 5);
  KdBuildOptions pbrt;
  pbrt.deep_levels = 0;
  const FlatKdTree tree = build_kdtree(random_soup(1024, 5), pbrt);
  EXPECT_EQ(tree.max_depth, 21);
  EXPECT_LE(tree.stats.max_depth_reached, 21);
  // fast's default: large nodes split up to 4 levels further (DeepLevelsSplitOnlyLargeNodes...)
  const FlatKdTree deep = build_kdtree(random_soup(1024, 5));
  EXPECT_EQ(deep.max_depth, 25);
  EXPECT_LE(deep.stats.max_depth_reached, 25);
}

TEST(KdTree, StepCapStopsAndReportsCapped) {
  const Positions soup = random_soup(1500, 21);
  const FlatKdTree tree = build_kdtree(soup);
  const std::vector<Ray> rays = make_rays(tree, soup, 300, 22);
  int checked = 0;
  for (const Ray& ray : rays) {
    for (int depth : {-1, 0, 2}) {
      TraversalStats full;
      const Hit expected = traverse(tree, ray, depth, full);
      ASSERT_EQ(full.capped, 0u);
      // One step per interior node and per triangle test, one per empty leaf.
      EXPECT_GE(full.steps, full.nodes_visited - full.leaves_visited + full.triangles_tested);
      EXPECT_LE(full.steps, full.nodes_visited + full.triangles_tested);
      if (full.steps == 0) continue;
      TraversalStats exact;
      const Hit same = traverse(tree, ray, depth, exact, int64_t(full.steps));
      EXPECT_EQ(exact.capped, 0u);
      EXPECT_EQ(same.prim, expected.prim);
      EXPECT_EQ(exact.steps, full.steps);
      TraversalStats cut;
      const Hit none = traverse(tree, ray, depth, cut, int64_t(full.steps) - 1);
      EXPECT_EQ(cut.capped, 1u);
      EXPECT_FALSE(none.valid());
      EXPECT_EQ(cut.steps, full.steps - 1);
      TraversalStats shadow;
      occluded(tree, ray, depth, shadow, 0);
      EXPECT_EQ(shadow.capped, 1u);
      ++checked;
    }
  }
  EXPECT_GT(checked, 100);
}

// The empty-child flags only save visits: the same hits as the same tree without them, in fewer
// steps, for every stack depth.
TEST(KdTree, EmptyChildFlagsSkipEmptyLeavesWithTheSameHits) {
  const Positions soup = random_soup(3000, 41);
  const FlatKdTree tree = build_kdtree(soup);
  FlatKdTree unflagged = tree;
  size_t flagged = 0;
  for (glm::vec4& n : unflagged.nodes) {
    if (n.z != float(MOBIRT_NODE_LEAF) && n.w != 0.0f) ++flagged;
    if (n.z != float(MOBIRT_NODE_LEAF)) n.w = 0.0f;
  }
  ASSERT_GT(flagged, 0u);
  // The build sets the flags while laying the tree out, top nodes (the soup's first levels) and
  // subtrees alike: the very flags of mark_empty_children.
  FlatKdTree marked = unflagged;
  mark_empty_children(marked);
  ASSERT_EQ(marked.nodes.size(), tree.nodes.size());
  EXPECT_EQ(std::memcmp(marked.nodes.data(), tree.nodes.data(), tree.nodes.size() * sizeof(glm::vec4)), 0);
  const std::vector<Ray> rays = make_rays(tree, soup, 1000, 42);
  for (int depth : {-1, 0, 1, 4}) {
    TraversalStats with, without;
    for (const Ray& ray : rays) {
      TraversalStats a, b;
      const Hit h = traverse(tree, ray, depth, a);
      const Hit g = traverse(unflagged, ray, depth, b);
      EXPECT_TRUE(same_hit(h, g)) << "stack " << depth;
      EXPECT_EQ(occluded(tree, ray, depth), occluded(unflagged, ray, depth)) << "stack " << depth;
      with += a;
      without += b;
    }
    // (Triangle tests may differ a little: a skipped push drops no older entry, so a short stack
    // restarts elsewhere.)
    EXPECT_LT(with.steps, without.steps) << "stack " << depth;
    EXPECT_LT(with.leaves_visited, without.leaves_visited) << "stack " << depth;
  }
}

TEST(KdTree, ShortStacksDropAndRestartButStayExact) {
  const Positions soup = random_soup(3000, 31);
  const FlatKdTree tree = build_kdtree(soup);
  ASSERT_GT(tree.stats.max_depth_reached, 10);
  const std::vector<Ray> rays = make_rays(tree, soup, 2000, 32);
  TraversalStats full, restart, short1;
  for (const Ray& ray : rays) {
    TraversalStats s;
    const Hit a = traverse(tree, ray, -1, s);
    full += s;
    const Hit b = traverse(tree, ray, 0, s);
    restart += s;
    const Hit c = traverse(tree, ray, 1, s);
    short1 += s;
    EXPECT_TRUE(same_hit(a, b));
    EXPECT_TRUE(same_hit(a, c));
  }
  EXPECT_EQ(full.restarts, 0u);
  EXPECT_EQ(full.dropped, 0u);
  EXPECT_GT(restart.restarts, 0u);
  EXPECT_EQ(restart.pops, 0u);
  EXPECT_GT(short1.dropped, 0u);
  EXPECT_GT(short1.pops, 0u);
  // kd-restart pays for the missing stack with node visits.
  EXPECT_GT(restart.nodes_visited, full.nodes_visited);
}

// traverse_fast and occluded_fast (the small generations walked on the CPU, RenderSettings::
// cpu_walks) return the full-stack walk's hit bit for bit under both ray tests, on every generated
// scene and on a tree with analytic shapes (mediump hands the walk to traverse's own, which this
// checks too).
TEST(KdTree, FastWalkIsTheFullStackWalkBitForBit) {
  const auto same = [](const Hit& a, const Hit& b) {
    return a.prim == b.prim && (!a.valid() || (a.t == b.t && a.u == b.u && a.v == b.v));
  };
  std::vector<std::pair<std::string, FlatKdTree>> trees;
  std::vector<std::vector<Ray>> rays;
  unsigned seed = 700;
  for (const NamedScene& scene : all_scenes()) {
    trees.emplace_back(scene.name, build_kdtree(scene.positions));
    rays.push_back(make_rays(trees.back().second, scene.positions, 2000 / test::sanitizer_stride(4), seed++));
  }
  const Scene shapes = test::shapes_scene();
  trees.emplace_back("shapes", build_kdtree(shapes.mesh.positions, shapes.shapes));
  rays.push_back(make_rays(trees.back().second, shapes.mesh.positions, 500, seed++));
  int compared = 0, hits = 0, blocked = 0;
  for (size_t k = 0; k < trees.size(); ++k) {
    SCOPED_TRACE(trees[k].first);
    const FlatKdTree& tree = trees[k].second;
    for (const IntersectTest it : {IntersectTest::MollerTrumbore, IntersectTest::Watertight}) {
      for (const Precision pr : {Precision::High, Precision::Medium}) {
        const RayTest test{it, pr};
        int failures = 0;
        for (const Ray& ray : rays[k]) {
          const Hit full = traverse(tree, ray, -1, test);
          const Hit fast = traverse_fast(tree, ray, test);
          // A shadow segment ending before, at or past the hit.
          Ray segment = ray;
          if (full.valid()) segment.tmax = ray.tmin + (full.t - ray.tmin) * (compared % 3 == 0 ? 0.5f : 1.5f);
          const bool occ = occluded(tree, segment, -1, test);
          ++compared;
          hits += full.valid() ? 1 : 0;
          blocked += occ ? 1 : 0;
          if ((!same(full, fast) || occluded_fast(tree, segment, test) != occ) && ++failures <= 3) {
            ADD_FAILURE() << describe(ray) << ": full stack prim " << full.prim << " t " << full.t << ", fast prim "
                          << fast.prim << " t " << fast.t;
          }
        }
      }
    }
  }
  EXPECT_GT(hits, compared / 4);
  EXPECT_GT(blocked, compared / 8);
}

TEST(KdTree, TiesGoToTheLowerPrimitiveIndex) {
  // The same triangle three times and a coplanar overlapping one: every path picks prim 0... and
  // the lowest index among the coincident ones wherever the ray hits.
  Positions p;
  for (int i = 0; i < 3; ++i) add_triangle(p, {0, 0, 0}, {4, 0, 0}, {0, 4, 0});
  add_triangle(p, {-1, -1, 0}, {5, -1, 0}, {-1, 5, 0});
  for (int i = 0; i < 40; ++i) add_triangle(p, {10.0f + float(i), 0, 0}, {11.0f + float(i), 0, 0}, {10.0f + float(i), 1, 0});
  const FlatKdTree tree = build_kdtree(p);
  Ray ray;
  ray.origin = glm::vec3(1.0f, 1.0f, 2.0f);
  ray.direction = glm::vec3(0.0f, 0.0f, -1.0f);
  EXPECT_EQ(brute_force(tree, ray).prim, 0);
  for (int depth : kStackDepths) EXPECT_EQ(traverse(tree, ray, depth).prim, 0);
  ray.origin = glm::vec3(4.5f, -0.5f, 2.0f);  // only the big one
  for (int depth : kStackDepths) EXPECT_EQ(traverse(tree, ray, depth).prim, 3);
}

// Flat grids of axis-aligned quads in the planes x = 0, y = 0 and z = 0 (the split planes of their
// trees), quads of 0.8 with gaps and touching unit quads, triangulated as glTF exporters do
// (0, 1, 2 and 0, 2, 3), seen head-on and obliquely through the pixel centres of a camera. Head-on,
// those pixel centres fall exactly on the quads' diagonals, where the textbook Möller-Trumbore
// test rounded u of one triangle and v of the other differently and rejected both (up to 26 of
// 28,676 rays per grid slipped through, in brute force and the kd-tree alike: the tree was never at
// fault). No ray that meets the grid may miss it, under either test, traversed or brute force; a
// ray on an edge may choose either triangle.
TEST(KdTree, FlatGridsOfQuadsHaveNoPinholes) {
  const auto in_plane = [](int axis, glm::vec3 q) {  // q.z is the coordinate along `axis`
    glm::vec3 r;
    r[axis] = q.z;
    r[(axis + 1) % 3] = q.x;
    r[(axis + 2) % 3] = q.y;
    return r;
  };
  RayTest watertight;
  watertight.test = IntersectTest::Watertight;
  for (int axis = 0; axis < 3; ++axis) {
    for (bool gaps : {true, false}) {
      Positions p;
      for (int i = 0; i < 40; ++i) {
        const glm::vec2 lo = gaps ? glm::vec2(float(i % 8) - 3.9f, 1.6f - float(i / 8))
                                  : glm::vec2(float(i % 8) - 4.0f, 1.5f - float(i / 8));
        const glm::vec2 hi = lo + glm::vec2(gaps ? 0.8f : 1.0f);
        add_quad(p, in_plane(axis, {lo.x, hi.y, 0}), in_plane(axis, {lo.x, lo.y, 0}), in_plane(axis, {hi.x, lo.y, 0}),
                 in_plane(axis, {hi.x, hi.y, 0}));
      }
      const FlatKdTree tree = build_kdtree(p);
      for (glm::vec3 eye : {glm::vec3(0, 0, 5), glm::vec3(-3, -2, 4)}) {
        SCOPED_TRACE("axis " + std::to_string(axis) + (gaps ? " gaps" : " touching") + " eye z " +
                     std::to_string(eye.z));
        const Camera camera{in_plane(axis, eye), glm::vec3(0.0f), in_plane(axis, {0, 1, 0}), 2.0f * std::atan(0.6f),
                            0.0f};
        const int width = 320, height = 200;
        int meets = 0, misses = 0;
        const int rows = int(test::sanitizer_stride(4));  // every 4th row under sanitizers
        for (int y = 0; y < height; y += rows) {
          for (int x = 0; x < width; ++x) {
            const Ray ray = camera_ray(camera, width, height, float(x) + 0.5f, float(y) + 0.5f);
            // Where the ray meets the plane, and whether that point lies on a quad (away from the
            // quads' outer borders, where either answer is right).
            const float t = -ray.origin[axis] / ray.direction[axis];
            const glm::vec3 q = ray.origin + t * ray.direction;
            const glm::vec2 g(q[(axis + 1) % 3] + 4.0f, 2.5f - q[(axis + 2) % 3]);
            const glm::vec2 f = glm::fract(g);
            const float margin = 1e-3f;
            if (!(g.x > margin && g.x < 8.0f - margin && g.y > margin && g.y < 5.0f - margin)) continue;
            if (gaps && !(f.x > 0.1f + margin && f.x < 0.9f - margin && f.y > 0.1f + margin && f.y < 0.9f - margin)) continue;
            ++meets;
            for (const RayTest& test : {RayTest{}, watertight}) {
              const int before = misses;
              misses += !brute_force(tree, ray, test).valid();
              misses += !traverse(tree, ray, 4, test).valid();
              misses += !traverse(tree, ray, 0, test).valid();
              if (misses > before && misses <= 3) ADD_FAILURE() << "pinhole at pixel " << x << ", " << y << ": " << describe(ray);
            }
          }
        }
        EXPECT_GT(meets, 10000 / rows);
        EXPECT_EQ(misses, 0) << "of " << meets << " rays";
      }
    }
  }
}

TEST(KdTree, IntersectTriangleRejectsDegenerateAndNaN) {
  Positions p = {{0, 0, 0}, {1, 1, 1}, {2, 2, 2},   // collinear
                 {0, 0, 0}, {0, 0, 0}, {0, 0, 0},   // a point
                 {0, 0, 0}, {1, 0, 0}, {0, 1, 0}};  // fine
  const FlatKdTree tree = build_kdtree(p);
  Ray ray;
  ray.origin = glm::vec3(0.1f, 0.1f, 1.0f);
  Hit hit;
  EXPECT_FALSE(intersect_triangle(tree, 0, ray, hit));
  EXPECT_FALSE(intersect_triangle(tree, 1, ray, hit));
  EXPECT_TRUE(intersect_triangle(tree, 2, ray, hit));
  EXPECT_FALSE(std::isnan(hit.t));
  // A ray in the triangle's plane: det == 0, no hit.
  Ray grazing;
  grazing.origin = glm::vec3(-1.0f, 0.1f, 0.0f);
  grazing.direction = glm::vec3(1.0f, 0.0f, 0.0f);
  Hit none;
  EXPECT_FALSE(intersect_triangle(tree, 2, grazing, none));
  // NaN rays and zero directions never hit and never hang.
  Ray nan_ray;
  nan_ray.origin = glm::vec3(std::numeric_limits<float>::quiet_NaN());
  EXPECT_FALSE(traverse(tree, nan_ray, 0).valid());
  Ray zero;
  zero.origin = glm::vec3(0.1f, 0.1f, 0.0f);
  zero.direction = glm::vec3(0.0f);
  for (int depth : kStackDepths) EXPECT_FALSE(traverse(tree, zero, depth).valid());
  // t exactly at tmin and tmax is accepted (closed interval).
  Ray exact;
  exact.origin = glm::vec3(0.25f, 0.25f, 1.0f);
  exact.tmin = 1.0f;
  exact.tmax = 1.0f;
  EXPECT_EQ(traverse(tree, exact).prim, 2);
  EXPECT_TRUE(occluded(tree, exact));
}

}  // namespace
}  // namespace mobirt
