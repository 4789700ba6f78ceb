// The compute engine (compute_engine.h): the backend's vk::Device, host-visible storage buffers
// (lavapipe's memory is the host's, so the pass reads and writes them in place), one descriptor set
// and one compute pipeline per specialisation. Like mobirt's backend every submission is waited
// for, so the buffers and the set are rewritten between submissions without further barriers.
#include "baseline/compute_engine.h"

#include <vulkan/vulkan.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <map>
#include <tuple>
#include <utility>

#include "backend/backend.h"
#include "backend/shader_constraints.h"
#include "backend/vulkan/vk_device.h"
#include "backend/vulkan/vk_pipeline.h"
#include "backend/vulkan/vk_resources.h"
#include "backend/vulkan/vk_util.h"
#include "core/error.h"
#include "layout.h"
#include "raytree/packing.h"
#include "render/renderer.h"  // trace_uniforms(): the traversal pass's uniforms, shared
#include "shader_ids.h"

namespace mobirt {

namespace {

using Clock = std::chrono::steady_clock;

constexpr uint32_t kTimestamps = 2;
// The storage buffers in binding order after the uniforms (glsl/trace_compute.comp).
enum Slot { Nodes, LeafPrims, Triangles, Origins, Directions, Records, kSlots };
constexpr uint32_t kBindings[kSlots] = {MOBIRT_BIND_NODES,      MOBIRT_BIND_LEAF_PRIMS,    MOBIRT_BIND_TRIANGLES,
                                        MOBIRT_BIND_RAY_ORIGIN, MOBIRT_BIND_RAY_DIRECTION, MOBIRT_BIND_HIT_RECORDS};

double ms_since(Clock::time_point t) { return std::chrono::duration<double, std::milli>(Clock::now() - t).count(); }

const ShaderSource& shader(ComputeData data = ComputeData::StorageBuffers) {
  return shader_source(data == ComputeData::TexelBuffers ? ShaderId::TraverseComputeTexelBuffers
                                                         : ShaderId::TraverseCompute);
}

// The scene data's texel format (Nodes, LeafPrims, Triangles: RGBA32F all), for their texel-buffer views.
constexpr VkFormat kDataFormat = VK_FORMAT_R32G32B32A32_SFLOAT;
// data_index() turns an exact float into an int by its bits: below 2^23 without WIDE_INDICES
// (prelude_vk.glsl), which this peer's pass does not take.
constexpr size_t kMaxDataElements = size_t(1) << 23;

}  // namespace

const char* compute_data_name(ComputeData data) {
  return data == ComputeData::TexelBuffers ? "texel-buffers" : "storage-buffers";
}

bool parse_compute_data(std::string_view text, ComputeData& data) {
  if (text == "storage-buffers") data = ComputeData::StorageBuffers;
  else if (text == "texel-buffers") data = ComputeData::TexelBuffers;
  else return false;
  return true;
}

struct ComputeEngine::Impl {
  Impl(const VulkanOptions& options, ComputeData data);
  ~Impl() {
    if (!hung) vkDeviceWaitIdle(device.handle());
  }

  // A mapped buffer of at least `bytes` for `usage` (grown with headroom; an empty array still
  // gets a few bytes, as a binding needs a buffer).
  void ensure(vk::HostBuffer& buffer, size_t bytes, VkBufferUsageFlags usage, bool cached);
  void write(vk::HostBuffer& buffer, const void* data, size_t bytes, VkBufferUsageFlags usage);
  VkPipeline pipeline(int lights, const ShadowSettings& shadows, const ComputeTraversal& traversal);
  void submit_and_wait();

