#include "test_support.h"

#include <gtest/gtest.h>

#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <cstdlib>

namespace mobirt::test {

std::filesystem::path shared_scenes() {
  const char* env = std::getenv("MOBIRT_SHARED_SCENES");
  std::filesystem::path path = env ? env : MOBIRT_SOURCE_DIR "/../shared/scenes";
  return std::filesystem::is_directory(path) ? path : std::filesystem::path();
}

std::filesystem::path output_path(const std::string& name) {
  std::filesystem::path dir(MOBIRT_TEST_OUTPUT_DIR);
  std::filesystem::create_directories(dir);
  return dir / name;
}

std::filesystem::path temp_dir() {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  std::string name = info ? std::string(info->test_suite_name()) + "." + info->name() : "mobirt";
  for (char& c : name) {
    if (c == '/') c = '_';
  }
  std::filesystem::path dir = std::filesystem::temp_directory_path() / ("mobirt-test-" + name);
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

CommandResult run_mobirt(const std::string& args) {
  const std::string command = std::string(MOBIRT_EXE) + " " + args + " 2>&1";
  CommandResult r;
  FILE* pipe = popen(command.c_str(), "r");
  if (!pipe) return r;
  std::array<char, 4096> buffer;
  size_t n;
  while ((n = fread(buffer.data(), 1, buffer.size(), pipe)) > 0) r.output.append(buffer.data(), n);
  const int status = pclose(pipe);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

RayBatch random_rays(const Scene& scene, const Camera& camera, uint32_t count, uint32_t width, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  const CameraBasis basis(camera, 400, 240);
  const Aabb box = scene.bounds();
  const glm::vec3 lo = box.lo - 0.1f * box.extent(), size = 1.2f * box.extent();
  RayBatch rays;
  rays.width = width;
  for (uint32_t i = 0; i < count; ++i) {
    if (i % 2 == 0) {
      rays.push(basis.ray(400.0f * unit(rng), 240.0f * unit(rng)), i, glm::vec3(1.0f));
    } else {
      const glm::vec3 o = lo + size * glm::vec3(unit(rng), unit(rng), unit(rng));
      rays.push(Ray{o, random_direction(rng), 0.0f, kInfinity}, i, glm::vec3(1.0f));
    }
  }
  return rays;
}

bool occluded_by_any(const FlatKdTree& tree, glm::vec3 origin, glm::vec3 light) {
  const Ray ray{origin, light - origin, 0.0f, 1.0f};
  const int32_t n = int32_t(tree.triangles.size() / MOBIRT_TEXELS_PER_TRIANGLE);
  for (int32_t t = 0; t < n; ++t) {
    Hit h;
    if (intersect_triangle(tree, t, ray, h)) return true;
  }
  return false;
}

}  // namespace mobirt::test
