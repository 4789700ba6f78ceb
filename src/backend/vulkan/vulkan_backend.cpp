// Headless Vulkan backend: lavapipe (or any Vulkan 1.1 device), one full-screen fragment pass per
// call, one RGBA8 texel per ray read back. Every pass is synchronous: record, submit, wait on a
// fence, read back; so objects can be reused across passes without further synchronisation.
// Uploads write the host's data once, in place: buffers and (where the device has them, as
// lavapipe does) linearly tiled images live in host-visible memory, persistently mapped, and every
// earlier pass was waited for, so nothing still reads them; a submission makes the host's writes
// visible to the device. Only optimal images (staged_images, or a device without such linear
// images) go through a staging buffer and a copy command. The same for the pass's output: the
// render target is a linear image in host-visible memory that the host reads in place after the
// fence (no copy command to a read-back buffer), where the device renders into one (lavapipe);
// staged_images or another device render into an optimal image and copy it to a buffer.
// This file is the pass: textures, uploads, recording and timing a pass. The instance and device
// are vk_device.*, memory and images vk_resources.*, pipelines vk_pipeline.*.
#include "backend/vulkan/vulkan_backend.h"

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <span>
#include <string>
#include <unordered_map>
#include <vector>

#include "backend/backend.h"
#include "backend/shader_constraints.h"
#include "backend/vulkan/vk_device.h"
#include "backend/vulkan/vk_pipeline.h"
#include "backend/vulkan/vk_raster.h"
#include "backend/vulkan/vk_resources.h"
#include "backend/vulkan/vk_util.h"
#include "core/error.h"
#include "core/parallel.h"
#include "layout.h"

namespace mobirt {

long vulkan_live_objects() { return vk::live_object_counter().load(); }

namespace {

using Clock = std::chrono::steady_clock;

// The layout a pass reads an image in: GENERAL for a host-written linear image (host writes are
// defined there), else the read-only one.
VkImageLayout read_layout(const vk::Texture& texture) {
  return texture.image.mapped ? VK_IMAGE_LAYOUT_GENERAL : VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL;
}

constexpr size_t kStagingChunkBytes = size_t(16) << 20;  // uploads go through at most 16 MiB
constexpr uint32_t kTimestampCount = 3;

// ---- The backend's state ---------------------------------------------------------------------

class Impl {
 public:
  explicit Impl(const VulkanOptions& options);
  ~Impl();

  DeviceInfo device_info() const { return device_.info(); }
  TextureHandle create_texture(uint32_t width, uint32_t height, TexelFormat format);
  // A uniform texel buffer or a read-only storage buffer (kind).
  TextureHandle create_buffer(uint32_t texels, TexelFormat format, TextureKind kind);
  void upload(TextureHandle texture, const void* data, size_t bytes);
  void* begin_write(TextureHandle texture, size_t bytes);
  void end_write(TextureHandle texture);
  void destroy(TextureHandle texture);
  PassHandle create_pass(const PassDesc& desc);
  void destroy(PassHandle pass);
  PassTiming run_pass(PassHandle pass, std::span<const TextureHandle> textures,
                      std::span<const float> uniforms, uint32_t width, uint32_t count,
                      std::span<uint32_t> out);
  PassTiming run_raster(std::span<const float> vertices, const RasterView& view, uint32_t width, uint32_t height,
                        std::span<uint32_t> out);
  void start_raster(std::span<const float> vertices, const RasterView& view, uint32_t width, uint32_t height);
  PassTiming finish_raster(std::span<uint32_t> out);
  void drop_raster() { drop_raster_in_flight(); }
  std::vector<std::string> take_debug_messages() { return device_.take_debug_messages(); }
  void save_pipeline_cache() const { pipelines_.save_cache(); }

  // After a fence timed out the device may still be executing: its objects must not be destroyed.
  bool hung() const { return hung_; }
  // Whether the current render target (made by the first pass that renders anything, made anew
  // when a pass outgrows it) is a linear image read in place (no copy command).
  bool reads_target_in_place() const { return target_.linear; }

 private:
  void create_command_objects();
  void usable() const;
  VkResult device_result(VkResult result, const char* call);  // notes VK_ERROR_DEVICE_LOST
  void ensure_staging(VkDeviceSize size);
  void flush(const vk::Memory& memory, bool coherent);  // host writes to non-coherent memory
  void stage(const void* data, size_t bytes);  // into the staging buffer, flushed
  void ensure_readback(vk::HostBuffer& buffer, VkDeviceSize size);  // readback_ or raster_readback_
  // Milliseconds between two timestamps of the query pool (the device's valid bits, its period).
  double timestamp_ms(uint64_t from, uint64_t to) const {
    const uint64_t mask = device_.timestamp_bits() >= 64 ? ~uint64_t(0) : (uint64_t(1) << device_.timestamp_bits()) - 1;
    return double((to - from) & mask) * double(device_.properties().limits.timestampPeriod) * 1e-6;
  }
  void ensure_target(uint32_t width, uint32_t height);
  void make_submission(uint32_t timestamps, VkCommandBuffer& commands, vk::Fence& fence, vk::QueryPool& queries);
  void begin_commands();
  void submit_and_wait(const char* what);
  void wait_for(VkFence fence, const char* what);  // then resets it; a timeout makes the backend hung
  void drop_raster_in_flight();                     // waits for a started raster pass, unread
  vk::Texture& texture_ref(TextureHandle handle);
  TextureHandle keep(vk::Texture texture);
  void upload_buffer(vk::Texture& texture, const void* data, size_t bytes);
  void upload_mapped_image(vk::Texture& texture, const void* data, size_t bytes);
  void upload_staged_image(vk::Texture& texture, const void* data, size_t bytes);
  vk::Pass& pass_ref(PassHandle handle);

