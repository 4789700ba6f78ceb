#include "backend/vulkan/vk_resources.h"

#include <string>

#include "core/error.h"

namespace mobirt::vk {

VkFormat vk_format(TexelFormat format) {
  switch (format) {
    case TexelFormat::RGBA32F: return VK_FORMAT_R32G32B32A32_SFLOAT;
    case TexelFormat::R32F: return VK_FORMAT_R32_SFLOAT;
    case TexelFormat::RGBA8: return VK_FORMAT_R8G8B8A8_UNORM;
    case TexelFormat::SRGBA8: return VK_FORMAT_R8G8B8A8_SRGB;
  }
  throw Error(ErrorKind::Internal, "unknown texel format " + std::to_string(int(format)));
}

const char* format_name(TexelFormat format) {
  switch (format) {
    case TexelFormat::RGBA32F: return "RGBA32F";
    case TexelFormat::R32F: return "R32F";
    case TexelFormat::RGBA8: return "RGBA8";
    case TexelFormat::SRGBA8: return "SRGBA8";
  }
  return "unknown";
}

void HostBuffer::reset() {
  mapped = nullptr;
  buffer.reset();
  memory.reset();
  size = 0;
}

void DeviceImage::reset() {
  view.reset();
  image.reset();
  memory.reset();
}

void TexelBuffer::reset() {
  view.reset();
  buffer.reset();
  memory.reset();
}

void RenderTarget::reset() {
  framebuffer.reset();
  image.reset();
  width = height = 0;
}

uint32_t memory_type(const VkPhysicalDeviceMemoryProperties& properties, uint32_t type_bits,
                     VkMemoryPropertyFlags required, VkMemoryPropertyFlags preferred, bool* coherent) {
  for (const VkMemoryPropertyFlags wanted : {required | preferred, required}) {
    for (uint32_t i = 0; i < properties.memoryTypeCount; ++i) {
      const VkMemoryPropertyFlags flags = properties.memoryTypes[i].propertyFlags;
      if ((type_bits & (1u << i)) && (flags & wanted) == wanted) {
        if (coherent) *coherent = (flags & VK_MEMORY_PROPERTY_HOST_COHERENT_BIT) != 0;
        return i;
      }
    }
  }
  throw Error(ErrorKind::Unsupported, "the Vulkan device has no memory type with the properties mobirt needs");
}

Memory allocate(const Device& device, const VkMemoryRequirements& requirements, VkMemoryPropertyFlags required,
                VkMemoryPropertyFlags preferred, bool* coherent) {
  VkMemoryAllocateInfo info{VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO};
  info.allocationSize = requirements.size;
  info.memoryTypeIndex =
      memory_type(device.memory_properties(), requirements.memoryTypeBits, required, preferred, coherent);
  VkDeviceMemory memory = VK_NULL_HANDLE;
  VK_CHECK(vkAllocateMemory(device.handle(), &info, nullptr, &memory));
  return Memory(device.handle(), memory);
}

namespace {

// A buffer of `size` bytes for `usage`, bound to memory of its own (allocate()'s rules).
void create_bound_buffer(const Device& device, VkDeviceSize size, VkBufferUsageFlags usage,
                         VkMemoryPropertyFlags required, VkMemoryPropertyFlags preferred, Buffer& buffer_out,
                         Memory& memory_out, bool* coherent) {
  const VkDevice vk_device = device.handle();
  VkBufferCreateInfo info{VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO};
  info.size = size;
  info.usage = usage;
  info.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
  VkBuffer buffer = VK_NULL_HANDLE;
  VK_CHECK(vkCreateBuffer(vk_device, &info, nullptr, &buffer));
  buffer_out = Buffer(vk_device, buffer);
  VkMemoryRequirements requirements{};
  vkGetBufferMemoryRequirements(vk_device, buffer, &requirements);
  memory_out = allocate(device, requirements, required, preferred, coherent);
  VK_CHECK(vkBindBufferMemory(vk_device, buffer, memory_out.get(), 0));
}

}  // namespace

HostBuffer create_host_buffer(const Device& device, VkDeviceSize size, VkBufferUsageFlags usage, bool prefer_cached) {
  HostBuffer result;
  result.size = size;
  create_bound_buffer(device, size, usage, VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT,
                      prefer_cached ? VK_MEMORY_PROPERTY_HOST_CACHED_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT
                                    : VK_MEMORY_PROPERTY_HOST_COHERENT_BIT,
                      result.buffer, result.memory, &result.coherent);
  VK_CHECK(vkMapMemory(device.handle(), result.memory.get(), 0, VK_WHOLE_SIZE, 0, &result.mapped));
  return result;
}

DeviceImage create_image(const Device& device, uint32_t width, uint32_t height, VkFormat format,
                         VkImageUsageFlags usage) {
  const VkDevice vk_device = device.handle();
  VkImageCreateInfo info{VK_STRUCTURE_TYPE_IMAGE_CREATE_INFO};
  info.imageType = VK_IMAGE_TYPE_2D;
  info.format = format;
  info.extent = {width, height, 1};
  info.mipLevels = 1;
  info.arrayLayers = 1;
  info.samples = VK_SAMPLE_COUNT_1_BIT;
  info.tiling = VK_IMAGE_TILING_OPTIMAL;
  info.usage = usage;
  info.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
  info.initialLayout = VK_IMAGE_LAYOUT_UNDEFINED;
  VkImage image = VK_NULL_HANDLE;
  VK_CHECK(vkCreateImage(vk_device, &info, nullptr, &image));
  DeviceImage result;
  result.image = Image(vk_device, image);
  VkMemoryRequirements requirements{};
  vkGetImageMemoryRequirements(vk_device, image, &requirements);
  result.memory = allocate(device, requirements, 0, VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT);
  VK_CHECK(vkBindImageMemory(vk_device, image, result.memory.get(), 0));

  VkImageViewCreateInfo view_info{VK_STRUCTURE_TYPE_IMAGE_VIEW_CREATE_INFO};
  view_info.image = image;
  view_info.viewType = VK_IMAGE_VIEW_TYPE_2D;
  view_info.format = format;
  view_info.subresourceRange = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 1, 0, 1};
  VkImageView view = VK_NULL_HANDLE;
  VK_CHECK(vkCreateImageView(vk_device, &view_info, nullptr, &view));
  result.view = ImageView(vk_device, view);
  return result;
}

