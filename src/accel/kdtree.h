// Binned-SAH kd-tree (Shevtsov, Soupikov and Kapustin 2007), rebuilt from scratch every frame,
// flattened into the texel arrays of glsl/layout.h, and traversed on the CPU for tests and for the
// ray-tree code.
#pragma once

#include <glm/glm.hpp>

#include <cstdint>
#include <span>
#include <string_view>
#include <vector>

#include "core/geometry.h"
#include "core/memory.h"
#include "core/shapes.h"
#include "layout.h"
#include "texels.h"

namespace mobirt {

// The most bins a build accepts (the CLI's limit too).
constexpr int kKdMaxBins = 1024;

// How much work the build spends on the tree (--build).
// quality: exact split clipping of every straddling reference (the triangle clipped to the node
//   box, then split), the tree of the first builder, byte for byte.
// fast (the default): the triangle is only split by the plane and its parts' bounds cut to the
//   reference's box, a looser but conservative clip, and nodes of up to 3 references stay leaves
//   (kd_leaf_size; with leaves of 1 they split only when that saves 15 % of the leaf's cost,
//   small_split_gain), and nodes of up to 6 keep vertex fans together (kd_cluster_refs): about
//   half quality's build instructions on fish and the toaster before the cluster rule (13.8M
//   against 31.0M, 92.4M against 190.0M), which then took another 22-27 % of the build off, the
//   traversal passes as fast, for an SAH cost (pbrt's) well above quality's (README, "The kd-tree
//   build").
enum class KdBuildMode { Quality, Fast };

// "quality" / "fast"; parse_kd_build_mode returns false for any other text.
const char* kd_build_mode_name(KdBuildMode mode);
bool parse_kd_build_mode(std::string_view text, KdBuildMode& mode);

// The widest SIMD the build's binning and plane sweep may use: the best the CPU has (Auto: AVX2 or
// SSE2), or at most SSE2. Both count the same bins and choose the same planes, so the tree is the
// same byte for byte (tested); the cap is for that test.
enum class KdSweepSimd { Auto, Sse2 };

// SAH parameters, named as in pbrt's KdTreeAggregate.
struct KdBuildOptions {
  KdBuildMode build = KdBuildMode::Fast;
  int bins = 32;                 // candidate split planes per axis and node, 2 .. kKdMaxBins
  float traversal_cost = 1.0f;
  float intersection_cost = 80.0f;
  // SAH discount for splits that cut off empty space. -1: kd_empty_bonus's (pbrt's 0.5, 0.2 for a
  // fast tree built for a frame's walks).
  float empty_bonus = -1.0f;
  // The empty bonus applies only when the empty child is at least this fraction of the node's
  // width. 0 = pbrt's rule. The bonus otherwise rewards cutting ever thinner empty slabs off flat
  // walls, which burns the depth limit: on the Utah toasters (32 bins) 0 gives SAH 893, a largest
  // leaf of 110 and 35 ms builds; 0.05 gives SAH 669, largest leaf 44, 11% fewer traversal steps,
  // but 1.6x the nodes and 50 ms builds. With 0, 32 bins even score worse than 4 bins (SAH 725).
  float empty_bonus_min_width = 0.0f;
  // A node with this many references or fewer becomes a leaf without trying a split. -1: the build
  // mode's (kd_leaf_size: fast 3, quality 1).
  int max_leaf_prims = -1;
  // A node of at most small_node_refs references splits only when the split's SAH cost is below
  // (1 - small_split_gain) times the leaf's. pbrt's SAH overrates splitting a node of 2 or 3
  // references: with fast's 0.15 the project's meshes get 9-21 % fewer nodes and 0.8-1.6 %
  // fewer traversal steps per ray for an SAH cost 1-3 % higher (README, "The kd-tree build").
  // -1: the build mode's (fast 0.15; quality 0, the first builder's rule).
  float small_split_gain = -1.0f;
  int small_node_refs = 3;
  // A node of at most cluster_refs references takes no split that keeps all of them on one side
  // and sends some to the other side as well. Such a node is typically the fan of triangles
  // around a mesh vertex (6 of them in a regular mesh), which no plane near the vertex separates:
  // pbrt's SAH peels 2 or 3 of them off again and again, each split duplicating the whole fan,
  // down to the depth limit (on the toaster, 4,600 of its 7,100 splits of 6-reference nodes).
  // Cuts of empty space stay. -1: the build mode's (kd_cluster_refs: fast 6, quality 0, the first
  // builder's rule).
  int cluster_refs = -1;
  int max_depth = -1;            // -1: 8 + 1.3 log2(N), pbrt's rule
  // Past max_depth, nodes of more than deep_refs references keep splitting for up to deep_levels
  // more levels; smaller ones become leaves at max_depth as before. The depth limit bounds the
  // build, but the leaves it forces on large nodes cost every ray that enters them a long triangle
  // loop: this splits those few nodes only. -1: the build mode's (kd_deep_levels: fast 4,
  // quality 0, the first builder's rule). The tree's max_depth is the limit plus these levels.
  int deep_levels = -1;
  int deep_refs = 10;
  // The rays the tree is built for (0: unbounded, the SAH's own termination alone). A node splits
  // only when the rays expected to enter it save more walking than the split costs to build:
  //   rays * area(node) / area(root) * (leaf cost - split cost) > build_ref_cost * references,
  // all in the SAH's units (a traversal step = traversal_cost). A frame whose tree only a few rays
  // walk (the flat mirrors drawn, the shadow rays testing light buffers, the primary hits
  // rasterized) gets a shallow tree in a fraction of a full build's time. Even 100,000 rays trim
  // the full tree (the toaster's: 9,777 nodes against 32,101, SAH cost 438 against 317, CPU walks
  // 8 % longer): measured in mobirt bench, frames walked 70,000-130,000 times (the fish's glass,
  // the Utah toasters' tray) ran as fast or faster with such trees (README, *The tree a frame's
  // walks pay for*).
  double rays = 0.0;
  // What partitioning (and binning, clipping) one reference at one node costs, in SAH units, for
  // the rule above. Measured: kKdBuildRefCost's comment (kdtree_build.cpp).
  double build_ref_cost = -1.0;  // -1: kKdBuildRefCost
  // Only nodes of at most this many references become leaves by the rule above (a larger node
  // splits as the SAH says; 0 turns the rule off): a ray the rays' estimate left out (the next
  // frame's rays are not the last one's) never meets a leaf the rule made longer than this (the
  // SAH and the depth limit make their own leaves as without the rule), and the shader's step cap
  // (--max-steps) stays far. 64: on the toaster for 2,500 rays (build_ref_cost 100), 1.6 ms builds
  // (2 threads) and 25 CPU steps per ray, against 2.1 ms and 22 for 32, 4.5 ms and 23 for the full
  // tree (mobirt_kdprofile); in mobirt bench 16, 32 and 64 within the noise.
  int rays_leaf_limit = 64;
  bool split_clipping = true;    // clip each triangle to the child boxes (tighter references)
  // Split clipping clips the triangle polygon against the child boxes (Sutherland-Hodgman, in
  // double, bounds rounded outwards), which also drops references whose triangle misses a child
  // box that its bounding box overlaps. Off: references keep the triangle's bounding box (clipping
  // only the box to the child box would build the very same tree, since the binning clamps to the
  // node box anyway).
  KdSweepSimd sweep_simd = KdSweepSimd::Auto;  // the widest binning and plane sweep (the same tree for each)
  int threads = 0;               // build threads: 0 = all hardware threads, 1 = serial. The tree
                                 // is the same, byte for byte, for any count.
};

// The leaf size a build uses: options.max_leaf_prims when >= 0, else the build mode's: quality 1
// (pbrt's rule); fast 3: pbrt's SAH, which prices a triangle test at 80 node steps, splits nodes of
// 2 and 3 references that the traversal pass walks no faster for. Measured on fish, marbles, the
// toaster and the Utah toasters: 29-44 % fewer nodes, 5-35 % less build time, the traversal
// passes' JIT instructions per frame within 1 %, for an SAH cost (pbrt's costs) 12-33 % higher
// (README, "The kd-tree build").
int kd_leaf_size(const KdBuildOptions& options);

// The cluster rule a build uses (KdBuildOptions::cluster_refs): options.cluster_refs when >= 0,
// else the build mode's: fast 6 (measured: kdtree_build.cpp, kFastClusterRefs), quality 0 (none).
int kd_cluster_refs(const KdBuildOptions& options);

// The empty bonus a build uses (KdBuildOptions::empty_bonus): options.empty_bonus when >= 0, else
// pbrt's 0.5, and kKdWalksEmptyBonus (0.2) for a fast tree built for a frame's walks (rays > 0).
// A smaller bonus makes more nodes and a longer build for walks a few per cent shorter; the full
// tree's build is issue 14's and a still scene's, while a walks tree is built on the frame
// pipeline's worker beside the passes, which the shorter walks pay for (README, *The empty bonus*).
float kd_empty_bonus(const KdBuildOptions& options);
inline constexpr float kKdWalksEmptyBonus = 0.2f;

// The cost per reference a build's rays rule uses (KdBuildOptions::build_ref_cost): the option
// when >= 0, else kKdBuildRefCost (kdtree_build.cpp).
double kd_build_ref_cost(const KdBuildOptions& options);

// The levels past the depth limit a build gives large nodes (KdBuildOptions::deep_levels):
// options.deep_levels when >= 0, else the build mode's: fast 4, quality 0 (none).
int kd_deep_levels(const KdBuildOptions& options);

// Every index that reaches a shader is an exact float below 2^24: node indices, triangle texels,
// leaf-primitive texels. build_kdtree throws Error(BadInput) when a tree would need more.
constexpr size_t kKdIndexLimit = size_t(1) << 24;
// At most kKdIndexLimit / MOBIRT_TEXELS_PER_TRIANGLE triangles, and as many leaf references.
constexpr size_t kKdMaxTriangles = kKdIndexLimit / MOBIRT_TEXELS_PER_TRIANGLE;
constexpr size_t kKdMaxLeafEntries = kKdIndexLimit / MOBIRT_TEXELS_PER_TRIANGLE;

// The depth limit build_kdtree uses: options.max_depth when >= 0, else pbrt's
// round(8 + 1.3 floor(log2 N)) (8 for N <= 1).
int kdtree_depth_limit(size_t triangle_count, int max_depth_option);

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

// A tree's texel array. Its resize() writes nothing (core/memory.h): the build writes every texel
// once, in parallel, where a zeroing pass first would be serial (a 1M-triangle tree's leaf
// entries are about 100 MB).
using TexelArray = std::vector<glm::vec4, UnwrittenAllocator<glm::vec4>>;

// The tree as flat texel arrays, exactly as uploaded (see glsl/layout.h for each texel's meaning).
struct FlatKdTree {
  Aabb bounds;                          // the root box, passed to the shaders as a uniform
  TexelArray nodes;                     // one texel per node, root first
  TexelArray triangles;                 // MOBIRT_TEXELS_PER_TRIANGLE texels per primitive
  // The leaves' primitives in leaf order, MOBIRT_TEXELS_PER_TRIANGLE texels per entry: each a copy
  // of its primitive's texels with the index in it (glsl/layout.h, leaf_prim_texel in texels.h).
  TexelArray leaf_prims;
  KdBuildStats stats;
  int max_depth = 0;                    // depth limit used; bounds the full traversal stack

