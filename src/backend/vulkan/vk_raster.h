// The raster pass of the Vulkan backend (Backend::run_raster, --primary raster): the triangles from
// a vertex buffer, drawn with a depth test into an RGBA8 colour attachment that writes each pixel's
// closest triangle (glsl/raster.vert, glsl/raster.frag), copied to the backend's read-back buffer.
// Its own render pass (colour and depth, both cleared), pipeline and optimal images: nothing of the
// fragment passes' target changes. Private to src/backend/vulkan/.
#pragma once

#include <vulkan/vulkan.h>

#include <cstdint>
#include <span>

#include "backend/backend.h"
#include "backend/vulkan/vk_device.h"
#include "backend/vulkan/vk_resources.h"
#include "backend/vulkan/vk_util.h"

namespace mobirt::vk {

class RasterPass {
 public:
  // Checks raster.frag against the ES 2.0 constraints and makes the render pass and pipeline.
  RasterPass(const Device& device, VkPipelineCache cache);

  // The target of at least width x height and the vertex buffer holding `vertices` (host-visible,
  // written here), each made anew when too small. The caller has waited for every earlier use.
  void prepare(uint32_t width, uint32_t height, std::span<const float> vertices);

  // Records the pass into `commands`: both attachments cleared, the triangles of prepare() drawn,
  // the colour copied to `readback` (rows of `width` texels, packed) and made visible to the host.
  void record(VkCommandBuffer commands, const RasterView& view, uint32_t width, uint32_t height,
              VkBuffer readback) const;

 private:
  const Device& device_;
  VkFormat depth_format_ = VK_FORMAT_UNDEFINED;
  RenderPass render_pass_;
  PipelineLayout layout_;
  Pipeline pipeline_;
  // The target, as large as the largest pass so far (declared so that the framebuffer goes first).
  uint32_t width_ = 0, height_ = 0;
  DeviceImage colour_;
  DeviceImage depth_;
  Framebuffer framebuffer_;
  HostBuffer vertices_;
  uint32_t vertex_count_ = 0;
};

}  // namespace mobirt::vk
