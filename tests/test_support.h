// Helpers shared by the tests: where the real data lives, where outputs go.
#pragma once

#include <glm/glm.hpp>
#include <gtest/gtest.h>

#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include "accel/kdtree.h"
#include "core/camera.h"
#include "core/error.h"
#include "raytree/rays.h"
#include "scene/scene.h"

namespace mobirt::test {

// A sanitizer build (MOBIRT_SANITIZE) runs 5 to 20x slower. It exists to find memory and undefined
// behaviour, which the first rays of a test find as well as the last, so the heaviest brute-force
// oracle loops check every `stride`-th ray there (and every ray in the normal build), to keep CI's
// sanitizer step well inside its time. Their assertions hold for any subset.
inline size_t sanitizer_stride(size_t stride) { return MOBIRT_SANITIZED ? stride : 1; }

// ../shared/scenes, or an empty path when it is absent (tests then GTEST_SKIP()).
std::filesystem::path shared_scenes();

// A path under the build folder for images a test writes (diff images on failure, ...).
std::filesystem::path output_path(const std::string& name);

// A fresh empty temporary folder for this test.
std::filesystem::path temp_dir();

// The mobirt command line run with `args` (a shell command line after the executable's name).
struct CommandResult {
  int exit_code = -1;
  std::string output;  // stdout and stderr together
};
CommandResult run_mobirt(const std::string& args);

// Runs `action`, expects a BadInput error whose message contains every string of `parts`.
template <class F>
void expect_bad_input(F&& action, const std::vector<std::string>& parts) {
  try {
    action();
    ADD_FAILURE() << "no error thrown";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::BadInput) << e.what();
    for (const std::string& part : parts) {
      EXPECT_NE(std::string(e.what()).find(part), std::string::npos)
          << "message '" << e.what() << "' lacks '" << part << "'";
    }
  }
}

inline void expect_vec3(const glm::vec3& got, const glm::vec3& want, float eps = 1e-5f) {
  EXPECT_NEAR(got.x, want.x, eps) << "x";
  EXPECT_NEAR(got.y, want.y, eps) << "y";
  EXPECT_NEAR(got.z, want.z, eps) << "z";
}

// A uniformly distributed unit vector.
inline glm::vec3 random_direction(std::mt19937& rng) {
  std::normal_distribution<float> n(0.0f, 1.0f);
  for (;;) {
    const glm::vec3 d(n(rng), n(rng), n(rng));
    const float l = glm::length(d);
    if (l > 1e-3f) return d / l;
  }
}

// Camera rays through random points of a 400x240 image, and rays from random points in and around
// the scene box in random directions, alternately; `width` rays a row.
RayBatch random_rays(const Scene& scene, const Camera& camera, uint32_t count, uint32_t width, uint32_t seed);

// Whether any triangle of `tree` meets the segment origin -> light (a light buffer's predicate,
// intersect_triangle, on every triangle): the light buffers' brute force.
bool occluded_by_any(const FlatKdTree& tree, glm::vec3 origin, glm::vec3 light);

}  // namespace mobirt::test

// Skips the current test unless ../shared/scenes/<relative> exists; yields its full path.
#define MOBIRT_REQUIRE_SHARED(var, relative)                                                 \
  const std::filesystem::path var = ::mobirt::test::shared_scenes() / (relative);            \
  if (::mobirt::test::shared_scenes().empty() || !std::filesystem::exists(var))               \
  GTEST_SKIP() << "shared scene " << (relative) << " is absent"