  // Members go in reverse order: resources, pipelines and commands, the device and instance.
  vk::Device device_;
  vk::CommandPool command_pool_;
  VkCommandBuffer commands_ = VK_NULL_HANDLE;  // freed with the pool
  vk::Fence fence_;
  vk::QueryPool queries_;
  vk::Pipelines pipelines_;
  vk::HostBuffer staging_;
  vk::HostBuffer readback_;
  vk::RenderTarget target_;
  std::unique_ptr<vk::RasterPass> raster_;  // made by the first start_raster (run_raster's too)
  // The raster pass in flight (start_raster): its own command buffer, fence, timestamps and
  // read-back buffer, so that uploads (a staged one submits commands) run while the driver sets up
  // its triangles.
  VkCommandBuffer raster_commands_ = VK_NULL_HANDLE;  // freed with the pool
  vk::Fence raster_fence_;
  vk::QueryPool raster_queries_;
  vk::HostBuffer raster_readback_;
  struct RasterInFlight {
    bool active = false;
    bool submitted = false;  // false for an empty size: nothing to wait for
    uint32_t width = 0, height = 0;
    double upload_ms = 0.0;
    Clock::time_point wall_start;
    Clock::time_point submitted_at;  // when the draw was handed to the queue
  } raster_flight_;
  std::unordered_map<uint32_t, vk::Texture> textures_;
  std::unordered_map<uint32_t, vk::Pass> passes_;
  uint32_t next_texture_ = 1;
  uint32_t next_pass_ = 1;
  double pending_upload_ms_ = 0.0;
  double timeout_s_ = vk::pass_timeout_seconds();
  bool staged_images_ = false;
  bool lost_ = false;
  bool hung_ = false;
};

Impl::Impl(const VulkanOptions& options)
    : device_(options), pipelines_(device_, options.pipeline_cache_dir), staged_images_(options.staged_images) {
  create_command_objects();
  device_.throw_validation_errors();
}

Impl::~Impl() {
  if (!hung_) vkDeviceWaitIdle(device_.handle());
}

void Impl::create_command_objects() {
  VkCommandPoolCreateInfo pool_info{VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO};
  pool_info.flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT;
  pool_info.queueFamilyIndex = device_.queue_family();
  VkCommandPool pool = VK_NULL_HANDLE;
  VK_CHECK(vkCreateCommandPool(device_.handle(), &pool_info, nullptr, &pool));
  command_pool_ = vk::CommandPool(device_.handle(), pool);

  make_submission(kTimestampCount, commands_, fence_, queries_);
}

// A command buffer from the pool, a fence and, where the passes are timed on the device's clock
// (vk::Device::gpu_timestamps), a pool of `timestamps` queries: what one submission in flight
// needs.
void Impl::make_submission(uint32_t timestamps, VkCommandBuffer& commands, vk::Fence& fence, vk::QueryPool& queries) {
  VkCommandBufferAllocateInfo alloc{VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO};
  alloc.commandPool = command_pool_.get();
  alloc.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
  alloc.commandBufferCount = 1;
  VK_CHECK(vkAllocateCommandBuffers(device_.handle(), &alloc, &commands));

  VkFenceCreateInfo fence_info{VK_STRUCTURE_TYPE_FENCE_CREATE_INFO};
  VkFence made = VK_NULL_HANDLE;
  VK_CHECK(vkCreateFence(device_.handle(), &fence_info, nullptr, &made));
  fence = vk::Fence(device_.handle(), made);

  if (device_.gpu_timestamps()) {
    VkQueryPoolCreateInfo query_info{VK_STRUCTURE_TYPE_QUERY_POOL_CREATE_INFO};
    query_info.queryType = VK_QUERY_TYPE_TIMESTAMP;
    query_info.queryCount = timestamps;
    VkQueryPool query_pool = VK_NULL_HANDLE;
    VK_CHECK(vkCreateQueryPool(device_.handle(), &query_info, nullptr, &query_pool));
    queries = vk::QueryPool(device_.handle(), query_pool);
  }
}

// ---- Helpers ---------------------------------------------------------------------------------

void Impl::usable() const {
  if (hung_) throw Error(ErrorKind::Internal, "the Vulkan backend is unusable: an earlier pass never finished");
  if (lost_) throw Error(ErrorKind::Internal, "the Vulkan backend is unusable: the device was lost earlier");
}

VkResult Impl::device_result(VkResult result, const char* call) {
  if (result == VK_ERROR_DEVICE_LOST) {
    lost_ = true;
    throw Error(ErrorKind::Internal,
                std::string(call) + " failed: VK_ERROR_DEVICE_LOST: the Vulkan driver lost the device "
                "(a shader crashed, ran out of bounds or was killed by a watchdog); the backend cannot "
                "be used any more");
  }
  return result;
}

void Impl::ensure_staging(VkDeviceSize size) {
  if (staging_.size >= size) return;
  staging_.reset();
  staging_ = vk::create_host_buffer(device_, std::max(size, VkDeviceSize(1) << 20), VK_BUFFER_USAGE_TRANSFER_SRC_BIT, false);
}

void Impl::flush(const vk::Memory& memory, bool coherent) {
  vk::flush_mapped(device_.handle(), memory.get(), coherent);
}

void Impl::stage(const void* data, size_t bytes) {
  parallel_copy(staging_.mapped, data, bytes);
  flush(staging_.memory, staging_.coherent);
}

void Impl::ensure_readback(vk::HostBuffer& buffer, VkDeviceSize size) {
  if (buffer.size >= size) return;
  buffer.reset();
  buffer = vk::create_host_buffer(device_, size, VK_BUFFER_USAGE_TRANSFER_DST_BIT, true);
}

void Impl::ensure_target(uint32_t width, uint32_t height) {
  if (target_.width >= width && target_.height >= height) return;
  const uint32_t w = std::max(width, target_.width), h = std::max(height, target_.height);
  target_.reset();

  vk::RenderTarget target;
  // A linear target the host reads in place where the device renders into one in host-cached
  // memory (lavapipe), as the data textures are written in place; staged_images, or a device
  // without one, keeps the optimal image and its copy to a host-cached read-back buffer.
  if (!staged_images_) {
    target.image = vk::create_host_image(device_, w, h, vk::kTargetFormat, VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT,
                                         /*host_cached=*/true);
    target.linear = target.image.mapped != nullptr;
  }
  if (!target.linear) {
    target.image = vk::create_image(device_, w, h, vk::kTargetFormat,
                                    VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT | VK_IMAGE_USAGE_TRANSFER_SRC_BIT);
  }
  const VkImageView view = target.image.view.get();
  VkFramebufferCreateInfo framebuffer_info{VK_STRUCTURE_TYPE_FRAMEBUFFER_CREATE_INFO};
  framebuffer_info.renderPass = target.linear ? pipelines_.host_render_pass() : pipelines_.render_pass();
  framebuffer_info.attachmentCount = 1;
  framebuffer_info.pAttachments = &view;
  framebuffer_info.width = w;
  framebuffer_info.height = h;
  framebuffer_info.layers = 1;
  VkFramebuffer framebuffer = VK_NULL_HANDLE;
  VK_CHECK(vkCreateFramebuffer(device_.handle(), &framebuffer_info, nullptr, &framebuffer));
  target.framebuffer = vk::Framebuffer(device_.handle(), framebuffer);
  target.width = w;
  target.height = h;
  target_ = std::move(target);
}

void Impl::begin_commands() {
  VK_CHECK(vkResetCommandBuffer(commands_, 0));
  VkCommandBufferBeginInfo begin{VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
  begin.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
  VK_CHECK(vkBeginCommandBuffer(commands_, &begin));
}

void Impl::submit_and_wait(const char* what) {
  VK_CHECK(vkEndCommandBuffer(commands_));
  VkSubmitInfo submit{VK_STRUCTURE_TYPE_SUBMIT_INFO};
  submit.commandBufferCount = 1;
  submit.pCommandBuffers = &commands_;
  VkFence fence = fence_.get();
  VK_CHECK_RESULT(device_result(vkQueueSubmit(device_.queue(), 1, &submit, fence), "vkQueueSubmit"), "vkQueueSubmit");
  wait_for(fence, what);
}

void Impl::wait_for(VkFence fence, const char* what) {
  const uint64_t timeout_ns = uint64_t(timeout_s_ * 1e9);
  const VkResult result = device_result(vkWaitForFences(device_.handle(), 1, &fence, VK_TRUE, timeout_ns), "vkWaitForFences");
  if (result == VK_TIMEOUT) {
    hung_ = true;
    char seconds[32];
    std::snprintf(seconds, sizeof(seconds), "%g", timeout_s_);
    throw Error(ErrorKind::Internal,
                std::string("GPU pass did not finish within ") + seconds + " s (" + what +
                    "): a shader loop without a working cap? The device is still busy, so the backend is "
                    "unusable (MOBIRT_PASS_TIMEOUT_S sets the limit)");
  }
  VK_CHECK_RESULT(result, "vkWaitForFences");
  VK_CHECK(vkResetFences(device_.handle(), 1, &fence));
}

vk::Texture& Impl::texture_ref(TextureHandle handle) {
  const auto it = textures_.find(handle.id);
  if (it == textures_.end()) throw Error(ErrorKind::Internal, "unknown texture handle " + std::to_string(handle.id));
  return it->second;
}

vk::Pass& Impl::pass_ref(PassHandle handle) {
  const auto it = passes_.find(handle.id);
  if (it == passes_.end()) throw Error(ErrorKind::Internal, "unknown pass handle " + std::to_string(handle.id));
  return it->second;
}

// ---- Backend operations ----------------------------------------------------------------------

TextureHandle Impl::create_texture(uint32_t width, uint32_t height, TexelFormat format) {
  usable();
  if (width == 0 || height == 0) {
    throw Error(ErrorKind::Internal, "create_texture: empty texture " + std::to_string(width) + "x" + std::to_string(height));
  }
  const uint32_t limit = device_.properties().limits.maxImageDimension2D;
  if (width > limit || height > limit) {
    throw Error(ErrorKind::BadInput, "a " + std::to_string(width) + "x" + std::to_string(height) + " " +
                                         vk::format_name(format) + " texture exceeds the device's maxImageDimension2D (" +
                                         std::to_string(limit) + "): the scene is too large for this device");
  }
  vk::Texture texture;
  texture.width = width;
  texture.height = height;
  texture.format = format;
  if (!staged_images_) {
    texture.image = vk::create_host_image(device_, width, height, vk::vk_format(format), VK_IMAGE_USAGE_SAMPLED_BIT);
  }
  if (texture.image.mapped) {
    texture.layout = VK_IMAGE_LAYOUT_PREINITIALIZED;
  } else {
    texture.image = vk::create_image(device_, width, height, vk::vk_format(format),
                                     VK_IMAGE_USAGE_SAMPLED_BIT | VK_IMAGE_USAGE_TRANSFER_DST_BIT);
  }

  return keep(std::move(texture));
}

TextureHandle Impl::keep(vk::Texture texture) {
  device_.throw_validation_errors();
  const uint32_t id = next_texture_++;
  textures_.emplace(id, std::move(texture));
  return TextureHandle{id};
}

TextureHandle Impl::create_buffer(uint32_t texels, TexelFormat format, TextureKind kind) {
  usable();
  const bool storage = kind == TextureKind::StorageBuffer;
  const char* what = storage ? "storage buffer" : "texel buffer";
  if (texels == 0) throw Error(ErrorKind::Internal, std::string("create_buffer: empty ") + what);
  // The shaders index buffers by exact floats, below 2^24 (glsl/layout.h), so that is a limit too.
  // Passes that bind more than 2^23 texels are specialised to WIDE_INDICES (run_pass checks it).
  const VkPhysicalDeviceLimits& l = device_.properties().limits;
  const uint32_t device_limit =
      storage ? uint32_t(std::min<uint64_t>(l.maxStorageBufferRange / texel_bytes(format), UINT32_MAX))
              : l.maxTexelBufferElements;
  const uint32_t limit = std::min(device_limit, uint32_t(MOBIRT_MAX_INDEX_TEXELS));
  if (texels > limit) {
    throw Error(ErrorKind::BadInput, std::string("a ") + what + " of " + std::to_string(texels) + " " +
                                         vk::format_name(format) + " texels exceeds the limit of " +
                                         std::to_string(limit) +
                                         (storage ? " (maxStorageBufferRange" : " (maxTexelBufferElements") +
                                         ", at most 2^24): render with --data images");
  }
  vk::Texture texture;
  texture.width = texels;
  texture.height = 1;
  texture.format = format;
  texture.kind = kind;
  texture.buffer = storage ? vk::create_storage_buffer(device_, texels, texel_bytes(format))
                           : vk::create_texel_buffer(device_, texels, vk::vk_format(format), texel_bytes(format));
  return keep(std::move(texture));
}

// A buffer's upload: in place (every earlier pass was waited for).
void Impl::upload_buffer(vk::Texture& texture, const void* data, size_t bytes) {
  parallel_copy(texture.buffer.mapped, data, bytes);
  flush(texture.buffer.memory, texture.buffer.coherent);
}

// A linear image's upload: in place, row by row where its rows are padded.
void Impl::upload_mapped_image(vk::Texture& texture, const void* data, size_t bytes) {
  const size_t row_bytes = size_t(texture.width) * texel_bytes(texture.format);
  char* target = static_cast<char*>(texture.image.mapped);
  const char* source = static_cast<const char*>(data);
  if (texture.image.row_pitch == row_bytes) {
    parallel_copy(target, source, bytes);
  } else {
    for (size_t done = 0; done < bytes; done += row_bytes, target += texture.image.row_pitch) {
      std::memcpy(target, source + done, std::min(row_bytes, bytes - done));
    }
  }
  flush(texture.image.memory, texture.image.coherent);
}

// Throws where `bytes` is not a whole number of the texture's texels or more than it holds.
void check_upload_size(const vk::Texture& texture, size_t bytes, const char* what) {
  const size_t texel = texel_bytes(texture.format);
  const size_t total = size_t(texture.width) * texel * texture.height;
  if (bytes > total) {
    throw Error(ErrorKind::Internal, std::string(what) + " of " + std::to_string(bytes) + " bytes into a " +
                                         std::to_string(texture.width) + "x" + std::to_string(texture.height) + " " +
                                         vk::format_name(texture.format) + " texture of " + std::to_string(total) +
                                         " bytes");
  }
  if (bytes % texel != 0) {
    throw Error(ErrorKind::Internal, std::string(what) + " of " + std::to_string(bytes) +
                                         " bytes: not a whole number of " + vk::format_name(texture.format) + " texels");
  }
}

void Impl::upload(TextureHandle handle, const void* data, size_t bytes) {
  usable();
  vk::Texture& texture = texture_ref(handle);
  check_upload_size(texture, bytes, "upload");
  if (bytes == 0) return;
  if (!data) throw Error(ErrorKind::Internal, "upload: no data");
  const auto start = Clock::now();
  if (texture.kind != TextureKind::Image2D) {
    upload_buffer(texture, data, bytes);
  } else if (texture.image.mapped) {
    upload_mapped_image(texture, data, bytes);
  } else {
    upload_staged_image(texture, data, bytes);
  }
  pending_upload_ms_ += elapsed_ms(start);
  device_.throw_validation_errors();
}

// In place where the texels are mapped and unpadded: a buffer's, or a linear image whose rows are
// contiguous (an image with padded rows or in optimal tiling is uploaded).
void* Impl::begin_write(TextureHandle handle, size_t bytes) {
  usable();
  vk::Texture& texture = texture_ref(handle);
  check_upload_size(texture, bytes, "write");
  if (texture.kind != TextureKind::Image2D) return texture.buffer.mapped;
  const size_t row_bytes = size_t(texture.width) * texel_bytes(texture.format);
  return texture.image.mapped && (texture.height == 1 || texture.image.row_pitch == row_bytes) ? texture.image.mapped
                                                                                                : nullptr;
}

void Impl::end_write(TextureHandle handle) {
  usable();
  vk::Texture& texture = texture_ref(handle);
  if (texture.kind != TextureKind::Image2D) {
    flush(texture.buffer.memory, texture.buffer.coherent);
  } else if (texture.image.mapped) {
    flush(texture.image.memory, texture.image.coherent);
  }
}

// An optimal image's upload: staged copies of at most kStagingChunkBytes, each one submission.
void Impl::upload_staged_image(vk::Texture& texture, const void* data, size_t bytes) {
  const size_t texel = texel_bytes(texture.format);
  const size_t row_bytes = size_t(texture.width) * texel;
  // Whole rows, then the partial last row, in chunks that fit the reusable staging buffer.
  const size_t texels = bytes / texel;
  const size_t rows_per_chunk = std::max<size_t>(1, kStagingChunkBytes / row_bytes);
  ensure_staging(std::min(bytes, rows_per_chunk * row_bytes));
  size_t row = 0;
  while (row * texture.width < texels) {
    const size_t remaining = texels - row * texture.width;
    const size_t full_rows = std::min(rows_per_chunk, remaining / texture.width);
    const size_t tail = full_rows < rows_per_chunk ? remaining - full_rows * texture.width : 0;
    const size_t chunk_bytes = (full_rows * texture.width + tail) * texel;
    stage(static_cast<const char*>(data) + row * row_bytes, chunk_bytes);

    begin_commands();
    VkImageMemoryBarrier barrier{VK_STRUCTURE_TYPE_IMAGE_MEMORY_BARRIER};
    barrier.srcAccessMask = 0;  // earlier reads finished: every submission is waited for
    barrier.dstAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
    barrier.oldLayout = texture.layout;
    barrier.newLayout = VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL;
    barrier.srcQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
    barrier.dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
    barrier.image = texture.image.image.get();
    barrier.subresourceRange = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 1, 0, 1};
    vkCmdPipelineBarrier(commands_, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, VK_PIPELINE_STAGE_TRANSFER_BIT, 0, 0, nullptr,
                         0, nullptr, 1, &barrier);
    VkBufferImageCopy regions[2]{};
    uint32_t region_count = 0;
    if (full_rows > 0) {
      VkBufferImageCopy& r = regions[region_count++];
      r.bufferOffset = 0;
      r.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
      r.imageOffset = {0, int32_t(row), 0};
      r.imageExtent = {texture.width, uint32_t(full_rows), 1};
    }
    if (tail > 0) {
      VkBufferImageCopy& r = regions[region_count++];
      r.bufferOffset = full_rows * row_bytes;
      r.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
      r.imageOffset = {0, int32_t(row + full_rows), 0};
      r.imageExtent = {uint32_t(tail), 1, 1};
    }
    vkCmdCopyBufferToImage(commands_, staging_.buffer.get(), texture.image.image.get(), VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL,
                           region_count, regions);
    barrier.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
    barrier.dstAccessMask = VK_ACCESS_SHADER_READ_BIT;
    barrier.oldLayout = VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL;
    barrier.newLayout = VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL;
    vkCmdPipelineBarrier(commands_, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_FRAGMENT_SHADER_BIT, 0, 0,
                         nullptr, 0, nullptr, 1, &barrier);
    texture.layout = VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL;
    submit_and_wait("texture upload");
    row += full_rows + (tail > 0 ? 1 : 0);
  }
}

void Impl::destroy(TextureHandle handle) {
  if (hung_) return;  // the device may still read it
  textures_.erase(handle.id);
}

PassHandle Impl::create_pass(const PassDesc& desc) {
  // The OpenGL ES 2.0 constraints come first: a pass that breaks one is refused before any
  // Vulkan object exists.
  // A pass whose description binds storage buffers may read them (the --data storage-buffers
  // measurement variant), and nothing else is waived.
  // So may one that binds buffers by their device addresses (--data device-addresses).
  const auto reads = [&](TextureKind kind) {
    return std::find(desc.texture_kinds.begin(), desc.texture_kinds.end(), kind) != desc.texture_kinds.end();
  };
  const bool address_reads = reads(TextureKind::DeviceAddress);
  const bool storage_reads = address_reads || reads(TextureKind::StorageBuffer);
  if (address_reads) {
    if (!device_.device_addresses()) {
      throw Error(ErrorKind::Unsupported, "pass " + std::string(desc.shader.name()) +
                                              " reads buffers by device address, which this Vulkan device lacks "
                                              "(VK_KHR_buffer_device_address): use --data texel-buffers");
    }
    for (uint32_t binding : desc.texture_bindings) {
      if (binding >= MOBIRT_PASS_ADDRESS_SLOTS) {
        throw Error(ErrorKind::Internal, "pass " + std::string(desc.shader.name()) + ": binding " +
                                             std::to_string(binding) + " has no device-address slot");
      }
    }
  }
  check_es2_constraints(desc.shader.name(), desc.shader.source().spirv, storage_reads);
  usable();
  check_pass_desc(desc);
  vk::Pass pass = pipelines_.create_pass(desc);
  device_.throw_validation_errors();  // before the pass is kept: a refused pass frees its objects
  const uint32_t id = next_pass_++;
  passes_.emplace(id, std::move(pass));
  return PassHandle{id};
}

void Impl::destroy(PassHandle handle) {
  if (hung_) return;  // the device may still run it
  passes_.erase(handle.id);
}

PassTiming Impl::run_pass(PassHandle handle, std::span<const TextureHandle> textures,
                          std::span<const float> uniforms, uint32_t width, uint32_t count,
                          std::span<uint32_t> out) {
  const auto wall_start = Clock::now();
  usable();
  vk::Pass& pass = pass_ref(handle);
  std::vector<vk::Texture*> bound;
  const uint32_t height = start_run_pass(
      pass.desc, textures, uniforms.size(), width, count, out.size(), device_.properties().limits.maxImageDimension2D,
      "maxImageDimension2D", [&](TextureHandle t) -> vk::Texture& { return texture_ref(t); }, bound);
  if (height == 0) return empty_pass_timing(pending_upload_ms_, wall_start);
  const std::string name = pass.desc.shader.name();
  PassTiming timing;
  timing.upload_ms = pending_upload_ms_;
  ensure_target(width, height);
  if (!target_.linear) ensure_readback(readback_, VkDeviceSize(width) * height * 4);

  // Uniforms and textures. Every earlier submission has finished, so the set is free to update.
  if (pass.uniforms) {
    std::memcpy(pass.uniforms, uniforms.data(), uniforms.size_bytes());
    std::memset(pass.uniforms + uniforms.size(), 0, size_t(MOBIRT_MAX_PARAM_VEC4S) * 16 - uniforms.size_bytes());
  }
  // The push constants: the width, then the addresses of the buffers read by device address.
  uint8_t constants[vk::kPassConstantBytes] = {};
  const int32_t ray_width = int32_t(width);
  std::memcpy(constants, &ray_width, sizeof(ray_width));
  if (!bound.empty()) {
    const bool wide_indices =
        std::any_of(pass.desc.specialization.begin(), pass.desc.specialization.end(),
                    [](const Specialization& s) { return s.id == MOBIRT_SPEC_WIDE_INDICES && s.value != 0; });
    std::vector<VkDescriptorImageInfo> image_infos(bound.size());
    std::vector<VkBufferView> buffer_views(bound.size());
    std::vector<VkDescriptorBufferInfo> buffer_infos(bound.size());
    std::vector<VkWriteDescriptorSet> writes(bound.size());
    size_t written = 0;
    for (size_t i = 0; i < bound.size(); ++i) {
      const TextureKind kind = pass.desc.kind(i);
      // A buffer read by its address is a storage buffer.
      const TextureKind resource = kind == TextureKind::DeviceAddress ? TextureKind::StorageBuffer : kind;
      if (bound[i]->kind != resource) {
        throw Error(ErrorKind::Internal, "pass " + name + ": texture " + std::to_string(i) + " is a " +
                                             texture_kind_name(bound[i]->kind) + " where the pass reads a " +
                                             texture_kind_name(kind));
      }
      if (resource != TextureKind::Image2D && bound[i]->width > MOBIRT_NARROW_INDEX_TEXELS && !wide_indices) {
        throw Error(ErrorKind::Internal, "pass " + name + ": texture " + std::to_string(i) + " is a buffer of " +
                                             std::to_string(bound[i]->width) +
                                             " texels, more than 2^23, but the pass is not specialised to "
                                             "WIDE_INDICES (its indices would be wrong)");
      }
      if (kind == TextureKind::DeviceAddress) {
        const VkDeviceAddress address = bound[i]->buffer.address;
        if (address == 0) throw Error(ErrorKind::Internal, "pass " + name + ": texture " + std::to_string(i) + " has no device address");
        std::memcpy(constants + MOBIRT_PASS_ADDRESSES + 8 * pass.desc.texture_bindings[i], &address, sizeof(address));
        continue;
      }
      const size_t w = written++;
      writes[w] = {VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET};
      writes[w].dstSet = pass.descriptor_set;
      writes[w].dstBinding = pass.desc.texture_bindings[i];
      writes[w].descriptorCount = 1;
      writes[w].descriptorType = vk::descriptor_type(kind);
      if (kind == TextureKind::TexelBuffer) {
        buffer_views[w] = bound[i]->buffer.view.get();
        writes[w].pTexelBufferView = &buffer_views[w];
      } else if (kind == TextureKind::StorageBuffer) {
        buffer_infos[w] = {bound[i]->buffer.buffer.get(), 0, VK_WHOLE_SIZE};
        writes[w].pBufferInfo = &buffer_infos[w];
      } else {
        image_infos[w] = {VK_NULL_HANDLE, bound[i]->image.view.get(), read_layout(*bound[i])};
        writes[w].pImageInfo = &image_infos[w];
      }
    }
    if (written > 0) vkUpdateDescriptorSets(device_.handle(), uint32_t(written), writes.data(), 0, nullptr);
  }

  begin_commands();
  const bool timed = bool(queries_);
  if (timed) vkCmdResetQueryPool(commands_, queries_.get(), 0, kTimestampCount);
  // An image's first pass: a linear one leaves its initial layout for GENERAL (the host goes on
  // writing it there), an optimal one never uploaded gets the layout it is read in.
  std::vector<VkImageMemoryBarrier> first_use;
  for (vk::Texture* t : bound) {
    if (t->kind != TextureKind::Image2D || t->layout == read_layout(*t)) continue;
    VkImageMemoryBarrier barrier{VK_STRUCTURE_TYPE_IMAGE_MEMORY_BARRIER};
    barrier.srcAccessMask = t->image.mapped ? VK_ACCESS_HOST_WRITE_BIT : 0;
    barrier.dstAccessMask = VK_ACCESS_SHADER_READ_BIT;
    barrier.oldLayout = t->layout;
    barrier.newLayout = read_layout(*t);
    barrier.srcQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
    barrier.dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
    barrier.image = t->image.image.get();
    barrier.subresourceRange = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 1, 0, 1};
    first_use.push_back(barrier);
    t->layout = barrier.newLayout;
  }
  if (!first_use.empty()) {
    vkCmdPipelineBarrier(commands_, VK_PIPELINE_STAGE_HOST_BIT | VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, VK_PIPELINE_STAGE_FRAGMENT_SHADER_BIT, 0, 0,
                         nullptr, 0, nullptr, uint32_t(first_use.size()), first_use.data());
  }
  if (timed) vkCmdWriteTimestamp(commands_, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, queries_.get(), 0);

