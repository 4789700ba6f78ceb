#include "backend/vulkan/vk_raster.h"

#include <algorithm>
#include <cstring>
#include <string>

#include "backend/shader_constraints.h"
#include "backend/vulkan/vk_pipeline.h"
#include "core/error.h"
#include "core/parallel.h"

// SPIR-V of the raster pass, generated at build time from glsl/ (build/spirv/<name>.h).
#include "raster.frag.h"
#include "raster.vert.h"

namespace mobirt::vk {

namespace {

constexpr uint32_t kVertexFloats = 4;  // xyz + index + 1

// The first depth format the device renders into: 32-bit float (the reversed depth of
// glsl/raster.vert keeps its relative precision at every distance there), else 24 or 16-bit unorm.
VkFormat choose_depth_format(VkPhysicalDevice physical) {
  for (VkFormat format : {VK_FORMAT_D32_SFLOAT, VK_FORMAT_X8_D24_UNORM_PACK32, VK_FORMAT_D16_UNORM}) {
    VkFormatProperties properties{};
    vkGetPhysicalDeviceFormatProperties(physical, format, &properties);
    if (properties.optimalTilingFeatures & VK_FORMAT_FEATURE_DEPTH_STENCIL_ATTACHMENT_BIT) return format;
  }
  throw Error(ErrorKind::Unsupported, "the Vulkan device has no depth attachment format: use --primary trace");
}

}  // namespace

RasterPass::RasterPass(const Device& device, VkPipelineCache cache) : device_(device) {
  // The same constraint check as every fragment pass: one RGBA8 output, no storage writes.
  check_es2_constraints("raster.frag", spirv_raster_frag, false);
  const VkDevice vk_device = device.handle();
  depth_format_ = choose_depth_format(device.physical());

  // Colour and depth, both cleared; the colour left for the copy, the depth discarded.
  VkAttachmentDescription attachments[2]{};
  attachments[0].format = kTargetFormat;
  attachments[0].samples = VK_SAMPLE_COUNT_1_BIT;
  attachments[0].loadOp = VK_ATTACHMENT_LOAD_OP_CLEAR;
  attachments[0].storeOp = VK_ATTACHMENT_STORE_OP_STORE;
  attachments[0].stencilLoadOp = VK_ATTACHMENT_LOAD_OP_DONT_CARE;
  attachments[0].stencilStoreOp = VK_ATTACHMENT_STORE_OP_DONT_CARE;
  attachments[0].initialLayout = VK_IMAGE_LAYOUT_UNDEFINED;
  attachments[0].finalLayout = VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL;
  attachments[1] = attachments[0];
  attachments[1].format = depth_format_;
  attachments[1].storeOp = VK_ATTACHMENT_STORE_OP_DONT_CARE;
  attachments[1].finalLayout = VK_IMAGE_LAYOUT_DEPTH_STENCIL_ATTACHMENT_OPTIMAL;
  const VkAttachmentReference colour_ref{0, VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL};
  const VkAttachmentReference depth_ref{1, VK_IMAGE_LAYOUT_DEPTH_STENCIL_ATTACHMENT_OPTIMAL};
  VkSubpassDescription subpass{};
  subpass.pipelineBindPoint = VK_PIPELINE_BIND_POINT_GRAPHICS;
  subpass.colorAttachmentCount = 1;
  subpass.pColorAttachments = &colour_ref;
  subpass.pDepthStencilAttachment = &depth_ref;
  VkSubpassDependency dependencies[2]{};
  // The previous raster pass's copy read the colour and its depth tests wrote the depth before
  // this one clears both (write after read, write after write).
  dependencies[0].srcSubpass = VK_SUBPASS_EXTERNAL;
  dependencies[0].dstSubpass = 0;
  dependencies[0].srcStageMask = VK_PIPELINE_STAGE_TRANSFER_BIT | VK_PIPELINE_STAGE_LATE_FRAGMENT_TESTS_BIT;
  dependencies[0].dstStageMask =
      VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT | VK_PIPELINE_STAGE_EARLY_FRAGMENT_TESTS_BIT;
  dependencies[0].srcAccessMask = VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_WRITE_BIT;
  dependencies[0].dstAccessMask = VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT | VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_READ_BIT |
                                  VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_WRITE_BIT;
  // The copy to the read-back buffer reads what the pass wrote.
  dependencies[1].srcSubpass = 0;
  dependencies[1].dstSubpass = VK_SUBPASS_EXTERNAL;
  dependencies[1].srcStageMask = VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT;
  dependencies[1].dstStageMask = VK_PIPELINE_STAGE_TRANSFER_BIT;
  dependencies[1].srcAccessMask = VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT;
  dependencies[1].dstAccessMask = VK_ACCESS_TRANSFER_READ_BIT;
  VkRenderPassCreateInfo render_pass_info{VK_STRUCTURE_TYPE_RENDER_PASS_CREATE_INFO};
  render_pass_info.attachmentCount = 2;
  render_pass_info.pAttachments = attachments;
  render_pass_info.subpassCount = 1;
  render_pass_info.pSubpasses = &subpass;
  render_pass_info.dependencyCount = 2;
  render_pass_info.pDependencies = dependencies;
  VkRenderPass render_pass = VK_NULL_HANDLE;
  VK_CHECK(vkCreateRenderPass(vk_device, &render_pass_info, nullptr, &render_pass));
  render_pass_ = RenderPass(vk_device, render_pass);

  // No descriptor set: the view is the vertex stage's push constants (RasterView).
  const VkPushConstantRange push_range{VK_SHADER_STAGE_VERTEX_BIT, 0, sizeof(RasterView)};
  VkPipelineLayoutCreateInfo layout_info{VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO};
  layout_info.pushConstantRangeCount = 1;
  layout_info.pPushConstantRanges = &push_range;
  VkPipelineLayout layout = VK_NULL_HANDLE;
  VK_CHECK(vkCreatePipelineLayout(vk_device, &layout_info, nullptr, &layout));
  layout_ = PipelineLayout(vk_device, layout);

  const ShaderModule vertex = create_shader_module(vk_device, spirv_raster_vert);
  const ShaderModule fragment = create_shader_module(vk_device, spirv_raster_frag);
  const VkVertexInputBindingDescription binding{0, kVertexFloats * sizeof(float), VK_VERTEX_INPUT_RATE_VERTEX};
  const VkVertexInputAttributeDescription attribute{0, 0, VK_FORMAT_R32G32B32A32_SFLOAT, 0};
  VkPipelineVertexInputStateCreateInfo vertex_input{VK_STRUCTURE_TYPE_PIPELINE_VERTEX_INPUT_STATE_CREATE_INFO};
  vertex_input.vertexBindingDescriptionCount = 1;
  vertex_input.pVertexBindingDescriptions = &binding;
  vertex_input.vertexAttributeDescriptionCount = 1;
  vertex_input.pVertexAttributeDescriptions = &attribute;
  VkPipelineDepthStencilStateCreateInfo depth{VK_STRUCTURE_TYPE_PIPELINE_DEPTH_STENCIL_STATE_CREATE_INFO};
  depth.depthTestEnable = VK_TRUE;
  depth.depthWriteEnable = VK_TRUE;
  depth.depthCompareOp = VK_COMPARE_OP_GREATER;  // reversed depth: glsl/raster.vert
  const VkPipeline pipeline = create_graphics_pipeline(vk_device, render_pass, layout, vertex.get(), fragment.get(),
                                                       nullptr, cache, &vertex_input, &depth);
  pipeline_ = Pipeline(vk_device, pipeline);
}

void RasterPass::prepare(uint32_t width, uint32_t height, std::span<const float> vertices) {
  const VkDevice vk_device = device_.handle();
  if (vertices.size() % (3 * kVertexFloats) != 0) {
    throw Error(ErrorKind::Internal, "run_raster: the vertices are not whole triangles of 4 floats a vertex");
  }
  const VkPhysicalDeviceLimits& limits = device_.properties().limits;
  if (width > limits.maxFramebufferWidth || height > limits.maxFramebufferHeight) {
    throw Error(ErrorKind::BadInput, "--size " + std::to_string(width) + "x" + std::to_string(height) +
                                         " is larger than the device's framebuffer limit (" +
                                         std::to_string(limits.maxFramebufferWidth) + "x" +
                                         std::to_string(limits.maxFramebufferHeight) + "): use --primary trace");
  }
  if (width > width_ || height > height_) {
    const uint32_t w = std::max(width, width_), h = std::max(height, height_);
    framebuffer_.reset();
    depth_.reset();
    colour_.reset();
    width_ = height_ = 0;  // no target until the new one exists (a failed creation leaves none)
    colour_ = create_image(device_, w, h, kTargetFormat,
                           VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT | VK_IMAGE_USAGE_TRANSFER_SRC_BIT);
    depth_ = create_image(device_, w, h, depth_format_, VK_IMAGE_USAGE_DEPTH_STENCIL_ATTACHMENT_BIT,
                          VK_IMAGE_ASPECT_DEPTH_BIT);
    const VkImageView views[] = {colour_.view.get(), depth_.view.get()};
    VkFramebufferCreateInfo info{VK_STRUCTURE_TYPE_FRAMEBUFFER_CREATE_INFO};
    info.renderPass = render_pass_.get();
    info.attachmentCount = 2;
    info.pAttachments = views;
    info.width = w;
    info.height = h;
    info.layers = 1;
    VkFramebuffer framebuffer = VK_NULL_HANDLE;
    VK_CHECK(vkCreateFramebuffer(vk_device, &info, nullptr, &framebuffer));
    framebuffer_ = Framebuffer(vk_device, framebuffer);
    width_ = w;
    height_ = h;
  }
  const VkDeviceSize bytes = std::max<VkDeviceSize>(vertices.size_bytes(), 16);
  if (vertices_.size < bytes) {
    vertices_.reset();
    // With headroom, so that an animation whose triangle count changes does not reallocate often.
    vertices_ = create_host_buffer(device_, bytes + bytes / 4, VK_BUFFER_USAGE_VERTEX_BUFFER_BIT, false);
  }
  if (!vertices.empty()) parallel_copy(vertices_.mapped, vertices.data(), vertices.size_bytes());
  flush_mapped(vk_device, vertices_.memory.get(), vertices_.coherent);
  vertex_count_ = uint32_t(vertices.size() / kVertexFloats);
}

void RasterPass::record(VkCommandBuffer commands, const RasterView& view, uint32_t width, uint32_t height,
                        VkBuffer readback) const {
  VkClearValue clears[2]{};
  clears[0].color = {{0.0f, 0.0f, 0.0f, 0.0f}};  // index + 1 = 0: no triangle
  clears[1].depthStencil = {0.0f, 0};  // reversed depth: 0 lies beyond everything
  VkRenderPassBeginInfo begin{VK_STRUCTURE_TYPE_RENDER_PASS_BEGIN_INFO};
  begin.renderPass = render_pass_.get();
  begin.framebuffer = framebuffer_.get();
  begin.renderArea = {{0, 0}, {width, height}};
  begin.clearValueCount = 2;
  begin.pClearValues = clears;
  vkCmdBeginRenderPass(commands, &begin, VK_SUBPASS_CONTENTS_INLINE);
  vkCmdBindPipeline(commands, VK_PIPELINE_BIND_POINT_GRAPHICS, pipeline_.get());
  vkCmdPushConstants(commands, layout_.get(), VK_SHADER_STAGE_VERTEX_BIT, 0, sizeof(RasterView), &view);
  const VkViewport viewport{0.0f, 0.0f, float(width), float(height), 0.0f, 1.0f};
  const VkRect2D scissor{{0, 0}, {width, height}};
  vkCmdSetViewport(commands, 0, 1, &viewport);
  vkCmdSetScissor(commands, 0, 1, &scissor);
  if (vertex_count_ > 0) {
    const VkBuffer buffer = vertices_.buffer.get();
    const VkDeviceSize offset = 0;
    vkCmdBindVertexBuffers(commands, 0, 1, &buffer, &offset);
    vkCmdDraw(commands, vertex_count_, 1, 0, 0);
  }
  vkCmdEndRenderPass(commands);

  record_copy_to_host(commands, colour_.image.get(), readback, width, height);
}

}  // namespace mobirt::vk
