// The fixtures of the GPU tests. VulkanTest, the one every Vulkan-only test derives from: a backend on the default device with the Khronos
// validation layer on, created in SetUp; TearDown fails the test if the layer reported anything
// that the test did not take itself, and prints the messages.
#pragma once

#include <gtest/gtest.h>

#include <memory>
#include <string>
#include <vector>

#include "backend/backend.h"
#include "backend/vulkan/vulkan_backend.h"

namespace mobirt::test {

// One line each, each ended by a newline.
inline std::string join(const std::vector<std::string>& lines) {
  std::string result;
  for (const std::string& line : lines) result.append(line).append("\n");
  return result;
}

// Default backend options with the validation layer on.
inline BackendOptions validated_options() {
  BackendOptions options;
  options.validation = true;
  return options;
}

class VulkanTest : public ::testing::Test {
 protected:
  void SetUp() override { backend = create_vulkan_backend(validated_options()); }
  void TearDown() override {
    if (!backend) return;
    const std::vector<std::string> messages = backend->take_debug_messages();
    EXPECT_TRUE(messages.empty()) << "validation layer messages:\n" << join(messages);
  }

  std::unique_ptr<Backend> backend;
};

// The two APIs a per-backend test runs on, and each one's backend with the validation it has (the
// layer on Vulkan; GLES's debug output).
enum class Api { Vulkan, Gles };

inline const char* api_name(Api api) { return api == Api::Vulkan ? "vulkan" : "gles"; }

inline std::unique_ptr<Backend> make_backend(Api api) {
  return api == Api::Vulkan ? create_vulkan_backend(validated_options()) : create_gles_backend(validated_options());
}

// The fixture of a test run once per API:
//   INSTANTIATE_TEST_SUITE_P(Backends, X, ::testing::Values(Api::Vulkan, Api::Gles), api_param_name);
// TearDown fails the test on any debug message the test did not take itself.
class PerBackendTest : public ::testing::TestWithParam<Api> {
 protected:
  void SetUp() override { backend = make_backend(GetParam()); }
  void TearDown() override {
    if (!backend) return;
    const std::vector<std::string> messages = backend->take_debug_messages();
    EXPECT_TRUE(messages.empty()) << api_name(GetParam()) << " debug messages:\n" << join(messages);
  }

  std::unique_ptr<Backend> backend;
};

inline std::string api_param_name(const ::testing::TestParamInfo<Api>& p) { return api_name(p.param); }

}  // namespace mobirt::test
