// Each file registers its benchmarks at start-up (so that benchmarks whose input is absent are
// simply not registered).
#pragma once

namespace mobirt::bench {

// CPU time of the whole process (every thread) in milliseconds: Google Benchmark's CPU column
// counts the main thread only, which says nothing about the work of a parallel build.
double process_cpu_ms();

void register_kdtree_benchmarks();
void register_embree_benchmarks();
void register_raytree_benchmarks();
void register_atlas_benchmarks();
void register_light_buffer_benchmarks();

}  // namespace mobirt::bench
