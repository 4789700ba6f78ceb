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
  mapped = nullptr;
  view.reset();
  image.reset();
  memory.reset();
}

void TexelBuffer::reset() {
  mapped = nullptr;
  address = 0;
  view.reset();
  buffer.reset();
  memory.reset();
}

void RenderTarget::reset() {
  framebuffer.reset();
  image.reset();
  width = height = 0;
  linear = false;
}

std::optional<uint32_t> find_memory_type(const VkPhysicalDeviceMemoryProperties& properties, uint32_t type_bits,
                                         VkMemoryPropertyFlags required, VkMemoryPropertyFlags preferred,
                                         bool* coherent) {
  for (const VkMemoryPropertyFlags wanted : {required | preferred, required}) {
    for (uint32_t i = 0; i < properties.memoryTypeCount; ++i) {
      const VkMemoryPropertyFlags flags = properties.memoryTypes[i].propertyFlags;
      if ((type_bits & (1u << i)) && (flags & wanted) == wanted) {
        if (coherent) *coherent = (flags & VK_MEMORY_PROPERTY_HOST_COHERENT_BIT) != 0;
        return i;
      }
    }
  }
  return std::nullopt;
}

uint32_t memory_type(const VkPhysicalDeviceMemoryProperties& properties, uint32_t type_bits,
                     VkMemoryPropertyFlags required, VkMemoryPropertyFlags preferred, bool* coherent) {
  if (const std::optional<uint32_t> type = find_memory_type(properties, type_bits, required, preferred, coherent)) {
    return *type;
  }
  throw Error(ErrorKind::Unsupported, "the Vulkan device has no memory type with the properties mobirt needs");
}

