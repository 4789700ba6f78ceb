// Memory, buffers and images of the Vulkan backend: memory types, host-visible buffers, and the
// one helper that creates a 2D image with its memory and view (data textures and the render
// target both use it). Private to src/backend/vulkan/.
#pragma once

#include <vulkan/vulkan.h>

#include <cstdint>
#include <optional>

#include "backend/backend.h"
#include "backend/vulkan/vk_device.h"
#include "backend/vulkan/vk_util.h"

namespace mobirt::vk {

VkFormat vk_format(TexelFormat format);
const char* format_name(TexelFormat format);

// Members are declared in creation order, so they are destroyed in reverse; reset() keeps that
// order too (a memberwise move assignment would free the memory before its buffer or image), so
// reset() an owner before moving another into it.
struct HostBuffer {
  VkDeviceSize size = 0;
  bool coherent = true;
  Memory memory;
  Buffer buffer;
  void* mapped = nullptr;  // persistently mapped; unmapped when the memory is freed

  void reset();
};

// A 2D image of one mip level and layer with a colour view of it: optimally tiled in device
// memory, or linearly tiled in host-visible memory, persistently mapped (`mapped` not null), that
// the host writes straight into (data textures) or reads straight from (the render target), rows
// `row_pitch` bytes apart.
struct DeviceImage {
  Memory memory;
  Image image;
  ImageView view;
  void* mapped = nullptr;  // the first texel; unmapped when the memory is freed
  VkDeviceSize row_pitch = 0;
  bool coherent = true;

  void reset();
};

// A buffer in host-visible memory, persistently mapped, with a texel view of it: a uniform texel
// buffer (samplerBuffer); without the view, a read-only storage buffer. The host writes it
// directly: every Vulkan device has host-visible coherent memory for buffers, and on lavapipe it
// is the only memory there is.
struct TexelBuffer {
  Memory memory;
  Buffer buffer;
  BufferView view;
  void* mapped = nullptr;
  bool coherent = true;
  VkDeviceAddress address = 0;  // storage buffers on a device with buffer device addresses, else 0

  void reset();
};

// A data texture: a 2D image (width x height) or a texel buffer (width texels, height 1).
struct Texture {
  uint32_t width = 0, height = 0;
  TexelFormat format = TexelFormat::RGBA32F;
  TextureKind kind = TextureKind::Image2D;
  VkImageLayout layout = VK_IMAGE_LAYOUT_UNDEFINED;  // images only
  DeviceImage image;
  TexelBuffer buffer;
};

struct RenderTarget {
  uint32_t width = 0, height = 0;
  DeviceImage image;
  Framebuffer framebuffer;
  // A linear image in host-visible memory (image.mapped): the host reads the pass's texels in
  // place, without a copy command to a read-back buffer.
  bool linear = false;

  void reset();
};

// The first memory type in type_bits with required | preferred, else with required; nullopt
// (find_memory_type) or Error(Unsupported) (memory_type) when none has `required`. *coherent:
// whether it is host-coherent.
std::optional<uint32_t> find_memory_type(const VkPhysicalDeviceMemoryProperties& properties, uint32_t type_bits,
                                         VkMemoryPropertyFlags required, VkMemoryPropertyFlags preferred,
                                         bool* coherent = nullptr);
uint32_t memory_type(const VkPhysicalDeviceMemoryProperties& properties, uint32_t type_bits,
                     VkMemoryPropertyFlags required, VkMemoryPropertyFlags preferred, bool* coherent = nullptr);
// addressable: the memory of a buffer read through its device address (VK_KHR_buffer_device_address).
Memory allocate(const Device& device, const VkMemoryRequirements& requirements, VkMemoryPropertyFlags required,
                VkMemoryPropertyFlags preferred, bool* coherent = nullptr, bool addressable = false);

// A host-visible buffer, mapped; host-cached memory first when prefer_cached (read-back).
HostBuffer create_host_buffer(const Device& device, VkDeviceSize size, VkBufferUsageFlags usage, bool prefer_cached);

// An optimally tiled width x height image of `format` for `usage`, in device-local memory where
// there is some, with its view.
// aspect: the view's (a depth attachment's is VK_IMAGE_ASPECT_DEPTH_BIT).
DeviceImage create_image(const Device& device, uint32_t width, uint32_t height, VkFormat format,
                         VkImageUsageFlags usage, VkImageAspectFlags aspect = VK_IMAGE_ASPECT_COLOR_BIT);

// A linearly tiled, host-mapped width x height image of `format` for `usage`, created in
// VK_IMAGE_LAYOUT_PREINITIALIZED (host writes are defined in it and in GENERAL), where the device
// supports one that the usage's features work on as on an optimal image (sampling and linear
// filtering for a sampled image, blending for an attachment) and maps its memory; otherwise an
// image without `mapped`, and the caller uses create_image(). host_cached: only in host-cached
// memory (an image the host reads: uncached or write-combined memory, a GPU's BAR, would make
// every read slow), else none.
DeviceImage create_host_image(const Device& device, uint32_t width, uint32_t height, VkFormat format,
                              VkImageUsageFlags usage, bool host_cached = false);

// The host's writes to mapped memory made visible to the device, and the device's writes to the
// host: both nothing for host-coherent memory.
void flush_mapped(VkDevice device, VkDeviceMemory memory, bool coherent);
void invalidate_mapped(VkDevice device, VkDeviceMemory memory, bool coherent);

// Records the copy of the top-left width x height texels of `image` (a colour image in
// TRANSFER_SRC_OPTIMAL) into `buffer`, rows packed, and the barrier that makes them visible to the
// host once the submission's fence signalled: a pass's read-back.
void record_copy_to_host(VkCommandBuffer commands, VkImage image, VkBuffer buffer, uint32_t width, uint32_t height);

// A host-visible uniform texel buffer of `texels` texels of `format`, mapped, with its view.
TexelBuffer create_texel_buffer(const Device& device, uint32_t texels, VkFormat format, size_t texel_bytes);
TexelBuffer create_storage_buffer(const Device& device, uint32_t texels, size_t texel_bytes);

}  // namespace mobirt::vk
