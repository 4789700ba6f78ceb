// The ray-query peer (ray_query_engine.h): a small Vulkan 1.2 context of its own with
// VK_KHR_acceleration_structure, VK_KHR_ray_query, VK_KHR_deferred_host_operations and buffer
// device addresses, the driver's BLAS + TLAS, and one fragment pass (glsl/ray_query.frag). Like
// mobirt's backend every submission is waited for, so objects are reused across calls; each
// command buffer starts with a full barrier against the previous submission's work.
#include "baseline/ray_query_engine.h"

#include <vulkan/vulkan.h>

#include <dlfcn.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <mutex>
#include <optional>
#include <tuple>
#include <utility>

#include "backend/shader_constraints.h"
#include "backend/vulkan/vk_pipeline.h"
#include "backend/vulkan/vk_resources.h"
#include "backend/vulkan/vk_util.h"
#include "core/error.h"
#include "layout.h"
#include "render/renderer.h"  // trace_uniforms(): the traversal pass's uniforms, shared

// SPIR-V generated at build time from glsl/ (build/spirv/<name>.h).
#include "fullscreen.vert.h"
#include "ray_query.frag.h"

namespace mobirt {

namespace {

using Clock = std::chrono::steady_clock;

constexpr VkFormat kRayFormat = VK_FORMAT_R32G32B32A32_SFLOAT;
constexpr uint32_t kTimestamps = 4;
constexpr const char* kExtensions[] = {VK_KHR_ACCELERATION_STRUCTURE_EXTENSION_NAME, VK_KHR_RAY_QUERY_EXTENSION_NAME,
                                       VK_KHR_DEFERRED_HOST_OPERATIONS_EXTENSION_NAME};

double ms_since(Clock::time_point t) { return std::chrono::duration<double, std::milli>(Clock::now() - t).count(); }

std::string version_string(uint32_t v) {
  return std::to_string(VK_API_VERSION_MAJOR(v)) + "." + std::to_string(VK_API_VERSION_MINOR(v)) + "." +
         std::to_string(VK_API_VERSION_PATCH(v));
}

std::string lower(std::string s) {
  for (char& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

bool validation_from_env() {
  const char* value = std::getenv("MOBIRT_VALIDATION");
  return value && *value && std::string(value) != "0";
}

// "A, B and C".
std::string join_and(const std::vector<std::string>& items) {
  std::string s;
  for (size_t i = 0; i < items.size(); ++i) {
    if (i > 0) s += i + 1 == items.size() ? " and " : ", ";
    s += items[i];
  }
  return s;
}

// The loader's vkGetInstanceProcAddr, looked up in libvulkan itself rather than bound by name: a
// process that preloads the validation layer (the sanitizer run of .ci/run does, to keep it mapped)
// gets the layer's exported vkGetInstanceProcAddr and vkGetDeviceProcAddr for those names, and
// they know only the handles of their own chain (without validation: every extension function
// came back null).
PFN_vkGetInstanceProcAddr loader_proc_addr() {
  static const PFN_vkGetInstanceProcAddr found = [] {
    void* loader = dlopen("libvulkan.so.1", RTLD_NOW | RTLD_NOLOAD);  // linked, so already loaded
    void* f = loader ? dlsym(loader, "vkGetInstanceProcAddr") : nullptr;
    return f ? reinterpret_cast<PFN_vkGetInstanceProcAddr>(f) : &vkGetInstanceProcAddr;
  }();
  return found;
}

struct DebugSink {
  std::mutex mutex;
  std::vector<std::string> messages;
  ~DebugSink() {  // messages nobody took, those of the device's and instance's destruction included
    for (const std::string& m : messages) std::fprintf(stderr, "mobirt: ray query: Vulkan %s\n", m.c_str());
  }
};

VKAPI_ATTR VkBool32 VKAPI_CALL debug_callback(VkDebugUtilsMessageSeverityFlagBitsEXT severity,
                                              VkDebugUtilsMessageTypeFlagsEXT,
                                              const VkDebugUtilsMessengerCallbackDataEXT* data, void* user) {
  const bool error = (severity & VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT) != 0;
  if (!error && !(severity & VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT)) return VK_FALSE;
  std::string text = error ? "validation error: " : "validation warning: ";
  if (data && data->pMessageIdName) text += std::string(data->pMessageIdName) + ": ";
  text += data && data->pMessage ? data->pMessage : "(no message)";
  auto* sink = static_cast<DebugSink*>(user);
  std::lock_guard lock(sink->mutex);
  sink->messages.push_back(text);
  return VK_FALSE;
}

struct InstanceOwner {
  VkInstance instance = VK_NULL_HANDLE;
  VkDebugUtilsMessengerEXT messenger = VK_NULL_HANDLE;
  InstanceOwner() = default;
  InstanceOwner(const InstanceOwner&) = delete;
  InstanceOwner& operator=(const InstanceOwner&) = delete;
  ~InstanceOwner() {
    if (messenger != VK_NULL_HANDLE) {
      auto destroy = reinterpret_cast<PFN_vkDestroyDebugUtilsMessengerEXT>(
          loader_proc_addr()(instance, "vkDestroyDebugUtilsMessengerEXT"));
      if (destroy) destroy(instance, messenger, nullptr);
    }
    if (instance != VK_NULL_HANDLE) vkDestroyInstance(instance, nullptr);
  }
};

struct DeviceOwner {
  VkDevice device = VK_NULL_HANDLE;
  DeviceOwner() = default;
  DeviceOwner(const DeviceOwner&) = delete;
  DeviceOwner& operator=(const DeviceOwner&) = delete;
  ~DeviceOwner() {
    if (device != VK_NULL_HANDLE) {
      vkDeviceWaitIdle(device);
      vkDestroyDevice(device, nullptr);
    }
  }
};

// A buffer and its memory (freed after the buffer), mapped when host-visible.
struct Buffer {
  vk::Memory memory;
  vk::Buffer buffer;
  VkDeviceSize size = 0;
  VkDeviceAddress address = 0;  // with VK_BUFFER_USAGE_SHADER_DEVICE_ADDRESS_BIT
  void* mapped = nullptr;
  void reset() {
    buffer.reset();
    memory.reset();
    size = 0;
    address = 0;
    mapped = nullptr;
  }
};

struct Image2D {
  vk::Memory memory;
  vk::Image image;
  vk::ImageView view;
  uint32_t width = 0, height = 0;
  void reset() {
    view.reset();
    image.reset();
    memory.reset();
    width = height = 0;
  }
};

// An acceleration structure; its destroy function is loaded from the device.
struct AccelerationStructure {
  VkDevice device = VK_NULL_HANDLE;
  PFN_vkDestroyAccelerationStructureKHR destroy = nullptr;
  VkAccelerationStructureKHR handle = VK_NULL_HANDLE;
  VkDeviceAddress address = 0;
  AccelerationStructure() = default;
  AccelerationStructure(const AccelerationStructure&) = delete;
  AccelerationStructure& operator=(const AccelerationStructure&) = delete;
  ~AccelerationStructure() { reset(); }
  void reset() {
    if (handle != VK_NULL_HANDLE) destroy(device, handle, nullptr);
    handle = VK_NULL_HANDLE;
    address = 0;
  }
};

VkImageMemoryBarrier image_barrier(VkImage image, VkImageLayout from, VkImageLayout to, VkAccessFlags src,
                                   VkAccessFlags dst) {
  VkImageMemoryBarrier b{VK_STRUCTURE_TYPE_IMAGE_MEMORY_BARRIER};
  b.srcAccessMask = src;
  b.dstAccessMask = dst;
  b.oldLayout = from;
  b.newLayout = to;
  b.srcQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
  b.dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
  b.image = image;
  b.subresourceRange = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 1, 0, 1};
  return b;
}

}  // namespace

struct RayQueryEngine::Impl {
  explicit Impl(const RayQueryOptions& options);
  // The members below the device are destroyed before DeviceOwner waits for it: wait here first,
  // so that nothing the device may still use (a pass cut short by an error) is freed under it.
  ~Impl() {
    if (device != VK_NULL_HANDLE) vkDeviceWaitIdle(device);
  }

  // Instance, device choice and the reason the device cannot run the peer ("" = it can).
  void create_instance(bool validation, bool sync_validation);
  void pick_physical_device(const std::string& wanted);
  std::string support_problem();
  void create_device();
  void create_objects();

