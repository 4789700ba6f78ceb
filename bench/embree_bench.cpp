// EmbreeBuild/<mesh>/threads:<n>: the baseline a user would pick instead, Embree 3's BVH build on
// the same triangles as KdBuild, set up as a per-frame rebuild: a dynamic scene
// (RTC_SCENE_FLAG_DYNAMIC) of LOW build quality (Embree's Morton builder) over a vertex buffer
// shared with the application (no copy), marked changed, the geometry and scene committed every
// iteration.
#include <benchmark/benchmark.h>
#include <embree3/rtcore.h>

#include <stdexcept>
#include <string>

#include "bench_meshes.h"
#include "benchmarks.h"

namespace mobirt::bench {

namespace {

void build_with_embree(benchmark::State& state, BenchMesh* mesh, int threads) {
  const std::vector<glm::vec3>& positions = mesh->positions();
  const size_t triangles = positions.size() / 3;
  // A device per run: Embree's "threads=N" limits TBB for the whole process while it lives.
  const std::string config = "threads=" + std::to_string(threads);
  RTCDevice device = rtcNewDevice(config.c_str());
  if (!device) throw std::runtime_error("rtcNewDevice failed");
  RTCScene scene = rtcNewScene(device);
  rtcSetSceneFlags(scene, RTC_SCENE_FLAG_DYNAMIC);
  rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_LOW);
  RTCGeometry geometry = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
  rtcSetGeometryBuildQuality(geometry, RTC_BUILD_QUALITY_LOW);
  // Embree reads 16 bytes at the last vertex: one vertex of padding.
  std::vector<glm::vec3> vertices(positions);
  vertices.emplace_back(0.0f);
  rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, vertices.data(), 0,
                             sizeof(glm::vec3), positions.size());
  auto* indices = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(
      geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(uint32_t), triangles));
  for (size_t i = 0; i < 3 * triangles; ++i) indices[i] = uint32_t(i);
  rtcAttachGeometry(scene, geometry);
  const double cpu_start = process_cpu_ms();
  for (auto _ : state) {
    rtcUpdateGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0);
    rtcCommitGeometry(geometry);
    rtcCommitScene(scene);
  }
  state.counters["cpu_ms"] = benchmark::Counter(process_cpu_ms() - cpu_start, benchmark::Counter::kAvgIterations);
  RTCBounds bounds;
  rtcGetSceneBounds(scene, &bounds);
  benchmark::DoNotOptimize(bounds);
  rtcReleaseGeometry(geometry);
  rtcReleaseScene(scene);
  rtcReleaseDevice(device);
  state.counters["tris"] = double(triangles);
  state.counters["tris/s"] = benchmark::Counter(double(triangles), benchmark::Counter::kIsIterationInvariantRate);
}

}  // namespace

void register_embree_benchmarks() {
  for (BenchMesh* mesh : build_meshes()) {
    for (int threads : {1, 2}) {
      const std::string name = "EmbreeBuild/" + mesh->name() + "/threads:" + std::to_string(threads);
      benchmark::RegisterBenchmark(name.c_str(), build_with_embree, mesh, threads)
          ->Unit(benchmark::kMillisecond)
          ->UseRealTime();
    }
  }
}

}  // namespace mobirt::bench
