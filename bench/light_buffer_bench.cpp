// LightBufferBuild/<mesh>/threads:<n>: build_light_buffer at kAutoShadowCells (64 x 64 cells a
// face) for a point light above the mesh's box (a key light's place: every triangle lit from one
// side), into one buffer whose memory is kept from build to build, as each frame of an animation
// with shadows builds its lights' buffers (on the frame pipeline's worker). Counters: refs/tri and
// the mean list (LightBuffer::mean_list), cpu_ms (all threads, per build).
#include <benchmark/benchmark.h>

#include <algorithm>
#include <string>

#include "accel/light_buffer.h"
#include "bench_meshes.h"
#include "benchmarks.h"
#include "render/renderer.h"

namespace mobirt::bench {

void register_light_buffer_benchmarks() {
  for (BenchMesh* mesh : build_meshes()) {
    for (int threads : {1, 2}) {
      const std::string name = "LightBufferBuild/" + mesh->name() + "/threads:" + std::to_string(threads);
      benchmark::RegisterBenchmark(name.c_str(), [mesh, threads](benchmark::State& state) {
        const std::vector<glm::vec3>& positions = mesh->positions();
        glm::vec3 lo(1e30f), hi(-1e30f);
        for (const glm::vec3& p : positions) {
          lo = glm::min(lo, p);
          hi = glm::max(hi, p);
        }
        const glm::vec3 extent = hi - lo;
        const glm::vec3 light = 0.5f * (lo + hi) + glm::vec3(0.3f * extent.x, 0.5f * extent.y + std::max({extent.x, extent.y, extent.z}), 0.4f * extent.z);
        LightBuffer lb;
        const double cpu_start = process_cpu_ms();
        for (auto _ : state) {
          build_light_buffer(positions, light, kAutoShadowCells, lb, unsigned(threads));
          benchmark::DoNotOptimize(lb.prims.data());
        }
        state.counters["cpu_ms"] = benchmark::Counter(process_cpu_ms() - cpu_start, benchmark::Counter::kAvgIterations);
        const double triangles = double(positions.size() / 3);
        state.counters["tris"] = triangles;
        state.counters["refs/tri"] = triangles > 0 ? double(lb.prims.size()) / triangles : 0.0;
        state.counters["mean_list"] = lb.mean_list();
      })->Unit(benchmark::kMillisecond)->UseRealTime();
    }
  }
}

}  // namespace mobirt::bench