  size_t leaf_entries() const { return leaf_prims.size() / MOBIRT_TEXELS_PER_TRIANGLE; }
  // No tree, the arrays' memory kept for the next rebuild_kdtree.
  void clear() {
    bounds = Aabb{};
    nodes.clear();
    triangles.clear();
    leaf_prims.clear();
    stats = KdBuildStats{};
    max_depth = 0;
  }
  // The primitive of leaf entry `entry` (< leaf_entries()).
  int32_t leaf_prim(size_t entry) const {
    return static_cast<int32_t>(leaf_prim_texel::prim(leaf_prim_texel::of(leaf_prims, entry)));
  }
};

FlatKdTree build_kdtree(std::span<const glm::vec3> positions, const KdBuildOptions& options = {});
// Triangles and analytic primitives (core/shapes.h) in one tree: shape k is primitive
// positions.size() / 3 + k, its texels (glsl/layout.h) follow the triangles'. A shape's
// references keep its bounding box, cut to each child's box where a split crosses it (no clipping
// of the surface itself: conservative, and exact for a box).
FlatKdTree build_kdtree(std::span<const glm::vec3> positions, std::span<const Shape> shapes,
                        const KdBuildOptions& options = {});
// The same tree, built into `tree` (its previous contents replaced) so that the arrays keep their
// memory from one build to the next: an animation's per-frame build, as Embree's rtcCommitScene
// keeps a dynamic scene's memory. A new tree's arrays are fresh pages, zeroed by the kernel as
// they are first written, wherever glibc maps them anew: on a thread other than the main one (the
// frame pipeline's worker), arrays above its arena's 64 MiB heaps, in every build, whatever
// retain_freed_memory() asks. A 1M-triangle tree's leaf entries are 104 MB: built on a worker
// thread, 31,000-35,000 page faults a build against 3,800-4,300 (docs/performance-history.md,
// *Session 13: each build into the last tree's memory*).
// On an error the tree is left empty.
void rebuild_kdtree(FlatKdTree& tree, std::span<const glm::vec3> positions, std::span<const Shape> shapes,
                    const KdBuildOptions& options = {});

// No tree at all: only the primitives' texels (`triangles`, as a build writes them) and the scene
// box, for a frame that never walks a tree (--primary raster without secondary rays, its shadow
// rays, if any, testing light buffers: decoding reads the triangles, offsets read the box). nodes and leaf_prims are left empty.
// Non-finite input is refused as the build refuses it; on an error the tree is left empty.
void flatten_primitives(FlatKdTree& tree, std::span<const glm::vec3> positions, std::span<const Shape> shapes);

// Sets the empty-child flags of every interior node (glsl/layout.h: MOBIRT_NODE_BELOW_EMPTY,
// MOBIRT_NODE_ABOVE_EMPTY in the node's fourth component), with which traversal closes an empty
// leaf without visiting it. build_kdtree sets the same flags as it lays the tree out; a tree
// without flags (all 0) traverses the same, only visiting its empty leaves.
void mark_empty_children(FlatKdTree& tree);

struct Hit {
  int32_t prim = -1;   // -1 = miss
  float t = kInfinity;
  float u = 0.0f;      // barycentric weight of v1
  float v = 0.0f;      // barycentric weight of v2
  bool valid() const { return prim >= 0; }
};

// The ray/triangle test and the float precision of its arithmetic (glsl/layout.h: --intersect and
// --precision); the traversal pass is specialised to the same choice, so that the CPU traversal
// stays its oracle.
enum class IntersectTest { MollerTrumbore = MOBIRT_INTERSECT_MT, Watertight = MOBIRT_INTERSECT_WATERTIGHT };
enum class Precision { High = MOBIRT_PRECISION_HIGH, Medium = MOBIRT_PRECISION_MEDIUM };
struct RayTest {
  IntersectTest test = IntersectTest::MollerTrumbore;
  // Medium: the ray, the vertices and every intermediate result of the test rounded to fp16
  // (round_to_half, src/core/half.h); the traversal rounds the ray once at its start.
  Precision precision = Precision::High;
};

// The order of hits: smaller t first; at equal t the lower primitive index wins. Every CPU path
// (traversal, occlusion, brute force) uses it, so results do not depend on the order of tests.
inline bool closer_hit(float t, int32_t prim, const Hit& best) {
  return t < best.t || (t == best.t && best.prim >= 0 && prim < best.prim);
}

// The ray/triangle test `test` (Möller-Trumbore by default, single precision) on the triangle
// texels of prim, the same arithmetic as glsl/traverse.glsl's intersect_triangle_texels(). Accepts t in
// [ray.tmin, ray.tmax] that is closer_hit() than hit; then fills hit and returns true.
// A degenerate triangle (det == 0) or NaN anywhere is never a hit.
bool intersect_triangle(const FlatKdTree& tree, int32_t prim, const Ray& ray, Hit& hit, const RayTest& test = {});

// Any primitive: the triangle test above, or the sphere and cone tests of glsl/traverse.glsl
// (intersect_sphere, intersect_cone), operation for operation, in the same precision. A shape's
// hit has u = v = 0 (its surface record comes from the shape: raytree/hits.cpp).
bool intersect_primitive(const FlatKdTree& tree, int32_t prim, const Ray& ray, Hit& hit, const RayTest& test = {});
// Whether prim is an analytic primitive (its first texel's kind, glsl/layout.h).
bool is_analytic(const FlatKdTree& tree, int32_t prim);
// An analytic primitive's geometric normal at p, unnormalised, outwards, as glsl/traverse.glsl's
// analytic_normal() computes it for the shadow rays.
glm::vec3 analytic_normal(const FlatKdTree& tree, int32_t prim, const glm::vec3& p);

// Cost counters of one traversal call (reset by each call; sum them with +=).
// steps = the GPU loop's unit: one per interior node, one per triangle test, and one for an empty
// leaf that is visited (a leaf's node fetch shares its step with its first triangle test; empty
// leaves flagged in their parent are closed without a visit), as in glsl/traverse.glsl.
struct TraversalStats {
  uint64_t nodes_visited = 0;     // interior nodes and leaves
  uint64_t leaves_visited = 0;
  uint64_t triangles_tested = 0;
  uint64_t steps = 0;
  uint64_t pops = 0;              // short-stack entries popped
  uint64_t dropped = 0;           // oldest entries overwritten by a full ring
  uint64_t restarts = 0;          // kd-restarts from the root
  uint64_t capped = 0;            // 1 when max_steps stopped the traversal (result then: miss)

