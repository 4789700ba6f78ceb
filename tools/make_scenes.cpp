// Generates the project's own scenes in scenes/:
//   mobirt_make_scenes OUT_DIR
// default.gltf (embedded buffer); toaster.gltf, marbles.gltf and fish.gltf (the MobiRT paper's three
// scenes, each with a .bin buffer and PNG textures in textures/); utah-toasters.mtl (materials for
// the real Utah toasters OBJ). The output is deterministic, so a test can regenerate the scenes and
// compare them with the committed files byte for byte.
#include "scenes/geometry.h"
#include "scenes/gltf_writer.h"
#include "scenes/paper_scenes.h"

#include <glm/glm.hpp>
#include <glm/gtc/quaternion.hpp>

#include <cstdio>
#include <cstring>
#include <filesystem>

namespace {

using namespace mobirt::scenes;

// The default scene: three objects on a floor under one point light, with clear shadows.
void make_default(const std::filesystem::path& dir) {
  Gltf g;
  const int floor_mat = g.material("floor", glm::vec3(0.75f, 0.75f, 0.72f), 0.0f, 0.8f);
  const int red = g.material("red plastic", glm::vec3(0.8f, 0.12f, 0.1f), 0.0f, 0.3f);
  const int blue = g.material("blue matte", glm::vec3(0.15f, 0.3f, 0.85f), 0.0f, 0.9f);
  const int gold = g.material("gold", glm::vec3(0.9f, 0.7f, 0.25f), 1.0f, 0.4f);
  g.object("floor", floor_plane(14.0f, 8), floor_mat, glm::vec3(0.0f));
  g.object("sphere", sphere(1.0f, 48, 24), red, glm::vec3(-1.6f, 1.0f, 0.2f));
  g.object("box", box(glm::vec3(1.4f)), blue, glm::vec3(1.5f, 0.7f, -0.6f),
           glm::angleAxis(0.5f, glm::vec3(0, 1, 0)));
  g.object("column", cylinder(0.45f, 2.2f, 40), gold, glm::vec3(0.4f, 0.0f, 1.9f));
  g.point_light("key light", glm::vec3(-3.0f, 6.5f, 4.0f), glm::vec3(1.0f, 0.97f, 0.9f), 70.0f);
  g.camera("camera", glm::vec3(0.5f, 3.6f, 8.5f), glm::vec3(0.0f, 0.8f, 0.0f), 40.0f, 400.0f / 240.0f);
  g.write(dir / "default.gltf");
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2 || std::strcmp(argv[1], "--help") == 0) {
    std::fprintf(stderr,
                 "usage: mobirt_make_scenes OUT_DIR   (writes default.gltf, toaster.gltf, marbles.gltf, fish.gltf\n"
                 "       with their .bin files, textures/*.png and utah-toasters.mtl)\n");
    return argc == 2 ? 0 : 2;
  }
  const std::filesystem::path dir(argv[1]);
  std::error_code ec;
  std::filesystem::create_directories(dir / "textures", ec);
  make_default(dir);
  make_toaster(dir);
  make_marbles(dir);
  make_fish(dir);
  make_utah_mtl(dir);
  return 0;
}
