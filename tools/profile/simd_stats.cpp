// mobirt_simd_stats: how well the traversal pass's rays fill llvmpipe's SIMD lanes.
//
// llvmpipe runs a fragment shader on 8 fragments at once (256-bit vectors): the two 2x2 quads
// side by side of one half of a 4x4 block, i.e. a 4x2 pixel tile. Its `if` never branches: both
// sides run under an execution mask, every iteration of a loop runs the whole body, and a loop
// runs until its last lane is done. The cost of the traversal pass is therefore
//   (loop iterations per 8-lane group, summed over groups) x (cost of one iteration),
// not the steps of the rays. This tool computes both from the CPU traversal, which counts the
// shader's steps exactly (src/accel/kdtree_traverse.cpp), for the rays of one frame:
//   lane steps   the rays' own steps (primary + shadow)
//   split loops  the shader as it was up to commit 24912a1: one loop for the closest hit, then
//                one loop per light for the shadow rays: sum over groups of
//                max(primary) + sum over lights of max(1, shadow_l)
//   one loop     every lane runs its primary and shadow rays one after the other in a single
//                loop: sum over groups of max(primary + shadows)
// and the lane occupancy (lane steps / 8 / group iterations) of each.
//
// Usage: mobirt_simd_stats SCENE [--mtl F] [--camera SPEC] [--light SPEC]... [--size WxH]
//        [--stack N] [--bins N] [--depth N] [--csv FILE]
#include <algorithm>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iostream>
#include <optional>
#include <string>
#include <vector>

#include "accel/kdtree.h"
#include "core/camera.h"
#include "core/error.h"
#include "raytree/hits.h"
#include "raytree/rays.h"
#include "raytree/secondary.h"
#include "render/renderer.h"
#include "scene/animation.h"
#include "scene/loader.h"
#include "scene/overrides.h"

