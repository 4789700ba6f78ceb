// Memory, buffers and images of the Vulkan backend: memory types, host-visible buffers, and the
// one helper that creates a 2D image with its memory and view (data textures and the render
// target both use it). Private to src/backend/vulkan/.
#pragma once

#include <vulkan/vulkan.h>

#include <cstdint>

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

// A 2D image of one mip level and layer in device memory, with a colour view of it.
struct DeviceImage {
  Memory memory;
  Image image;
  ImageView view;

  void reset();
};

// A device-local buffer with a texel view of it: a uniform texel buffer (samplerBuffer); without
// the view, a read-only storage buffer.
struct TexelBuffer {
  Memory memory;
  Buffer buffer;
  BufferView view;

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

  void reset();
};

// The first memory type in type_bits with required | preferred, else with required; throws
// Error(Unsupported) when none has `required`. *coherent: whether it is host-coherent.
uint32_t memory_type(const VkPhysicalDeviceMemoryProperties& properties, uint32_t type_bits,
                     VkMemoryPropertyFlags required, VkMemoryPropertyFlags preferred, bool* coherent = nullptr);
Memory allocate(const Device& device, const VkMemoryRequirements& requirements, VkMemoryPropertyFlags required,
                VkMemoryPropertyFlags preferred, bool* coherent = nullptr);

// A host-visible buffer, mapped; host-cached memory first when prefer_cached (read-back).
HostBuffer create_host_buffer(const Device& device, VkDeviceSize size, VkBufferUsageFlags usage, bool prefer_cached);

// An optimally tiled width x height image of `format` for `usage`, in device-local memory where
// there is some, with its view.
DeviceImage create_image(const Device& device, uint32_t width, uint32_t height, VkFormat format,
                         VkImageUsageFlags usage);

// A device-local uniform texel buffer of `texels` texels of `format` (also a transfer destination),
// with its view.
TexelBuffer create_texel_buffer(const Device& device, uint32_t texels, VkFormat format, size_t texel_bytes);
TexelBuffer create_storage_buffer(const Device& device, uint32_t texels, size_t texel_bytes);

}  // namespace mobirt::vk
