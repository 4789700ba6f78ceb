// Each file registers its benchmarks at start-up (so that benchmarks whose input is absent are
// simply not registered).
#pragma once

namespace mobirt::bench {

void register_kdtree_benchmarks();
void register_embree_benchmarks();
void register_raytree_benchmarks();
void register_atlas_benchmarks();

}  // namespace mobirt::bench
