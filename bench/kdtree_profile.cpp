// mobirt_kdprofile MESH [ITERATIONS] [THREADS] [quality|fast]: builds the kd-tree of one
// microbenchmark mesh (fish, marbles, toaster, utah-toasters, torus100k, torus1m, soup100k)
// ITERATIONS times and prints the median build time (wall and CPU of all threads), the tree's
// statistics and a hash of its arrays (to tell whether two builders made the same tree), then the
// tree's cost on 20,000 fixed rays (steps per ray, CPU traversal Mrays/s), to compare builds. A
// driver for profilers, which need one process per mesh rather than Google Benchmark's loop over
// all of them: valgrind --tool=callgrind --toggle-collect='mobirt::rebuild_kdtree*' with THREADS 1
// (callgrind counts only the threads that enter rebuild_kdtree). Environment knobs for experiments
// are read below (MOBIRT_KD_ISECT, _LEAF, _BINS, _DEPTH, _GAIN, _SMALL, _CLUSTER, _EMPTY, _SSE2,
// _FRAMES, _COLD, _PAUSE_MS, _FRESH, _WORKER). Each build goes into the same tree, as an animation's
// per-frame build does (rebuild_kdtree); MOBIRT_KD_FRESH=1 builds a new tree every time instead.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "accel/kdtree.h"
#include "core/geometry.h"
#include "bench_meshes.h"
#include "core/cpu_time.h"
#include "core/memory.h"
#include "scene/animation.h"

