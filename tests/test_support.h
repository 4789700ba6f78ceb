// Helpers shared by the tests: where the real data lives, where outputs go.
#pragma once

#include <filesystem>
#include <string>

namespace mobirt::test {

// ../shared/scenes, or an empty path when it is absent (tests then GTEST_SKIP()).
std::filesystem::path shared_scenes();

// A path under the build folder for images a test writes (diff images on failure, ...).
std::filesystem::path output_path(const std::string& name);

// A fresh empty temporary folder for this test.
std::filesystem::path temp_dir();

}  // namespace mobirt::test

// Skips the current test unless ../shared/scenes/<relative> exists; yields its full path.
#define MOBIRT_REQUIRE_SHARED(var, relative)                                                 \
  const std::filesystem::path var = ::mobirt::test::shared_scenes() / (relative);            \
  if (::mobirt::test::shared_scenes().empty() || !std::filesystem::exists(var))               \
  GTEST_SKIP() << "shared scene " << (relative) << " is absent"
