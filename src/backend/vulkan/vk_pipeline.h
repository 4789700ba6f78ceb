// Pipelines of the Vulkan backend: what every pass's pipeline shares (the render pass of one RGBA8
// attachment, the full-screen triangle's vertex shader, the immutable sampler, the pipeline cache
// and its file on disk), and one pass's descriptor set, uniform block and specialised graphics
// pipeline. Private to src/backend/vulkan/.
#pragma once

#include <vulkan/vulkan.h>

#include <span>
#include <string>
#include <vector>

#include "backend/backend.h"
#include "backend/vulkan/vk_device.h"
#include "backend/vulkan/vk_util.h"
#include "layout.h"

namespace mobirt::vk {

// The descriptor a pass binds for a texture of this kind: a combined image sampler, a uniform texel
// buffer or a storage buffer. The set layout, its pool and the writes all take it from here.
VkDescriptorType descriptor_type(TextureKind kind);

// The immutable sampler of every texelFetch (NEAREST, CLAMP_TO_EDGE: its filtering never applies),
// or with LINEAR the bilinear sampler of PassDesc::linear_bindings (no mipmaps, CLAMP_TO_EDGE).
Sampler create_fetch_sampler(VkDevice device, VkFilter filter = VK_FILTER_NEAREST);
// The render pass of every fragment pass: one kTargetFormat attachment, not loaded, stored and left
// for the copy to the host, ordered after the previous pass's copy and before this one's; with
// host_read, left in GENERAL for the host to read a linear target in place (a compatible pass).
RenderPass create_target_render_pass(VkDevice device, bool host_read = false);

// A shader module of SPIR-V `code`.
ShaderModule create_shader_module(VkDevice device, std::span<const uint32_t> code);

// The graphics pipeline of a full-screen fragment pass: one triangle from `vertex`, `fragment` with
// its specialisation (may be null), no culling, no blending, dynamic viewport and scissor, one
// RGBA8 attachment of `render_pass`. Every fragment pass uses it, the peers' included.
VkPipeline create_fullscreen_pipeline(VkDevice device, VkRenderPass render_pass, VkPipelineLayout layout,
                                      VkShaderModule vertex, VkShaderModule fragment,
                                      const VkSpecializationInfo* specialization, VkPipelineCache cache);

// The same pipeline state with the vertex stage's input and a depth test where given (the raster
// pass of --primary raster, vk_raster.h): null keeps the full-screen pass's (no vertex input, no
// depth attachment).
VkPipeline create_graphics_pipeline(VkDevice device, VkRenderPass render_pass, VkPipelineLayout layout,
                                    VkShaderModule vertex, VkShaderModule fragment,
                                    const VkSpecializationInfo* specialization, VkPipelineCache cache,
                                    const VkPipelineVertexInputStateCreateInfo* vertex_input,
                                    const VkPipelineDepthStencilStateCreateInfo* depth);

// A pass's specialization constants as Vulkan takes them; info() points into this object.
class SpecializationConstants {
 public:
  explicit SpecializationConstants(std::span<const Specialization> constants);
  SpecializationConstants(const SpecializationConstants&) = delete;
  SpecializationConstants& operator=(const SpecializationConstants&) = delete;
  const VkSpecializationInfo* info() const { return entries_.empty() ? nullptr : &info_; }

 private:
  std::vector<VkSpecializationMapEntry> entries_;
  std::vector<int32_t> values_;
  VkSpecializationInfo info_{};
};

// The compute pipeline of `shader` (entry point main) with its specialisation (may be null): the
// compute engine's pass (src/baseline/compute_engine.h).
VkPipeline create_compute_pipeline(VkDevice device, VkPipelineLayout layout, VkShaderModule shader,
                                   const VkSpecializationInfo* specialization, VkPipelineCache cache);

// The push constants of every fragment pass: the pass's width (int u_ray_width, prelude_vk.glsl).
// Then the device addresses of the bindings a pass reads as TextureKind::DeviceAddress
// (glsl/layout.h, MOBIRT_PASS_ADDRESSES).
constexpr uint32_t kPassConstantBytes = MOBIRT_PASS_ADDRESSES + 8 * MOBIRT_PASS_ADDRESS_SLOTS;

struct Pass {
  PassDesc desc;
  DescriptorSetLayout set_layout;
  PipelineLayout pipeline_layout;
  Pipeline pipeline;
  Memory uniform_memory;
  Buffer uniform_buffer;
  float* uniforms = nullptr;  // persistently mapped, MOBIRT_MAX_PARAM_VEC4S vec4
  DescriptorPool descriptor_pool;
  VkDescriptorSet descriptor_set = VK_NULL_HANDLE;  // freed with the pool
};

class Pipelines {
 public:
  // cache_dir: VulkanOptions::pipeline_cache_dir (empty: no cache on disk).
  Pipelines(const Device& device, const std::string& cache_dir);

  // The pass's objects for desc, already checked (check_es2_constraints, check_pass_desc).
  Pass create_pass(const PassDesc& desc) const;
  VkRenderPass render_pass() const { return render_pass_.get(); }
  // The same, compatible, for a linear target that the host reads in place (left in GENERAL).
  VkRenderPass host_render_pass() const { return host_render_pass_.get(); }
  // Writes the pipeline cache to its file, whole or not at all; never throws (a cache is an
  // optimisation, so a folder that cannot be written only costs the next run its compile time).
  void save_cache() const;
  // The pipeline cache (the raster pass's pipeline goes into it too).
  VkPipelineCache cache() const { return cache_.get(); }

 private:
  std::vector<char> load_cache() const;

  const Device& device_;
  std::string cache_file_;  // where the pipeline cache is saved, empty = nowhere
  Sampler sampler_;
  Sampler linear_sampler_;  // PassDesc::linear_bindings
  RenderPass render_pass_;
  RenderPass host_render_pass_;
  ShaderModule vertex_shader_;
  PipelineCache cache_;
};

}  // namespace mobirt::vk