TexelBuffer create_texel_buffer(const Device& device, uint32_t texels, VkFormat format, size_t texel_bytes) {
  const VkDevice vk_device = device.handle();
  TexelBuffer result;
  create_bound_buffer(device, VkDeviceSize(texels) * texel_bytes,
                      VK_BUFFER_USAGE_UNIFORM_TEXEL_BUFFER_BIT | VK_BUFFER_USAGE_TRANSFER_DST_BIT, 0,
                      VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT, result.buffer, result.memory, nullptr);
  VkBufferViewCreateInfo view_info{VK_STRUCTURE_TYPE_BUFFER_VIEW_CREATE_INFO};
  view_info.buffer = result.buffer.get();
  view_info.format = format;
  view_info.offset = 0;
  view_info.range = VK_WHOLE_SIZE;
  VkBufferView view = VK_NULL_HANDLE;
  VK_CHECK(vkCreateBufferView(vk_device, &view_info, nullptr, &view));
  result.view = BufferView(vk_device, view);
  return result;
}

TexelBuffer create_storage_buffer(const Device& device, uint32_t texels, size_t texel_bytes) {
  TexelBuffer result;
  create_bound_buffer(device, VkDeviceSize(texels) * texel_bytes,
                      VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_TRANSFER_DST_BIT, 0,
                      VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT, result.buffer, result.memory, nullptr);
  return result;
}

}  // namespace mobirt::vk
