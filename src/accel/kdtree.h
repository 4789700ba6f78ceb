// Binned-SAH kd-tree (Shevtsov, Soupikov and Kapustin 2007), rebuilt from scratch every frame,
// flattened into the texel arrays of glsl/layout.h, and traversed on the CPU for tests and for the
// ray-tree code.
#pragma once

#include <glm/glm.hpp>

#include <cstdint>
#include <span>
#include <vector>

#include "core/geometry.h"

namespace mobirt {

// SAH parameters, named as in pbrt's KdTreeAggregate.
struct KdBuildOptions {
  int bins = 32;                 // candidate split planes per axis and node
  float traversal_cost = 1.0f;
  float intersection_cost = 80.0f;
  float empty_bonus = 0.5f;      // SAH discount for splits that cut off empty space
  int max_leaf_prims = 1;        // a node with this many primitives or fewer becomes a leaf
  int max_depth = -1;            // -1: 8 + 1.3 log2(N), pbrt's rule
  bool split_clipping = true;    // clip each triangle to the child boxes (tighter references)
};

// Build statistics, for benchmarks and the accuracy report.
struct KdBuildStats {
  size_t nodes = 0;
  size_t leaves = 0;
  size_t empty_leaves = 0;
  size_t prim_references = 0;    // sum of leaf sizes
  int max_depth_reached = 0;
  size_t max_leaf_size = 0;
  double sah_cost = 0.0;         // expected cost of the finished tree under the options' costs
};

// The tree as flat texel arrays, exactly as uploaded (see glsl/layout.h for each texel's meaning).
struct FlatKdTree {
  Aabb bounds;                          // the root box, passed to the shaders as a uniform
  std::vector<glm::vec4> nodes;         // one texel per node, root first
  std::vector<float> prim_list;         // primitive indices of leaves with two or more prims
  std::vector<glm::vec4> triangles;     // MOBIRT_TEXELS_PER_TRIANGLE texels per primitive
  KdBuildStats stats;
  int max_depth = 0;                    // depth limit used; bounds the full traversal stack
};

FlatKdTree build_kdtree(std::span<const glm::vec3> positions, const KdBuildOptions& options = {});

struct Hit {
  int32_t prim = -1;   // -1 = miss
  float t = kInfinity;
  float u = 0.0f;      // barycentric weight of v1
  float v = 0.0f;      // barycentric weight of v2
  bool valid() const { return prim >= 0; }
};

// Möller-Trumbore on the triangle texels of prim; fills hit when it is closer than hit.t.
bool intersect_triangle(const FlatKdTree& tree, int32_t prim, const Ray& ray, Hit& hit);

// Closest hit in [ray.tmin, ray.tmax] by traversal of the flattened arrays.
// stack_depth < 0: a full stack; 0: pure kd-restart; N > 0: a short stack of N entries that drops
// its oldest entry on overflow and restarts from the root when it runs dry (Horn et al. 2007),
// the same algorithm as glsl/traverse.glsl.
Hit traverse(const FlatKdTree& tree, const Ray& ray, int stack_depth = -1);

// Any hit in [ray.tmin, ray.tmax]: shadow rays.
bool occluded(const FlatKdTree& tree, const Ray& ray, int stack_depth = -1);

// Closest hit by testing every triangle: the oracle for the kd-tree tests.
Hit brute_force(const FlatKdTree& tree, const Ray& ray);

}  // namespace mobirt