namespace mobirt {
namespace {

struct RaySteps {
  uint32_t primary = 0;
  std::vector<uint32_t> shadow;  // one per light, 0 when that light casts no shadow ray
};

struct PassStats {
  uint64_t rays = 0, shadow_rays = 0;
  uint64_t primary_steps = 0, shadow_steps = 0;
  uint64_t interior_steps = 0, triangle_steps = 0;
  uint64_t groups = 0;
  uint64_t split_iterations = 0;  // split loops (see the header)
  uint64_t merged_iterations = 0;  // one loop
};

PassStats simulate(const FlatKdTree& tree, const Scene& scene, const RayBatch& rays, int stack,
                   std::vector<SurfaceHit>& hits) {
  PassStats s;
  const size_t lights = scene.lights.size();
  std::vector<RaySteps> steps(rays.count());
  hits.assign(rays.count(), SurfaceHit{});
  for (uint32_t i = 0; i < rays.count(); ++i) {
    const Ray ray = rays.ray(i);
    TraversalStats ts;
    const Hit h = traverse(tree, ray, stack, ts);
    steps[i].primary = uint32_t(ts.steps);
    steps[i].shadow.assign(lights, 0);
    s.primary_steps += ts.steps;
    s.interior_steps += ts.nodes_visited - ts.leaves_visited;
    s.triangle_steps += ts.triangles_tested;
    ++s.rays;
    if (!h.valid()) continue;
    uint32_t mask = 0;
    const auto shadows = shadow_rays(tree, scene.lights, h.prim, ray, h.t, ShadowSettings{});
    for (size_t l = 0; l < lights; ++l) {
      if (!shadows[l]) continue;
      TraversalStats ss;
      if (!occluded(tree, *shadows[l], stack, ss)) mask |= 1u << l;
      steps[i].shadow[l] = uint32_t(ss.steps);
      s.shadow_steps += ss.steps;
      s.interior_steps += ss.nodes_visited - ss.leaves_visited;
      s.triangle_steps += ss.triangles_tested;
      ++s.shadow_rays;
    }
    hits[i] = surface_hit(scene, tree, ray, h.prim);
    hits[i].mask = mask;
  }
  // llvmpipe's 8-lane groups: 4x2 pixel tiles of the pass (ray i at (i mod W, i div W)).
  const uint32_t w = rays.width, rows = rays.rows();
  for (uint32_t y0 = 0; y0 < rows; y0 += 2) {
    for (uint32_t x0 = 0; x0 < w; x0 += 4) {
      uint32_t max_primary = 0, max_merged = 0;
      std::vector<uint32_t> max_shadow(lights, 0);
      bool any = false;
      for (uint32_t y = y0; y < std::min(y0 + 2, rows); ++y) {
        for (uint32_t x = x0; x < std::min(x0 + 4, w); ++x) {
          const uint32_t i = y * w + x;
          if (i >= rays.count()) continue;
          any = true;
          const RaySteps& r = steps[i];
          max_primary = std::max(max_primary, r.primary);
          uint32_t all = r.primary;
          for (size_t l = 0; l < lights; ++l) {
            max_shadow[l] = std::max(max_shadow[l], r.shadow[l]);
            all += r.shadow[l];
          }
          max_merged = std::max(max_merged, all);
        }
      }
      if (!any) continue;
      ++s.groups;
      s.split_iterations += std::max(1u, max_primary);
      for (size_t l = 0; l < lights; ++l) s.split_iterations += std::max(1u, max_shadow[l]);
      s.merged_iterations += std::max(1u, max_merged);
    }
  }
  return s;
}

int run(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr,
                 "usage: mobirt_simd_stats SCENE [--mtl F] [--camera SPEC] [--light SPEC]... [--size WxH] "
                 "[--stack N] [--bins N] [--depth N] [--csv FILE]\n");
    return 2;
  }
  std::string scene_path = argv[1], csv;
  LoadOptions load;
  std::vector<Light> lights;
  std::optional<Camera> camera;
  int width = 400, height = 240, stack = 4, depth = 0;
  KdBuildOptions kd;
  for (int i = 2; i < argc; ++i) {
    const std::string a = argv[i];
    if (i + 1 >= argc) throw Error(ErrorKind::BadInput, a + " needs a value");
    const std::string v = argv[++i];
    if (a == "--mtl") load.mtl = v;
    else if (a == "--camera") camera = parse_camera(v);
    else if (a == "--light") lights.push_back(parse_light(v));
    else if (a == "--size") std::sscanf(v.c_str(), "%dx%d", &width, &height);
    else if (a == "--stack") stack = std::stoi(v);
    else if (a == "--bins") kd.bins = std::stoi(v);
    else if (a == "--depth") depth = std::stoi(v);
    else if (a == "--csv") csv = v;
    else throw Error(ErrorKind::BadInput, "unknown option " + a);
  }
  const AnimatedScene animation = load_animated_scene(scene_path, load);
  Scene scene = animation.rest();
  apply_overrides(scene, lights, camera);
  const Camera view = scene.camera ? *scene.camera
                                   : frame_box(scene.bounds(), 0.7854f, float(width) / float(height));
  const FlatKdTree tree = build_kdtree(scene.mesh.positions, kd);
  RayBatch rays = primary_rays(view, width, height);
  std::FILE* out = csv.empty() ? nullptr : std::fopen(csv.c_str(), "w");
  if (out) {
    std::fprintf(out, "generation,rays,shadow_rays,primary_steps,shadow_steps,interior_steps,triangle_steps,"
                      "groups,split_iterations,merged_iterations,occupancy_split,occupancy_merged\n");
  }
  std::printf("%s: %zu triangles, %zu lights, %dx%d, stack %d, %zu nodes\n", scene_path.c_str(),
              scene.mesh.triangle_count(), scene.lights.size(), width, height, stack, tree.nodes.size());
  std::printf("gen    rays  shadow  steps/ray  node/tri   groups  iter(split) occ    iter(1 loop) occ\n");
  for (int g = 0; g <= depth && rays.count() > 0; ++g) {
    std::vector<SurfaceHit> hits;
    const PassStats s = simulate(tree, scene, rays, stack, hits);
    const double lane_steps = double(s.primary_steps + s.shadow_steps);
    const double occ_split = lane_steps / (8.0 * double(s.split_iterations));
    const double occ_merged = lane_steps / (8.0 * double(s.merged_iterations));
    std::printf("%3d %7llu %7llu %10.2f %5.2f/%-5.2f %7llu %12llu %4.2f %14llu %4.2f\n", g,
                (unsigned long long)s.rays, (unsigned long long)s.shadow_rays,
                lane_steps / double(s.rays + s.shadow_rays),
                double(s.interior_steps) / double(s.rays + s.shadow_rays),
                double(s.triangle_steps) / double(s.rays + s.shadow_rays), (unsigned long long)s.groups,
                (unsigned long long)s.split_iterations, occ_split, (unsigned long long)s.merged_iterations,
                occ_merged);
    if (out) {
      std::fprintf(out, "%d,%llu,%llu,%llu,%llu,%llu,%llu,%llu,%llu,%llu,%.4f,%.4f\n", g,
                   (unsigned long long)s.rays, (unsigned long long)s.shadow_rays,
                   (unsigned long long)s.primary_steps, (unsigned long long)s.shadow_steps,
                   (unsigned long long)s.interior_steps, (unsigned long long)s.triangle_steps,
                   (unsigned long long)s.groups, (unsigned long long)s.split_iterations,
                   (unsigned long long)s.merged_iterations, occ_split, occ_merged);
    }
    if (g < depth) rays = next_generation(scene, tree.bounds, rays, hits, SecondarySettings{});
  }
  if (out) std::fclose(out);
  return 0;
}

}  // namespace
}  // namespace mobirt

int main(int argc, char** argv) {
  try {
    return mobirt::run(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "mobirt_simd_stats: error: %s\n", e.what());
    return 2;
  }
}
