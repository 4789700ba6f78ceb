// mobirt_simd_stats: how well the traversal pass's rays fill llvmpipe's SIMD lanes.
//
// llvmpipe runs a fragment shader on 8 fragments at once (256-bit vectors): the two 2x2 quads
// side by side of one half of a 4x4 block, a 4x2 pixel tile of the pass. Both sides of an `if` run
// under an execution mask (Mesa 25 skips a side that no lane takes), and a loop runs until the last
// of its lanes is done (at least once). The traversal pass therefore costs loop iterations per
// 8-lane group, not ray steps. This tool replays the CPU traversal
// (src/accel/kdtree_traverse.cpp, which the shader follows step for step) for the rays of one
// frame, groups the rays as llvmpipe does and counts, per generation of rays:
//   steps/ray         the rays' own steps (interior nodes / triangle tests per ray)
//   node, leaf iter.  iterations of glsl/traverse.glsl's node loop and triangle loop summed over
//                     the 8-lane groups (primary walk, then one walk per light)
//   node occ.         lane node-loop iterations / (8 x group node-loop iterations): the share of
//                     lanes doing useful work in the node loop
//   ... (8 in a row)  the same with each group made of 8 consecutive rays instead of a 4x2 tile
//                     of the ray texture (for comparison; secondary rays are ordered by
//                     order_for_traversal, as the renderer does: sorted by direction octant and
//                     origin when their octants are mixed, then laid out so that a tile holds 8
//                     consecutive rays; --ray-order sorted always sorts, tiles never does)
//   postponed leaves  the node-loop and triangle-loop iterations the same groups would run if a
//                     lane kept the leaf it reached and walked on (speculative traversal), with
//                     and without a vote between the lanes, against the pass as it is; see
//                     simulate_postponed() below
//   short stack       per ray (closest-hit and shadow walks): short-stack entries popped, the
//                     oldest entries a full stack dropped, and kd-restarts from the root
//   leaf steps in     the node-loop iterations if a parent's texel said where a child leaf's
//   their parents     entries are, so that a walk went from the parent's step to the triangle
//                     loop without the leaf's own step (not built; see node_iterations() below)
//   two levels a      the node-loop iterations if a node's texel held its children's splits too,
//   node fetch        so that one iteration decided at a node and at the interior child it chose
//                     (not built; TraversalTrace::Segment::two_level_iterations)
//   entry nodes       (primary rays) the leading steps from the root that every ray of a 4x2
//                     tile takes to one child, its interval unchanged: what a pass that started
//                     each tile's rays below the root could skip at most; see entry_chain() below
//   ropes             (secondary generations) the closest-hit walks along ropes instead of the
//                     short stack, from the root and from the leaf that holds the ray's origin
//                     (found on the CPU, its cost per ray given), with one to three node-loop
//                     iterations charged for leaving a leaf; see rope_walk() below
//   packets           (secondary generations) the closest-hit walks with each 4x2 tile walking one
//                     node sequence together (a packet traversal): node-loop and triangle-loop
//                     iterations against the pass's own walk; see packet_walk() below
//   continued in a    (secondary generations) the closest-hit walks stopped after 16 to 64 steps
//   second pass       at a leaf and walked on from that leaf's end by a second pass over the
//                     stopped rays packed 8 to a group: both passes' iterations against the one
//                     pass's; see estimate_continued() below
//   CPU walks         the generation's closest hits walked on the CPU on one thread, with
//                     traverse() (full stack) and with traverse_fast() (what --cpu-walks uses for
//                     small generations): time a ray, and the hits that differ (none expected)
//
// Usage: mobirt_simd_stats SCENE [--mtl F] [--camera SPEC] [--light SPEC]... [--size WxH]
//        [--stack N] [--bins N] [--leaf-size N] [--isect-cost C] [--depth N]
//        [--ray-order coherent|sorted|tiles] [--csv FILE]
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <optional>
#include <string>
#include <vector>

#include "accel/kdtree.h"
#include "core/camera.h"
#include "core/error.h"
#include "raytree/hits.h"
#include "raytree/ray_order.h"
#include "raytree/rays.h"
#include "raytree/secondary.h"
#include "profile_scene.h"

namespace mobirt {
namespace {

// The walks of one ray: its closest-hit walk, then one per light (empty: no shadow ray).
struct RayWalks {
  std::vector<TraversalTrace> walks;
  bool active = false;  // the fragment has a ray at all
};

struct LoopCounts {
  uint64_t node = 0, leaf = 0;        // group iterations
  uint64_t lane_node = 0, lane_leaf = 0;  // iterations the lanes needed
  LoopCounts& operator+=(const LoopCounts& o) {
    node += o.node;
    leaf += o.leaf;
    lane_node += o.lane_node;
    lane_leaf += o.lane_leaf;
    return *this;
  }
};

// What simulate_group() simulates: the pass as it is, postponed leaves without or with a vote
// (simulate_postponed()), leaf steps folded into their parents, or two levels a node fetch
// (node_iterations()).
enum class Walk { AsIs, Postponed, PostponedVote, FoldedLeaves, TwoLevels };

// The node-loop iterations of a segment. FoldedLeaves: as if a parent's texel said where a child
// leaf's entries are, so that a segment that walked down to its leaf (2 iterations or more) ends
// at the parent's step, without the leaf's own; a leaf taken from the stack or reached by a restart
// keeps that iteration (its pop or restart needs it). TwoLevels: as if a node's texel held its
// children's splits too (TraversalTrace::Segment::two_level_iterations).
uint32_t node_iterations(const TraversalTrace::Segment& seg, Walk walk) {
  if (walk == Walk::TwoLevels) return seg.two_level_iterations;
  const bool folds = walk == Walk::FoldedLeaves && seg.triangle_tests > 0 && seg.node_iterations >= 2;
  return seg.node_iterations - (folds ? 1 : 0);
}

// One traverse() call run by a group in lock step (see TraversalTrace for the segments); walk: AsIs,
// FoldedLeaves or TwoLevels (the postponed walks are simulate_postponed()'s).
LoopCounts simulate_walk(const std::vector<const TraversalTrace*>& lanes, Walk walk = Walk::AsIs) {
  LoopCounts c;
  size_t outer = 1;  // a loop runs at least once, even with every lane masked off
  for (const TraversalTrace* t : lanes) outer = std::max(outer, t->segments.size());
  for (size_t k = 0; k < outer; ++k) {
    uint32_t node = 1, leaf = 1;
    for (const TraversalTrace* t : lanes) {
      if (k >= t->segments.size()) continue;
      const uint32_t steps = node_iterations(t->segments[k], walk);
      node = std::max(node, steps);
      leaf = std::max(leaf, t->segments[k].triangle_tests);
      c.lane_node += steps;
      c.lane_leaf += t->segments[k].triangle_tests;
    }
    c.node += node;
    c.leaf += leaf;
  }
  return c;
}

// Postponed leaves (Aila and Laine 2009, "speculative traversal"), estimated from the same walks:
// a lane that reaches a leaf with primitives keeps it and walks on toward the next one; the leaf
// loop then tests the kept leaf and, when the lane reached it, the next. Each lane tests its
// leaves in the same order as now, so the hits and the step counts would not change (the steps
// walked past a leaf that ends the ray would be dropped). Two ways to end the node loop:
//   no vote  each lane walks until it holds two leaves (or its walk ends), the loop runs until
//            the last lane does (GLSL ES 1.00 has no cross-lane operation);
//   vote     the loop ends once every lane holds a leaf or is done (subgroupAll, Vulkan only);
//            lanes that found theirs early walk on meanwhile, and keep their progress.
// A lane whose walk ended at a hit walks on past that leaf for nothing: the trace measures how far
// (TraversalTrace::past_hit_iterations, the CPU walk continued with the hit set aside). Without a
// vote the group waits for it; with one it only fills iterations the group runs anyway.
struct LaneWalk {
  std::vector<TraversalTrace::Segment> leaves;  // the segments that end at a leaf with primitives
  uint32_t end = 0;       // node iterations of the walk's last segment (after its last leaf)
  bool hit = false;       // the walk ended at a hit (at its last leaf)
  uint32_t past_hit = 0;  // the node iterations of walking on past that leaf
  size_t next = 0;        // the leaf the lane walks toward
  uint32_t walked = 0;    // node iterations already walked toward it
  bool done = false;

