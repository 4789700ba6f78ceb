// Inputs of the microbenchmarks: the project's scenes, the shared real-data scenes when present,
// and deterministic generated meshes for sizes no scene has (100K and 1M triangles).
#pragma once

#include <glm/glm.hpp>

#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "scene/scene.h"

namespace mobirt::bench {

// A torus of 2 * rings * segments triangles (every one with an area, no poles), its surface
// displaced along the normal by a fixed sum of sines, so that it has the varied curvature and
// triangle sizes of a scanned model rather than the flat regularity of a plain grid.
std::vector<glm::vec3> bumpy_torus(int rings, int segments);

// n small triangles at random in a 10-unit cube (the soup of tests/kdtree_test.cpp, with a
// generator that is the same on every platform): overlapping triangles everywhere, the worst case
// for split clipping and reference duplication.
std::vector<glm::vec3> random_soup(size_t n, uint32_t seed);

// scenes/NAME under the source folder.
std::string project_scene(const std::string& name);

// ../shared/scenes/RELATIVE (or $MOBIRT_SHARED_SCENES/RELATIVE), or an empty path when absent.
std::filesystem::path shared_scene(const std::string& relative);

// A triangle set (3 positions per triangle) loaded or generated on first use, so that filtered-out
// benchmarks never pay for their input.
class BenchMesh {
 public:
  BenchMesh(std::string name, std::function<std::vector<glm::vec3>()> make)
      : name_(std::move(name)), make_(std::move(make)) {}
  const std::string& name() const { return name_; }
  const std::vector<glm::vec3>& positions();
  size_t triangles() { return positions().size() / 3; }

 private:
  std::string name_;
  std::function<std::vector<glm::vec3>()> make_;
  std::vector<glm::vec3> positions_;
  bool made_ = false;
};

// The build benchmarks' inputs, smallest first: fish 1,392, marbles 8,000, toaster 11,102 (the
// project's scenes at t = 0), utah-toasters 11,141 (when ../shared/scenes has it), torus 100K
// and 1M, soup 100K. Each mesh lives as long as the program.
std::vector<BenchMesh*> build_meshes();

// The scene `name` (scenes/NAME.gltf) loaded once.
const Scene& project_scene_loaded(const std::string& name);

}  // namespace mobirt::bench