  VkRenderPassBeginInfo begin{VK_STRUCTURE_TYPE_RENDER_PASS_BEGIN_INFO};
  begin.renderPass = target_.linear ? pipelines_.host_render_pass() : pipelines_.render_pass();
  begin.framebuffer = target_.framebuffer.get();
  begin.renderArea = {{0, 0}, {width, height}};
  vkCmdBeginRenderPass(commands_, &begin, VK_SUBPASS_CONTENTS_INLINE);
  vkCmdBindPipeline(commands_, VK_PIPELINE_BIND_POINT_GRAPHICS, pass.pipeline.get());
  if (pass.descriptor_set != VK_NULL_HANDLE) {
    vkCmdBindDescriptorSets(commands_, VK_PIPELINE_BIND_POINT_GRAPHICS, pass.pipeline_layout.get(), 0, 1,
                            &pass.descriptor_set, 0, nullptr);
  }
  vkCmdPushConstants(commands_, pass.pipeline_layout.get(), VK_SHADER_STAGE_FRAGMENT_BIT, 0, vk::kPassConstantBytes,
                     constants);
  const VkViewport viewport{0.0f, 0.0f, float(width), float(height), 0.0f, 1.0f};
  const VkRect2D scissor{{0, 0}, {width, height}};
  vkCmdSetViewport(commands_, 0, 1, &viewport);
  vkCmdSetScissor(commands_, 0, 1, &scissor);
  vkCmdDraw(commands_, 3, 1, 0, 0);
  vkCmdEndRenderPass(commands_);
  if (timed) vkCmdWriteTimestamp(commands_, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, queries_.get(), 1);

