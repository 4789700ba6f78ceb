#include "bench_meshes.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <memory>

#include "scene/loader.h"

namespace mobirt::bench {

namespace {

// SplitMix64: a fixed, portable sequence (std::uniform_real_distribution is not portable).
struct SplitMix {
  uint64_t state;
  uint64_t next() {
    uint64_t z = (state += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  float uniform() { return float(next() >> 40) * (1.0f / 16777216.0f); }  // [0, 1)
};

}  // namespace

std::vector<glm::vec3> bumpy_torus(int rings, int segments) {
  constexpr float kMajor = 1.0f;
  constexpr float kMinor = 0.35f;
  constexpr float kTwoPi = 6.28318530718f;
  const auto point = [&](int i, int j) {
    const float u = kTwoPi * float(i % rings) / float(rings);
    const float v = kTwoPi * float(j % segments) / float(segments);
    const float bump = 0.04f * std::sin(7.0f * u) * std::sin(5.0f * v) +
                       0.015f * std::sin(23.0f * u + 3.0f * v) + 0.006f * std::sin(61.0f * v - 41.0f * u);
    const float r = kMinor + bump;
    const glm::vec3 ring_center(kMajor * std::cos(u), 0.0f, kMajor * std::sin(u));
    const glm::vec3 normal(std::cos(v) * std::cos(u), std::sin(v), std::cos(v) * std::sin(u));
    return ring_center + r * normal;
  };
  std::vector<glm::vec3> p;
  p.reserve(size_t(6) * size_t(rings) * size_t(segments));
  for (int i = 0; i < rings; ++i) {
    for (int j = 0; j < segments; ++j) {
      const glm::vec3 a = point(i, j), b = point(i + 1, j), c = point(i + 1, j + 1), d = point(i, j + 1);
      p.insert(p.end(), {a, b, c, a, c, d});
    }
  }
  return p;
}

std::vector<glm::vec3> random_soup(size_t n, uint32_t seed) {
  SplitMix rng{seed};
  std::vector<glm::vec3> p;
  p.reserve(3 * n);
  // Triangles of about the same size relative to the scene as the tests' 2,000-triangle soup
  // would have at n triangles: the size shrinks with the cube root of the count.
  const float shrink = std::cbrt(2000.0f / float(std::max<size_t>(n, 1)));
  for (size_t i = 0; i < n; ++i) {
    const glm::vec3 c(rng.uniform() * 10.0f, rng.uniform() * 10.0f, rng.uniform() * 10.0f);
    const float size = shrink * (0.1f + 1.5f * rng.uniform() * rng.uniform());
    for (int k = 0; k < 3; ++k) {
      p.push_back(c + size * glm::vec3(rng.uniform() - 0.5f, rng.uniform() - 0.5f, rng.uniform() - 0.5f));
    }
  }
  return p;
}

std::string project_scene(const std::string& name) { return std::string(MOBIRT_SOURCE_DIR) + "/scenes/" + name; }

std::filesystem::path shared_scene(const std::string& relative) {
  const char* env = std::getenv("MOBIRT_SHARED_SCENES");
  const std::filesystem::path path = std::filesystem::path(env ? env : MOBIRT_BENCH_SHARED_SCENES) / relative;
  return std::filesystem::exists(path) ? path : std::filesystem::path();
}

const std::vector<glm::vec3>& BenchMesh::positions() {
  if (!made_) {
    positions_ = make_();
    made_ = true;
  }
  return positions_;
}

const Scene& project_scene_loaded(const std::string& name) {
  static std::map<std::string, std::unique_ptr<Scene>> scenes;
  std::unique_ptr<Scene>& scene = scenes[name];
  if (!scene) scene = std::make_unique<Scene>(load_scene(project_scene(name + ".gltf")));
  return *scene;
}

std::vector<BenchMesh*> build_meshes() {
  static std::vector<std::unique_ptr<BenchMesh>> meshes;
  if (meshes.empty()) {
    for (const char* name : {"fish", "marbles", "toaster"}) {
      meshes.push_back(std::make_unique<BenchMesh>(
          name, [name] { return project_scene_loaded(name).mesh.positions; }));
    }
    const std::filesystem::path toasters = shared_scene("utah-toasters/Toasters004.obj");
    if (!toasters.empty()) {
      meshes.push_back(std::make_unique<BenchMesh>(
          "utah-toasters", [toasters] { return load_scene(toasters.string()).mesh.positions; }));
    } else {
      std::fprintf(stderr, "mobirt_microbench: ../shared/scenes/utah-toasters is absent: "
                           "its benchmarks are skipped\n");
    }
    meshes.push_back(std::make_unique<BenchMesh>("torus100k", [] { return bumpy_torus(250, 200); }));
    meshes.push_back(std::make_unique<BenchMesh>("torus1m", [] { return bumpy_torus(1000, 500); }));
    meshes.push_back(std::make_unique<BenchMesh>("soup100k", [] { return random_soup(100000, 5); }));
  }
  std::vector<BenchMesh*> result;
  for (const auto& m : meshes) result.push_back(m.get());
  return result;
}

}  // namespace mobirt::bench