  vk::Device device;
  ComputeData reads;
  bool hung = false;
  vk::CommandPool command_pool;
  VkCommandBuffer commands = VK_NULL_HANDLE;  // freed with the pool
  vk::Fence fence;
  vk::QueryPool queries;
  vk::DescriptorSetLayout set_layout;
  vk::PipelineLayout pipeline_layout;
  vk::DescriptorPool descriptor_pool;
  VkDescriptorSet descriptor_set = VK_NULL_HANDLE;  // freed with the pool
  vk::ShaderModule module;
  vk::PipelineCache cache;
  std::map<std::tuple<int, int, int, int, int, int>, vk::Pipeline> pipelines;
  vk::HostBuffer uniforms;
  vk::HostBuffer buffers[kSlots];
  vk::BufferView views[3];  // TexelBuffers: over buffers[Nodes .. Triangles], destroyed first
  FlatKdTree tree_box;  // the uploaded tree's box (trace_uniforms reads bounds only)
  bool uploaded = false;
};

ComputeEngine::Impl::Impl(const VulkanOptions& options, ComputeData data_reads) : device(options), reads(data_reads) {
  const VkDevice d = device.handle();
  uint32_t families = 0;
  vkGetPhysicalDeviceQueueFamilyProperties(device.physical(), &families, nullptr);
  std::vector<VkQueueFamilyProperties> family(families);
  vkGetPhysicalDeviceQueueFamilyProperties(device.physical(), &families, family.data());
  if (!(family[device.queue_family()].queueFlags & VK_QUEUE_COMPUTE_BIT)) {
    throw Error(ErrorKind::Unsupported, std::string("Vulkan device ") + device.properties().deviceName +
                                            ": its graphics queue has no compute; the compute engine needs one");
  }

  VkCommandPoolCreateInfo pool_info{VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO};
  pool_info.flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT;
  pool_info.queueFamilyIndex = device.queue_family();
  VkCommandPool pool = VK_NULL_HANDLE;
  VK_CHECK(vkCreateCommandPool(d, &pool_info, nullptr, &pool));
  command_pool = vk::CommandPool(d, pool);
  VkCommandBufferAllocateInfo alloc{VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO};
  alloc.commandPool = pool;
  alloc.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
  alloc.commandBufferCount = 1;
  VK_CHECK(vkAllocateCommandBuffers(d, &alloc, &commands));
  VkFenceCreateInfo fence_info{VK_STRUCTURE_TYPE_FENCE_CREATE_INFO};
  VkFence f = VK_NULL_HANDLE;
  VK_CHECK(vkCreateFence(d, &fence_info, nullptr, &f));
  fence = vk::Fence(d, f);
  // Timed as mobirt's passes are (GpuTimestamps: on lavapipe each timestamp waits for the work).
  if (device.gpu_timestamps()) {
    VkQueryPoolCreateInfo query_info{VK_STRUCTURE_TYPE_QUERY_POOL_CREATE_INFO};
    query_info.queryType = VK_QUERY_TYPE_TIMESTAMP;
    query_info.queryCount = kTimestamps;
    VkQueryPool q = VK_NULL_HANDLE;
    VK_CHECK(vkCreateQueryPool(d, &query_info, nullptr, &q));
    queries = vk::QueryPool(d, q);
  }

  std::vector<VkDescriptorSetLayoutBinding> bindings;
  bindings.push_back({MOBIRT_BIND_TRACE_PARAMS, VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER, 1, VK_SHADER_STAGE_COMPUTE_BIT, nullptr});
  const bool texel = reads == ComputeData::TexelBuffers;
  for (int slot = 0; slot < kSlots; ++slot) {
    const bool scene_data = slot <= Triangles;
    bindings.push_back({kBindings[slot],
                        texel && scene_data ? VK_DESCRIPTOR_TYPE_UNIFORM_TEXEL_BUFFER : VK_DESCRIPTOR_TYPE_STORAGE_BUFFER,
                        1, VK_SHADER_STAGE_COMPUTE_BIT, nullptr});
  }
  VkDescriptorSetLayoutCreateInfo set_info{VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO};
  set_info.bindingCount = uint32_t(bindings.size());
  set_info.pBindings = bindings.data();
  VkDescriptorSetLayout layout = VK_NULL_HANDLE;
  VK_CHECK(vkCreateDescriptorSetLayout(d, &set_info, nullptr, &layout));
  set_layout = vk::DescriptorSetLayout(d, layout);
  const VkPushConstantRange push{VK_SHADER_STAGE_COMPUTE_BIT, 0, sizeof(uint32_t)};  // the ray count
  VkPipelineLayoutCreateInfo layout_info{VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO};
  layout_info.setLayoutCount = 1;
  layout_info.pSetLayouts = &layout;
  layout_info.pushConstantRangeCount = 1;
  layout_info.pPushConstantRanges = &push;
  VkPipelineLayout pl = VK_NULL_HANDLE;
  VK_CHECK(vkCreatePipelineLayout(d, &layout_info, nullptr, &pl));
  pipeline_layout = vk::PipelineLayout(d, pl);

  const VkDescriptorPoolSize sizes[] = {{VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER, 1},
                                        {VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, texel ? kSlots - 3u : uint32_t(kSlots)},
                                        {VK_DESCRIPTOR_TYPE_UNIFORM_TEXEL_BUFFER, 3}};
  VkDescriptorPoolCreateInfo dp_info{VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO};
  dp_info.maxSets = 1;
  dp_info.poolSizeCount = texel ? 3 : 2;
  dp_info.pPoolSizes = sizes;
  VkDescriptorPool dp = VK_NULL_HANDLE;
  VK_CHECK(vkCreateDescriptorPool(d, &dp_info, nullptr, &dp));
  descriptor_pool = vk::DescriptorPool(d, dp);
  VkDescriptorSetAllocateInfo set_alloc{VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO};
  set_alloc.descriptorPool = dp;
  set_alloc.descriptorSetCount = 1;
  set_alloc.pSetLayouts = &layout;
  VK_CHECK(vkAllocateDescriptorSets(d, &set_alloc, &descriptor_set));

  const std::span<const uint32_t> code = shader(reads).spirv;
  VkShaderModuleCreateInfo module_info{VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO};
  module_info.codeSize = code.size_bytes();
  module_info.pCode = code.data();
  VkShaderModule m = VK_NULL_HANDLE;
  VK_CHECK(vkCreateShaderModule(d, &module_info, nullptr, &m));
  module = vk::ShaderModule(d, m);
  VkPipelineCacheCreateInfo cache_info{VK_STRUCTURE_TYPE_PIPELINE_CACHE_CREATE_INFO};
  VkPipelineCache c = VK_NULL_HANDLE;
  VK_CHECK(vkCreatePipelineCache(d, &cache_info, nullptr, &c));
  cache = vk::PipelineCache(d, c);

  uniforms = vk::create_host_buffer(device, VkDeviceSize(MOBIRT_MAX_PARAM_VEC4S) * 16, VK_BUFFER_USAGE_UNIFORM_BUFFER_BIT,
                                    false);
  device.throw_validation_errors();
}

void ComputeEngine::Impl::ensure(vk::HostBuffer& buffer, size_t bytes, VkBufferUsageFlags usage, bool cached) {
  bytes = std::max<size_t>(bytes, 16);
  if (buffer.size >= bytes) return;
  // Whole RGBA32F texels, so that a texel-buffer view covers the buffer exactly.
  const size_t grown = (std::max<size_t>(bytes, size_t(buffer.size) + size_t(buffer.size) / 2) + 15) / 16 * 16;
  buffer.reset();
  buffer = vk::create_host_buffer(device, grown, usage, cached);
}

void ComputeEngine::Impl::write(vk::HostBuffer& buffer, const void* data, size_t bytes, VkBufferUsageFlags usage) {
  ensure(buffer, bytes, usage, false);
  if (bytes > 0) std::memcpy(buffer.mapped, data, bytes);
  if (!buffer.coherent) {
    VkMappedMemoryRange range{VK_STRUCTURE_TYPE_MAPPED_MEMORY_RANGE};
    range.memory = buffer.memory.get();
    range.size = VK_WHOLE_SIZE;
    VK_CHECK(vkFlushMappedMemoryRanges(device.handle(), 1, &range));
  }
}

VkPipeline ComputeEngine::Impl::pipeline(int lights, const ShadowSettings& shadows, const ComputeTraversal& traversal) {
  const auto key = std::make_tuple(lights, traversal.stack_depth, traversal.max_steps, int(shadows.ray_test.test),
                                   int(shadows.ray_test.precision), int(shadows.offset.mode));
  const auto it = pipelines.find(key);
  if (it != pipelines.end()) return it->second.get();
  // The fragment pass's constants (Renderer::trace_pass); the packing does not apply to a record.
  const Specialization constants[] = {{MOBIRT_SPEC_LIGHT_COUNT, lights},
                                      {MOBIRT_SPEC_STACK_DEPTH, traversal.stack_depth},
                                      {MOBIRT_SPEC_MAX_STEPS, traversal.max_steps},
                                      {MOBIRT_SPEC_INTERSECT, int(shadows.ray_test.test)},
                                      {MOBIRT_SPEC_PRECISION, int(shadows.ray_test.precision)},
                                      {MOBIRT_SPEC_OFFSET, int(shadows.offset.mode)}};
  const vk::SpecializationConstants specialization(constants);
  vk::Pipeline made(device.handle(), vk::create_compute_pipeline(device.handle(), pipeline_layout.get(), module.get(),
                                                                 specialization.info(), cache.get()));
  return pipelines.emplace(key, std::move(made)).first->second.get();
}

void ComputeEngine::Impl::submit_and_wait() {
  VK_CHECK(vkEndCommandBuffer(commands));
  VkSubmitInfo submit{VK_STRUCTURE_TYPE_SUBMIT_INFO};
  submit.commandBufferCount = 1;
  submit.pCommandBuffers = &commands;
  const VkFence f = fence.get();
  VK_CHECK(vkQueueSubmit(device.queue(), 1, &submit, f));
  const double timeout_s = vk::pass_timeout_seconds();
  const VkResult result = vkWaitForFences(device.handle(), 1, &f, VK_TRUE, uint64_t(timeout_s * 1e9));
  if (result == VK_TIMEOUT) {
    hung = true;
    char seconds[32];
    std::snprintf(seconds, sizeof(seconds), "%g", timeout_s);
    throw Error(ErrorKind::Internal, std::string("the compute traversal did not finish within ") + seconds +
                                         " s: a shader loop without a working cap? (MOBIRT_PASS_TIMEOUT_S sets the "
                                         "limit; the engine is unusable now)");
  }
  VK_CHECK_RESULT(result, "vkWaitForFences");
  VK_CHECK(vkResetFences(device.handle(), 1, &f));
}

ComputeEngine::ComputeEngine(const VulkanOptions& options, ComputeData data)
    : impl_(std::make_unique<Impl>(options, data)) {}
ComputeEngine::~ComputeEngine() = default;

std::vector<std::string> ComputeEngine::info() const {
  const DeviceInfo d = impl_->device.info();
  std::vector<std::string> lines;
  lines.push_back("compute engine: " + d.device + " (" + d.api + "), " + d.driver);
  lines.push_back("mobirt's kd-tree traversal (traverse.glsl) as a compute shader, " +
                  std::to_string(MOBIRT_COMPUTE_GROUP_SIZE) + " rays a workgroup: the scene from " +
                  (impl_->reads == ComputeData::TexelBuffers ? "uniform texel buffers (as the fragment pass reads it)"
                                                            : "read-only storage buffers") +
                  ", one " + std::to_string(MOBIRT_HIT_RECORD_BYTES) + "-byte hit record per ray out");
  for (const std::string& c : broken_constraints()) lines.push_back("breaks the OpenGL ES 2.0 constraints: " + c);
  return lines;
}

double ComputeEngine::upload_tree(const FlatKdTree& tree) {
  Impl& d = *impl_;
  if (d.hung) throw Error(ErrorKind::Internal, "the compute engine is unusable: an earlier pass never finished");
  const size_t most = std::max({tree.nodes.size(), tree.leaf_prims.size(), tree.triangles.size()});
  if (most > kMaxDataElements) {
    throw Error(ErrorKind::BadInput, "the kd-tree needs " + std::to_string(most) + " texels in one array; the compute "
                                     "pass indexes at most 2^23 (render a smaller scene, or split it)");
  }
  const auto start = Clock::now();
  const bool texel = d.reads == ComputeData::TexelBuffers;
  const VkBufferUsageFlags usage = texel ? VK_BUFFER_USAGE_UNIFORM_TEXEL_BUFFER_BIT : VK_BUFFER_USAGE_STORAGE_BUFFER_BIT;
  for (vk::BufferView& v : d.views) v.reset();  // before a buffer they view may be replaced
  d.write(d.buffers[Nodes], tree.nodes.data(), tree.nodes.size() * sizeof(glm::vec4), usage);
  d.write(d.buffers[LeafPrims], tree.leaf_prims.data(), tree.leaf_prims.size() * sizeof(glm::vec4), usage);
  d.write(d.buffers[Triangles], tree.triangles.data(), tree.triangles.size() * sizeof(glm::vec4), usage);
  for (int i = 0; texel && i < 3; ++i) {
    VkBufferViewCreateInfo info{VK_STRUCTURE_TYPE_BUFFER_VIEW_CREATE_INFO};
    info.buffer = d.buffers[i].buffer.get();
    info.format = kDataFormat;
    info.range = VK_WHOLE_SIZE;
    VkBufferView view = VK_NULL_HANDLE;
    VK_CHECK(vkCreateBufferView(d.device.handle(), &info, nullptr, &view));
    d.views[i] = vk::BufferView(d.device.handle(), view);
  }
  d.tree_box.bounds = tree.bounds;
  d.uploaded = true;
  return ms_since(start);
}

void ComputeEngine::trace(const RayBatch& rays, std::span<const Light> lights, const ShadowSettings& shadows,
                          const ComputeTraversal& traversal, std::span<HitRecord> out, ComputeTimings* timings) {
  Impl& d = *impl_;
  const auto start = Clock::now();
  if (d.hung) throw Error(ErrorKind::Internal, "the compute engine is unusable: an earlier pass never finished");
  if (!d.uploaded) throw Error(ErrorKind::Internal, "ComputeEngine::trace before upload_tree()");
  const uint32_t count = rays.count();
  if (out.size() < count) throw Error(ErrorKind::Internal, "ComputeEngine::trace: fewer records than rays");
  if (lights.size() > size_t(MOBIRT_MAX_LIGHTS)) {
    throw Error(ErrorKind::BadInput, std::to_string(lights.size()) + " lights: a pass casts shadow rays to at most " +
                                         std::to_string(MOBIRT_MAX_LIGHTS) + " (drop lights with --light)");
  }
  if (timings) *timings = ComputeTimings{};
  if (count == 0) return;
  // Made on first use (the shader compiles then): outside the upload's time.
  const VkPipeline pass = d.pipeline(int(lights.size()), shadows, traversal);

  const auto upload_start = Clock::now();
  const VkBufferUsageFlags storage = VK_BUFFER_USAGE_STORAGE_BUFFER_BIT;
  d.write(d.buffers[Origins], rays.origin.data(), size_t(count) * sizeof(glm::vec4), storage);
  d.write(d.buffers[Directions], rays.direction.data(), size_t(count) * sizeof(glm::vec4), storage);
  d.ensure(d.buffers[Records], size_t(count) * sizeof(HitRecord), storage, true);
  const std::vector<float> params = trace_uniforms(d.tree_box, lights, shadows, int(lights.size()));
  d.write(d.uniforms, params.data(), std::min(params.size() * sizeof(float), size_t(MOBIRT_MAX_PARAM_VEC4S) * 16),
          VK_BUFFER_USAGE_UNIFORM_BUFFER_BIT);
  // Every earlier submission has finished: the set may be rewritten (a buffer may have grown).
  VkDescriptorBufferInfo infos[kSlots + 1];
  VkWriteDescriptorSet writes[kSlots + 1];
  const VkBufferView views[3] = {d.views[0].get(), d.views[1].get(), d.views[2].get()};
  for (uint32_t i = 0; i <= kSlots; ++i) {
    const vk::HostBuffer& b = i == 0 ? d.uniforms : d.buffers[i - 1];
    infos[i] = {b.buffer.get(), 0, VK_WHOLE_SIZE};
    writes[i] = {VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET};
    writes[i].dstSet = d.descriptor_set;
    writes[i].dstBinding = i == 0 ? uint32_t(MOBIRT_BIND_TRACE_PARAMS) : kBindings[i - 1];
    writes[i].descriptorCount = 1;
    writes[i].descriptorType = i == 0 ? VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER : VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
    writes[i].pBufferInfo = &infos[i];
    const VkBufferView* view = i >= 1 && i <= 3 ? &views[i - 1] : nullptr;
    if (view && *view != VK_NULL_HANDLE) {  // TexelBuffers: the scene data through its views
      writes[i].descriptorType = VK_DESCRIPTOR_TYPE_UNIFORM_TEXEL_BUFFER;
      writes[i].pBufferInfo = nullptr;
      writes[i].pTexelBufferView = view;
    }
  }
  vkUpdateDescriptorSets(d.device.handle(), kSlots + 1, writes, 0, nullptr);
  const double upload_ms = ms_since(upload_start);

  VK_CHECK(vkResetCommandBuffer(d.commands, 0));
  VkCommandBufferBeginInfo begin{VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
  begin.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
  VK_CHECK(vkBeginCommandBuffer(d.commands, &begin));
  if (d.queries) {
    vkCmdResetQueryPool(d.commands, d.queries.get(), 0, kTimestamps);
    vkCmdWriteTimestamp(d.commands, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, d.queries.get(), 0);
  }
  vkCmdBindPipeline(d.commands, VK_PIPELINE_BIND_POINT_COMPUTE, pass);
  vkCmdBindDescriptorSets(d.commands, VK_PIPELINE_BIND_POINT_COMPUTE, d.pipeline_layout.get(), 0, 1,
                          &d.descriptor_set, 0, nullptr);
  vkCmdPushConstants(d.commands, d.pipeline_layout.get(), VK_SHADER_STAGE_COMPUTE_BIT, 0, sizeof(count), &count);
  vkCmdDispatch(d.commands, (count + MOBIRT_COMPUTE_GROUP_SIZE - 1) / MOBIRT_COMPUTE_GROUP_SIZE, 1, 1);
  if (d.queries) vkCmdWriteTimestamp(d.commands, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, d.queries.get(), 1);
  // The records, written by the shader, read by the host after the fence.
  VkBufferMemoryBarrier to_host{VK_STRUCTURE_TYPE_BUFFER_MEMORY_BARRIER};
  to_host.srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT;
  to_host.dstAccessMask = VK_ACCESS_HOST_READ_BIT;
  to_host.srcQueueFamilyIndex = to_host.dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
  to_host.buffer = d.buffers[Records].buffer.get();
  to_host.size = VK_WHOLE_SIZE;
  vkCmdPipelineBarrier(d.commands, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_PIPELINE_STAGE_HOST_BIT, 0, 0, nullptr, 1,
                       &to_host, 0, nullptr);
  const auto submit_start = Clock::now();
  d.submit_and_wait();
  const double submit_ms = ms_since(submit_start);

  const auto copy_start = Clock::now();
  const vk::HostBuffer& records = d.buffers[Records];
  if (!records.coherent) {
    VkMappedMemoryRange range{VK_STRUCTURE_TYPE_MAPPED_MEMORY_RANGE};
    range.memory = records.memory.get();
    range.size = VK_WHOLE_SIZE;
    VK_CHECK(vkInvalidateMappedMemoryRanges(d.device.handle(), 1, &range));
  }
  std::memcpy(out.data(), records.mapped, size_t(count) * sizeof(HitRecord));
  const double copy_ms = ms_since(copy_start);
  double trace_ms = submit_ms;  // no timestamps: the whole submission on the CPU clock
  if (d.queries) {
    uint64_t stamps[kTimestamps] = {};
    VK_CHECK(vkGetQueryPoolResults(d.device.handle(), d.queries.get(), 0, kTimestamps, sizeof(stamps), stamps,
                                   sizeof(uint64_t), VK_QUERY_RESULT_64_BIT | VK_QUERY_RESULT_WAIT_BIT));
    const uint32_t bits = d.device.timestamp_bits();
    const uint64_t mask = bits >= 64 ? ~uint64_t(0) : (uint64_t(1) << bits) - 1;
    trace_ms = double((stamps[1] - stamps[0]) & mask) * double(d.device.properties().limits.timestampPeriod) * 1e-6;
  }
  d.device.throw_validation_errors();
  if (timings) {
    timings->upload_ms = upload_ms;
    timings->trace_ms = trace_ms;
    timings->readback_ms = copy_ms;
    timings->wall_ms = ms_since(start);
    timings->rays = count;
    timings->bytes_read = uint64_t(count) * sizeof(HitRecord);
  }
}

std::vector<std::string> ComputeEngine::take_debug_messages() { return impl_->device.take_debug_messages(); }

std::vector<std::string> ComputeEngine::broken_constraints() { return es2_constraints_broken(shader().spirv); }

std::string ComputeEngine::unavailable_reason(const VulkanOptions& options) {
  try {
    ComputeEngine probe(options);
    return "";
  } catch (const Error& e) {
    if (e.kind() == ErrorKind::Internal) throw;
    return e.what();
  }
}

}  // namespace mobirt