  if (!target_.linear) {
    vk::record_copy_to_host(commands_, target_.image.image.get(), readback_.buffer.get(), width, height);
  }
  if (timed) vkCmdWriteTimestamp(commands_, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, queries_.get(), 2);

  const auto gpu_start = Clock::now();
  submit_and_wait(name.c_str());
  const double submit_ms = elapsed_ms(gpu_start);

  const auto copy_start = Clock::now();
  if (target_.linear) {
    vk::invalidate_mapped(device_.handle(), target_.image.memory.get(), target_.image.coherent);
  } else {
    vk::invalidate_mapped(device_.handle(), readback_.memory.get(), readback_.coherent);
  }
  if (target_.linear && target_.image.row_pitch == VkDeviceSize(width) * 4) {
    parallel_copy(out.data(), target_.image.mapped, size_t(count) * 4);
  } else if (target_.linear) {
    // Row by row: the target is as wide as the widest pass so far, its rows row_pitch apart.
    const char* rows = static_cast<const char*>(target_.image.mapped);
    for (uint32_t y = 0; y < height; ++y) {
      const uint32_t first = y * width;
      std::memcpy(out.data() + first, rows + VkDeviceSize(y) * target_.image.row_pitch,
                  size_t(std::min(width, count - first)) * 4);
    }
  } else {
    parallel_copy(out.data(), readback_.mapped, size_t(count) * 4);
  }
  const double copy_ms = elapsed_ms(copy_start);