namespace {

// An on/off knob: set to a non-zero number.
bool env_on(const char* name) {
  const char* value = std::getenv(name);
  return value && std::atoi(value) != 0;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace mobirt;
  if (argc < 2) {
    std::fprintf(stderr, "usage: mobirt_kdprofile MESH [ITERATIONS] [THREADS] [quality|fast]\n");
    return 2;
  }
  retain_freed_memory();
  const std::string name = argv[1];
  const int iterations = argc > 2 ? std::max(1, std::atoi(argv[2])) : 1;
  KdBuildOptions options;
  options.threads = argc > 3 ? std::atoi(argv[3]) : 0;
  if (argc > 4 && !parse_kd_build_mode(argv[4], options.build)) {
    std::fprintf(stderr, "mobirt_kdprofile: no build mode named %s (quality, fast)\n", argv[4]);
    return 2;
  }
  // Exploration of the cost model and the termination: MOBIRT_KD_ISECT (intersection cost),
  // MOBIRT_KD_LEAF (max_leaf_prims), MOBIRT_KD_DEPTH (max_depth).
  if (const char* isect = std::getenv("MOBIRT_KD_ISECT")) options.intersection_cost = std::strtof(isect, nullptr);
  if (const char* leaf = std::getenv("MOBIRT_KD_LEAF")) options.max_leaf_prims = std::atoi(leaf);
  if (const char* bins = std::getenv("MOBIRT_KD_BINS")) options.bins = std::atoi(bins);
  if (const char* depth = std::getenv("MOBIRT_KD_DEPTH")) options.max_depth = std::atoi(depth);
  // MOBIRT_KD_GAIN (small_split_gain), MOBIRT_KD_SMALL (small_node_refs).
  if (const char* gain = std::getenv("MOBIRT_KD_GAIN")) options.small_split_gain = std::strtof(gain, nullptr);
  if (const char* small = std::getenv("MOBIRT_KD_SMALL")) options.small_node_refs = std::atoi(small);
  // MOBIRT_KD_CLUSTER (cluster_refs), MOBIRT_KD_EMPTY (empty_bonus); MOBIRT_KD_SSE2=1: the SSE2
  // sweep only (the same tree: the hash says so).
  if (const char* cluster = std::getenv("MOBIRT_KD_CLUSTER")) options.cluster_refs = std::atoi(cluster);
  if (const char* empty = std::getenv("MOBIRT_KD_EMPTY")) options.empty_bonus = std::strtof(empty, nullptr);
  // MOBIRT_KD_DEEP (deep_levels: 0 = the depth limit alone), MOBIRT_KD_DEEP_REFS (deep_refs).
  if (const char* deep = std::getenv("MOBIRT_KD_DEEP")) options.deep_levels = std::atoi(deep);
  if (const char* deep_refs = std::getenv("MOBIRT_KD_DEEP_REFS")) options.deep_refs = std::atoi(deep_refs);
  // MOBIRT_KD_RAYS (rays: the rays the tree is built for; above 0 the walks trees' empty bonus,
  // 0.2, unless MOBIRT_KD_EMPTY sets one: kd_empty_bonus), MOBIRT_KD_REF_COST (build_ref_cost).
  if (const char* rays = std::getenv("MOBIRT_KD_RAYS")) options.rays = std::strtod(rays, nullptr);
  if (const char* cost = std::getenv("MOBIRT_KD_REF_COST")) options.build_ref_cost = std::strtod(cost, nullptr);
  if (env_on("MOBIRT_KD_SSE2")) {
    options.sweep_simd = KdSweepSimd::Sse2;
  }
  bench::BenchMesh* mesh = nullptr;
  for (bench::BenchMesh* m : bench::build_meshes()) {
    if (m->name() == name) mesh = m;
  }
  if (!mesh) {
    std::fprintf(stderr, "mobirt_kdprofile: no mesh named %s\n", name.c_str());
    return 2;
  }
  const std::vector<glm::vec3>& positions = mesh->positions();
  // MOBIRT_KD_FRAMES=1: build iteration i from frame i of the scene's animation, as `mobirt bench`
  // does, instead of frame 0 every time; MOBIRT_KD_COLD=1: write 32 MB between builds, as the rest
  // of a frame does, so that the build starts with cold caches.
  const bool frames = std::getenv("MOBIRT_KD_FRAMES") != nullptr;
  const bool cold = std::getenv("MOBIRT_KD_COLD") != nullptr;
  // MOBIRT_KD_PAUSE_MS=N: sleep N ms between builds, as a frame's other stages keep the build's
  // threads idle (TBB's workers go to sleep).
  const int pause_ms = std::getenv("MOBIRT_KD_PAUSE_MS") ? std::atoi(std::getenv("MOBIRT_KD_PAUSE_MS")) : 0;
  AnimatedScene animation;
  Scene frame;
  if (frames) {
    animation = load_animated_scene(bench::project_scene(name + ".gltf"));
    frame = animation.rest();
  }
  std::vector<char> flush(cold ? size_t(32) << 20 : 0);
  std::vector<double> ms;
  std::vector<double> cpu;
  const bool fresh = env_on("MOBIRT_KD_FRESH");
  // MOBIRT_KD_WORKER=1: the builds run on a thread of their own, as the frame pipeline's worker
  // runs them (glibc serves a non-main thread's allocations above its arena's 64 MiB heaps with
  // fresh pages every time, whatever retain_freed_memory() asks).
  const bool on_worker = env_on("MOBIRT_KD_WORKER");
  FlatKdTree tree;
  auto build_all = [&] {
    for (int i = 0; i < iterations; ++i) {
      if (frames && animation.animated()) animation.evaluate(double(i) / animation.fps(), frame);
      for (size_t k = 0; k < flush.size(); k += 64) flush[k] = char(k + size_t(i));
      if (pause_ms > 0) std::this_thread::sleep_for(std::chrono::milliseconds(pause_ms));
      const std::span<const glm::vec3> input = frames ? std::span<const glm::vec3>(frame.mesh.positions) : positions;
      const double cpu_start = process_cpu_ms();
      const auto start = std::chrono::steady_clock::now();
      if (fresh) {
        tree = build_kdtree(input, options);
      } else {
        rebuild_kdtree(tree, input, {}, options);
      }
      ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count());
      cpu.push_back(process_cpu_ms() - cpu_start);
    }
  };
  if (on_worker) {
    std::thread worker(build_all);
    worker.join();
  } else {
    build_all();
  }
  std::sort(cpu.begin(), cpu.end());
  const KdBuildStats& stats = tree.stats;
  // A hash of the arrays, to tell whether two builders made the very same tree.
  uint64_t hash = 14695981039346656037ull;
  const auto mix = [&hash](const void* data, size_t bytes) {
    for (size_t i = 0; i < bytes; ++i) hash = (hash ^ static_cast<const unsigned char*>(data)[i]) * 1099511628211ull;
  };
  mix(tree.nodes.data(), tree.nodes.size() * sizeof(glm::vec4));
  mix(tree.leaf_prims.data(), tree.leaf_prims.size() * sizeof(glm::vec4));
  std::sort(ms.begin(), ms.end());
  // The tree's traversal cost on the same rays for every build: 20,000 rays from points around
  // the box through points inside it, the CPU twin of the traversal pass (short stack of 4).
  const glm::vec3 lo = tree.bounds.lo;
  const glm::vec3 ext = tree.bounds.extent();
  uint32_t state = 12345;
  const auto uniform = [&state] {
    state = state * 1664525u + 1013904223u;
    return float(state >> 8) / float(1 << 24);
  };
  std::vector<Ray> rays(20000);
  for (Ray& ray : rays) {
    const glm::vec3 to = lo + ext * glm::vec3(uniform(), uniform(), uniform());
    const glm::vec3 from = lo + ext * (glm::vec3(uniform(), uniform(), uniform()) * 3.0f - 1.0f);
    ray.origin = from;
    ray.direction = glm::normalize(to - from);
  }
  TraversalStats traversal;
  size_t hits = 0;
  const auto trace_start = std::chrono::steady_clock::now();
  for (const Ray& ray : rays) {
    TraversalStats one;
    hits += traverse(tree, ray, 4, one).valid() ? 1 : 0;
    traversal += one;
  }
  const double trace_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - trace_start).count();
  const double tris = double(positions.size() / 3);
  std::printf("%s %s: %.0f triangles, build median %.3f ms (min %.3f, CPU median %.3f) over %d, nodes %zu, refs/tri %.3f, "
              "sah %.2f, largest leaf %zu, depth %d/%d, hash %016llx; traversal: %zu hits, %.2f steps/ray, %.2f Mrays/s (1 thread)\n",
              name.c_str(), kd_build_mode_name(options.build), tris, ms[ms.size() / 2], ms[0], cpu[cpu.size() / 2], iterations, stats.nodes,
              double(stats.prim_references) / std::max(tris, 1.0), stats.sah_cost, stats.max_leaf_size, stats.max_depth_reached, tree.max_depth, static_cast<unsigned long long>(hash), hits,
              double(traversal.steps) / double(rays.size()), double(rays.size()) / trace_s * 1e-6);
  return 0;
}
