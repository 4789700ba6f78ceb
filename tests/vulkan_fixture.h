// The fixture every Vulkan test derives from: a backend on the default device with the Khronos
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

}  // namespace mobirt::test
