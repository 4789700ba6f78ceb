// PrimaryRays/<w>x<h>: the CPU's ray generation of every frame (raytree/rays.h).
// DecodeHits/toaster/<w>x<h>: decoding one traversal pass's read-back (raytree/hits.h) for the
// toaster scene's primary rays at the paper's 400x240, with its lights: the texels are what the
// GPU would return (closest hit and shadow mask, computed once on the CPU before timing), so the
// batch has the scene's real mix of hits, misses and shadow bits.
// NextGeneration/fish: the ray-tree manager's step from the fish's primary hits (400x240) to the
// mirror and refracted rays of its glass (raytree/secondary.h), on all cores.
// OrderRays/fish/<coherent>: packing the fish's first secondary generation (mirror and refracted
// rays of its glass, 400x240 primary rays) for the traversal pass: 1 = the coherent order
// (raytree/ray_order.h: sort, then SIMD tiles), 0 = the SIMD tiles alone; the sort's cost.
#include <benchmark/benchmark.h>

#include <string>
#include <vector>

#include "accel/kdtree.h"
#include "bench_meshes.h"
#include "benchmarks.h"
#include "core/camera.h"
#include "raytree/hits.h"
#include "raytree/packing.h"
#include "raytree/ray_order.h"
#include "raytree/rays.h"
#include "raytree/secondary.h"

namespace mobirt::bench {

namespace {

Camera scene_camera(const Scene& scene, int width, int height) {
  return scene.camera ? *scene.camera : frame_box(scene.bounds(), 0.7854f, float(width) / float(height));
}

void primary_ray_generation(benchmark::State& state) {
  const int width = int(state.range(0));
  const int height = int(state.range(1));
  const Camera camera = scene_camera(project_scene_loaded("toaster"), width, height);
  for (auto _ : state) {
    RayBatch rays = primary_rays(camera, width, height);
    benchmark::DoNotOptimize(rays.origin.data());
  }
  state.counters["rays/s"] =
      benchmark::Counter(double(width) * double(height), benchmark::Counter::kIsIterationInvariantRate);
}

void hit_decoding(benchmark::State& state) {
  const int width = int(state.range(0));
  const int height = int(state.range(1));
  const Scene& scene = project_scene_loaded("toaster");
  const FlatKdTree tree = build_kdtree(scene.mesh.positions);
  const RayBatch rays = primary_rays(scene_camera(scene, width, height), width, height);
  const ShadowSettings shadows;
  const Packing packing = choose_packing(scene.mesh.triangle_count(), int(scene.lights.size()), scene.source);
  std::vector<uint32_t> texels(rays.count());
  for (uint32_t i = 0; i < rays.count(); ++i) {
    const Ray ray = rays.ray(i);
    const Hit hit = traverse(tree, ray);
    const uint32_t mask = hit.valid() ? shadow_mask(tree, scene.lights, hit.prim, ray, hit.t, shadows, -1) : 0u;
    texels[i] = pack_trace(packing, uint32_t(hit.prim + 1), mask);
  }
  DecodeStats stats;
  for (auto _ : state) {
    SurfaceHits hits = decode_hits(scene, tree, rays, texels, packing, scene.lights, shadows, &stats);
    benchmark::DoNotOptimize(hits.hit_flags());
  }
  state.counters["rays"] = double(rays.count());
  state.counters["hits"] = double(stats.hits);
  state.counters["rays/s"] =
      benchmark::Counter(double(rays.count()), benchmark::Counter::kIsIterationInvariantRate);
}

// The fish's primary hits, for the secondary-ray benchmarks.
struct FishGeneration {
  const Scene& scene;
  FlatKdTree tree;
  RayBatch primary;
  SurfaceHits hits;
};

FishGeneration fish_generation() {
  const Scene& scene = project_scene_loaded("fish");
  FishGeneration g{scene, build_kdtree(scene.mesh.positions), primary_rays(scene_camera(scene, 400, 240), 400, 240), {}};
  g.hits.resize(g.primary.count());
  for (uint32_t i = 0; i < g.primary.count(); ++i) {
    const Hit h = traverse(g.tree, g.primary.ray(i));
    g.hits.set(i, h.valid() ? surface_hit(scene, g.tree, g.primary.ray(i), h.prim) : SurfaceHit{});
  }
  return g;
}

void secondary_ray_generation(benchmark::State& state) {
  const FishGeneration g = fish_generation();
  uint32_t count = 0;
  for (auto _ : state) {
    RayBatch rays = next_generation(g.scene, g.tree.bounds, g.primary, g.hits, SecondarySettings{});
    count = rays.count();
    benchmark::DoNotOptimize(rays.origin.data());
  }
  state.counters["rays"] = double(count);
}

void secondary_ray_order(benchmark::State& state) {
  const bool coherent = state.range(0) != 0;
  const FishGeneration g = fish_generation();
  const FlatKdTree& tree = g.tree;
  const RayBatch secondary = next_generation(g.scene, tree.bounds, g.primary, g.hits, SecondarySettings{});
  for (auto _ : state) {
    RayBatch rays = secondary;
    if (coherent) {
      order_for_traversal(rays, tree.bounds);
    } else {
      order_in_simd_tiles(rays);
    }
    benchmark::DoNotOptimize(rays.origin.data());
  }
  state.counters["rays"] = double(secondary.count());
}

}  // namespace

void register_raytree_benchmarks() {
  benchmark::RegisterBenchmark("PrimaryRays", primary_ray_generation)
      ->Args({400, 240})
      ->Args({1920, 1080})
      ->ArgNames({"w", "h"})
      ->Unit(benchmark::kMicrosecond);
  benchmark::RegisterBenchmark("NextGeneration/fish", secondary_ray_generation)->Unit(benchmark::kMicrosecond);
  benchmark::RegisterBenchmark("OrderRays/fish", secondary_ray_order)
      ->Arg(0)
      ->Arg(1)
      ->ArgName("coherent")
      ->Unit(benchmark::kMicrosecond);
  benchmark::RegisterBenchmark("DecodeHits/toaster", hit_decoding)
      ->Args({400, 240})
      ->ArgNames({"w", "h"})
      ->Unit(benchmark::kMicrosecond);
}

}  // namespace mobirt::bench
