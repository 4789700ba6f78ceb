#include "backend/vulkan/vk_pipeline.h"

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <span>
#include <string>
#include <vector>

#include <unistd.h>

#include "backend/vulkan/vk_resources.h"
#include "core/error.h"
#include "layout.h"

// SPIR-V of the full-screen triangle, generated at build time from glsl/ (build/spirv/<name>.h).
#include "fullscreen.vert.h"

namespace mobirt::vk {

ShaderModule create_shader_module(VkDevice vk_device, std::span<const uint32_t> code) {
  VkShaderModuleCreateInfo info{VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO};
  info.codeSize = code.size_bytes();
  info.pCode = code.data();
  VkShaderModule module = VK_NULL_HANDLE;
  VK_CHECK(vkCreateShaderModule(vk_device, &info, nullptr, &module));
  return ShaderModule(vk_device, module);
}

VkDescriptorType descriptor_type(TextureKind kind) {
  switch (kind) {
    case TextureKind::TexelBuffer: return VK_DESCRIPTOR_TYPE_UNIFORM_TEXEL_BUFFER;
    case TextureKind::StorageBuffer:
    case TextureKind::DeviceAddress: return VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
    case TextureKind::Image2D: break;
  }
  return VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER;
}

namespace {

// "<dir>/pipelines-<cache UUID in hex>.bin"; empty without a folder.
std::string cache_file_name(const std::string& dir, const VkPhysicalDeviceProperties& properties) {
  if (dir.empty()) return {};
  std::string name = "pipelines-";
  char hex[3];
  for (uint8_t byte : properties.pipelineCacheUUID) {
    std::snprintf(hex, sizeof(hex), "%02x", byte);
    name.append(hex);
  }
  return (std::filesystem::path(dir) / name.append(".bin")).string();
}

}  // namespace

Sampler create_fetch_sampler(VkDevice vk_device, VkFilter filter) {
  // Shaders read texels with texelFetch: the sampler's filtering never applies, but a sampler is
  // part of a combined image sampler, so one immutable NEAREST / CLAMP_TO_EDGE sampler serves all;
  // a LINEAR one serves PassDesc::linear_bindings (the atlas pages' one bilinear fetch).
  VkSamplerCreateInfo sampler_info{VK_STRUCTURE_TYPE_SAMPLER_CREATE_INFO};
  sampler_info.magFilter = filter;
  sampler_info.minFilter = filter;
  sampler_info.mipmapMode = VK_SAMPLER_MIPMAP_MODE_NEAREST;
  sampler_info.addressModeU = VK_SAMPLER_ADDRESS_MODE_CLAMP_TO_EDGE;
  sampler_info.addressModeV = VK_SAMPLER_ADDRESS_MODE_CLAMP_TO_EDGE;
  sampler_info.addressModeW = VK_SAMPLER_ADDRESS_MODE_CLAMP_TO_EDGE;
  sampler_info.maxLod = 0.0f;
  VkSampler sampler = VK_NULL_HANDLE;
  VK_CHECK(vkCreateSampler(vk_device, &sampler_info, nullptr, &sampler));
  return Sampler(vk_device, sampler);
}

// One render pass for every pipeline: one RGBA8 colour attachment, contents not loaded (every
// texel of the render area is written) and stored. host_read: the target is a linear image in
// host-visible memory that the host reads in place, left in GENERAL; else it is left ready for the
// copy to the read-back buffer. Compatible render passes may differ only in layouts and load and
// store operations, their dependencies must be identical (then the pipelines made with one run in
// the other), so both carry the union of the two ways' dependencies.
RenderPass create_target_render_pass(VkDevice vk_device, bool host_read) {
  VkAttachmentDescription attachment{};
  attachment.format = kTargetFormat;
  attachment.samples = VK_SAMPLE_COUNT_1_BIT;
  attachment.loadOp = VK_ATTACHMENT_LOAD_OP_DONT_CARE;
  attachment.storeOp = VK_ATTACHMENT_STORE_OP_STORE;
  attachment.stencilLoadOp = VK_ATTACHMENT_LOAD_OP_DONT_CARE;
  attachment.stencilStoreOp = VK_ATTACHMENT_STORE_OP_DONT_CARE;
  attachment.initialLayout = VK_IMAGE_LAYOUT_UNDEFINED;
  attachment.finalLayout = host_read ? VK_IMAGE_LAYOUT_GENERAL : VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL;
  VkAttachmentReference color{0, VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL};
  VkSubpassDescription subpass{};
  subpass.pipelineBindPoint = VK_PIPELINE_BIND_POINT_GRAPHICS;
  subpass.colorAttachmentCount = 1;
  subpass.pColorAttachments = &color;
  VkSubpassDependency dependencies[2]{};
  // The previous pass's copy read the image before this pass overwrites it (write after read; the
  // host's reads of a linear target came before this submission, which orders them).
  dependencies[0].srcSubpass = VK_SUBPASS_EXTERNAL;
  dependencies[0].dstSubpass = 0;
  dependencies[0].srcStageMask = VK_PIPELINE_STAGE_TRANSFER_BIT;
  dependencies[0].dstStageMask = VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT;
  dependencies[0].srcAccessMask = 0;
  dependencies[0].dstAccessMask = VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT;
  // The copy to the read-back buffer, or the host, reads what the pass wrote.
  dependencies[1].srcSubpass = 0;
  dependencies[1].dstSubpass = VK_SUBPASS_EXTERNAL;
  dependencies[1].srcStageMask = VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT;
  dependencies[1].dstStageMask = VK_PIPELINE_STAGE_TRANSFER_BIT | VK_PIPELINE_STAGE_HOST_BIT;
  dependencies[1].srcAccessMask = VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT;
  dependencies[1].dstAccessMask = VK_ACCESS_TRANSFER_READ_BIT | VK_ACCESS_HOST_READ_BIT;
  VkRenderPassCreateInfo render_pass_info{VK_STRUCTURE_TYPE_RENDER_PASS_CREATE_INFO};
  render_pass_info.attachmentCount = 1;
  render_pass_info.pAttachments = &attachment;
  render_pass_info.subpassCount = 1;
  render_pass_info.pSubpasses = &subpass;
  render_pass_info.dependencyCount = 2;
  render_pass_info.pDependencies = dependencies;
  VkRenderPass render_pass = VK_NULL_HANDLE;
  VK_CHECK(vkCreateRenderPass(vk_device, &render_pass_info, nullptr, &render_pass));
  return RenderPass(vk_device, render_pass);
}

Pipelines::Pipelines(const Device& device, const std::string& cache_dir)
    : device_(device), cache_file_(cache_file_name(cache_dir, device.properties())) {
  const VkDevice vk_device = device.handle();
  sampler_ = create_fetch_sampler(vk_device, VK_FILTER_NEAREST);
  linear_sampler_ = create_fetch_sampler(vk_device, VK_FILTER_LINEAR);

  render_pass_ = create_target_render_pass(vk_device, false);
  host_render_pass_ = create_target_render_pass(vk_device, true);

  vertex_shader_ = create_shader_module(vk_device, spirv_fullscreen_vert);

  VkPipelineCacheCreateInfo cache_info{VK_STRUCTURE_TYPE_PIPELINE_CACHE_CREATE_INFO};
  const std::vector<char> cached = load_cache();
  cache_info.initialDataSize = cached.size();
  cache_info.pInitialData = cached.empty() ? nullptr : cached.data();
  VkPipelineCache cache = VK_NULL_HANDLE;
  VK_CHECK(vkCreatePipelineCache(vk_device, &cache_info, nullptr, &cache));
  cache_ = PipelineCache(vk_device, cache);
}

std::vector<char> Pipelines::load_cache() const {
  const VkPhysicalDeviceProperties& properties = device_.properties();
  std::vector<char> data;
  if (cache_file_.empty()) return data;
  std::ifstream in(cache_file_, std::ios::binary);
  if (!in) return data;
  data.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  // The header (VkPipelineCacheHeaderVersionOne) must name this device and driver; anything else
  // is ignored rather than handed to the driver.
  VkPipelineCacheHeaderVersionOne header{};
  if (data.size() < sizeof(header)) return {};
  std::memcpy(&header, data.data(), sizeof(header));
  if (header.headerVersion != VK_PIPELINE_CACHE_HEADER_VERSION_ONE || header.vendorID != properties.vendorID ||
      header.deviceID != properties.deviceID ||
      std::memcmp(header.pipelineCacheUUID, properties.pipelineCacheUUID, VK_UUID_SIZE) != 0) {
    return {};
  }
  return data;
}

void Pipelines::save_cache() const {
  if (cache_file_.empty() || !cache_.get()) return;
  size_t size = 0;
  if (vkGetPipelineCacheData(device_.handle(), cache_.get(), &size, nullptr) != VK_SUCCESS || size == 0) return;
  std::vector<char> data(size);
  if (vkGetPipelineCacheData(device_.handle(), cache_.get(), &size, data.data()) != VK_SUCCESS) return;
  // Written whole or not at all: a temporary file renamed into place.
  std::error_code ec;
  const std::filesystem::path target(cache_file_);
  std::filesystem::create_directories(target.parent_path(), ec);
  std::string temp_name = cache_file_;
  temp_name.append(".tmp").append(std::to_string(::getpid()));
  {
    std::ofstream out(temp_name, std::ios::binary);
    out.write(data.data(), std::streamsize(size));
    if (!out) {
      std::filesystem::remove(temp_name, ec);
      return;
    }
  }
  std::filesystem::rename(temp_name, target, ec);
  if (ec) std::filesystem::remove(temp_name, ec);
}

VkPipeline create_fullscreen_pipeline(VkDevice vk_device, VkRenderPass render_pass, VkPipelineLayout pipeline_layout,
                                      VkShaderModule vertex, VkShaderModule fragment,
                                      const VkSpecializationInfo* specialization, VkPipelineCache cache) {
  return create_graphics_pipeline(vk_device, render_pass, pipeline_layout, vertex, fragment, specialization, cache,
                                  nullptr, nullptr);
}

VkPipeline create_graphics_pipeline(VkDevice vk_device, VkRenderPass render_pass, VkPipelineLayout pipeline_layout,
                                    VkShaderModule vertex, VkShaderModule fragment,
                                    const VkSpecializationInfo* specialization, VkPipelineCache cache,
                                    const VkPipelineVertexInputStateCreateInfo* vertex_input,
                                    const VkPipelineDepthStencilStateCreateInfo* depth) {
  VkPipelineShaderStageCreateInfo stages[2]{};
  stages[0].sType = VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO;
  stages[0].stage = VK_SHADER_STAGE_VERTEX_BIT;
  stages[0].module = vertex;
  stages[0].pName = "main";
  stages[1].sType = VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO;
  stages[1].stage = VK_SHADER_STAGE_FRAGMENT_BIT;
  stages[1].module = fragment;
  stages[1].pName = "main";
  stages[1].pSpecializationInfo = specialization;

  const VkPipelineVertexInputStateCreateInfo no_vertex_input{VK_STRUCTURE_TYPE_PIPELINE_VERTEX_INPUT_STATE_CREATE_INFO};
  VkPipelineInputAssemblyStateCreateInfo assembly{VK_STRUCTURE_TYPE_PIPELINE_INPUT_ASSEMBLY_STATE_CREATE_INFO};
  assembly.topology = VK_PRIMITIVE_TOPOLOGY_TRIANGLE_LIST;
  VkPipelineViewportStateCreateInfo viewport{VK_STRUCTURE_TYPE_PIPELINE_VIEWPORT_STATE_CREATE_INFO};
  viewport.viewportCount = 1;
  viewport.scissorCount = 1;
  VkPipelineRasterizationStateCreateInfo raster{VK_STRUCTURE_TYPE_PIPELINE_RASTERIZATION_STATE_CREATE_INFO};
  raster.polygonMode = VK_POLYGON_MODE_FILL;
  raster.cullMode = VK_CULL_MODE_NONE;  // rays hit both sides of a triangle
  raster.frontFace = VK_FRONT_FACE_COUNTER_CLOCKWISE;
  raster.lineWidth = 1.0f;
  VkPipelineMultisampleStateCreateInfo multisample{VK_STRUCTURE_TYPE_PIPELINE_MULTISAMPLE_STATE_CREATE_INFO};
  multisample.rasterizationSamples = VK_SAMPLE_COUNT_1_BIT;
  VkPipelineColorBlendAttachmentState blend_attachment{};
  blend_attachment.blendEnable = VK_FALSE;
  blend_attachment.colorWriteMask =
      VK_COLOR_COMPONENT_R_BIT | VK_COLOR_COMPONENT_G_BIT | VK_COLOR_COMPONENT_B_BIT | VK_COLOR_COMPONENT_A_BIT;
  VkPipelineColorBlendStateCreateInfo blend{VK_STRUCTURE_TYPE_PIPELINE_COLOR_BLEND_STATE_CREATE_INFO};
  blend.attachmentCount = 1;
  blend.pAttachments = &blend_attachment;
  const VkDynamicState dynamic_states[] = {VK_DYNAMIC_STATE_VIEWPORT, VK_DYNAMIC_STATE_SCISSOR};
  VkPipelineDynamicStateCreateInfo dynamic{VK_STRUCTURE_TYPE_PIPELINE_DYNAMIC_STATE_CREATE_INFO};
  dynamic.dynamicStateCount = 2;
  dynamic.pDynamicStates = dynamic_states;

  VkGraphicsPipelineCreateInfo pipeline_info{VK_STRUCTURE_TYPE_GRAPHICS_PIPELINE_CREATE_INFO};
  pipeline_info.stageCount = 2;
  pipeline_info.pStages = stages;
  pipeline_info.pVertexInputState = vertex_input ? vertex_input : &no_vertex_input;
  pipeline_info.pInputAssemblyState = &assembly;
  pipeline_info.pViewportState = &viewport;
  pipeline_info.pRasterizationState = &raster;
  pipeline_info.pMultisampleState = &multisample;
  pipeline_info.pDepthStencilState = depth;
  pipeline_info.pColorBlendState = &blend;
  pipeline_info.pDynamicState = &dynamic;
  pipeline_info.layout = pipeline_layout;
  pipeline_info.renderPass = render_pass;
  pipeline_info.subpass = 0;
  VkPipeline pipeline = VK_NULL_HANDLE;
  VK_CHECK(vkCreateGraphicsPipelines(vk_device, cache, 1, &pipeline_info, nullptr, &pipeline));
  return pipeline;
}

SpecializationConstants::SpecializationConstants(std::span<const Specialization> constants) {
  for (const Specialization& s : constants) {
    entries_.push_back({s.id, uint32_t(values_.size() * sizeof(int32_t)), sizeof(int32_t)});
    values_.push_back(s.value);
  }
  info_ = {uint32_t(entries_.size()), entries_.data(), values_.size() * sizeof(int32_t), values_.data()};
}

VkPipeline create_compute_pipeline(VkDevice vk_device, VkPipelineLayout pipeline_layout, VkShaderModule shader,
                                   const VkSpecializationInfo* specialization, VkPipelineCache cache) {
  VkComputePipelineCreateInfo info{VK_STRUCTURE_TYPE_COMPUTE_PIPELINE_CREATE_INFO};
  info.stage.sType = VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO;
  info.stage.stage = VK_SHADER_STAGE_COMPUTE_BIT;
  info.stage.module = shader;
  info.stage.pName = "main";
  info.stage.pSpecializationInfo = specialization;
  info.layout = pipeline_layout;
  VkPipeline pipeline = VK_NULL_HANDLE;
  VK_CHECK(vkCreateComputePipelines(vk_device, cache, 1, &info, nullptr, &pipeline));
  return pipeline;
}

Pass Pipelines::create_pass(const PassDesc& desc) const {
  const VkDevice vk_device = device_.handle();
  const std::span<const uint32_t> code = desc.shader.source().spirv;
  Pass pass;
  pass.desc = desc;

  // Descriptor set layout: the uniform block, then per texture its kind's descriptor (images with
  // the immutable texelFetch sampler).
  const VkSampler immutable_sampler = sampler_.get();
  const VkSampler linear_sampler = linear_sampler_.get();
  std::vector<VkDescriptorSetLayoutBinding> bindings;
  if (desc.uniform_vec4s > 0) {
    bindings.push_back({MOBIRT_BIND_TRACE_PARAMS, VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER, 1, VK_SHADER_STAGE_FRAGMENT_BIT, nullptr});
  }
  for (size_t i = 0; i < desc.texture_bindings.size(); ++i) {
    const TextureKind kind = desc.kind(i);
    if (kind == TextureKind::DeviceAddress) continue;  // no descriptor: its address is a push constant
    bindings.push_back({desc.texture_bindings[i], descriptor_type(kind), 1, VK_SHADER_STAGE_FRAGMENT_BIT,
                        kind != TextureKind::Image2D                  ? nullptr
                        : desc.linear(desc.texture_bindings[i]) ? &linear_sampler
                                                                : &immutable_sampler});
  }
  VkDescriptorSetLayoutCreateInfo set_info{VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO};
  set_info.bindingCount = uint32_t(bindings.size());
  set_info.pBindings = bindings.data();
  VkDescriptorSetLayout set_layout = VK_NULL_HANDLE;
  VK_CHECK(vkCreateDescriptorSetLayout(vk_device, &set_info, nullptr, &set_layout));
  pass.set_layout = DescriptorSetLayout(vk_device, set_layout);

  // Every pass gets its width as a push constant: a shader that reads per-ray texel buffers
  // (prelude_vk.glsl's ray_index) needs it; others ignore it. Then the device addresses.
  const VkPushConstantRange push_range{VK_SHADER_STAGE_FRAGMENT_BIT, 0, kPassConstantBytes};
  VkPipelineLayoutCreateInfo layout_info{VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO};
  layout_info.setLayoutCount = 1;
  layout_info.pSetLayouts = &set_layout;
  layout_info.pushConstantRangeCount = 1;
  layout_info.pPushConstantRanges = &push_range;
  VkPipelineLayout pipeline_layout = VK_NULL_HANDLE;
  VK_CHECK(vkCreatePipelineLayout(vk_device, &layout_info, nullptr, &pipeline_layout));
  pass.pipeline_layout = PipelineLayout(vk_device, pipeline_layout);

  // The uniform block: always the full MOBIRT_MAX_PARAM_VEC4S array the shaders declare.
  if (desc.uniform_vec4s > 0) {
    HostBuffer ubo = create_host_buffer(device_, VkDeviceSize(MOBIRT_MAX_PARAM_VEC4S) * 16, VK_BUFFER_USAGE_UNIFORM_BUFFER_BIT, false);
    if (!ubo.coherent) throw Error(ErrorKind::Unsupported, "the Vulkan device has no host-coherent memory for uniforms");
    pass.uniforms = static_cast<float*>(ubo.mapped);
    std::memset(pass.uniforms, 0, size_t(MOBIRT_MAX_PARAM_VEC4S) * 16);
    pass.uniform_memory = std::move(ubo.memory);
    pass.uniform_buffer = std::move(ubo.buffer);
  }

  if (!bindings.empty()) {
    // One pool size per descriptor type the layout uses, counted from the bindings themselves.
    std::vector<VkDescriptorPoolSize> sizes;
    for (const VkDescriptorSetLayoutBinding& b : bindings) {
      auto it = std::find_if(sizes.begin(), sizes.end(), [&](const VkDescriptorPoolSize& s) { return s.type == b.descriptorType; });
      if (it == sizes.end()) sizes.push_back({b.descriptorType, b.descriptorCount});
      else it->descriptorCount += b.descriptorCount;
    }
    VkDescriptorPoolCreateInfo pool_info{VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO};
    pool_info.maxSets = 1;
    pool_info.poolSizeCount = uint32_t(sizes.size());
    pool_info.pPoolSizes = sizes.data();
    VkDescriptorPool pool = VK_NULL_HANDLE;
    VK_CHECK(vkCreateDescriptorPool(vk_device, &pool_info, nullptr, &pool));
    pass.descriptor_pool = DescriptorPool(vk_device, pool);
    VkDescriptorSetAllocateInfo alloc{VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO};
    alloc.descriptorPool = pool;
    alloc.descriptorSetCount = 1;
    alloc.pSetLayouts = &set_layout;
    VK_CHECK(vkAllocateDescriptorSets(vk_device, &alloc, &pass.descriptor_set));
    if (desc.uniform_vec4s > 0) {
      VkDescriptorBufferInfo buffer_info{pass.uniform_buffer.get(), 0, VK_WHOLE_SIZE};
      VkWriteDescriptorSet write{VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET};
      write.dstSet = pass.descriptor_set;
      write.dstBinding = MOBIRT_BIND_TRACE_PARAMS;
      write.descriptorCount = 1;
      write.descriptorType = VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER;
      write.pBufferInfo = &buffer_info;
      vkUpdateDescriptorSets(vk_device, 1, &write, 0, nullptr);
    }
  }

  // The pipeline: a full-screen triangle, the specialised fragment shader, dynamic viewport.
  const ShaderModule fragment_module = create_shader_module(vk_device, code);  // needed until the pipeline exists

  const SpecializationConstants specialization(desc.specialization);
  pass.pipeline = Pipeline(vk_device, create_fullscreen_pipeline(vk_device, render_pass_.get(), pipeline_layout,
                                                                vertex_shader_.get(), fragment_module.get(),
                                                                specialization.info(), cache_.get()));
  return pass;
}

}  // namespace mobirt::vk