Memory allocate(const Device& device, const VkMemoryRequirements& requirements, VkMemoryPropertyFlags required,
                VkMemoryPropertyFlags preferred, bool* coherent, bool addressable) {
  VkMemoryAllocateInfo info{VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO};
  VkMemoryAllocateFlagsInfo flags{VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_FLAGS_INFO};
  if (addressable) {
    flags.flags = VK_MEMORY_ALLOCATE_DEVICE_ADDRESS_BIT_KHR;
    info.pNext = &flags;
  }
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
  memory_out = allocate(device, requirements, required, preferred, coherent,
                        (usage & VK_BUFFER_USAGE_SHADER_DEVICE_ADDRESS_BIT_KHR) != 0);
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

namespace {

// A 2D image of one level and layer; its memory and view are the caller's.
Image create_bare_image(VkDevice vk_device, uint32_t width, uint32_t height, VkFormat format, VkImageUsageFlags usage,
                        VkImageTiling tiling, VkImageLayout initial_layout) {
  VkImageCreateInfo info{VK_STRUCTURE_TYPE_IMAGE_CREATE_INFO};
  info.imageType = VK_IMAGE_TYPE_2D;
  info.format = format;
  info.extent = {width, height, 1};
  info.mipLevels = 1;
  info.arrayLayers = 1;
  info.samples = VK_SAMPLE_COUNT_1_BIT;
  info.tiling = tiling;
  info.usage = usage;
  info.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
  info.initialLayout = initial_layout;
  VkImage image = VK_NULL_HANDLE;
  VK_CHECK(vkCreateImage(vk_device, &info, nullptr, &image));
  return Image(vk_device, image);
}

ImageView create_view(VkDevice vk_device, VkImage image, VkFormat format,
                      VkImageAspectFlags aspect = VK_IMAGE_ASPECT_COLOR_BIT) {
  VkImageViewCreateInfo view_info{VK_STRUCTURE_TYPE_IMAGE_VIEW_CREATE_INFO};
  view_info.image = image;
  view_info.viewType = VK_IMAGE_VIEW_TYPE_2D;
  view_info.format = format;
  view_info.subresourceRange = {aspect, 0, 1, 0, 1};
  VkImageView view = VK_NULL_HANDLE;
  VK_CHECK(vkCreateImageView(vk_device, &view_info, nullptr, &view));
  return ImageView(vk_device, view);
}

// The format features that `usage` relies on, of those mobirt uses.
VkFormatFeatureFlags usage_features(VkImageUsageFlags usage) {
  VkFormatFeatureFlags features = 0;
  if (usage & VK_IMAGE_USAGE_SAMPLED_BIT) {
    features |= VK_FORMAT_FEATURE_SAMPLED_IMAGE_BIT | VK_FORMAT_FEATURE_SAMPLED_IMAGE_FILTER_LINEAR_BIT;
  }
  if (usage & VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT) {
    features |= VK_FORMAT_FEATURE_COLOR_ATTACHMENT_BIT | VK_FORMAT_FEATURE_COLOR_ATTACHMENT_BLEND_BIT;
  }
  if (usage & VK_IMAGE_USAGE_TRANSFER_SRC_BIT) features |= VK_FORMAT_FEATURE_TRANSFER_SRC_BIT;
  if (usage & VK_IMAGE_USAGE_TRANSFER_DST_BIT) features |= VK_FORMAT_FEATURE_TRANSFER_DST_BIT;
  return features;
}

}  // namespace

namespace {
VkMappedMemoryRange whole(VkDeviceMemory memory) {
  VkMappedMemoryRange range{VK_STRUCTURE_TYPE_MAPPED_MEMORY_RANGE};
  range.memory = memory;
  range.size = VK_WHOLE_SIZE;
  return range;
}
}  // namespace

void flush_mapped(VkDevice device, VkDeviceMemory memory, bool coherent) {
  if (coherent) return;
  const VkMappedMemoryRange range = whole(memory);
  VK_CHECK(vkFlushMappedMemoryRanges(device, 1, &range));
}

void invalidate_mapped(VkDevice device, VkDeviceMemory memory, bool coherent) {
  if (coherent) return;
  const VkMappedMemoryRange range = whole(memory);
  VK_CHECK(vkInvalidateMappedMemoryRanges(device, 1, &range));
}

void record_copy_to_host(VkCommandBuffer commands, VkImage image, VkBuffer buffer, uint32_t width, uint32_t height) {
  VkBufferImageCopy region{};
  region.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
  region.imageExtent = {width, height, 1};
  vkCmdCopyImageToBuffer(commands, image, VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL, buffer, 1, &region);
  VkBufferMemoryBarrier to_host{VK_STRUCTURE_TYPE_BUFFER_MEMORY_BARRIER};
  to_host.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
  to_host.dstAccessMask = VK_ACCESS_HOST_READ_BIT;
  to_host.srcQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
  to_host.dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
  to_host.buffer = buffer;
  to_host.size = VK_WHOLE_SIZE;
  vkCmdPipelineBarrier(commands, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_HOST_BIT, 0, 0, nullptr, 1,
                       &to_host, 0, nullptr);
}

DeviceImage create_image(const Device& device, uint32_t width, uint32_t height, VkFormat format,
                         VkImageUsageFlags usage, VkImageAspectFlags aspect) {
  const VkDevice vk_device = device.handle();
  DeviceImage result;
  result.image = create_bare_image(vk_device, width, height, format, usage, VK_IMAGE_TILING_OPTIMAL,
                                   VK_IMAGE_LAYOUT_UNDEFINED);
  VkMemoryRequirements requirements{};
  vkGetImageMemoryRequirements(vk_device, result.image.get(), &requirements);
  result.memory = allocate(device, requirements, 0, VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT);
  VK_CHECK(vkBindImageMemory(vk_device, result.image.get(), result.memory.get(), 0));
  result.view = create_view(vk_device, result.image.get(), format, aspect);
  return result;
}

DeviceImage create_host_image(const Device& device, uint32_t width, uint32_t height, VkFormat format,
                              VkImageUsageFlags usage, bool host_cached) {
  const VkDevice vk_device = device.handle();
  DeviceImage result;
  // Only where the linear image does everything the optimal one would (a filtered atlas page, a
  // colour attachment), in this size.
  VkFormatProperties format_properties{};
  vkGetPhysicalDeviceFormatProperties(device.physical(), format, &format_properties);
  const VkFormatFeatureFlags wanted = usage_features(usage) & format_properties.optimalTilingFeatures;
  if ((format_properties.linearTilingFeatures & wanted) != wanted) return result;
  VkImageFormatProperties limits{};
  if (vkGetPhysicalDeviceImageFormatProperties(device.physical(), format, VK_IMAGE_TYPE_2D, VK_IMAGE_TILING_LINEAR,
                                               usage, 0, &limits) != VK_SUCCESS ||
      width > limits.maxExtent.width || height > limits.maxExtent.height) {
    return result;
  }
  Image image = create_bare_image(vk_device, width, height, format, usage, VK_IMAGE_TILING_LINEAR,
                                  VK_IMAGE_LAYOUT_PREINITIALIZED);
  VkMemoryRequirements requirements{};
  vkGetImageMemoryRequirements(vk_device, image.get(), &requirements);
  const VkMemoryPropertyFlags required =
      VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | (host_cached ? VK_MEMORY_PROPERTY_HOST_CACHED_BIT : 0);
  if (!find_memory_type(device.memory_properties(), requirements.memoryTypeBits, required, 0, nullptr)) {
    return result;
  }
  result.memory = allocate(device, requirements, required,
                           VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT,
                           &result.coherent);
  result.image = std::move(image);
  VK_CHECK(vkBindImageMemory(vk_device, result.image.get(), result.memory.get(), 0));
  const VkImageSubresource subresource{VK_IMAGE_ASPECT_COLOR_BIT, 0, 0};
  VkSubresourceLayout layout{};
  vkGetImageSubresourceLayout(vk_device, result.image.get(), &subresource, &layout);
  void* base = nullptr;
  VK_CHECK(vkMapMemory(vk_device, result.memory.get(), 0, VK_WHOLE_SIZE, 0, &base));
  result.mapped = static_cast<char*>(base) + layout.offset;
  result.row_pitch = layout.rowPitch;
  result.view = create_view(vk_device, result.image.get(), format);
  return result;
}

namespace {

// Host-visible (device-local too where it can be), mapped: the host writes the data in place.
void create_mapped_buffer(const Device& device, VkDeviceSize size, VkBufferUsageFlags usage, TexelBuffer& result) {
  create_bound_buffer(device, size, usage, VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT,
                      VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT, result.buffer,
                      result.memory, &result.coherent);
  VK_CHECK(vkMapMemory(device.handle(), result.memory.get(), 0, VK_WHOLE_SIZE, 0, &result.mapped));
}

}  // namespace

TexelBuffer create_texel_buffer(const Device& device, uint32_t texels, VkFormat format, size_t texel_bytes) {
  const VkDevice vk_device = device.handle();
  TexelBuffer result;
  create_mapped_buffer(device, VkDeviceSize(texels) * texel_bytes, VK_BUFFER_USAGE_UNIFORM_TEXEL_BUFFER_BIT, result);
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
  // Also read through its address (TextureKind::DeviceAddress) where the device has them.
  const VkBufferUsageFlags address =
      device.device_addresses() ? VkBufferUsageFlags(VK_BUFFER_USAGE_SHADER_DEVICE_ADDRESS_BIT_KHR) : 0;
  create_mapped_buffer(device, VkDeviceSize(texels) * texel_bytes, VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | address, result);
  if (address) result.address = device.buffer_address(result.buffer.get());
  return result;
}

}  // namespace mobirt::vk