  TraversalStats& operator+=(const TraversalStats& o) {
    nodes_visited += o.nodes_visited;
    leaves_visited += o.leaves_visited;
    triangles_tested += o.triangles_tested;
    steps += o.steps;
    pops += o.pops;
    dropped += o.dropped;
    restarts += o.restarts;
    capped += o.capped;
    return *this;
  }
};

// The walk as the loops of glsl/traverse.glsl run it, for SIMD simulations
// (tools/profile/simd_stats.cpp): one segment per leaf with primitives, the iterations of the node
// loop that led to it (one per node fetched, interior or leaf, the first also closing the previous
// leaf) and the triangles tested there; a walk that ends by closing a leaf (not by an any-hit)
// ends with a segment of the node-loop iterations after the last leaf, plus the closing one, and
// no triangles. A walk that ends at a hit in its last leaf (closest or any hit) has no such
// segment: the pass returns right after the triangle loop.
struct TraversalTrace {
  struct Segment {
    uint32_t node_iterations = 0;
    uint32_t triangle_tests = 0;
    float tmax = 0.0f;  // a leaf's: the end of the ray's interval in it (where a walk resumed after it would start)
    // The node-loop iterations if a node's texel also held its children's splits, so that one
    // iteration decided at an interior node and at the interior child it chose (two levels a
    // fetch; a leaf, a pop and a restart still take an iteration of their own): an estimate for
    // tools/profile/simd_stats.cpp, not a layout the shader has.
    uint32_t two_level_iterations = 0;
  };
  std::vector<Segment> segments;
  // When the walk ended at a hit in a leaf: the node-loop iterations a lane that had not yet
  // tested that leaf (knowing only the hits of the leaves before it) would run past it, to its
  // next leaf with primitives (that leaf's fetch included) or to its end (the closing iteration
  // included): what a lane walking on speculatively spends.
  bool ended_at_hit = false;
  uint32_t past_hit_iterations = 0;
};

// Closest hit in [ray.tmin, ray.tmax] by traversal of the flattened arrays.
// stack_depth < 0: a full stack; 0: pure kd-restart; N > 0: a short stack of N entries that drops
// its oldest entry on overflow and restarts from the root when it runs dry (Horn et al. 2007),
// the same algorithm as glsl/traverse.glsl.
Hit traverse(const FlatKdTree& tree, const Ray& ray, int stack_depth = -1, const RayTest& test = {});

// The same, with counters and the GPU's loop cap: max_steps < 0 is unlimited; a ray that needs
// more than max_steps steps stops with a miss and stats.capped = 1 (the GPU then reports "capped"
// and the CPU traces that ray without a cap).
Hit traverse(const FlatKdTree& tree, const Ray& ray, int stack_depth, TraversalStats& stats,
             int64_t max_steps = -1, const RayTest& test = {}, TraversalTrace* trace = nullptr);

// Any hit in [ray.tmin, ray.tmax]: shadow rays.
bool occluded(const FlatKdTree& tree, const Ray& ray, int stack_depth = -1, const RayTest& test = {});

// The same, with counters and the loop cap (a capped call returns false with stats.capped = 1).
bool occluded(const FlatKdTree& tree, const Ray& ray, int stack_depth, TraversalStats& stats,
              int64_t max_steps = -1, const RayTest& test = {}, TraversalTrace* trace = nullptr);

// traverse() and occluded() with a full stack, the same hits, at the CPU's pace: no counters, no
// cap, no trace and no index checks (trees made by build_kdtree only).
Hit traverse_fast(const FlatKdTree& tree, const Ray& ray, const RayTest& test = {});
bool occluded_fast(const FlatKdTree& tree, const Ray& ray, const RayTest& test = {});

// Closest hit by testing every triangle: the oracle for the kd-tree tests.
Hit brute_force(const FlatKdTree& tree, const Ray& ray, const RayTest& test = {});

}  // namespace mobirt