  if (timed) {
    uint64_t stamps[kTimestampCount] = {};
    VK_CHECK_RESULT(device_result(vkGetQueryPoolResults(device_.handle(), queries_.get(), 0, kTimestampCount, sizeof(stamps), stamps,
                                                  sizeof(uint64_t), VK_QUERY_RESULT_64_BIT | VK_QUERY_RESULT_WAIT_BIT), "vkGetQueryPoolResults"), "vkGetQueryPoolResults");
    timing.gpu_ms = timestamp_ms(stamps[0], stamps[1]);
    timing.readback_ms = timestamp_ms(stamps[1], stamps[2]) + copy_ms;
  } else {
    timing.gpu_ms = submit_ms;  // no timestamps: the whole submission on the CPU clock
    timing.readback_ms = copy_ms;
  }
  timing.bytes_read = uint64_t(count) * 4;
  pending_upload_ms_ = 0.0;
  timing.wall_ms = elapsed_ms(wall_start);
  device_.throw_validation_errors();
  return timing;
}

// The started raster finished at once: one pass, on the raster's own command buffer, fence,
// timestamps and read-back buffer. A wrong output size is refused before any work.
PassTiming Impl::run_raster(std::span<const float> vertices, const RasterView& view, uint32_t width, uint32_t height,
                            std::span<uint32_t> out) {
  usable();
  if (out.size() != size_t(width) * height) {
    throw Error(ErrorKind::Internal, "run_raster: the output holds " + std::to_string(out.size()) + " texels, not " +
                                         std::to_string(width) + "x" + std::to_string(height));
  }
  start_raster(vertices, view, width, height);
  return finish_raster(out);
}

void Impl::drop_raster_in_flight() {
  const bool submitted = raster_flight_.active && raster_flight_.submitted;
  raster_flight_ = RasterInFlight{};
  if (submitted) wait_for(raster_fence_.get(), "raster");
}

void Impl::start_raster(std::span<const float> vertices, const RasterView& view, uint32_t width, uint32_t height) {
  const auto wall_start = Clock::now();
  usable();
  drop_raster_in_flight();
  RasterInFlight flight;
  flight.width = width;
  flight.height = height;
  flight.wall_start = wall_start;
  flight.upload_ms = std::exchange(pending_upload_ms_, 0.0);  // what was uploaded before it: its own
  if (width == 0 || height == 0) {
    flight.active = true;
    raster_flight_ = flight;
    return;
  }
  if (!raster_) raster_ = std::make_unique<vk::RasterPass>(device_, pipelines_.cache());
  if (!raster_fence_) make_submission(2, raster_commands_, raster_fence_, raster_queries_);
  const auto upload_start = Clock::now();
  raster_->prepare(width, height, vertices);
  flight.upload_ms += elapsed_ms(upload_start);
  ensure_readback(raster_readback_, VkDeviceSize(width) * height * 4);
  VK_CHECK(vkResetCommandBuffer(raster_commands_, 0));
  VkCommandBufferBeginInfo begin{VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
  begin.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
  VK_CHECK(vkBeginCommandBuffer(raster_commands_, &begin));
  const bool timed = bool(raster_queries_);
  if (timed) {
    vkCmdResetQueryPool(raster_commands_, raster_queries_.get(), 0, 2);
    vkCmdWriteTimestamp(raster_commands_, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, raster_queries_.get(), 0);
  }
  raster_->record(raster_commands_, view, width, height, raster_readback_.buffer.get());
  if (timed) vkCmdWriteTimestamp(raster_commands_, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, raster_queries_.get(), 1);
  VK_CHECK(vkEndCommandBuffer(raster_commands_));
  VkSubmitInfo submit{VK_STRUCTURE_TYPE_SUBMIT_INFO};
  submit.commandBufferCount = 1;
  submit.pCommandBuffers = &raster_commands_;
  VK_CHECK_RESULT(device_result(vkQueueSubmit(device_.queue(), 1, &submit, raster_fence_.get()), "vkQueueSubmit"),
                  "vkQueueSubmit");
  flight.submitted_at = Clock::now();
  flight.active = true;
  flight.submitted = true;
  raster_flight_ = flight;
  device_.throw_validation_errors();
}

PassTiming Impl::finish_raster(std::span<uint32_t> out) {
  usable();
  if (!raster_flight_.active) throw Error(ErrorKind::Internal, "finish_raster without start_raster");
  const RasterInFlight flight = std::exchange(raster_flight_, RasterInFlight{});
  PassTiming timing;
  timing.upload_ms = flight.upload_ms;
  if (out.size() != size_t(flight.width) * flight.height) {
    if (flight.submitted) wait_for(raster_fence_.get(), "raster");
    throw Error(ErrorKind::Internal, "finish_raster: the output holds " + std::to_string(out.size()) + " texels, not " +
                                         std::to_string(flight.width) + "x" + std::to_string(flight.height));
  }
  if (!flight.submitted) {
    timing.wall_ms = elapsed_ms(flight.wall_start);
    return timing;
  }
  wait_for(raster_fence_.get(), "raster");
  // Without timestamps: the draw's time from its submission until the fence was seen signalled,
  // an upper bound (the caller's work meanwhile included), never only the part it waited for.
  const double submitted_ms = elapsed_ms(flight.submitted_at);
  const auto copy_start = Clock::now();
  vk::invalidate_mapped(device_.handle(), raster_readback_.memory.get(), raster_readback_.coherent);
  parallel_copy(out.data(), raster_readback_.mapped, out.size_bytes());
  timing.readback_ms = elapsed_ms(copy_start);
  if (raster_queries_) {
    uint64_t stamps[2] = {};
    VK_CHECK_RESULT(device_result(vkGetQueryPoolResults(device_.handle(), raster_queries_.get(), 0, 2, sizeof(stamps),
                                                        stamps, sizeof(uint64_t),
                                                        VK_QUERY_RESULT_64_BIT | VK_QUERY_RESULT_WAIT_BIT),
                                  "vkGetQueryPoolResults"),
                    "vkGetQueryPoolResults");
    timing.gpu_ms = timestamp_ms(stamps[0], stamps[1]);
  } else {
    timing.gpu_ms = submitted_ms;
  }
  timing.bytes_read = uint64_t(out.size()) * 4;
  timing.wall_ms = elapsed_ms(flight.wall_start);
  device_.throw_validation_errors();
  return timing;
}

// ---- The Backend --------------------------------------------------------------------------------

class VulkanBackend final : public Backend {
 public:
  explicit VulkanBackend(const VulkanOptions& options) : impl_(std::make_unique<Impl>(options)) {}
  ~VulkanBackend() override {
    // A pass that never finished may still use every object: leak them rather than free memory
    // the driver is executing from.
    if (impl_ && impl_->hung()) {
      static_cast<void>(impl_.release());
      return;
    }
    if (impl_) impl_->save_pipeline_cache();
  }

  DeviceInfo device_info() const override { return impl_->device_info(); }
  TextureHandle create_texture(uint32_t width, uint32_t height, TexelFormat format) override {
    return impl_->create_texture(width, height, format);
  }
  TextureHandle create_texel_buffer(uint32_t texels, TexelFormat format) override {
    return impl_->create_buffer(texels, format, TextureKind::TexelBuffer);
  }
  TextureHandle create_storage_buffer(uint32_t texels, TexelFormat format) override {
    return impl_->create_buffer(texels, format, TextureKind::StorageBuffer);
  }
  void upload(TextureHandle texture, const void* data, size_t bytes) override { impl_->upload(texture, data, bytes); }
  void* begin_write(TextureHandle texture, size_t bytes) override { return impl_->begin_write(texture, bytes); }
  void end_write(TextureHandle texture) override { impl_->end_write(texture); }
  void destroy(TextureHandle texture) override { impl_->destroy(texture); }
  PassHandle create_pass(const PassDesc& desc) override { return impl_->create_pass(desc); }
  void destroy(PassHandle pass) override { impl_->destroy(pass); }
  PassTiming run_pass(PassHandle pass, std::span<const TextureHandle> textures, std::span<const float> uniforms,
                      uint32_t width, uint32_t count, std::span<uint32_t> out) override {
    return impl_->run_pass(pass, textures, uniforms, width, count, out);
  }
  PassTiming run_raster(std::span<const float> vertices, const RasterView& view, uint32_t width, uint32_t height,
                        std::span<uint32_t> out) override {
    return impl_->run_raster(vertices, view, width, height, out);
  }
  void start_raster(std::span<const float> vertices, const RasterView& view, uint32_t width, uint32_t height) override {
    impl_->start_raster(vertices, view, width, height);
  }
  PassTiming finish_raster(std::span<uint32_t> out) override { return impl_->finish_raster(out); }
  void drop_raster() override { impl_->drop_raster(); }
  std::vector<std::string> take_debug_messages() override { return impl_->take_debug_messages(); }
  bool reads_target_in_place() const { return impl_->reads_target_in_place(); }

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace

std::unique_ptr<Backend> create_vulkan_backend(const VulkanOptions& options) {
  return std::make_unique<VulkanBackend>(options);
}

bool vulkan_reads_target_in_place(const Backend& backend) {
  const auto* vulkan = dynamic_cast<const VulkanBackend*>(&backend);
  return vulkan && vulkan->reads_target_in_place();
}

std::unique_ptr<Backend> create_vulkan_backend(const BackendOptions& options) {
  return create_vulkan_backend(VulkanOptions{options});
}

}  // namespace mobirt