  explicit LaneWalk(const TraversalTrace& trace)
      : hit(trace.ended_at_hit), past_hit(trace.past_hit_iterations) {
    for (const TraversalTrace::Segment& seg : trace.segments) {
      if (seg.triangle_tests > 0) {
        leaves.push_back(seg);
      } else {
        end = seg.node_iterations;
      }
    }
    hit = hit && !leaves.empty();
  }
  // Node iterations still needed to reach the next leaf, or the end of the walk.
  uint32_t need() const {
    const uint32_t total = next < leaves.size() ? leaves[next].node_iterations : end;
    return total - std::min(walked, total);
  }
};

LoopCounts simulate_postponed(const std::vector<const TraversalTrace*>& lanes, bool vote) {
  LoopCounts c;
  std::vector<LaneWalk> ls;
  for (const TraversalTrace* t : lanes) ls.emplace_back(*t);
  bool first_round = true;
  for (;;) {
    bool active = false;
    for (const LaneWalk& x : ls) active = active || !x.done;
    if (!active && !first_round) break;  // a loop runs at least once
    first_round = false;
    // The node loop's length: until every lane holds a leaf (vote), or holds two (no vote).
    uint32_t node = 1;
    for (const LaneWalk& x : ls) {
      if (x.done) continue;
      uint32_t n = x.need();
      if (!vote && x.next < x.leaves.size()) {
        if (x.next + 1 < x.leaves.size()) {
          n += x.leaves[x.next + 1].node_iterations;
        } else {
          n += x.hit ? x.past_hit : x.end;
        }
      }
      node = std::max(node, n);
    }
    uint32_t leaf = 1;
    for (LaneWalk& x : ls) {
      if (x.done) continue;
      uint32_t budget = node;
      const uint32_t n0 = x.need();
      c.lane_node += n0;
      budget -= n0;
      if (x.next >= x.leaves.size()) {  // the walk ends without another leaf
        x.done = true;
        continue;
      }
      uint32_t tests = x.leaves[x.next].triangle_tests;
      ++x.next;
      x.walked = 0;
      if (x.next >= x.leaves.size() && x.hit) {  // this leaf ends the ray: walking on is dropped
        c.lane_node += vote ? 0 : x.past_hit;
        x.done = true;
      } else {
        const uint32_t n1 = x.need();
        if (n1 <= budget) {
          c.lane_node += n1;
          if (x.next < x.leaves.size()) {  // reached its second leaf: tested too
            tests += x.leaves[x.next].triangle_tests;
            ++x.next;
            if (x.next >= x.leaves.size() && x.hit) x.done = true;
          } else {
            x.done = true;  // reached the end of its walk
          }
        } else {
          c.lane_node += budget;
          x.walked = budget;
        }
      }
      c.lane_leaf += tests;
      leaf = std::max(leaf, tests);
    }
    c.node += node;
    c.leaf += leaf;
  }
  return c;
}

// A group's traversal pass: the closest-hit walk, then the light loop.
LoopCounts simulate_group(const std::vector<const RayWalks*>& lanes, size_t lights, Walk walk = Walk::AsIs) {
  LoopCounts c;
  for (size_t w = 0; w <= lights; ++w) {
    std::vector<const TraversalTrace*> walks;
    for (const RayWalks* r : lanes) walks.push_back(&r->walks[w]);
    const bool postponed = walk == Walk::Postponed || walk == Walk::PostponedVote;
    c += postponed ? simulate_postponed(walks, walk == Walk::PostponedVote)
                   : simulate_walk(walks, walk);
  }
  return c;
}

struct PassStats {
  uint64_t rays = 0, shadow_rays = 0;
  TraversalStats steps;
  LoopCounts tiled, linear;  // 4x2 tiles of the ray texture; 8 consecutive rays
  LoopCounts postponed, voted;  // 4x2 tiles, postponed leaves without and with a vote
  LoopCounts folded;            // 4x2 tiles, leaf steps folded into their parents
  LoopCounts two_levels;        // 4x2 tiles, two levels a node fetch (an estimate, not built)
  LoopCounts shadow_tiled;      // 4x2 tiles, the light loop's walks alone
  LoopCounts shadow_dense;      // the same walks packed 8 to a group, in tile order
  // The light-loop group iterations `tiled` counts for tiles without a shadow ray for that light
  // (simulate_walk charges a loop at least one iteration; the shader skips it: a miss returns
  // before the light loop, and `if (lit)` is skipped when no lane takes it).
  uint64_t shadow_idle_groups = 0;
};

// Each ray's closest-hit walk as the pass runs it, and its hit, in ray order (the rope estimate
// compares its walks with these).
struct ClosestWalks {
  std::vector<TraversalTrace> traces;
  std::vector<Hit> hits;
};

// primary_stats, when given: each ray's own closest-hit walk statistics, in ray order; closest,
// when given: the closest-hit walks and hits.
PassStats simulate(const FlatKdTree& tree, const Scene& scene, const RayBatch& rays, int stack,
                   std::vector<SurfaceHit>& hits, std::vector<TraversalStats>* primary_stats = nullptr,
                   ClosestWalks* closest = nullptr) {
  PassStats s;
  const size_t lights = scene.lights.size();
  std::vector<RayWalks> walks(rays.count());
  hits.assign(rays.count(), SurfaceHit{});
  for (uint32_t i = 0; i < rays.count(); ++i) {
    RayWalks& r = walks[i];
    r.active = true;
    r.walks.resize(lights + 1);
    const Ray ray = rays.ray(i);
    TraversalStats ts;
    const Hit h = traverse(tree, ray, stack, ts, -1, RayTest{}, &r.walks[0]);
    if (closest) closest->hits.push_back(h);
    if (primary_stats) primary_stats->push_back(ts);
    s.steps += ts;
    ++s.rays;
    if (!h.valid()) continue;
    uint32_t mask = 0;
    const auto shadows = shadow_rays(tree, scene.lights, h.prim, ray, h.t, ShadowSettings{});
    for (size_t l = 0; l < lights; ++l) {
      if (!shadows[l]) continue;
      TraversalStats ss;
      if (!occluded(tree, *shadows[l], stack, ss, -1, RayTest{}, &r.walks[l + 1])) mask |= 1u << l;
      s.steps += ss;
      ++s.shadow_rays;
    }
    hits[i] = surface_hit(scene, tree, ray, h.prim);
    hits[i].mask = mask;
  }
  const RayWalks idle{std::vector<TraversalTrace>(lights + 1), false};
  auto lane = [&](uint64_t i) { return i < rays.count() ? &walks[i] : &idle; };
  // llvmpipe's groups: 4x2 tiles of the pass (ray i at (i mod W, i div W)).
  const uint32_t w = rays.width, rows = rays.rows();
  std::vector<std::vector<const TraversalTrace*>> packed(lights);  // per light, its shadow walks in tile order
  for (uint32_t y0 = 0; y0 < rows; y0 += 2) {
    for (uint32_t x0 = 0; x0 < w; x0 += 4) {
      std::vector<const RayWalks*> group;
      for (uint32_t y = y0; y < std::min(y0 + 2, rows); ++y) {
        for (uint32_t x = x0; x < std::min(x0 + 4, w); ++x) group.push_back(lane(uint64_t(y) * w + x));
      }
      s.tiled += simulate_group(group, lights);
      s.postponed += simulate_group(group, lights, Walk::Postponed);
      s.voted += simulate_group(group, lights, Walk::PostponedVote);
      s.folded += simulate_group(group, lights, Walk::FoldedLeaves);
      s.two_levels += simulate_group(group, lights, Walk::TwoLevels);
      // The light loop's walks alone (a lane without a shadow ray, an idle one included, has an
      // empty walk), and each shadow walk for the packed estimate below.
      for (size_t l = 0; l < lights; ++l) {
        std::vector<const TraversalTrace*> tile;
        for (const RayWalks* r : group) {
          tile.push_back(&r->walks[l + 1]);
          if (!r->walks[l + 1].segments.empty()) packed[l].push_back(&r->walks[l + 1]);
        }
        if (std::any_of(tile.begin(), tile.end(), [](const TraversalTrace* t) { return !t->segments.empty(); })) {
          s.shadow_tiled += simulate_walk(tile);
        } else {
          ++s.shadow_idle_groups;  // a group with no shadow ray skips the walk
        }
      }
    }
  }
  for (uint64_t i0 = 0; i0 < rays.count(); i0 += 8) {
    std::vector<const RayWalks*> group;
    for (uint64_t i = i0; i < i0 + 8; ++i) group.push_back(lane(i));
    s.linear += simulate_group(group, lights);
  }
  // Shadow walks compacted (an estimate, not built): a pass of its own over the shadow rays
  // alone, packed 8 to a group in the 4x2 tiles' order (collected by the tile loop above),
  // against the light loop as it runs in the tiles now.
  for (const std::vector<const TraversalTrace*>& walks_of_light : packed) {
    for (size_t i0 = 0; i0 < walks_of_light.size(); i0 += 8) {
      std::vector<const TraversalTrace*> group(walks_of_light.begin() + long(i0),
                                               walks_of_light.begin() + long(std::min(walks_of_light.size(), i0 + 8)));
      s.shadow_dense += simulate_walk(group);
    }
  }
  if (closest) {
    closest->traces.reserve(walks.size());
    for (RayWalks& r : walks) closest->traces.push_back(std::move(r.walks[0]));
  }
  return s;
}

// Entry nodes (an estimate, not built): a primary ray's first steps from the root often take one
// child without touching the ray's interval (near side only, or far side only, the child not an
// empty leaf that closes the walk): the pass leaves tmin, tmax, the stack and every flag as they
// were and only moves `node`. A tile whose rays all share such a chain could start at its last
// node, with the chain's steps added to its step count (the cap stays exact) and its kd-restarts
// going there too. entry_chain() walks the chain with the shader's decisions (glsl/traverse.glsl,
// the scene box slab test included) and returns its nodes; empty when the ray misses the box.
std::vector<uint32_t> entry_chain(const FlatKdTree& tree, const Ray& ray) {
  std::vector<uint32_t> chain;
  // The box test traverse() itself makes (the CPU walk's, which the shader's slab test follows).
  float t0 = 0.0f, t1 = 0.0f;
  if (tree.nodes.empty() || tree.bounds.empty() || !intersect_aabb(tree.bounds, ray, t0, t1)) return chain;
  const glm::vec3 inv = 1.0f / ray.direction;
  uint32_t node = 0;
  chain.push_back(node);
  for (;;) {
    const glm::vec4 n = tree.nodes[node];
    if (node_texel::is_leaf(n)) break;
    const int a = int(node_texel::axis(n));
    const float split = node_texel::split(n);
    const float oa = ray.origin[a];
    const float tsplit = (split - oa) * inv[a];
    // d_a <= 0 as the CPU walk tests it (the shader: its inv_s, -inf for a zero component).
    const bool below_first = oa < split || (oa == split && ray.direction[a] <= 0.0f);
    const bool near_only = tsplit > t1 || tsplit <= 0.0f || std::isnan(tsplit);
    const bool far_only = !near_only && tsplit < t0;
    if (!near_only && !far_only) break;
    const bool below = below_first != far_only;
    if (below ? node_texel::below_empty(n) : node_texel::above_empty(n)) break;
    node = below ? node + 1 : uint32_t(node_texel::above_child(n));
    chain.push_back(node);
  }
  return chain;
}

// Over the 4x2 tiles of a primary generation: the steps of the chain every in-box ray of the tile
// shares (the longest common prefix), summed over the in-box rays (once per descent from the
// root: the first and each kd-restart), and those rays' interior steps; and per tile the group
// iterations of the node loop its first descent would skip (the chain's steps: every lane that
// walks skips them together).
struct EntryEstimate {
  uint64_t in_box = 0, shared_steps = 0, own_steps = 0, interior_steps = 0, group_iterations = 0;
};

// walk_stats: each ray's closest-hit walk statistics (simulate()'s primary_stats).
EntryEstimate estimate_entry_nodes(const FlatKdTree& tree, const RayBatch& rays,
                                   const std::vector<TraversalStats>& walk_stats) {
  EntryEstimate e;
  std::vector<std::vector<uint32_t>> chains(rays.count());
  std::vector<uint64_t> descents(rays.count(), 0);
  for (uint32_t i = 0; i < rays.count(); ++i) {
    chains[i] = entry_chain(tree, rays.ray(i));
    if (chains[i].empty()) continue;
    ++e.in_box;
    const TraversalStats& ts = walk_stats[i];
    e.interior_steps += ts.nodes_visited - ts.leaves_visited;
    descents[i] = 1 + ts.restarts;
    e.own_steps += (chains[i].size() - 1) * descents[i];
  }
  const uint32_t w = rays.width, rows = rays.rows();
  for (uint32_t y0 = 0; y0 < rows; y0 += 2) {
    for (uint32_t x0 = 0; x0 < w; x0 += 4) {
      const std::vector<uint32_t>* first = nullptr;
      size_t common = 0;
      uint64_t lane_descents = 0;
      for (uint32_t y = y0; y < std::min(y0 + 2, rows); ++y) {
        for (uint32_t x = x0; x < std::min(x0 + 4, w); ++x) {
          const uint64_t i = uint64_t(y) * w + x;
          if (i >= rays.count() || chains[i].empty()) continue;
          lane_descents += descents[i];
          if (!first) {
            first = &chains[i];
            common = first->size();
            continue;
          }
          size_t k = 0;
          while (k < common && k < chains[i].size() && chains[i][k] == (*first)[k]) ++k;
          common = k;
        }
      }
      if (!first) continue;
      e.shared_steps += lane_descents * (common - 1);
      e.group_iterations += common - 1;
    }
  }
  return e;
}

// Ropes (Havran 1998; Popov, Günther, Seidel and Slusallek 2007, "Stackless KD-Tree Traversal
// for High Performance GPU Ray Tracing"), estimated, not built. Each leaf keeps its box and, per
// face, a rope: the node on the other side of that face (optimised: the deepest node whose box
// still covers the whole face), -1 past the scene's box. A walk enters a leaf at its entry point,
// tests the leaf's triangles, ends at a hit before the leaf's exit or else follows the exit face's
// rope, walking down from the rope's node to the leaf that holds the exit point. No stack and no restart; a secondary ray
// could start at the leaf that holds its origin, found on the CPU, instead of walking down from
// the root (session 32 counted that first descent at 14-20 of the secondary walks' 21-43
// node-loop iterations).
struct Ropes {
  std::vector<std::array<int32_t, 6>> rope;  // per node (leaves only): face 2a (lo), 2a + 1 (hi)
  std::vector<Aabb> box;                     // per node
};

Ropes make_ropes(const FlatKdTree& tree) {
  Ropes r;
  r.rope.assign(tree.nodes.size(), {-1, -1, -1, -1, -1, -1});
  r.box.assign(tree.nodes.size(), Aabb{});
  if (tree.nodes.empty()) return r;
  // Popov et al.'s optimisation: down from the rope's node while one child covers the whole face.
  const auto optimise = [&](int32_t node, int face, const Aabb& b) {
    const int fa = face / 2;
    const bool hi = (face & 1) != 0;
    while (node >= 0) {
      const glm::vec4 n = tree.nodes[size_t(node)];
      if (node_texel::is_leaf(n)) break;
      const int a = int(node_texel::axis(n));
      const float s = node_texel::split(n);
      const int32_t below = node + 1, above = int32_t(node_texel::above_child(n));
      if (a == fa) {
        node = hi ? below : above;  // the child that touches the face
      } else if (s >= b.hi[a]) {
        node = below;
      } else if (s <= b.lo[a]) {
        node = above;
      } else {
        break;
      }
    }
    return node;
  };
  struct Item {
    int32_t node;
    Aabb box;
    std::array<int32_t, 6> rope;
  };
  std::vector<Item> stack{{0, tree.bounds, {-1, -1, -1, -1, -1, -1}}};
  while (!stack.empty()) {
    Item it = stack.back();
    stack.pop_back();
    for (int f = 0; f < 6; ++f) it.rope[size_t(f)] = optimise(it.rope[size_t(f)], f, it.box);
    r.box[size_t(it.node)] = it.box;
    r.rope[size_t(it.node)] = it.rope;
    const glm::vec4 n = tree.nodes[size_t(it.node)];
    if (node_texel::is_leaf(n)) continue;
    const int a = int(node_texel::axis(n));
    const float s = node_texel::split(n);
    const int32_t below = it.node + 1, above = int32_t(node_texel::above_child(n));
    Item b{below, it.box, it.rope}, c{above, it.box, it.rope};
    b.box.hi[a] = s;
    b.rope[size_t(2 * a + 1)] = above;
    c.box.lo[a] = s;
    c.rope[size_t(2 * a)] = below;
    stack.push_back(c);
    stack.push_back(b);
  }
  return r;
}

// Down from `node` to the leaf that holds p (a point on the plane of a split goes the way the
// direction leaves it, as the walk's below_first does). steps: the nodes fetched, the leaf's included.
int32_t locate(const FlatKdTree& tree, int32_t node, const glm::vec3& p, const glm::vec3& d, uint32_t& steps) {
  for (;;) {
    ++steps;
    const glm::vec4 n = tree.nodes[size_t(node)];
    if (node_texel::is_leaf(n)) return node;
    const int a = int(node_texel::axis(n));
    const float s = node_texel::split(n);
    const bool below = p[a] < s || (p[a] == s && d[a] <= 0.0f);
    node = below ? node + 1 : int32_t(node_texel::above_child(n));
  }
}

// A closest-hit walk along the ropes, from the leaf that holds the ray's entry point (start_leaf
// >= 0: that leaf, found elsewhere; -1: walked down from the root). The trace as TraversalTrace's
// segments: node-loop iterations (nodes fetched on the way down from a rope, plus exit_cost per
// leaf left: its box and ropes read and the exit face chosen) up to a leaf with primitives, then
// its triangle tests (the segments' two_level_iterations stay 0: only the pass's own walks are
// counted for two levels a fetch). A leaf's triangles are tested over the whole ray, the hit kept
// as the pass keeps it, and a hit at or before the leaf's exit ends the walk. Stops after
// kMaxRopeSteps leaves (a guard for the tool; the walk moves forward by a leaf each time).
constexpr uint32_t kMaxRopeSteps = 1u << 20;

Hit rope_walk(const FlatKdTree& tree, const Ropes& ropes, const Ray& ray, int32_t start_leaf, uint32_t exit_cost,
              TraversalTrace& trace) {
  trace = TraversalTrace{};
  Hit best;
  float t0 = 0.0f, t1 = 0.0f;
  if (tree.nodes.empty() || tree.bounds.empty() || !intersect_aabb(tree.bounds, ray, t0, t1)) return best;
  const glm::vec3 inv = 1.0f / ray.direction;
  uint32_t iterations = 0;
  int32_t node = start_leaf >= 0 ? start_leaf : 0;
  float t = t0;
  for (uint32_t leaves = 0; leaves < kMaxRopeSteps; ++leaves) {
    node = locate(tree, node, ray.origin + t * ray.direction, ray.direction, iterations);
    const Aabb& b = ropes.box[size_t(node)];
    float exit = kInfinity;
    int face = -1;
    for (int a = 0; a < 3; ++a) {
      if (ray.direction[a] == 0.0f) continue;
      const bool up = ray.direction[a] > 0.0f;
      const float te = ((up ? b.hi[a] : b.lo[a]) - ray.origin[a]) * inv[a];
      if (te < exit) {
        exit = te;
        face = 2 * a + (up ? 1 : 0);
      }
    }
    const glm::vec4 n = tree.nodes[size_t(node)];
    const uint32_t count = uint32_t(node_texel::leaf_count(n));
    if (count > 0) {
      // Hits anywhere on the ray are kept, as the pass keeps them (a triangle on the scene box's
      // face can be hit a rounding past the last leaf's exit); one within this leaf ends the walk.
      const size_t first = size_t(node_texel::leaf_first(n));
      for (size_t e = first; e < first + count; ++e) intersect_primitive(tree, tree.leaf_prim(e), ray, best);
      trace.segments.push_back({iterations, count});
      iterations = 0;
      if (best.valid() && best.t <= exit) {
        trace.ended_at_hit = true;
        return best;
      }
    }
    iterations += exit_cost;
    if (face < 0 || !(exit < t1)) break;
    node = ropes.rope[size_t(node)][size_t(face)];
    if (node < 0) break;
    t = std::max(t, exit);
  }
  trace.segments.push_back({iterations, 0});
  return best;
}

// Per secondary generation: the closest-hit walks (the light loop aside) in the 4x2 tiles, as the
// pass walks them now (`walks`, simulate()'s) and along ropes, from the root and from the origin's
// leaf, with 1 to 3 node-loop iterations charged for leaving a leaf; the hits compared with the
// pass's walk.
constexpr int kRopeExitCosts = 3;

struct RopeEstimate {
  LoopCounts as_is, from_root;
  LoopCounts from_leaf[kRopeExitCosts];  // exit cost 1, 2, 3
  uint64_t rays = 0;
  uint64_t differ_root = 0, differ_leaf = 0;  // rays whose hit (primitive or t) is not the walk's
  uint64_t located = 0, locate_steps = 0;
  double locate_ns = 0.0;  // the CPU's point location per located ray
};

RopeEstimate estimate_ropes(const FlatKdTree& tree, const RayBatch& rays, const ClosestWalks& walks) {
  RopeEstimate e;
  const Ropes ropes = make_ropes(tree);
  const uint32_t n = rays.count();
  const std::vector<TraversalTrace>& as_is = walks.traces;
  std::vector<TraversalTrace> root(n);
  std::vector<std::vector<TraversalTrace>> leaf(kRopeExitCosts, std::vector<TraversalTrace>(n));
  std::vector<int32_t> start(n, -1);
  std::vector<Ray> ray_of(n);
  for (uint32_t i = 0; i < n; ++i) ray_of[i] = rays.ray(i);
  // The start leaves as the CPU would find them: the origin located from the root, for the rays
  // that start inside the scene's box (the others enter it from the root).
  const Aabb& sb = tree.bounds;
  const auto inside = [&](const glm::vec3& o) {
    return o.x >= sb.lo.x && o.y >= sb.lo.y && o.z >= sb.lo.z && o.x <= sb.hi.x && o.y <= sb.hi.y && o.z <= sb.hi.z;
  };
  const auto t_begin = std::chrono::steady_clock::now();
  for (uint32_t i = 0; i < n; ++i) {
    if (!inside(ray_of[i].origin)) continue;
    uint32_t steps = 0;
    start[i] = locate(tree, 0, ray_of[i].origin, ray_of[i].direction, steps);
    e.locate_steps += steps;
    ++e.located;
  }
  e.locate_ns = 1e9 * std::chrono::duration<double>(std::chrono::steady_clock::now() - t_begin).count() /
                double(std::max<uint64_t>(e.located, 1));
  const auto differs = [](const Hit& a, const Hit& b) { return a.prim != b.prim || (a.valid() && a.t != b.t); };
  for (uint32_t i = 0; i < n; ++i) {
    const Ray& ray = ray_of[i];
    const Hit& h = walks.hits[i];
    if (differs(h, rope_walk(tree, ropes, ray, -1, 1, root[i]))) ++e.differ_root;
    for (int c = 0; c < kRopeExitCosts; ++c) {
      const Hit r = rope_walk(tree, ropes, ray, start[i], uint32_t(c + 1), leaf[size_t(c)][i]);
      if (c == 0 && differs(h, r)) ++e.differ_leaf;
    }
    ++e.rays;
  }
  const TraversalTrace idle;
  const uint32_t w = rays.width, rows = rays.rows();
  for (uint32_t y0 = 0; y0 < rows; y0 += 2) {
    for (uint32_t x0 = 0; x0 < w; x0 += 4) {
      std::vector<const TraversalTrace*> g[2 + kRopeExitCosts];
      for (uint32_t y = y0; y < std::min(y0 + 2, rows); ++y) {
        for (uint32_t x = x0; x < std::min(x0 + 4, w); ++x) {
          const uint64_t i = uint64_t(y) * w + x;
          const bool in = i < n;
          g[0].push_back(in ? &as_is[i] : &idle);
          g[1].push_back(in ? &root[i] : &idle);
          for (int c = 0; c < kRopeExitCosts; ++c) g[2 + c].push_back(in ? &leaf[size_t(c)][i] : &idle);
        }
      }
      e.as_is += simulate_walk(g[0]);
      e.from_root += simulate_walk(g[1]);
      for (int c = 0; c < kRopeExitCosts; ++c) e.from_leaf[c] += simulate_walk(g[2 + c]);
    }
  }
  return e;
}

// Packet walks (an estimate, not built): the 8 lanes of a 4x2 tile walk one node sequence
// together (Wald 2004's packet kd-tree traversal), each lane with its own interval and its own hit,
// so that the node and the triangle a group reads are the same for every lane (one load instead
// of eight). A node's child is taken if any live lane needs it; when lanes need both, the group
// goes first to the child that most of them see as near and keeps the other on a full stack with
// every lane's interval (a lane whose direction sees the other order walks back to front, still
// exact: a lane drops a node whose interval starts past its best hit). Empty children are never
// visited (the parent's flags). Counted: nodes fetched (the node loop), triangles tested by the
// group (the triangle loop: one iteration a primitive of a leaf that a live lane reaches), pops
// that find no live lane (no fetch), the deepest stack, and rays whose hit differs from the pass's.
struct PacketCounts {
  uint64_t node = 0, leaf = 0, empty_pops = 0, differ = 0, groups = 0;
  uint32_t max_stack = 0;
};

void packet_walk(const FlatKdTree& tree, const std::vector<Ray>& lanes, std::vector<Hit>& best, PacketCounts& c) {
  const size_t n = lanes.size();
  best.assign(n, Hit{});
  struct Entry {
    int32_t node;
    std::array<float, 8> lo, hi;
    uint32_t live;
  };
  Entry cur{0, {}, {}, 0};
  std::array<glm::vec3, 8> inv{};
  for (size_t i = 0; i < n; ++i) {
    float t0 = 0.0f, t1 = 0.0f;
    if (tree.nodes.empty() || tree.bounds.empty() || !intersect_aabb(tree.bounds, lanes[i], t0, t1)) continue;
    cur.lo[i] = t0;
    cur.hi[i] = t1;
    cur.live |= 1u << i;
    inv[i] = 1.0f / lanes[i].direction;
  }
  if (!cur.live) return;
  ++c.groups;
  std::vector<Entry> stack;
  const auto cull = [&](Entry& e) {
    for (size_t i = 0; i < n; ++i) {
      if ((e.live >> i & 1u) && e.lo[i] > best[i].t) e.live &= ~(1u << i);
    }
  };
  for (;;) {
    if (!cur.live) {
      if (stack.empty()) return;
      cur = stack.back();
      stack.pop_back();
      cull(cur);
      if (!cur.live) ++c.empty_pops;
      continue;
    }
    const glm::vec4 nd = tree.nodes[size_t(cur.node)];
    ++c.node;
    if (node_texel::is_leaf(nd)) {
      const uint32_t count = uint32_t(node_texel::leaf_count(nd));
      const size_t first = size_t(node_texel::leaf_first(nd));
      for (size_t e = first; e < first + count; ++e) {
        ++c.leaf;
        for (size_t i = 0; i < n; ++i) {
          if (cur.live >> i & 1u) intersect_primitive(tree, tree.leaf_prim(e), lanes[i], best[i]);
        }
      }
      cur.live = 0;
      continue;
    }
    const int a = int(node_texel::axis(nd));
    const float s = node_texel::split(nd);
    const int32_t below = cur.node + 1, above = int32_t(node_texel::above_child(nd));
    const bool empty[2] = {node_texel::below_empty(nd), node_texel::above_empty(nd)};
    Entry child[2] = {{below, cur.lo, cur.hi, 0}, {above, cur.lo, cur.hi, 0}};
    int votes = 0;  // lanes that want both children and see "below" first, minus those that see "above" first
    for (size_t i = 0; i < n; ++i) {
      if (!(cur.live >> i & 1u)) continue;
      const glm::vec3& o = lanes[i].origin;
      const glm::vec3& d = lanes[i].direction;
      const float tsplit = (s - o[a]) * inv[i][a];
      const bool below_first = o[a] < s || (o[a] == s && d[a] <= 0.0f);
      const int near = below_first ? 0 : 1, far = 1 - near;
      if (tsplit > cur.hi[i] || tsplit <= 0.0f || std::isnan(tsplit)) {
        if (!empty[near]) child[near].live |= 1u << i;
      } else if (tsplit < cur.lo[i]) {
        if (!empty[far]) child[far].live |= 1u << i;
      } else {
        if (!empty[near]) {
          child[near].live |= 1u << i;
          child[near].hi[i] = tsplit;
        }
        if (!empty[far]) {
          child[far].live |= 1u << i;
          child[far].lo[i] = tsplit;
        }
        if (!empty[near] && !empty[far]) votes += below_first ? 1 : -1;
      }
    }
    if (child[0].live && child[1].live) {
      const int first = votes >= 0 ? 0 : 1;
      stack.push_back(child[1 - first]);
      c.max_stack = std::max(c.max_stack, uint32_t(stack.size()));
      cur = child[first];
    } else {
      cur = child[0].live ? child[0] : child[1];
    }
  }
}

// The closest-hit walks of a generation as packets of the pass's 4x2 tiles, against the pass's
// own walks on the same tiles (`walks`, simulate()'s).
struct PacketEstimate {
  LoopCounts as_is;
  PacketCounts packet;
};

PacketEstimate estimate_packets(const FlatKdTree& tree, const RayBatch& rays, const ClosestWalks& walks) {
  PacketEstimate e;
  const uint32_t n = rays.count(), w = rays.width, rows = rays.rows();
  const TraversalTrace idle;
  for (uint32_t y0 = 0; y0 < rows; y0 += 2) {
    for (uint32_t x0 = 0; x0 < w; x0 += 4) {
      std::vector<const TraversalTrace*> g;
      std::vector<Ray> lanes;
      std::vector<uint64_t> index;
      for (uint32_t y = y0; y < std::min(y0 + 2, rows); ++y) {
        for (uint32_t x = x0; x < std::min(x0 + 4, w); ++x) {
          const uint64_t i = uint64_t(y) * w + x;
          g.push_back(i < n ? &walks.traces[i] : &idle);
          if (i < n) {
            lanes.push_back(rays.ray(uint32_t(i)));
            index.push_back(i);
          }
        }
      }
      e.as_is += simulate_walk(g);
      std::vector<Hit> best;
      packet_walk(tree, lanes, best, e.packet);
      for (size_t k = 0; k < lanes.size(); ++k) {
        const Hit& h = walks.hits[index[k]];
        if (h.prim != best[k].prim || (h.valid() && h.t != best[k].t)) ++e.packet.differ;
      }
    }
  }
  return e;
}

// Walks continued in a second pass (an estimate, not built): the pass stops a closest-hit walk at
// the first leaf it closes after `cap` steps (node iterations and triangle tests), writing the
// leaf instead of a hit; the CPU packs the walks so stopped 8 to a group (in the order of the
// generation, tiles of 8 consecutive rays) and a second pass walks them on from the root, from
// the end of that leaf's interval (no hit lies before it: every leaf before it was closed without
// one). Counted: the node-loop and triangle-loop group iterations of both passes against the one
// pass's, the walks continued, and rays whose hit differs from the one pass's walk.
struct ContinueEstimate {
  LoopCounts as_is, first, second;
  uint64_t continued = 0, differ = 0;
};

ContinueEstimate estimate_continued(const FlatKdTree& tree, const RayBatch& rays, const ClosestWalks& walks,
                                    int stack, uint32_t cap) {
  ContinueEstimate e;
  const uint32_t n = rays.count(), w = rays.width, rows = rays.rows();
  std::vector<TraversalTrace> first(n);
  std::vector<TraversalTrace> resumed;
  std::vector<uint32_t> resumed_ray;
  std::vector<int64_t> resumed_of(n, -1);
  for (uint32_t i = 0; i < n; ++i) {
    const TraversalTrace& t = walks.traces[i];
    uint32_t steps = 0;
    size_t stop = t.segments.size();
    for (size_t k = 0; k < t.segments.size(); ++k) {
      const TraversalTrace::Segment& seg = t.segments[k];
      steps += seg.node_iterations + seg.triangle_tests;
      // A leaf closed with the walk going on after it: not the walk's last segment, nor the one
      // before a last segment that is only the closing iteration (an empty stack and the scene's
      // end: the pass knows the walk is over there and writes its miss).
      const bool ends_at_close = k + 2 == t.segments.size() && t.segments[k + 1].triangle_tests == 0 &&
                                 t.segments[k + 1].node_iterations <= 1;
      if (steps >= cap && seg.triangle_tests > 0 && k + 1 < t.segments.size() && !ends_at_close) {
        stop = k;
        break;
      }
    }
    if (stop == t.segments.size()) {
      first[i] = t;
      continue;
    }
    first[i].segments.assign(t.segments.begin(), t.segments.begin() + std::ptrdiff_t(stop) + 1);
    Ray r = rays.ray(i);
    r.tmin = t.segments[stop].tmax;
    TraversalStats stats;
    TraversalTrace trace;
    const Hit h = traverse(tree, r, stack, stats, -1, {}, &trace);
    const Hit& want = walks.hits[i];
    if (h.prim != want.prim || (want.valid() && h.t != want.t)) ++e.differ;
    resumed_of[i] = int64_t(resumed.size());
    resumed.push_back(std::move(trace));
    ++e.continued;
  }
  const TraversalTrace idle;
  for (uint32_t y0 = 0; y0 < rows; y0 += 2) {
    for (uint32_t x0 = 0; x0 < w; x0 += 4) {
      std::vector<const TraversalTrace*> g0, g1;
      for (uint32_t y = y0; y < std::min(y0 + 2, rows); ++y) {
        for (uint32_t x = x0; x < std::min(x0 + 4, w); ++x) {
          const uint64_t i = uint64_t(y) * w + x;
          g0.push_back(i < n ? &walks.traces[i] : &idle);
          g1.push_back(i < n ? &first[i] : &idle);
        }
      }
      e.as_is += simulate_walk(g0);
      e.first += simulate_walk(g1);
    }
  }
  // The continued walks in the generation's order (tile by tile: the k-th ray of the order sits at
  // simd_tile_place(k)), 8 to a group.
  const uint32_t tiled = simd_tiled_rays(rays);
  std::vector<const TraversalTrace*> g;
  for (uint32_t k = 0; k < n; ++k) {
    const int64_t r = resumed_of[simd_tile_place(k, tiled, w)];
    if (r < 0) continue;
    g.push_back(&resumed[size_t(r)]);
    if (g.size() == 8) {
      e.second += simulate_walk(g);
      g.clear();
    }
  }
  if (!g.empty()) {
    while (g.size() < 8) g.push_back(&idle);
    e.second += simulate_walk(g);
  }
  return e;
}

double occupancy(uint64_t lane, uint64_t group) { return group ? double(lane) / (8.0 * double(group)) : 0.0; }

int run(int argc, char** argv) {
  const profile::ProfileScene p = profile::load_profile_scene(
      argc, argv,
      "usage: mobirt_simd_stats SCENE [--mtl F] [--camera SPEC] [--light SPEC]... [--size WxH] [--stack N] "
      "[--bins N] [--leaf-size N] [--isect-cost C] [--depth N] [--ray-order coherent|sorted|tiles] [--csv FILE]");
  const Scene& scene = p.scene;
  const FlatKdTree& tree = p.tree;
  const int width = p.width, height = p.height, stack = p.stack, depth = p.depth;
  const std::string& scene_path = p.path;
  const std::string& csv = p.csv;
  RayBatch rays = primary_rays(p.camera, width, height);
  std::FILE* out = csv.empty() ? nullptr : std::fopen(csv.c_str(), "w");
  if (out) {
    std::fprintf(out, "generation,rays,shadow_rays,steps,interior_steps,triangle_tests,empty_leaves,"
                      "node_iterations,leaf_iterations,node_occupancy,leaf_occupancy,"
                      "node_iterations_linear,leaf_iterations_linear,node_occupancy_linear\n");
  }
  std::printf("%s: %zu triangles, %zu lights, %dx%d, stack %d, %zu nodes, SAH %.0f\n", scene_path.c_str(),
              scene.mesh.triangle_count(), scene.lights.size(), width, height, stack, tree.nodes.size(),
              tree.stats.sah_cost);
  std::printf("gen    rays  shadow  steps/ray  interior/tri/empty   node iter. occ.  leaf iter. occ."
              "   (8 in a row: node iter. occ.)\n");
  for (int g = 0; g <= depth && rays.count() > 0; ++g) {
    std::vector<SurfaceHit> hits;
    std::vector<TraversalStats> walk_stats;  // generation 0's, for the entry-node estimate
    ClosestWalks closest;                     // the secondary generations', for the rope estimate
    const PassStats s = simulate(tree, scene, rays, stack, hits, g == 0 ? &walk_stats : nullptr,
                                 g > 0 ? &closest : nullptr);
    {  // The CPU's walks of the generation's closest hits on one thread (--cpu-walks walks small
       // generations with traverse_fast): traverse()'s full stack against traverse_fast, the same hits.
      const uint32_t count = rays.count();
      std::vector<Hit> a(count), b(count);
      const auto t0 = std::chrono::steady_clock::now();
      for (uint32_t i = 0; i < count; ++i) a[i] = traverse(tree, rays.ray(i), -1, RayTest{});
      const auto t1 = std::chrono::steady_clock::now();
      for (uint32_t i = 0; i < count; ++i) b[i] = traverse_fast(tree, rays.ray(i), RayTest{});
      const auto t2 = std::chrono::steady_clock::now();
      uint32_t differ = 0;
      for (uint32_t i = 0; i < count; ++i) differ += (a[i].prim != b[i].prim || (a[i].valid() && a[i].t != b[i].t)) ? 1 : 0;
      const double ms_a = std::chrono::duration<double, std::milli>(t1 - t0).count();
      const double ms_b = std::chrono::duration<double, std::milli>(t2 - t1).count();
      std::printf("    CPU walks, one thread: traverse %.2f ms (%.0f ns a ray), traverse_fast %.2f ms (%.0f ns a ray), hits that differ %u\n",
                  ms_a, 1e6 * ms_a / std::max(count, 1u), ms_b, 1e6 * ms_b / std::max(count, 1u), differ);
    }
    const double n = double(s.rays + s.shadow_rays);
    const uint64_t interior = s.steps.nodes_visited - s.steps.leaves_visited;
    const uint64_t empty = s.steps.steps - interior - s.steps.triangles_tested;
    std::printf("%3d %7llu %7llu %10.2f %6.2f/%.2f/%.2f %12llu %4.2f %11llu %4.2f   (%12llu %4.2f)\n", g,
                (unsigned long long)s.rays, (unsigned long long)s.shadow_rays, double(s.steps.steps) / n,
                double(interior) / n, double(s.steps.triangles_tested) / n, double(empty) / n,
                (unsigned long long)s.tiled.node, occupancy(s.tiled.lane_node, s.tiled.node),
                (unsigned long long)s.tiled.leaf, occupancy(s.tiled.lane_leaf, s.tiled.leaf),
                (unsigned long long)s.linear.node, occupancy(s.linear.lane_node, s.linear.node));
    std::printf("    short stack: per ray %.3f pops, %.3f entries dropped, %.3f kd-restarts from the root\n",
                double(s.steps.pops) / n, double(s.steps.dropped) / n, double(s.steps.restarts) / n);
    // Weighted 1 to 2: a node iteration is one texel fetch and the split decision, a leaf
    // iteration three fetches and the intersection (the toaster's JIT samples, jit_dump.sh, put
    // about 65 % in the node loop and 35 % in the triangle loop over 497K and 160K group
    // iterations: 1 to 1.7).
    for (const auto& [label, counts] : {std::pair<const char*, const LoopCounts*>{"no vote", &s.postponed},
                                        std::pair<const char*, const LoopCounts*>{"vote", &s.voted}}) {
      std::printf("    postponed leaves, %-7s node iter. %12llu (x%.3f)  leaf iter. %11llu (x%.3f)  1:2 weighted x%.3f\n",
                  label, (unsigned long long)counts->node, double(counts->node) / double(s.tiled.node),
                  (unsigned long long)counts->leaf, double(counts->leaf) / double(s.tiled.leaf),
                  double(counts->node + 2 * counts->leaf) / double(s.tiled.node + 2 * s.tiled.leaf));
    }
    if (s.shadow_rays > 0) {
      std::printf("    shadow walks: in the tiles node iter. %llu (occ. %.2f), leaf iter. %llu (occ. %.2f); packed 8 to a "
                  "group node iter. %llu (x%.3f), leaf iter. %llu (x%.3f); of all the pass's node iter. %.1f %%\n",
                  (unsigned long long)s.shadow_tiled.node, occupancy(s.shadow_tiled.lane_node, s.shadow_tiled.node),
                  (unsigned long long)s.shadow_tiled.leaf, occupancy(s.shadow_tiled.lane_leaf, s.shadow_tiled.leaf),
                  (unsigned long long)s.shadow_dense.node,
                  double(s.shadow_dense.node) / double(std::max<uint64_t>(s.shadow_tiled.node, 1)),
                  (unsigned long long)s.shadow_dense.leaf,
                  double(s.shadow_dense.leaf) / double(std::max<uint64_t>(s.shadow_tiled.leaf, 1)),
                  // The pass's node iterations without the walks the shader skips (see PassStats).
                  100.0 * double(s.shadow_tiled.node) /
                      double(std::max<uint64_t>(s.tiled.node - std::min(s.tiled.node, s.shadow_idle_groups), 1)));
    }
    std::printf("    leaf steps in their parents: node iter. %12llu (x%.3f), lanes' node iter. x%.3f\n",
                (unsigned long long)s.folded.node, double(s.folded.node) / double(s.tiled.node),
                double(s.folded.lane_node) / double(std::max<uint64_t>(s.tiled.lane_node, 1)));
    std::printf("    two levels a node fetch: node iter. %12llu (x%.3f), lanes' node iter. x%.3f\n",
                (unsigned long long)s.two_levels.node, double(s.two_levels.node) / double(s.tiled.node),
                double(s.two_levels.lane_node) / double(std::max<uint64_t>(s.tiled.lane_node, 1)));
    if (g > 0) {
      // Weighted 1 to 2 as above: a node iteration against a leaf iteration.
      const RopeEstimate r = estimate_ropes(tree, rays, closest);
      const auto line = [&](const char* label, const LoopCounts& c) {
        std::printf("      %-34s node iter. %10llu (x%.3f)  leaf iter. %10llu (x%.3f)  1:2 weighted x%.3f\n", label,
                    (unsigned long long)c.node, double(c.node) / double(std::max<uint64_t>(r.as_is.node, 1)),
                    (unsigned long long)c.leaf, double(c.leaf) / double(std::max<uint64_t>(r.as_is.leaf, 1)),
                    double(c.node + 2 * c.leaf) / double(std::max<uint64_t>(r.as_is.node + 2 * r.as_is.leaf, 1)));
      };
      std::printf("    ropes (closest-hit walks alone, 4x2 tiles): rays whose hit differs from the walk's %llu (from "
                  "the root) and %llu (from the start leaf) of %llu; the CPU's start leaves %.1f nodes and %.0f ns a "
                  "ray (one thread, %llu rays located)\n",
                  (unsigned long long)r.differ_root, (unsigned long long)r.differ_leaf, (unsigned long long)r.rays,
                  double(r.locate_steps) / double(std::max<uint64_t>(r.located, 1)), r.locate_ns,
                  (unsigned long long)r.located);
      line("as the pass walks now", r.as_is);
      line("ropes from the root, exit 1 iter.", r.from_root);
      line("ropes from the start leaf, exit 1", r.from_leaf[0]);
      line("ropes from the start leaf, exit 2", r.from_leaf[1]);
      line("ropes from the start leaf, exit 3", r.from_leaf[2]);
      for (const uint32_t cap : {16u, 24u, 32u, 48u, 64u}) {
        const ContinueEstimate c = estimate_continued(tree, rays, closest, stack, cap);
        const LoopCounts both = [&] { LoopCounts x = c.first; x += c.second; return x; }();
        std::printf("    continued in a second pass after %2u steps: %6llu walks (%.1f %%), node iter. %llu + %llu (x%.3f), "
                    "leaf iter. %llu + %llu (x%.3f), 1:2 weighted x%.3f, hits that differ %llu\n",
                    cap, (unsigned long long)c.continued, 100.0 * double(c.continued) / double(std::max<uint32_t>(rays.count(), 1)),
                    (unsigned long long)c.first.node, (unsigned long long)c.second.node,
                    double(both.node) / double(std::max<uint64_t>(c.as_is.node, 1)),
                    (unsigned long long)c.first.leaf, (unsigned long long)c.second.leaf,
                    double(both.leaf) / double(std::max<uint64_t>(c.as_is.leaf, 1)),
                    double(both.node + 2 * both.leaf) / double(std::max<uint64_t>(c.as_is.node + 2 * c.as_is.leaf, 1)),
                    (unsigned long long)c.differ);
      }
      const PacketEstimate pk = estimate_packets(tree, rays, closest);
      std::printf("    packets (closest-hit walks, 4x2 tiles walking one node sequence): node iter. %llu (x%.3f of "
                  "the pass's %llu), triangle iter. %llu (x%.3f of %llu), pops with no live lane %llu, deepest stack "
                  "%u, rays whose hit differs %llu\n",
                  (unsigned long long)pk.packet.node, double(pk.packet.node) / double(std::max<uint64_t>(pk.as_is.node, 1)),
                  (unsigned long long)pk.as_is.node, (unsigned long long)pk.packet.leaf,
                  double(pk.packet.leaf) / double(std::max<uint64_t>(pk.as_is.leaf, 1)), (unsigned long long)pk.as_is.leaf,
                  (unsigned long long)pk.packet.empty_pops, pk.packet.max_stack, (unsigned long long)pk.packet.differ);
    }
    if (out) {
      std::fprintf(out, "%d,%llu,%llu,%llu,%llu,%llu,%llu,%llu,%llu,%.4f,%.4f,%llu,%llu,%.4f\n", g,
                   (unsigned long long)s.rays, (unsigned long long)s.shadow_rays,
                   (unsigned long long)s.steps.steps, (unsigned long long)interior,
                   (unsigned long long)s.steps.triangles_tested, (unsigned long long)empty,
                   (unsigned long long)s.tiled.node, (unsigned long long)s.tiled.leaf,
                   occupancy(s.tiled.lane_node, s.tiled.node), occupancy(s.tiled.lane_leaf, s.tiled.leaf),
                   (unsigned long long)s.linear.node, (unsigned long long)s.linear.leaf,
                   occupancy(s.linear.lane_node, s.linear.node));
    }
    if (g == 0) {
      const EntryEstimate e = estimate_entry_nodes(tree, rays, walk_stats);
      const double in_box = double(std::max<uint64_t>(e.in_box, 1));
      std::printf("    entry nodes: %llu rays enter the scene box; per such ray %.2f leading one-child steps shared by its "
                  "4x2 tile (%.2f its own) of %.2f interior steps (%.1f %%); the node loop's group iterations %llu "
                  "fewer of %llu (%.1f %%, the light loop's included)\n",
                  (unsigned long long)e.in_box, double(e.shared_steps) / in_box, double(e.own_steps) / in_box,
                  double(e.interior_steps) / in_box,
                  100.0 * double(e.shared_steps) / double(std::max<uint64_t>(e.interior_steps, 1)),
                  (unsigned long long)e.group_iterations, (unsigned long long)s.tiled.node,
                  100.0 * double(e.group_iterations) / double(std::max<uint64_t>(s.tiled.node, 1)));
    }
    if (g < depth) {
      rays = next_generation(scene, tree.bounds, rays, SurfaceHits::copy_of(hits), SecondarySettings{});
      // As the renderer does (--ray-order tiles: the tiling alone, to measure what the sort buys).
      std::printf("    next generation: %.1f %% of consecutive rays change octant (sorted at %.0f %% or more)\n",
                  100.0 * octant_change_rate(rays), 100.0 * kSortAboveOctantChanges);
      order_for_traversal(rays, tree.bounds, p.sort_above);
    }
  }
  if (out) std::fclose(out);
  return 0;
}

}  // namespace
}  // namespace mobirt

int main(int argc, char** argv) { return mobirt::profile::run_tool("mobirt_simd_stats", argc, argv, mobirt::run); }