  uint32_t memory_type(uint32_t bits, VkMemoryPropertyFlags required, VkMemoryPropertyFlags preferred) const;
  vk::Memory allocate(const VkMemoryRequirements& req, bool host, const void* next = nullptr);
  Buffer make_buffer(VkDeviceSize size, VkBufferUsageFlags usage, bool host);
  void ensure_host(Buffer& b, VkDeviceSize size, VkBufferUsageFlags usage);
  void ensure_device(Buffer& b, VkDeviceSize size, VkBufferUsageFlags usage);
  void ensure_image(Image2D& image, uint32_t width, uint32_t height, VkFormat format, VkImageUsageFlags usage);
  void ensure_target(uint32_t width, uint32_t height);
  VkPipeline pipeline(int lights, Packing packing, OffsetMode offset);
  void begin();
  void submit_and_wait(const char* what);
  std::vector<double> timestamps_ms();  // kTimestamps values relative to the first
  void create_as(AccelerationStructure& as, Buffer& storage, VkAccelerationStructureTypeKHR type, VkDeviceSize size);
  VkDeviceAddress scratch_address(VkDeviceSize size);

  void build(const Scene& scene, AsBuildTimings* timings);
  Packing trace(const RayBatch& rays, std::span<const Light> lights, const ShadowSettings& shadows,
                std::span<uint32_t> out, RayQueryTimings* timings);

  AsBuildMode mode;
  DebugSink sink;  // before the instance: outlives it and hears its last messages
  InstanceOwner instance;
  VkPhysicalDevice physical = VK_NULL_HANDLE;
  VkPhysicalDeviceProperties properties{};
  VkPhysicalDeviceMemoryProperties memory{};
  std::string driver;       // "llvmpipe / Mesa 25.0.7 (LLVM 15.0.6)"
  std::string who;          // "lavapipe of Mesa 25.0.7", for messages
  uint32_t queue_family = 0;
  uint32_t timestamp_bits = 0;
  GpuTimestamps timestamps = GpuTimestamps::Auto;  // RayQueryOptions::timestamps
  VkDeviceSize scratch_alignment = 256;
  DeviceOwner device_owner;
  VkDevice device = VK_NULL_HANDLE;
  VkQueue queue = VK_NULL_HANDLE;

  PFN_vkCreateAccelerationStructureKHR create_acceleration_structure = nullptr;
  PFN_vkDestroyAccelerationStructureKHR destroy_acceleration_structure = nullptr;
  PFN_vkGetAccelerationStructureBuildSizesKHR build_sizes = nullptr;
  PFN_vkCmdBuildAccelerationStructuresKHR cmd_build = nullptr;
  PFN_vkGetAccelerationStructureDeviceAddressKHR as_address = nullptr;

  vk::CommandPool command_pool;
  VkCommandBuffer commands = VK_NULL_HANDLE;  // freed with the pool
  vk::Fence fence;
  vk::QueryPool queries;
  vk::Sampler sampler;
  vk::RenderPass render_pass;
  vk::ShaderModule vertex_shader, fragment_shader;
  vk::DescriptorSetLayout set_layout;
  vk::PipelineLayout pipeline_layout;
  vk::DescriptorPool descriptor_pool;
  VkDescriptorSet descriptor_set = VK_NULL_HANDLE;  // freed with the pool
  std::map<std::tuple<int, int, int>, vk::Pipeline> pipelines;  // (lights, packing, offset)

