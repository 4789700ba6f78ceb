// mobirt_embree_rays: Embree 3 on the rays of mobirt's traversal pass, for the Mrays/s ratio.
//
// The traversal pass of one frame traces the primary rays (closest hit) and, from their hits, one
// shadow ray per light (any hit). This tool makes the same rays (primary_rays(); hits from the CPU
// kd-tree traversal, which equals the GPU's; shadow rays from shadow_rays()) and traces them with
// Embree 3 on 2 threads (or --threads N), each ray on its own (rtcIntersect1 / rtcOccluded1),
// --repeat times, and prints the median Mrays/s of:
//   intersect1      every ray, primary and shadow, with rtcIntersect1 (closest hit): the baseline
//                   of issue 5's traversal target (Embree rtcIntersect1 on the same rays)
//   mixed           primaries with rtcIntersect1, shadow rays with rtcOccluded1: what the pass does
// plus Embree's BVH build time (RTC_BUILD_QUALITY_MEDIUM, the default).
//
// Usage: mobirt_embree_rays SCENE [--camera SPEC] [--light SPEC]... [--mtl F] [--size WxH]
//        [--repeat N] [--threads N]
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "baseline/embree_engine.h"
#include "core/parallel.h"
#include "raytree/hits.h"
#include "raytree/rays.h"
#include "profile_scene.h"

namespace mobirt {
namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

int run(int argc, char** argv) {
  int threads = 2;
  std::vector<char*> args;
  for (int i = 0; i < argc; ++i) {
    if (std::strcmp(argv[i], "--threads") == 0 && i + 1 < argc) {
      threads = std::max(1, std::atoi(argv[++i]));
    } else {
      args.push_back(argv[i]);
    }
  }
  const profile::ProfileScene p = profile::load_profile_scene(
      int(args.size()), args.data(),
      "usage: mobirt_embree_rays SCENE [--camera SPEC] [--light SPEC]... [--mtl F] [--size WxH] [--repeat N] "
      "[--threads N]");

  // The pass's rays: primaries, and the shadow rays of their hits (hits as the GPU finds them).
  const RayBatch batch = primary_rays(p.camera, p.width, p.height);
  std::vector<Ray> primary, shadow;
  for (uint32_t i = 0; i < batch.count(); ++i) {
    const Ray ray = batch.ray(i);
    primary.push_back(ray);
    const Hit hit = traverse(p.tree, ray, p.stack);
    if (!hit.valid()) continue;
    for (const std::optional<Ray>& s : shadow_rays(p.tree, p.scene.lights, hit.prim, ray, hit.t, ShadowSettings{})) {
      if (s) shadow.push_back(*s);
    }
  }

  // The same Embree the benchmark baseline uses (src/baseline/), here with a static MEDIUM BVH.
  EmbreeEngine embree(EmbreeOptions{unsigned(threads), false});
  const auto build_start = Clock::now();
  embree.build(p.scene);
  const double build_ms = seconds_since(build_start) * 1e3;
  const std::vector<glm::vec3>& positions = p.scene.mesh.positions;

  std::vector<double> intersect_ms, mixed_ms;
  std::atomic<size_t> primary_hits{0}, occluded{0};
  for (int r = 0; r < std::max(1, p.repeat) + 1; ++r) {  // the first round warms up
    primary_hits = 0;
    occluded = 0;
    const uint32_t n = uint32_t(primary.size() + shadow.size());
    auto start = Clock::now();
    parallel_for(n, unsigned(threads), [&](uint32_t i) {
      embree.closest(i < primary.size() ? primary[i] : shadow[i - primary.size()]);
    });
    const double a = seconds_since(start) * 1e3;
    start = Clock::now();
    parallel_for(n, unsigned(threads), [&](uint32_t i) {
      if (i < primary.size()) {
        if (embree.closest(primary[i]).valid()) ++primary_hits;
      } else if (embree.occluded(shadow[i - primary.size()])) {
        ++occluded;
      }
    });
    const double b = seconds_since(start) * 1e3;
    if (r > 0) {
      intersect_ms.push_back(a);
      mixed_ms.push_back(b);
    }
  }

  const double rays = double(primary.size() + shadow.size());
  const double ia = median(intersect_ms), mx = median(mixed_ms);
  std::printf("%s: %zu triangles, %zux%d... %zu primary + %zu shadow rays, Embree 3, %d threads, median of %d\n",
              p.path.c_str(), positions.size() / 3, size_t(p.width), p.height, primary.size(), shadow.size(),
              threads, p.repeat);
  std::printf("bvh build            %8.2f ms\n", build_ms);
  std::printf("intersect1           %8.2f ms  %6.2f Mrays/s   (every ray closest-hit)\n", ia, rays / (ia * 1e3));
  std::printf("intersect1+occluded1 %8.2f ms  %6.2f Mrays/s   (%zu primary hits, %zu shadow rays occluded)\n", mx,
              rays / (mx * 1e3), size_t(primary_hits), size_t(occluded));
  return 0;
}

}  // namespace
}  // namespace mobirt

int main(int argc, char** argv) { return mobirt::profile::run_tool("mobirt_embree_rays", argc, argv, mobirt::run); }
