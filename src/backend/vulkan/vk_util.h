// Small helpers of the Vulkan backend: VkResult checking that throws mobirt::Error, and RAII
// owners for device-level objects. Private to src/backend/vulkan/.
#pragma once

#include <vulkan/vulkan.h>

#include <atomic>
#include <cstddef>
#include <string>
#include <utility>

namespace mobirt::vk {

// "VK_ERROR_DEVICE_LOST", ... ("VkResult(-13)" for codes this header does not know).
std::string result_name(VkResult result);

// Throws Error(Internal, "vkCreateImage failed (src/backend/vulkan/vk_resources.cpp:42):
// VK_ERROR_OUT_OF_DEVICE_MEMORY") unless result is VK_SUCCESS. `call` is the call's text: its name
// is what comes before the first '('.
void check(VkResult result, const char* call, const char* file, int line);

// How long one GPU submission may run before mobirt gives up: MOBIRT_PASS_TIMEOUT_S, default 120 s.
double pass_timeout_seconds();

}  // namespace mobirt::vk

// VK_CHECK(vkCreateFence(device, &info, nullptr, &fence)): the call, checked, its name and
// place in the error (../shared/STYLE.md). VK_CHECK_RESULT(result, "vkWaitForFences") for a result
// in hand. The Vulkan headers define no VK_CHECK; every use is in src/backend/vulkan/.
#define VK_CHECK(call) ::mobirt::vk::check((call), #call, __FILE__, __LINE__)
#define VK_CHECK_RESULT(result, name) ::mobirt::vk::check((result), name, __FILE__, __LINE__)

namespace mobirt::vk {

// Live Vulkan objects owned through Unique, over every backend in the process (leak tests).
std::atomic<long>& live_object_counter();

// Owner of one device-level object, destroyed with the matching vkDestroy*/vkFree* call.
template <typename T>
using DeviceDestroyFn = void (*)(VkDevice, T, const VkAllocationCallbacks*);

template <typename T, DeviceDestroyFn<T> Destroy>
class Unique {
 public:
  Unique() = default;
  Unique(VkDevice device, T handle) : device_(device), handle_(handle) {
    if (handle_ != VK_NULL_HANDLE) ++live_object_counter();
  }
  Unique(const Unique&) = delete;
  Unique& operator=(const Unique&) = delete;
  Unique(Unique&& other) noexcept
      : device_(other.device_), handle_(std::exchange(other.handle_, VK_NULL_HANDLE)) {}
  Unique& operator=(Unique&& other) noexcept {
    if (this != &other) {
      reset();
      device_ = other.device_;
      handle_ = std::exchange(other.handle_, VK_NULL_HANDLE);
    }
    return *this;
  }
  ~Unique() { reset(); }

  void reset() {
    if (handle_ != VK_NULL_HANDLE) {
      Destroy(device_, handle_, nullptr);
      handle_ = VK_NULL_HANDLE;
      --live_object_counter();
    }
  }
  T get() const { return handle_; }
  explicit operator bool() const { return handle_ != VK_NULL_HANDLE; }

 private:
  VkDevice device_ = VK_NULL_HANDLE;
  T handle_ = VK_NULL_HANDLE;
};

using Buffer = Unique<VkBuffer, vkDestroyBuffer>;
using BufferView = Unique<VkBufferView, vkDestroyBufferView>;
using Image = Unique<VkImage, vkDestroyImage>;
using ImageView = Unique<VkImageView, vkDestroyImageView>;
using Memory = Unique<VkDeviceMemory, vkFreeMemory>;
using Sampler = Unique<VkSampler, vkDestroySampler>;
using ShaderModule = Unique<VkShaderModule, vkDestroyShaderModule>;
using DescriptorSetLayout = Unique<VkDescriptorSetLayout, vkDestroyDescriptorSetLayout>;
using DescriptorPool = Unique<VkDescriptorPool, vkDestroyDescriptorPool>;
using PipelineLayout = Unique<VkPipelineLayout, vkDestroyPipelineLayout>;
using Pipeline = Unique<VkPipeline, vkDestroyPipeline>;
using PipelineCache = Unique<VkPipelineCache, vkDestroyPipelineCache>;
using RenderPass = Unique<VkRenderPass, vkDestroyRenderPass>;
using Framebuffer = Unique<VkFramebuffer, vkDestroyFramebuffer>;
using CommandPool = Unique<VkCommandPool, vkDestroyCommandPool>;
using Fence = Unique<VkFence, vkDestroyFence>;
using QueryPool = Unique<VkQueryPool, vkDestroyQueryPool>;

}  // namespace mobirt::vk
