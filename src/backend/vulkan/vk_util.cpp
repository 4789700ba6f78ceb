#include "backend/vulkan/vk_util.h"

#include <cstdlib>

#include "core/error.h"

namespace mobirt::vk {

std::string result_name(VkResult result) {
  switch (result) {
#define MOBIRT_VK_RESULT(name) \
  case name: return #name;
    MOBIRT_VK_RESULT(VK_SUCCESS)
    MOBIRT_VK_RESULT(VK_NOT_READY)
    MOBIRT_VK_RESULT(VK_TIMEOUT)
    MOBIRT_VK_RESULT(VK_EVENT_SET)
    MOBIRT_VK_RESULT(VK_EVENT_RESET)
    MOBIRT_VK_RESULT(VK_INCOMPLETE)
    MOBIRT_VK_RESULT(VK_ERROR_OUT_OF_HOST_MEMORY)
    MOBIRT_VK_RESULT(VK_ERROR_OUT_OF_DEVICE_MEMORY)
    MOBIRT_VK_RESULT(VK_ERROR_INITIALIZATION_FAILED)
    MOBIRT_VK_RESULT(VK_ERROR_DEVICE_LOST)
    MOBIRT_VK_RESULT(VK_ERROR_MEMORY_MAP_FAILED)
    MOBIRT_VK_RESULT(VK_ERROR_LAYER_NOT_PRESENT)
    MOBIRT_VK_RESULT(VK_ERROR_EXTENSION_NOT_PRESENT)
    MOBIRT_VK_RESULT(VK_ERROR_FEATURE_NOT_PRESENT)
    MOBIRT_VK_RESULT(VK_ERROR_INCOMPATIBLE_DRIVER)
    MOBIRT_VK_RESULT(VK_ERROR_TOO_MANY_OBJECTS)
    MOBIRT_VK_RESULT(VK_ERROR_FORMAT_NOT_SUPPORTED)
    MOBIRT_VK_RESULT(VK_ERROR_FRAGMENTED_POOL)
    MOBIRT_VK_RESULT(VK_ERROR_UNKNOWN)
    MOBIRT_VK_RESULT(VK_ERROR_OUT_OF_POOL_MEMORY)
    MOBIRT_VK_RESULT(VK_ERROR_INVALID_EXTERNAL_HANDLE)
    MOBIRT_VK_RESULT(VK_ERROR_FRAGMENTATION)
    MOBIRT_VK_RESULT(VK_ERROR_INVALID_OPAQUE_CAPTURE_ADDRESS)
    MOBIRT_VK_RESULT(VK_PIPELINE_COMPILE_REQUIRED)
    MOBIRT_VK_RESULT(VK_ERROR_VALIDATION_FAILED_EXT)
    MOBIRT_VK_RESULT(VK_ERROR_INVALID_SHADER_NV)
#undef MOBIRT_VK_RESULT
    default: return "VkResult(" + std::to_string(int(result)) + ")";
  }
}

void check(VkResult result, const char* call, const char* file, int line) {
  if (result == VK_SUCCESS) return;
  std::string name(call);
  name = name.substr(0, name.find('('));
  while (!name.empty() && name.back() == ' ') name.pop_back();
  // The place from the source tree's root ("src/backend/vulkan/vk_device.cpp:120"), else the file's name.
  std::string place(file);
  if (const size_t src = place.rfind("/src/"); src != std::string::npos) {
    place.erase(0, src + 1);
  } else if (const size_t slash = place.rfind('/'); slash != std::string::npos) {
    place.erase(0, slash + 1);
  }
  throw Error(ErrorKind::Internal,
              name + " failed (" + place + ":" + std::to_string(line) + "): " + result_name(result));
}

double pass_timeout_seconds() {
  if (const char* value = std::getenv("MOBIRT_PASS_TIMEOUT_S")) {
    const double seconds = std::atof(value);
    if (seconds > 0.0) return seconds;
  }
  return 120.0;
}

std::atomic<long>& live_object_counter() {
  static std::atomic<long> counter{0};
  return counter;
}

}  // namespace mobirt::vk
