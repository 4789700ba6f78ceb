// KdBuild/<mesh>/<quality|fast>/threads:<n>: build_kdtree (binned SAH, default options but the
// build mode: 32 bins, pbrt costs, split clipping) from the triangle positions to the flat texel arrays, as every frame does.
// KdBuild/<mesh>/fast/rays:<r>/threads:2: the tree for r rays (KdBuildOptions::rays, what --tree
// walks builds for a frame whose passes walked r times: 2,500 as the toaster's bounce frames,
// 100,000 as a frame of traced rays), with the walks trees' empty bonus (kd_empty_bonus: 0.2).
// Counters: SAH cost, nodes, leaf references per triangle, triangles/s, and cpu_ms, the CPU time
// of all threads per build (compare with the real time to see how parallel a build ran).
#include <benchmark/benchmark.h>

#include <string>
#include <utility>

#include "accel/kdtree.h"
#include "bench_meshes.h"
#include "benchmarks.h"

namespace mobirt::bench {

void register_kdtree_benchmarks() {
  for (BenchMesh* mesh : build_meshes()) {
    for (KdBuildMode mode : {KdBuildMode::Quality, KdBuildMode::Fast}) {
      for (const auto& [threads, rays] : {std::pair{1, 0}, {2, 0}, {2, 2500}, {2, 100000}}) {
        if (rays > 0 && mode != KdBuildMode::Fast) continue;
        const std::string name = "KdBuild/" + mesh->name() + "/" + kd_build_mode_name(mode) +
                                 (rays > 0 ? "/rays:" + std::to_string(rays) : "") + "/threads:" + std::to_string(threads);
        benchmark::RegisterBenchmark(name.c_str(), [mesh, mode, threads, rays](benchmark::State& state) {
          const std::vector<glm::vec3>& positions = mesh->positions();
          KdBuildOptions options;
          options.build = mode;
          options.threads = threads;
          options.rays = rays;
          KdBuildStats stats;
          const double cpu_start = process_cpu_ms();
          // One tree rebuilt in every iteration, its arrays' memory kept, as the Embree benchmark
          // commits its one scene again (an animation's per-frame build).
          FlatKdTree tree;
          for (auto _ : state) {
            rebuild_kdtree(tree, positions, {}, options);
            benchmark::DoNotOptimize(tree.nodes.data());
            stats = tree.stats;
          }
          state.counters["cpu_ms"] = benchmark::Counter(process_cpu_ms() - cpu_start, benchmark::Counter::kAvgIterations);
          const double triangles = double(positions.size() / 3);
          state.counters["tris"] = triangles;
          state.counters["tris/s"] = benchmark::Counter(triangles, benchmark::Counter::kIsIterationInvariantRate);
          state.counters["sah"] = stats.sah_cost;
          state.counters["nodes"] = double(stats.nodes);
          state.counters["refs/tri"] = triangles > 0 ? double(stats.prim_references) / triangles : 0.0;
        })->Unit(benchmark::kMillisecond)->UseRealTime();
      }
    }
  }
}

}  // namespace mobirt::bench
