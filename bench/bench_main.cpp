// mobirt_microbench: kd-tree build (1 and 2 threads) beside Embree's BVH build on the same
// triangles, hit decoding, primary ray generation and atlas packing. See bench/CMakeLists.txt.
#include <benchmark/benchmark.h>

#include <ctime>

#include "benchmarks.h"
#include "core/memory.h"

double mobirt::bench::process_cpu_ms() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return double(t.tv_sec) * 1e3 + double(t.tv_nsec) * 1e-6;
}

int main(int argc, char** argv) {
  mobirt::retain_freed_memory();  // as the mobirt command does: no page faults per frame buffer
  mobirt::bench::register_kdtree_benchmarks();
  mobirt::bench::register_embree_benchmarks();
  mobirt::bench::register_raytree_benchmarks();
  mobirt::bench::register_atlas_benchmarks();
  mobirt::bench::register_light_buffer_benchmarks();
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
