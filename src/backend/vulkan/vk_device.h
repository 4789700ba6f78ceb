// Instance and device of the Vulkan backend: the loader and layer checks, the validation
// messenger, the physical device picked by BackendOptions::device, the logical device with one
// graphics queue, and what the device tells about itself (DeviceInfo). Private to
// src/backend/vulkan/.
#pragma once

#include <vulkan/vulkan.h>

#include <mutex>
#include <string>
#include <vector>

#include "backend/backend.h"
#include "backend/vulkan/vulkan_backend.h"

namespace mobirt::vk {

// The target of every pass: one RGBA8 texel per ray.
constexpr VkFormat kTargetFormat = VK_FORMAT_R8G8B8A8_UNORM;

// "1.3.239"
std::string version_string(uint32_t version);

// Validation messages, as the debug messenger delivers them (any thread).
struct DebugSink {
  std::mutex mutex;
  std::vector<std::string> messages;
  std::vector<std::string> unreported_errors;  // ERROR messages no call has thrown for yet
};

// Prints the messages nobody took (those from destroying the device and instance included) when
// the backend goes away, so that leaks the validation layer reports at shutdown are not silent.
struct ShutdownReport {
  DebugSink* sink = nullptr;
  ~ShutdownReport();
};

struct InstanceOwner {
  VkInstance instance = VK_NULL_HANDLE;
  VkDebugUtilsMessengerEXT messenger = VK_NULL_HANDLE;
  InstanceOwner() = default;
  InstanceOwner(const InstanceOwner&) = delete;
  InstanceOwner& operator=(const InstanceOwner&) = delete;
  ~InstanceOwner();
};

struct DeviceOwner {
  VkDevice device = VK_NULL_HANDLE;
  DeviceOwner() = default;
  DeviceOwner(const DeviceOwner&) = delete;
  DeviceOwner& operator=(const DeviceOwner&) = delete;
  ~DeviceOwner();
};

// The instance and device, created in the constructor, destroyed in reverse order (the device,
// the messenger and instance, then the report of what the layer said last). Not movable: the
// messenger holds the sink's address.
class Device {
 public:
  explicit Device(const VulkanOptions& options);
  Device(const Device&) = delete;
  Device& operator=(const Device&) = delete;

  VkDevice handle() const { return device_.device; }
  VkPhysicalDevice physical() const { return physical_; }
  VkQueue queue() const { return queue_; }
  uint32_t queue_family() const { return queue_family_; }
  uint32_t timestamp_bits() const { return timestamp_bits_; }
  // Whether passes on this device are timed with timestamp queries (VulkanOptions::timestamps,
  // takes_gpu_timestamps: the device's clock on a GPU, the CPU's on lavapipe by default).
  bool gpu_timestamps() const { return gpu_timestamps_; }
  const VkPhysicalDeviceProperties& properties() const { return properties_; }
  const VkPhysicalDeviceMemoryProperties& memory_properties() const { return memory_properties_; }

  DeviceInfo info() const;
  // VK_KHR_buffer_device_address enabled (buffers of TextureKind::DeviceAddress are then possible).
  bool device_addresses() const { return device_addresses_; }
  VkDeviceAddress buffer_address(VkBuffer buffer) const;
  // Throws the first validation error that no call has reported yet.
  void throw_validation_errors();
  std::vector<std::string> take_debug_messages();

 private:
  void create_instance(bool validation, bool sync_validation);
  void pick_physical_device(const std::string& wanted);
  void create_device();

  DebugSink sink_;
  ShutdownReport shutdown_report_{&sink_};  // destroyed after the instance: sees its last messages
  InstanceOwner instance_;
  VkPhysicalDevice physical_ = VK_NULL_HANDLE;
  VkPhysicalDeviceProperties properties_{};
  VkPhysicalDeviceMemoryProperties memory_properties_{};
  std::string driver_;          // "llvmpipe / Mesa 25.0.7 (LLVM 15.0.6)"
  std::string driver_version_;  // "Mesa 25.0.7"
  bool ray_query_ = false;      // VK_KHR_ray_query + VK_KHR_acceleration_structure
  bool device_addresses_ = false;  // VK_KHR_buffer_device_address with bufferDeviceAddress
  PFN_vkGetBufferDeviceAddressKHR get_buffer_address_ = nullptr;
  uint32_t queue_family_ = 0;
  uint32_t timestamp_bits_ = 0;
  bool gpu_timestamps_ = false;
  DeviceOwner device_;
  VkQueue queue_ = VK_NULL_HANDLE;
};

}  // namespace mobirt::vk