  Buffer uniforms, staging, readback, vertices, instances, scratch, blas_storage, tlas_storage;
  AccelerationStructure blas, tlas;  // after their storage: destroyed first
  uint32_t blas_triangles = 0;       // what the BLAS was built over
  bool blas_updatable = false;
  Image2D triangle_texels, ray_origin, ray_direction, target;
  vk::Framebuffer framebuffer;  // over target
  FlatKdTree triangles;         // texels and box of the last build
  std::string scene_name;
  bool built = false;
};

RayQueryEngine::Impl::Impl(const RayQueryOptions& options) : mode(options.build_mode), timestamps(options.timestamps) {
  create_instance(options.validation || options.sync_validation || validation_from_env(), options.sync_validation);
  pick_physical_device(options.device);
  const std::string problem = support_problem();
  if (!problem.empty()) throw Error(ErrorKind::Unsupported, problem);
  create_device();
  create_objects();
}

void RayQueryEngine::Impl::create_instance(bool validation, bool sync_validation) {
  uint32_t loader = VK_API_VERSION_1_0;
  if (vkEnumerateInstanceVersion(&loader) != VK_SUCCESS || loader < VK_API_VERSION_1_2) {
    throw Error(ErrorKind::Unsupported, "the Vulkan loader supports Vulkan " + version_string(loader) +
                                            "; the ray-query peer needs 1.2: update libvulkan1");
  }
  std::vector<const char*> layers, extensions;
  if (validation) {
    uint32_t count = 0;
    VK_CHECK_RESULT(vkEnumerateInstanceLayerProperties(&count, nullptr), "vkEnumerateInstanceLayerProperties");
    std::vector<VkLayerProperties> available(count);
    VK_CHECK_RESULT(vkEnumerateInstanceLayerProperties(&count, available.data()), "vkEnumerateInstanceLayerProperties");
    if (std::none_of(available.begin(), available.end(), [](const VkLayerProperties& l) {
          return std::strcmp(l.layerName, "VK_LAYER_KHRONOS_validation") == 0;
        })) {
      throw Error(ErrorKind::Unsupported,
                  "validation was requested but the layer VK_LAYER_KHRONOS_validation is not installed: install "
                  "vulkan-validationlayers");
    }
    layers.push_back("VK_LAYER_KHRONOS_validation");
    extensions.push_back(VK_EXT_DEBUG_UTILS_EXTENSION_NAME);
  }
  VkApplicationInfo app{VK_STRUCTURE_TYPE_APPLICATION_INFO};
  app.pApplicationName = "mobirt ray query";
  app.pEngineName = "mobirt";
  // 1.2 has buffer device addresses and SPIR-V 1.5 in core; the 1.3 loader and layers know it all.
  app.apiVersion = VK_API_VERSION_1_2;
  VkDebugUtilsMessengerCreateInfoEXT messenger{VK_STRUCTURE_TYPE_DEBUG_UTILS_MESSENGER_CREATE_INFO_EXT};
  messenger.messageSeverity =
      VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT;
  messenger.messageType = VK_DEBUG_UTILS_MESSAGE_TYPE_GENERAL_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_TYPE_VALIDATION_BIT_EXT |
                          VK_DEBUG_UTILS_MESSAGE_TYPE_PERFORMANCE_BIT_EXT;
  messenger.pfnUserCallback = debug_callback;
  messenger.pUserData = &sink;
  VkInstanceCreateInfo info{VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO};
  info.pNext = validation ? &messenger : nullptr;
  const VkValidationFeatureEnableEXT sync = VK_VALIDATION_FEATURE_ENABLE_SYNCHRONIZATION_VALIDATION_EXT;
  VkValidationFeaturesEXT features{VK_STRUCTURE_TYPE_VALIDATION_FEATURES_EXT};
  if (validation && sync_validation) {
    features.enabledValidationFeatureCount = 1;
    features.pEnabledValidationFeatures = &sync;
    features.pNext = info.pNext;  // the messenger's create info stays unchained: it is reused below
    info.pNext = &features;
  }
  info.pApplicationInfo = &app;
  info.enabledLayerCount = uint32_t(layers.size());
  info.ppEnabledLayerNames = layers.data();
  info.enabledExtensionCount = uint32_t(extensions.size());
  info.ppEnabledExtensionNames = extensions.data();
  const VkResult result = vkCreateInstance(&info, nullptr, &instance.instance);
  if (result == VK_ERROR_INCOMPATIBLE_DRIVER) {
    throw Error(ErrorKind::NoDevice, "no Vulkan device: install mesa-vulkan-drivers (lavapipe) or a GPU driver");
  }
  VK_CHECK_RESULT(result, "vkCreateInstance");
  if (validation) {
    auto create = reinterpret_cast<PFN_vkCreateDebugUtilsMessengerEXT>(
        loader_proc_addr()(instance.instance, "vkCreateDebugUtilsMessengerEXT"));
    if (!create) throw Error(ErrorKind::Unsupported, "VK_EXT_debug_utils is missing: install vulkan-validationlayers");
    VK_CHECK_RESULT(create(instance.instance, &messenger, nullptr, &instance.messenger), "vkCreateDebugUtilsMessengerEXT");
  }
}

void RayQueryEngine::Impl::pick_physical_device(const std::string& wanted) {
  uint32_t count = 0;
  const VkResult result = vkEnumeratePhysicalDevices(instance.instance, &count, nullptr);
  if (result == VK_ERROR_INITIALIZATION_FAILED || (result == VK_SUCCESS && count == 0)) {
    throw Error(ErrorKind::NoDevice, "no Vulkan device: install mesa-vulkan-drivers (lavapipe) or a GPU driver");
  }
  VK_CHECK_RESULT(result, "vkEnumeratePhysicalDevices");
  std::vector<VkPhysicalDevice> devices(count);
  VK_CHECK_RESULT(vkEnumeratePhysicalDevices(instance.instance, &count, devices.data()), "vkEnumeratePhysicalDevices");
  std::vector<VkPhysicalDeviceProperties> props(count);
  for (uint32_t i = 0; i < count; ++i) vkGetPhysicalDeviceProperties(devices[i], &props[i]);
  // The same choice as mobirt's backend (BackendOptions::device): empty = lavapipe, else the first.
  size_t chosen = count;
  const bool numeric =
      std::all_of(wanted.begin(), wanted.end(), [](char c) { return std::isdigit(static_cast<unsigned char>(c)); });
  if (wanted.empty()) {
    for (size_t i = 0; i < count && chosen == count; ++i) {
      const bool cpu = props[i].deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU;
      if (cpu || lower(props[i].deviceName).find("llvmpipe") != std::string::npos) chosen = i;
    }
    if (chosen == count) chosen = 0;
  } else if (numeric) {
    const unsigned long index = std::strtoul(wanted.c_str(), nullptr, 10);
    if (index < count) chosen = size_t(index);
  } else {
    for (size_t i = 0; i < count && chosen == count; ++i) {
      if (lower(props[i].deviceName).find(lower(wanted)) != std::string::npos) chosen = i;
    }
  }
  if (chosen == count) throw Error(ErrorKind::NoDevice, "no Vulkan device matches \"" + wanted + "\"");
  physical = devices[chosen];
  properties = props[chosen];
  vkGetPhysicalDeviceMemoryProperties(physical, &memory);
  who = properties.deviceName;
  driver = "driver version " + std::to_string(properties.driverVersion);
  if (properties.apiVersion >= VK_API_VERSION_1_2) {
    VkPhysicalDeviceDriverProperties d{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_DRIVER_PROPERTIES};
    VkPhysicalDeviceProperties2 p2{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_PROPERTIES_2};
    p2.pNext = &d;
    vkGetPhysicalDeviceProperties2(physical, &p2);
    driver = std::string(d.driverName) + " / " + d.driverInfo;
    const std::string info = d.driverInfo;  // "Mesa 25.0.7 (LLVM 15.0.6)"
    who = d.driverID == VK_DRIVER_ID_MESA_LLVMPIPE ? "lavapipe of " + info.substr(0, info.find(" ("))
                                                   : who + " (" + driver + ")";
  } else if (lower(who).find("llvmpipe") != std::string::npos) {
    who = "lavapipe (Vulkan " + version_string(properties.apiVersion) + ")";
  }
}

std::string RayQueryEngine::Impl::support_problem() {
  const bool lavapipe = who.rfind("lavapipe", 0) == 0;
  const std::string newer = lavapipe ? "; Mesa >= 24.1 has " : "";
  if (properties.apiVersion < VK_API_VERSION_1_2) {
    return who + " supports Vulkan " + version_string(properties.apiVersion) + "; the ray-query peer needs 1.2";
  }
  uint32_t count = 0;
  VK_CHECK_RESULT(vkEnumerateDeviceExtensionProperties(physical, nullptr, &count, nullptr),
            "vkEnumerateDeviceExtensionProperties");
  std::vector<VkExtensionProperties> available(count);
  VK_CHECK_RESULT(vkEnumerateDeviceExtensionProperties(physical, nullptr, &count, available.data()),
            "vkEnumerateDeviceExtensionProperties");
  std::vector<std::string> missing;
  for (const char* name : kExtensions) {
    if (std::none_of(available.begin(), available.end(),
                     [&](const VkExtensionProperties& e) { return std::strcmp(e.extensionName, name) == 0; })) {
      missing.push_back(name);
    }
  }
  if (!missing.empty()) {
    return who + " lacks " + join_and(missing) + (lavapipe ? newer + (missing.size() == 1 ? "it" : "them") : "");
  }
  VkPhysicalDeviceRayQueryFeaturesKHR ray_query{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_RAY_QUERY_FEATURES_KHR};
  VkPhysicalDeviceAccelerationStructureFeaturesKHR as{
      VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_ACCELERATION_STRUCTURE_FEATURES_KHR};
  as.pNext = &ray_query;
  VkPhysicalDeviceVulkan12Features v12{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VULKAN_1_2_FEATURES};
  v12.pNext = &as;
  VkPhysicalDeviceFeatures2 features{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_FEATURES_2};
  features.pNext = &v12;
  vkGetPhysicalDeviceFeatures2(physical, &features);
  std::vector<std::string> lacking;
  if (!as.accelerationStructure) lacking.push_back("accelerationStructure");
  if (!ray_query.rayQuery) lacking.push_back("rayQuery");
  if (!v12.bufferDeviceAddress) lacking.push_back("bufferDeviceAddress");
  if (!lacking.empty()) return who + " has the ray-query extensions but not the feature " + join_and(lacking);

  VkPhysicalDeviceAccelerationStructurePropertiesKHR as_props{
      VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_ACCELERATION_STRUCTURE_PROPERTIES_KHR};
  VkPhysicalDeviceProperties2 p2{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_PROPERTIES_2};
  p2.pNext = &as_props;
  vkGetPhysicalDeviceProperties2(physical, &p2);
  scratch_alignment = std::max<VkDeviceSize>(1, as_props.minAccelerationStructureScratchOffsetAlignment);

  uint32_t families = 0;
  vkGetPhysicalDeviceQueueFamilyProperties(physical, &families, nullptr);
  std::vector<VkQueueFamilyProperties> family(families);
  vkGetPhysicalDeviceQueueFamilyProperties(physical, &families, family.data());
  const VkQueueFlags needed = VK_QUEUE_GRAPHICS_BIT | VK_QUEUE_COMPUTE_BIT;  // AS builds need compute
  for (uint32_t i = 0; i < families; ++i) {
    if ((family[i].queueFlags & needed) == needed) {
      queue_family = i;
      timestamp_bits = family[i].timestampValidBits;
      return "";
    }
  }
  return who + " has no queue with graphics and compute";
}

void RayQueryEngine::Impl::create_device() {
  VkPhysicalDeviceRayQueryFeaturesKHR ray_query{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_RAY_QUERY_FEATURES_KHR};
  ray_query.rayQuery = VK_TRUE;
  VkPhysicalDeviceAccelerationStructureFeaturesKHR as{
      VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_ACCELERATION_STRUCTURE_FEATURES_KHR};
  as.accelerationStructure = VK_TRUE;
  as.pNext = &ray_query;
  VkPhysicalDeviceVulkan12Features v12{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VULKAN_1_2_FEATURES};
  v12.bufferDeviceAddress = VK_TRUE;
  v12.pNext = &as;
  const float priority = 1.0f;
  VkDeviceQueueCreateInfo queue_info{VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO};
  queue_info.queueFamilyIndex = queue_family;
  queue_info.queueCount = 1;
  queue_info.pQueuePriorities = &priority;
  VkDeviceCreateInfo info{VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO};
  info.pNext = &v12;
  info.queueCreateInfoCount = 1;
  info.pQueueCreateInfos = &queue_info;
  info.enabledExtensionCount = uint32_t(std::size(kExtensions));
  info.ppEnabledExtensionNames = kExtensions;
  VK_CHECK_RESULT(vkCreateDevice(physical, &info, nullptr, &device_owner.device), "vkCreateDevice");
  device = device_owner.device;
  vkGetDeviceQueue(device, queue_family, 0, &queue);
  // The loader's trampolines, which dispatch on the device: vkGetDeviceProcAddr, even the one the
  // loader hands out, was the preloaded layer's too (null for every extension function).
  auto load = [&](const char* name) {
    const PFN_vkVoidFunction f = loader_proc_addr()(instance.instance, name);
    if (!f) throw Error(ErrorKind::Unsupported, who + " does not give " + name);
    return f;
  };
  create_acceleration_structure =
      reinterpret_cast<PFN_vkCreateAccelerationStructureKHR>(load("vkCreateAccelerationStructureKHR"));
  destroy_acceleration_structure =
      reinterpret_cast<PFN_vkDestroyAccelerationStructureKHR>(load("vkDestroyAccelerationStructureKHR"));
  build_sizes =
      reinterpret_cast<PFN_vkGetAccelerationStructureBuildSizesKHR>(load("vkGetAccelerationStructureBuildSizesKHR"));
  cmd_build = reinterpret_cast<PFN_vkCmdBuildAccelerationStructuresKHR>(load("vkCmdBuildAccelerationStructuresKHR"));
  as_address = reinterpret_cast<PFN_vkGetAccelerationStructureDeviceAddressKHR>(
      load("vkGetAccelerationStructureDeviceAddressKHR"));
  for (AccelerationStructure* a : {&blas, &tlas}) {
    a->device = device;
    a->destroy = destroy_acceleration_structure;
  }
}

void RayQueryEngine::Impl::create_objects() {
  VkCommandPoolCreateInfo pool_info{VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO};
  pool_info.flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT;
  pool_info.queueFamilyIndex = queue_family;
  VkCommandPool pool = VK_NULL_HANDLE;
  VK_CHECK_RESULT(vkCreateCommandPool(device, &pool_info, nullptr, &pool), "vkCreateCommandPool");
  command_pool = vk::CommandPool(device, pool);
  VkCommandBufferAllocateInfo alloc{VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO};
  alloc.commandPool = pool;
  alloc.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
  alloc.commandBufferCount = 1;
  VK_CHECK_RESULT(vkAllocateCommandBuffers(device, &alloc, &commands), "vkAllocateCommandBuffers");
  VkFenceCreateInfo fence_info{VK_STRUCTURE_TYPE_FENCE_CREATE_INFO};
  VkFence f = VK_NULL_HANDLE;
  VK_CHECK_RESULT(vkCreateFence(device, &fence_info, nullptr, &f), "vkCreateFence");
  fence = vk::Fence(device, f);
  if (takes_gpu_timestamps(timestamps, timestamp_bits, properties.deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU)) {
    VkQueryPoolCreateInfo query_info{VK_STRUCTURE_TYPE_QUERY_POOL_CREATE_INFO};
    query_info.queryType = VK_QUERY_TYPE_TIMESTAMP;
    query_info.queryCount = kTimestamps;
    VkQueryPool q = VK_NULL_HANDLE;
    VK_CHECK_RESULT(vkCreateQueryPool(device, &query_info, nullptr, &q), "vkCreateQueryPool");
    queries = vk::QueryPool(device, q);
  }

  sampler = vk::create_fetch_sampler(device);

  render_pass = vk::create_target_render_pass(device);  // the same as mobirt's passes

  auto module = [&](std::span<const uint32_t> code) {
    VkShaderModuleCreateInfo info{VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO};
    info.codeSize = code.size_bytes();
    info.pCode = code.data();
    VkShaderModule m = VK_NULL_HANDLE;
    VK_CHECK_RESULT(vkCreateShaderModule(device, &info, nullptr, &m), "vkCreateShaderModule");
    return vk::ShaderModule(device, m);
  };
  vertex_shader = module(spirv_fullscreen_vert);
  fragment_shader = module(spirv_ray_query_frag);

  const VkShaderStageFlags fragment = VK_SHADER_STAGE_FRAGMENT_BIT;
  const VkDescriptorSetLayoutBinding bindings[] = {
      {MOBIRT_BIND_TRACE_PARAMS, VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER, 1, fragment, nullptr},
      {MOBIRT_BIND_NODES, VK_DESCRIPTOR_TYPE_ACCELERATION_STRUCTURE_KHR, 1, fragment, nullptr},  // u_scene
      {MOBIRT_BIND_TRIANGLES, VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER, 1, fragment, nullptr},
      {MOBIRT_BIND_RAY_ORIGIN, VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER, 1, fragment, nullptr},
      {MOBIRT_BIND_RAY_DIRECTION, VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER, 1, fragment, nullptr},
  };
  VkDescriptorSetLayoutCreateInfo set_info{VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO};
  set_info.bindingCount = uint32_t(std::size(bindings));
  set_info.pBindings = bindings;
  VkDescriptorSetLayout layout = VK_NULL_HANDLE;
  VK_CHECK_RESULT(vkCreateDescriptorSetLayout(device, &set_info, nullptr, &layout), "vkCreateDescriptorSetLayout");
  set_layout = vk::DescriptorSetLayout(device, layout);
  VkPipelineLayoutCreateInfo pl{VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO};
  pl.setLayoutCount = 1;
  pl.pSetLayouts = &layout;
  VkPipelineLayout pipe_layout = VK_NULL_HANDLE;
  VK_CHECK_RESULT(vkCreatePipelineLayout(device, &pl, nullptr, &pipe_layout), "vkCreatePipelineLayout");
  pipeline_layout = vk::PipelineLayout(device, pipe_layout);
  const VkDescriptorPoolSize sizes[] = {{VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER, 1},
                                        {VK_DESCRIPTOR_TYPE_ACCELERATION_STRUCTURE_KHR, 1},
                                        {VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER, 3}};
  VkDescriptorPoolCreateInfo dp{VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO};
  dp.maxSets = 1;
  dp.poolSizeCount = uint32_t(std::size(sizes));
  dp.pPoolSizes = sizes;
  VkDescriptorPool dpool = VK_NULL_HANDLE;
  VK_CHECK_RESULT(vkCreateDescriptorPool(device, &dp, nullptr, &dpool), "vkCreateDescriptorPool");
  descriptor_pool = vk::DescriptorPool(device, dpool);
  VkDescriptorSetAllocateInfo ds{VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO};
  ds.descriptorPool = dpool;
  ds.descriptorSetCount = 1;
  ds.pSetLayouts = &layout;
  VK_CHECK_RESULT(vkAllocateDescriptorSets(device, &ds, &descriptor_set), "vkAllocateDescriptorSets");

  uniforms = make_buffer(MOBIRT_MAX_PARAM_VEC4S * 16, VK_BUFFER_USAGE_UNIFORM_BUFFER_BIT, true);
  std::memset(uniforms.mapped, 0, MOBIRT_MAX_PARAM_VEC4S * 16);
}

uint32_t RayQueryEngine::Impl::memory_type(uint32_t bits, VkMemoryPropertyFlags required,
                                           VkMemoryPropertyFlags preferred) const {
  if (const std::optional<uint32_t> type = vk::find_memory_type(memory, bits, required, preferred)) return *type;
  throw Error(ErrorKind::Unsupported, who + " has no memory type the ray-query peer can use");
}

vk::Memory RayQueryEngine::Impl::allocate(const VkMemoryRequirements& req, bool host, const void* next) {
  VkMemoryAllocateInfo alloc{VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO};
  alloc.pNext = next;
  alloc.allocationSize = req.size;
  alloc.memoryTypeIndex =
      host ? memory_type(req.memoryTypeBits, VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT,
                         VK_MEMORY_PROPERTY_HOST_CACHED_BIT)
           : memory_type(req.memoryTypeBits, 0, VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT);
  VkDeviceMemory mem = VK_NULL_HANDLE;
  VK_CHECK_RESULT(vkAllocateMemory(device, &alloc, nullptr, &mem), "vkAllocateMemory");
  return vk::Memory(device, mem);
}

Buffer RayQueryEngine::Impl::make_buffer(VkDeviceSize size, VkBufferUsageFlags usage, bool host) {
  Buffer b;
  VkBufferCreateInfo info{VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO};
  info.size = size;
  info.usage = usage;
  info.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
  VkBuffer buffer = VK_NULL_HANDLE;
  VK_CHECK_RESULT(vkCreateBuffer(device, &info, nullptr, &buffer), "vkCreateBuffer");
  b.buffer = vk::Buffer(device, buffer);
  VkMemoryRequirements req{};
  vkGetBufferMemoryRequirements(device, buffer, &req);
  const bool addressed = (usage & VK_BUFFER_USAGE_SHADER_DEVICE_ADDRESS_BIT) != 0;
  VkMemoryAllocateFlagsInfo flags{VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_FLAGS_INFO};
  flags.flags = VK_MEMORY_ALLOCATE_DEVICE_ADDRESS_BIT;
  b.memory = allocate(req, host, addressed ? &flags : nullptr);
  VK_CHECK_RESULT(vkBindBufferMemory(device, buffer, b.memory.get(), 0), "vkBindBufferMemory");
  if (host) VK_CHECK_RESULT(vkMapMemory(device, b.memory.get(), 0, VK_WHOLE_SIZE, 0, &b.mapped), "vkMapMemory");
  if (addressed) {
    VkBufferDeviceAddressInfo address{VK_STRUCTURE_TYPE_BUFFER_DEVICE_ADDRESS_INFO};
    address.buffer = buffer;
    b.address = vkGetBufferDeviceAddress(device, &address);
  }
  b.size = size;
  return b;
}

void RayQueryEngine::Impl::ensure_host(Buffer& b, VkDeviceSize size, VkBufferUsageFlags usage) {
  if (b.size >= size) return;
  const VkDeviceSize grown = std::max(size, b.size + b.size / 2);  // headroom for growing scenes
  b.reset();
  b = make_buffer(grown, usage, true);
}

void RayQueryEngine::Impl::ensure_device(Buffer& b, VkDeviceSize size, VkBufferUsageFlags usage) {
  if (b.size >= size) return;
  const VkDeviceSize grown = std::max(size, b.size + b.size / 2);
  b.reset();
  b = make_buffer(grown, usage, false);
}

void RayQueryEngine::Impl::ensure_image(Image2D& image, uint32_t width, uint32_t height, VkFormat format,
                                        VkImageUsageFlags usage) {
  if (image.width == width && image.height >= height) return;
  const uint32_t limit = properties.limits.maxImageDimension2D;
  if (width > limit || height > limit) {
    throw Error(ErrorKind::BadInput, "a " + std::to_string(width) + "x" + std::to_string(height) +
                                         " image exceeds the device's maxImageDimension2D (" + std::to_string(limit) +
                                         "): too many rays or triangles for this device");
  }
  const uint32_t rows = std::max(height, image.width == width ? image.height + image.height / 2 : 0u);
  image.reset();
  VkImageCreateInfo info{VK_STRUCTURE_TYPE_IMAGE_CREATE_INFO};
  info.imageType = VK_IMAGE_TYPE_2D;
  info.format = format;
  info.extent = {width, std::min(rows, limit), 1};
  info.mipLevels = 1;
  info.arrayLayers = 1;
  info.samples = VK_SAMPLE_COUNT_1_BIT;
  info.tiling = VK_IMAGE_TILING_OPTIMAL;
  info.usage = usage;
  info.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
  info.initialLayout = VK_IMAGE_LAYOUT_UNDEFINED;
  VkImage img = VK_NULL_HANDLE;
  VK_CHECK_RESULT(vkCreateImage(device, &info, nullptr, &img), "vkCreateImage");
  image.image = vk::Image(device, img);
  VkMemoryRequirements req{};
  vkGetImageMemoryRequirements(device, img, &req);
  image.memory = allocate(req, false);
  VK_CHECK_RESULT(vkBindImageMemory(device, img, image.memory.get(), 0), "vkBindImageMemory");
  VkImageViewCreateInfo view{VK_STRUCTURE_TYPE_IMAGE_VIEW_CREATE_INFO};
  view.image = img;
  view.viewType = VK_IMAGE_VIEW_TYPE_2D;
  view.format = format;
  view.subresourceRange = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 1, 0, 1};
  VkImageView v = VK_NULL_HANDLE;
  VK_CHECK_RESULT(vkCreateImageView(device, &view, nullptr, &v), "vkCreateImageView");
  image.view = vk::ImageView(device, v);
  image.width = width;
  image.height = info.extent.height;
}

void RayQueryEngine::Impl::ensure_target(uint32_t width, uint32_t height) {
  if (target.width == width && target.height >= height && framebuffer) return;
  framebuffer.reset();
  ensure_image(target, width, height, vk::kTargetFormat,
               VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT | VK_IMAGE_USAGE_TRANSFER_SRC_BIT);
  VkImageView view = target.view.get();
  VkFramebufferCreateInfo info{VK_STRUCTURE_TYPE_FRAMEBUFFER_CREATE_INFO};
  info.renderPass = render_pass.get();
  info.attachmentCount = 1;
  info.pAttachments = &view;
  info.width = target.width;
  info.height = target.height;
  info.layers = 1;
  VkFramebuffer fb = VK_NULL_HANDLE;
  VK_CHECK_RESULT(vkCreateFramebuffer(device, &info, nullptr, &fb), "vkCreateFramebuffer");
  framebuffer = vk::Framebuffer(device, fb);
}

VkPipeline RayQueryEngine::Impl::pipeline(int lights, Packing packing, OffsetMode offset) {
  const auto key = std::make_tuple(lights, int(packing), int(offset));
  const auto found = pipelines.find(key);
  if (found != pipelines.end()) return found->second.get();
  const int32_t values[] = {lights, int32_t(packing), int32_t(offset)};
  const VkSpecializationMapEntry entries[] = {{MOBIRT_SPEC_LIGHT_COUNT, 0, 4}, {MOBIRT_SPEC_PACKING, 4, 4},
                                              {MOBIRT_SPEC_OFFSET, 8, 4}};
  VkSpecializationInfo spec{};
  spec.mapEntryCount = uint32_t(std::size(entries));
  spec.pMapEntries = entries;
  spec.dataSize = sizeof(values);
  spec.pData = values;
  const VkPipeline p = vk::create_fullscreen_pipeline(device, render_pass.get(), pipeline_layout.get(),
                                                     vertex_shader.get(), fragment_shader.get(), &spec, VK_NULL_HANDLE);
  return pipelines.emplace(key, vk::Pipeline(device, p)).first->second.get();
}

void RayQueryEngine::Impl::begin() {
  VK_CHECK_RESULT(vkResetCommandBuffer(commands, 0), "vkResetCommandBuffer");
  VkCommandBufferBeginInfo info{VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
  info.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
  VK_CHECK_RESULT(vkBeginCommandBuffer(commands, &info), "vkBeginCommandBuffer");
  // Everything the previous submission wrote or read is done and visible before this one starts.
  VkMemoryBarrier all{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
  all.srcAccessMask = VK_ACCESS_MEMORY_WRITE_BIT;
  all.dstAccessMask = VK_ACCESS_MEMORY_READ_BIT | VK_ACCESS_MEMORY_WRITE_BIT;
  vkCmdPipelineBarrier(commands, VK_PIPELINE_STAGE_ALL_COMMANDS_BIT, VK_PIPELINE_STAGE_ALL_COMMANDS_BIT, 0, 1, &all, 0,
                       nullptr, 0, nullptr);
  if (queries) vkCmdResetQueryPool(commands, queries.get(), 0, kTimestamps);
}

void RayQueryEngine::Impl::submit_and_wait(const char* what) {
  VK_CHECK_RESULT(vkEndCommandBuffer(commands), "vkEndCommandBuffer");
  VkSubmitInfo submit{VK_STRUCTURE_TYPE_SUBMIT_INFO};
  submit.commandBufferCount = 1;
  submit.pCommandBuffers = &commands;
  VkFence f = fence.get();
  VK_CHECK_RESULT(vkQueueSubmit(queue, 1, &submit, f), what);
  // The passes never loop without bound (the driver walks its BVH), so a long wait means a broken
  // driver: two minutes, as mobirt's backend.
  const VkResult result = vkWaitForFences(device, 1, &f, VK_TRUE, uint64_t(120e9));
  if (result == VK_TIMEOUT) throw Error(ErrorKind::Internal, std::string(what) + " did not finish within 120 s");
  VK_CHECK_RESULT(result, "vkWaitForFences");
  VK_CHECK_RESULT(vkResetFences(device, 1, &f), "vkResetFences");
}

std::vector<double> RayQueryEngine::Impl::timestamps_ms() {
  std::vector<double> ms(kTimestamps, 0.0);
  if (!queries) return ms;
  uint64_t ticks[kTimestamps]{};
  VK_CHECK_RESULT(vkGetQueryPoolResults(device, queries.get(), 0, kTimestamps, sizeof(ticks), ticks, sizeof(uint64_t),
                                  VK_QUERY_RESULT_64_BIT | VK_QUERY_RESULT_WAIT_BIT),
            "vkGetQueryPoolResults");
  for (uint32_t i = 1; i < kTimestamps; ++i) {
    ms[i] = double(ticks[i] - ticks[0]) * double(properties.limits.timestampPeriod) * 1e-6;
  }
  return ms;
}

void RayQueryEngine::Impl::create_as(AccelerationStructure& as, Buffer& storage, VkAccelerationStructureTypeKHR type,
                                     VkDeviceSize size) {
  as.reset();
  ensure_device(storage, size,
                VK_BUFFER_USAGE_ACCELERATION_STRUCTURE_STORAGE_BIT_KHR | VK_BUFFER_USAGE_SHADER_DEVICE_ADDRESS_BIT);
  VkAccelerationStructureCreateInfoKHR info{VK_STRUCTURE_TYPE_ACCELERATION_STRUCTURE_CREATE_INFO_KHR};
  info.buffer = storage.buffer.get();
  info.size = size;
  info.type = type;
  VK_CHECK_RESULT(create_acceleration_structure(device, &info, nullptr, &as.handle), "vkCreateAccelerationStructureKHR");
  VkAccelerationStructureDeviceAddressInfoKHR address{VK_STRUCTURE_TYPE_ACCELERATION_STRUCTURE_DEVICE_ADDRESS_INFO_KHR};
  address.accelerationStructure = as.handle;
  as.address = as_address(device, &address);
}

VkDeviceAddress RayQueryEngine::Impl::scratch_address(VkDeviceSize size) {
  ensure_device(scratch, size + scratch_alignment,
                VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_SHADER_DEVICE_ADDRESS_BIT);
  return (scratch.address + scratch_alignment - 1) / scratch_alignment * scratch_alignment;
}

void RayQueryEngine::Impl::build(const Scene& scene, AsBuildTimings* timings) {
  const auto start = Clock::now();
  // The driver's acceleration structure holds triangles: analytic shapes are the caller's to
  // tessellate (scene/tessellate.h).
  if (!scene.shapes.empty()) {
    throw Error(ErrorKind::Internal, "ray query build: the scene's analytic shapes must be tessellated first");
  }
  const std::vector<glm::vec3>& positions = scene.mesh.positions;
  const uint32_t n = uint32_t(positions.size() / 3);
  if (positions.size() != size_t(n) * 3 || n != scene.mesh.triangle_count()) {
    throw Error(ErrorKind::Internal, "ray query build: " + std::to_string(positions.size()) + " positions for " +
                                         std::to_string(scene.mesh.triangle_count()) + " triangles");
  }
  if (size_t(n) * MOBIRT_TEXELS_PER_TRIANGLE > size_t(1) << 24) {
    throw input_error(scene.source, std::to_string(n) + " triangles: the triangle texels hold at most " +
                                        std::to_string((size_t(1) << 24) / MOBIRT_TEXELS_PER_TRIANGLE));
  }
  scene_name = scene.source;

  // The CPU side: the triangle texels and box (as a FlatKdTree's), the vertices, the instance.
  triangles = FlatKdTree{};
  triangles.bounds = scene.bounds();
  triangles.triangles.reserve(positions.size());
  for (const glm::vec3& p : positions) triangles.triangles.emplace_back(p, 0.0f);
  const size_t texels = triangles.triangles.size();
  const uint32_t rows = std::max<uint32_t>(1, uint32_t((texels + MOBIRT_DATA_WIDTH - 1) / MOBIRT_DATA_WIDTH));
  const VkDeviceSize texel_bytes = VkDeviceSize(rows) * MOBIRT_DATA_WIDTH * sizeof(glm::vec4);
  ensure_host(staging, texel_bytes, VK_BUFFER_USAGE_TRANSFER_SRC_BIT);
  // (An empty scene's vectors have no data(): memcpy must not see a null source.)
  if (texels > 0) std::memcpy(staging.mapped, triangles.triangles.data(), texels * sizeof(glm::vec4));
  std::memset(static_cast<char*>(staging.mapped) + triangles.triangles.size() * sizeof(glm::vec4), 0,
              texel_bytes - triangles.triangles.size() * sizeof(glm::vec4));
  ensure_image(triangle_texels, MOBIRT_DATA_WIDTH, rows, kRayFormat,
               VK_IMAGE_USAGE_SAMPLED_BIT | VK_IMAGE_USAGE_TRANSFER_DST_BIT);
  const VkBufferUsageFlags input =
      VK_BUFFER_USAGE_ACCELERATION_STRUCTURE_BUILD_INPUT_READ_ONLY_BIT_KHR | VK_BUFFER_USAGE_SHADER_DEVICE_ADDRESS_BIT;
  ensure_host(vertices, std::max<VkDeviceSize>(1, n) * 3 * sizeof(glm::vec3), input);
  if (n > 0) std::memcpy(vertices.mapped, positions.data(), positions.size() * sizeof(glm::vec3));
  ensure_host(instances, sizeof(VkAccelerationStructureInstanceKHR), input);
  const double upload_cpu_ms = ms_since(start);

  // The BLAS: one opaque triangle geometry, non-indexed, in Scene::mesh order (primitive index =
  // triangle index). Updated in place when the mode and the triangle count allow.
  VkAccelerationStructureGeometryKHR geometry{VK_STRUCTURE_TYPE_ACCELERATION_STRUCTURE_GEOMETRY_KHR};
  geometry.geometryType = VK_GEOMETRY_TYPE_TRIANGLES_KHR;
  geometry.flags = VK_GEOMETRY_OPAQUE_BIT_KHR;
  VkAccelerationStructureGeometryTrianglesDataKHR& tri = geometry.geometry.triangles;
  tri.sType = VK_STRUCTURE_TYPE_ACCELERATION_STRUCTURE_GEOMETRY_TRIANGLES_DATA_KHR;
  tri.vertexFormat = VK_FORMAT_R32G32B32_SFLOAT;
  tri.vertexData.deviceAddress = vertices.address;
  tri.vertexStride = sizeof(glm::vec3);
  tri.maxVertex = n > 0 ? 3 * n - 1 : 0;
  tri.indexType = VK_INDEX_TYPE_NONE_KHR;
  const bool update =
      mode == AsBuildMode::Update && blas.handle != VK_NULL_HANDLE && blas_updatable && blas_triangles == n;
  VkAccelerationStructureBuildGeometryInfoKHR blas_info{
      VK_STRUCTURE_TYPE_ACCELERATION_STRUCTURE_BUILD_GEOMETRY_INFO_KHR};
  blas_info.type = VK_ACCELERATION_STRUCTURE_TYPE_BOTTOM_LEVEL_KHR;
  blas_info.flags = VK_BUILD_ACCELERATION_STRUCTURE_PREFER_FAST_BUILD_BIT_KHR |
                    (mode == AsBuildMode::Update ? VK_BUILD_ACCELERATION_STRUCTURE_ALLOW_UPDATE_BIT_KHR : 0);
  blas_info.mode =
      update ? VK_BUILD_ACCELERATION_STRUCTURE_MODE_UPDATE_KHR : VK_BUILD_ACCELERATION_STRUCTURE_MODE_BUILD_KHR;
  blas_info.geometryCount = 1;
  blas_info.pGeometries = &geometry;
  VkAccelerationStructureBuildSizesInfoKHR blas_sizes{VK_STRUCTURE_TYPE_ACCELERATION_STRUCTURE_BUILD_SIZES_INFO_KHR};
  build_sizes(device, VK_ACCELERATION_STRUCTURE_BUILD_TYPE_DEVICE_KHR, &blas_info, &n, &blas_sizes);
  if (!update && n > 0) {
    // A fresh build: a new BLAS object when the old one is too small (its address changes).
    if (blas.handle == VK_NULL_HANDLE || blas_storage.size < blas_sizes.accelerationStructureSize) {
      create_as(blas, blas_storage, VK_ACCELERATION_STRUCTURE_TYPE_BOTTOM_LEVEL_KHR,
                blas_sizes.accelerationStructureSize);
    }
    blas_triangles = n;
    blas_updatable = mode == AsBuildMode::Update;
  }

  // The TLAS: the BLAS once, identity transform; none for an empty scene (every ray misses).
  VkAccelerationStructureInstanceKHR one{};
  one.transform.matrix[0][0] = one.transform.matrix[1][1] = one.transform.matrix[2][2] = 1.0f;
  one.mask = 0xFF;
  one.flags = VK_GEOMETRY_INSTANCE_TRIANGLE_FACING_CULL_DISABLE_BIT_KHR;
  one.accelerationStructureReference = blas.address;
  std::memcpy(instances.mapped, &one, sizeof(one));
  const uint32_t instance_count = n > 0 ? 1 : 0;
  VkAccelerationStructureGeometryKHR top{VK_STRUCTURE_TYPE_ACCELERATION_STRUCTURE_GEOMETRY_KHR};
  top.geometryType = VK_GEOMETRY_TYPE_INSTANCES_KHR;
  top.geometry.instances.sType = VK_STRUCTURE_TYPE_ACCELERATION_STRUCTURE_GEOMETRY_INSTANCES_DATA_KHR;
  top.geometry.instances.data.deviceAddress = instances.address;
  VkAccelerationStructureBuildGeometryInfoKHR tlas_info{
      VK_STRUCTURE_TYPE_ACCELERATION_STRUCTURE_BUILD_GEOMETRY_INFO_KHR};
  tlas_info.type = VK_ACCELERATION_STRUCTURE_TYPE_TOP_LEVEL_KHR;
  tlas_info.flags = VK_BUILD_ACCELERATION_STRUCTURE_PREFER_FAST_BUILD_BIT_KHR;
  tlas_info.mode = VK_BUILD_ACCELERATION_STRUCTURE_MODE_BUILD_KHR;
  tlas_info.geometryCount = 1;
  tlas_info.pGeometries = &top;
  VkAccelerationStructureBuildSizesInfoKHR tlas_sizes{VK_STRUCTURE_TYPE_ACCELERATION_STRUCTURE_BUILD_SIZES_INFO_KHR};
  const uint32_t max_instances = 1;  // sized for one instance, so an empty scene keeps the same TLAS
  build_sizes(device, VK_ACCELERATION_STRUCTURE_BUILD_TYPE_DEVICE_KHR, &tlas_info, &max_instances, &tlas_sizes);
  if (tlas.handle == VK_NULL_HANDLE) {
    create_as(tlas, tlas_storage, VK_ACCELERATION_STRUCTURE_TYPE_TOP_LEVEL_KHR, tlas_sizes.accelerationStructureSize);
  }

  const VkDeviceSize scratch_size =
      std::max({update ? blas_sizes.updateScratchSize : blas_sizes.buildScratchSize, tlas_sizes.buildScratchSize,
                VkDeviceSize(256)});
  const VkDeviceAddress scratch_at = scratch_address(scratch_size);
  blas_info.srcAccelerationStructure = update ? blas.handle : VK_NULL_HANDLE;
  blas_info.dstAccelerationStructure = blas.handle;
  blas_info.scratchData.deviceAddress = scratch_at;
  tlas_info.dstAccelerationStructure = tlas.handle;
  tlas_info.scratchData.deviceAddress = scratch_at;

  begin();
  if (queries) vkCmdWriteTimestamp(commands, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, queries.get(), 0);
  VkImageMemoryBarrier to_copy = image_barrier(triangle_texels.image.get(), VK_IMAGE_LAYOUT_UNDEFINED,
                                               VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, 0, VK_ACCESS_TRANSFER_WRITE_BIT);
  vkCmdPipelineBarrier(commands, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, VK_PIPELINE_STAGE_TRANSFER_BIT, 0, 0, nullptr, 0,
                       nullptr, 1, &to_copy);
  VkBufferImageCopy region{};
  region.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
  region.imageExtent = {MOBIRT_DATA_WIDTH, rows, 1};
  vkCmdCopyBufferToImage(commands, staging.buffer.get(), triangle_texels.image.get(),
                         VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, 1, &region);
  VkImageMemoryBarrier to_read =
      image_barrier(triangle_texels.image.get(), VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL,
                    VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL, VK_ACCESS_TRANSFER_WRITE_BIT, VK_ACCESS_SHADER_READ_BIT);
  vkCmdPipelineBarrier(commands, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_FRAGMENT_SHADER_BIT, 0, 0, nullptr,
                       0, nullptr, 1, &to_read);
  if (queries) vkCmdWriteTimestamp(commands, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, queries.get(), 1);
  VkMemoryBarrier built_barrier{VK_STRUCTURE_TYPE_MEMORY_BARRIER};  // BLAS (and scratch) before the TLAS build
  built_barrier.srcAccessMask = VK_ACCESS_ACCELERATION_STRUCTURE_WRITE_BIT_KHR;
  built_barrier.dstAccessMask =
      VK_ACCESS_ACCELERATION_STRUCTURE_READ_BIT_KHR | VK_ACCESS_ACCELERATION_STRUCTURE_WRITE_BIT_KHR;
  if (n > 0) {
    const VkAccelerationStructureBuildRangeInfoKHR range{n, 0, 0, 0};
    const VkAccelerationStructureBuildRangeInfoKHR* ranges = &range;
    cmd_build(commands, 1, &blas_info, &ranges);
    vkCmdPipelineBarrier(commands, VK_PIPELINE_STAGE_ACCELERATION_STRUCTURE_BUILD_BIT_KHR,
                         VK_PIPELINE_STAGE_ACCELERATION_STRUCTURE_BUILD_BIT_KHR, 0, 1, &built_barrier, 0, nullptr, 0,
                         nullptr);
  }
  if (queries) vkCmdWriteTimestamp(commands, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, queries.get(), 2);
  const VkAccelerationStructureBuildRangeInfoKHR top_range{instance_count, 0, 0, 0};
  const VkAccelerationStructureBuildRangeInfoKHR* top_ranges = &top_range;
  cmd_build(commands, 1, &tlas_info, &top_ranges);
  if (queries) vkCmdWriteTimestamp(commands, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, queries.get(), 3);
  submit_and_wait("the acceleration-structure build");
  const std::vector<double> ts = timestamps_ms();
  built = true;
  if (timings) {
    timings->upload_ms = upload_cpu_ms + ts[1];
    timings->blas_ms = ts[2] - ts[1];
    timings->tlas_ms = ts[3] - ts[2];
    timings->wall_ms = ms_since(start);
    timings->updated = update;
    timings->triangles = n;
  }
}

Packing RayQueryEngine::Impl::trace(const RayBatch& rays, std::span<const Light> lights, const ShadowSettings& shadows,
                                    std::span<uint32_t> out, RayQueryTimings* timings) {
  const auto start = Clock::now();
  if (!built) throw Error(ErrorKind::Internal, "RayQueryEngine::trace before build()");
  if (shadows.ray_test.precision == Precision::Medium) {
    throw Error(ErrorKind::Unsupported, "the ray-query peer traces in fp32 only: the driver's ray/triangle test has no "
                                        "mediump (drop --precision mediump)");
  }
  const uint32_t count = rays.count();
  if (out.size() < count) {
    throw Error(ErrorKind::Internal, "RayQueryEngine::trace: the output holds fewer texels than rays");
  }
  if (lights.size() > size_t(MOBIRT_MAX_LIGHTS)) {
    throw input_error(scene_name, std::to_string(lights.size()) + " lights: a pass casts shadow rays to at most " +
                                      std::to_string(MOBIRT_MAX_LIGHTS));
  }
  const Packing packing =
      choose_packing(triangles.triangles.size() / MOBIRT_TEXELS_PER_TRIANGLE, int(lights.size()), scene_name);
  if (timings) *timings = RayQueryTimings{};
  if (count == 0) return packing;
  if (rays.width == 0) throw Error(ErrorKind::Internal, "RayQueryEngine::trace: a ray batch of width 0");
  const uint32_t width = rays.width, rows = rays.rows();
  // Made on first use (the shader compiles then): outside the upload's time.
  const VkPipeline pass = pipeline(int(lights.size()), packing, shadows.offset.mode);
  const auto upload_start = Clock::now();

  // The rays into staging, the last row padded with rays of length 0 (valid, never hitting).
  const VkDeviceSize ray_bytes = VkDeviceSize(width) * rows * sizeof(glm::vec4);
  ensure_host(staging, 2 * ray_bytes, VK_BUFFER_USAGE_TRANSFER_SRC_BIT);
  char* at = static_cast<char*>(staging.mapped);
  for (const RayArray<glm::vec4>* v : {&rays.origin, &rays.direction}) {
    std::memcpy(at, v->data(), size_t(count) * sizeof(glm::vec4));
    std::memset(at + size_t(count) * sizeof(glm::vec4), 0, ray_bytes - size_t(count) * sizeof(glm::vec4));
    at += ray_bytes;
  }
  const VkImageUsageFlags sampled = VK_IMAGE_USAGE_SAMPLED_BIT | VK_IMAGE_USAGE_TRANSFER_DST_BIT;
  ensure_image(ray_origin, width, rows, kRayFormat, sampled);
  ensure_image(ray_direction, width, rows, kRayFormat, sampled);
  ensure_target(width, rows);
  ensure_host(readback, VkDeviceSize(width) * rows * 4, VK_BUFFER_USAGE_TRANSFER_DST_BIT);
  const std::vector<float> params = trace_uniforms(triangles, lights, shadows, int(lights.size()));
  std::memcpy(uniforms.mapped, params.data(),
              std::min(params.size() * sizeof(float), size_t(MOBIRT_MAX_PARAM_VEC4S * 16)));

  VkDescriptorBufferInfo ubo{uniforms.buffer.get(), 0, MOBIRT_MAX_PARAM_VEC4S * 16};
  VkWriteDescriptorSetAccelerationStructureKHR as_write{
      VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET_ACCELERATION_STRUCTURE_KHR};
  as_write.accelerationStructureCount = 1;
  as_write.pAccelerationStructures = &tlas.handle;
  const VkDescriptorImageInfo images[] = {
      {sampler.get(), triangle_texels.view.get(), VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL},
      {sampler.get(), ray_origin.view.get(), VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL},
      {sampler.get(), ray_direction.view.get(), VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL}};
  const uint32_t image_bindings[] = {MOBIRT_BIND_TRIANGLES, MOBIRT_BIND_RAY_ORIGIN, MOBIRT_BIND_RAY_DIRECTION};
  VkWriteDescriptorSet writes[5]{};
  for (VkWriteDescriptorSet& w : writes) {
    w.sType = VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET;
    w.dstSet = descriptor_set;
    w.descriptorCount = 1;
  }
  writes[0].dstBinding = MOBIRT_BIND_TRACE_PARAMS;
  writes[0].descriptorType = VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER;
  writes[0].pBufferInfo = &ubo;
  writes[1].pNext = &as_write;
  writes[1].dstBinding = MOBIRT_BIND_NODES;
  writes[1].descriptorType = VK_DESCRIPTOR_TYPE_ACCELERATION_STRUCTURE_KHR;
  for (int i = 0; i < 3; ++i) {
    writes[2 + i].dstBinding = image_bindings[i];
    writes[2 + i].descriptorType = VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER;
    writes[2 + i].pImageInfo = &images[i];
  }
  vkUpdateDescriptorSets(device, uint32_t(std::size(writes)), writes, 0, nullptr);
  const double upload_cpu_ms = ms_since(upload_start);

  begin();
  if (queries) vkCmdWriteTimestamp(commands, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, queries.get(), 0);
  VkImageMemoryBarrier to_copy[2], to_read[2];
  const Image2D* targets[2] = {&ray_origin, &ray_direction};
  for (int i = 0; i < 2; ++i) {
    const VkImage image = targets[i]->image.get();
    to_copy[i] = image_barrier(image, VK_IMAGE_LAYOUT_UNDEFINED, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, 0,
                               VK_ACCESS_TRANSFER_WRITE_BIT);
    to_read[i] = image_barrier(image, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL,
                               VK_ACCESS_TRANSFER_WRITE_BIT, VK_ACCESS_SHADER_READ_BIT);
  }
  vkCmdPipelineBarrier(commands, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, VK_PIPELINE_STAGE_TRANSFER_BIT, 0, 0, nullptr, 0,
                       nullptr, 2, to_copy);
  for (int i = 0; i < 2; ++i) {
    VkBufferImageCopy region{};
    region.bufferOffset = VkDeviceSize(i) * ray_bytes;
    region.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
    region.imageExtent = {width, rows, 1};
    vkCmdCopyBufferToImage(commands, staging.buffer.get(), targets[i]->image.get(),
                           VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, 1, &region);
  }
  vkCmdPipelineBarrier(commands, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_FRAGMENT_SHADER_BIT, 0, 0, nullptr,
                       0, nullptr, 2, to_read);
  if (queries) vkCmdWriteTimestamp(commands, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, queries.get(), 1);

  VkRenderPassBeginInfo rp{VK_STRUCTURE_TYPE_RENDER_PASS_BEGIN_INFO};
  rp.renderPass = render_pass.get();
  rp.framebuffer = framebuffer.get();
  rp.renderArea = {{0, 0}, {width, rows}};
  vkCmdBeginRenderPass(commands, &rp, VK_SUBPASS_CONTENTS_INLINE);
  vkCmdBindPipeline(commands, VK_PIPELINE_BIND_POINT_GRAPHICS, pass);
  const VkViewport viewport{0.0f, 0.0f, float(width), float(rows), 0.0f, 1.0f};
  const VkRect2D scissor{{0, 0}, {width, rows}};
  vkCmdSetViewport(commands, 0, 1, &viewport);
  vkCmdSetScissor(commands, 0, 1, &scissor);
  vkCmdBindDescriptorSets(commands, VK_PIPELINE_BIND_POINT_GRAPHICS, pipeline_layout.get(), 0, 1, &descriptor_set, 0,
                          nullptr);
  vkCmdDraw(commands, 3, 1, 0, 0);
  vkCmdEndRenderPass(commands);
  if (queries) vkCmdWriteTimestamp(commands, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, queries.get(), 2);

  VkBufferImageCopy region{};
  region.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
  region.imageExtent = {width, rows, 1};
  vkCmdCopyImageToBuffer(commands, target.image.get(), VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL, readback.buffer.get(), 1,
                         &region);
  VkBufferMemoryBarrier to_host{VK_STRUCTURE_TYPE_BUFFER_MEMORY_BARRIER};
  to_host.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
  to_host.dstAccessMask = VK_ACCESS_HOST_READ_BIT;
  to_host.srcQueueFamilyIndex = to_host.dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
  to_host.buffer = readback.buffer.get();
  to_host.size = VK_WHOLE_SIZE;
  vkCmdPipelineBarrier(commands, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_HOST_BIT, 0, 0, nullptr, 1, &to_host,
                       0, nullptr);
  if (queries) vkCmdWriteTimestamp(commands, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, queries.get(), 3);
  const auto submit_start = Clock::now();
  submit_and_wait("the ray-query pass");
  const double submit_ms = ms_since(submit_start);
  const auto copy_start = Clock::now();
  std::memcpy(out.data(), readback.mapped, size_t(count) * sizeof(uint32_t));
  const double copy_ms = ms_since(copy_start);
  if (timings) {
    const std::vector<double> ts = timestamps_ms();
    timings->upload_ms = upload_cpu_ms + ts[1];
    // Without timestamps the submission (the rays' copies, the pass, the read-back's copy) is the
    // pass, on the CPU's clock, as mobirt's passes are timed then.
    timings->trace_ms = queries ? ts[2] - ts[1] : submit_ms;
    timings->readback_ms = ts[3] - ts[2] + copy_ms;
    timings->wall_ms = ms_since(start);
    timings->rays = count;
    timings->bytes_read = uint64_t(count) * 4;
  }
  return packing;
}

// ---- The public face ---------------------------------------------------------------------------

RayQueryEngine::RayQueryEngine(const RayQueryOptions& options) : impl_(std::make_unique<Impl>(options)) {}
RayQueryEngine::~RayQueryEngine() = default;

std::vector<std::string> RayQueryEngine::info() const {
  const Impl& d = *impl_;
  std::vector<std::string> lines;
  lines.push_back("ray-query peer: " + std::string(d.properties.deviceName) + " (Vulkan " +
                  version_string(d.properties.apiVersion) + "), " + d.driver);
  lines.push_back(std::string("acceleration structures: one BLAS over the scene's triangles, a TLAS with one instance, "
                              "PREFER_FAST_BUILD, ") +
                  (d.mode == AsBuildMode::Update ? "updated (ALLOW_UPDATE, mode UPDATE) while the triangle count stays"
                                                 : "built afresh every frame"));
  for (const std::string& c : broken_constraints()) lines.push_back("breaks the OpenGL ES 2.0 constraints: " + c);
  return lines;
}

void RayQueryEngine::build(const Scene& scene, AsBuildTimings* timings) { impl_->build(scene, timings); }

Packing RayQueryEngine::trace(const RayBatch& rays, std::span<const Light> lights, const ShadowSettings& shadows,
                              std::span<uint32_t> out, RayQueryTimings* timings) {
  return impl_->trace(rays, lights, shadows, out, timings);
}

const FlatKdTree& RayQueryEngine::triangles() const { return impl_->triangles; }

std::vector<std::string> RayQueryEngine::take_debug_messages() {
  std::lock_guard lock(impl_->sink.mutex);
  return std::exchange(impl_->sink.messages, {});
}

std::vector<std::string> RayQueryEngine::broken_constraints() { return es2_constraints_broken(spirv_ray_query_frag); }

std::string RayQueryEngine::unavailable_reason(const RayQueryOptions& options) {
  try {
    RayQueryEngine probe(options);
    return "";
  } catch (const Error& e) {
    if (e.kind() == ErrorKind::Internal) throw;
    return e.what();
  }
}

}  // namespace mobirt
