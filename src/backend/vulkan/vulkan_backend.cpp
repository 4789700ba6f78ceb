// Headless Vulkan backend: lavapipe (or any Vulkan 1.1 device), one full-screen fragment pass per
// call, one RGBA8 texel per ray read back. Every pass is synchronous: record, submit, wait on a
// fence, read back; so objects can be reused across passes without further synchronisation.
#include "backend/vulkan/vulkan_backend.h"

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <mutex>
#include <span>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include <unistd.h>

#include "backend/backend.h"
#include "backend/shader_constraints.h"
#include "backend/vulkan/vk_util.h"
#include "core/error.h"
#include "layout.h"

// SPIR-V of the shaders, generated at build time from glsl/ (build/spirv/<name>.h).
#include "atlas_lookup.frag.h"
#include "copy_input.frag.h"
#include "fullscreen.vert.h"
#include "nine_textures.frag.h"
#include "numerics.frag.h"
#include "spin.frag.h"
#include "storage_write.frag.h"
#include "two_outputs.frag.h"
// The traversal and shading shaders are optional until glsl/trace.frag and glsl/shade.frag exist.
// Note: a header that appears later is not a dependency of this file's object yet; touch this file
// (or drop the guards) once those shaders are in the tree.
#if __has_include("trace.frag.h")
#include "trace.frag.h"
#define MOBIRT_HAVE_TRACE_FRAG 1
#endif
#if __has_include("shade.frag.h")
#include "shade.frag.h"
#define MOBIRT_HAVE_SHADE_FRAG 1
#endif

namespace mobirt {

long vulkan_live_objects() { return vk::live_object_counter().load(); }

namespace {

using Clock = std::chrono::steady_clock;

constexpr VkFormat kTargetFormat = VK_FORMAT_R8G8B8A8_UNORM;
constexpr size_t kStagingChunkBytes = size_t(16) << 20;  // uploads go through at most 16 MiB
constexpr uint32_t kTimestampCount = 3;

VkFormat vk_format(TexelFormat format) {
  switch (format) {
    case TexelFormat::RGBA32F: return VK_FORMAT_R32G32B32A32_SFLOAT;
    case TexelFormat::R32F: return VK_FORMAT_R32_SFLOAT;
    case TexelFormat::RGBA8: return VK_FORMAT_R8G8B8A8_UNORM;
  }
  throw Error(ErrorKind::Internal, "unknown texel format " + std::to_string(int(format)));
}

const char* format_name(TexelFormat format) {
  switch (format) {
    case TexelFormat::RGBA32F: return "RGBA32F";
    case TexelFormat::R32F: return "R32F";
    case TexelFormat::RGBA8: return "RGBA8";
  }
  return "unknown";
}

std::span<const uint32_t> shader_code(ShaderId id) {
  switch (id) {
    case ShaderId::Traverse:
#ifdef MOBIRT_HAVE_TRACE_FRAG
      return spirv_trace_frag;
#else
      break;
#endif
    case ShaderId::Shade:
#ifdef MOBIRT_HAVE_SHADE_FRAG
      return spirv_shade_frag;
#else
      break;
#endif
    case ShaderId::TestTwoOutputs: return spirv_two_outputs_frag;
    case ShaderId::TestStorageWrite: return spirv_storage_write_frag;
    case ShaderId::TestNineTextures: return spirv_nine_textures_frag;
    case ShaderId::TestCopyInput: return spirv_copy_input_frag;
    case ShaderId::TestSpin: return spirv_spin_frag;
    case ShaderId::TestAtlasLookup: return spirv_atlas_lookup_frag;
    case ShaderId::TestNumerics: return spirv_numerics_frag;
  }
  throw Error(ErrorKind::Internal, std::string("shader ") + shader_name(id) +
                                       " not built: its source is missing from glsl/ at build time");
}

std::string version_string(uint32_t version) {
  return std::to_string(VK_API_VERSION_MAJOR(version)) + "." + std::to_string(VK_API_VERSION_MINOR(version)) +
         "." + std::to_string(VK_API_VERSION_PATCH(version));
}

std::string lower(std::string s) {
  for (char& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

bool env_flag(const char* name) {
  const char* value = std::getenv(name);
  return value && *value && std::string(value) != "0";
}

double pass_timeout_seconds() {
  if (const char* value = std::getenv("MOBIRT_PASS_TIMEOUT_S")) {
    const double seconds = std::atof(value);
    if (seconds > 0.0) return seconds;
  }
  return 120.0;
}

// ---- Validation messages ---------------------------------------------------------------------

struct DebugSink {
  std::mutex mutex;
  std::vector<std::string> messages;
  std::vector<std::string> unreported_errors;  // ERROR messages no call has thrown for yet
};

VKAPI_ATTR VkBool32 VKAPI_CALL debug_callback(VkDebugUtilsMessageSeverityFlagBitsEXT severity,
                                              VkDebugUtilsMessageTypeFlagsEXT /*types*/,
                                              const VkDebugUtilsMessengerCallbackDataEXT* data,
                                              void* user) {
  const bool error = (severity & VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT) != 0;
  const bool warning = (severity & VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT) != 0;
  if (!error && !warning) return VK_FALSE;  // INFO and VERBOSE are ignored
  std::string text = error ? "validation error: " : "validation warning: ";
  if (data && data->pMessageIdName) text += std::string(data->pMessageIdName) + ": ";
  text += data && data->pMessage ? data->pMessage : "(no message)";
  auto* sink = static_cast<DebugSink*>(user);
  std::lock_guard lock(sink->mutex);
  sink->messages.push_back(text);
  if (error) sink->unreported_errors.push_back(text);
  return VK_FALSE;
}

// Prints the messages nobody took (those from destroying the device and instance included) when
// the backend goes away, so that leaks the validation layer reports at shutdown are not silent.
struct ShutdownReport {
  DebugSink* sink = nullptr;
  ~ShutdownReport() {
    std::lock_guard lock(sink->mutex);
    for (const std::string& message : sink->messages) std::fprintf(stderr, "mobirt: Vulkan %s\n", message.c_str());
  }
};

// ---- Instance and device owners --------------------------------------------------------------

struct InstanceOwner {
  VkInstance instance = VK_NULL_HANDLE;
  VkDebugUtilsMessengerEXT messenger = VK_NULL_HANDLE;
  InstanceOwner() = default;
  InstanceOwner(const InstanceOwner&) = delete;
  InstanceOwner& operator=(const InstanceOwner&) = delete;
  ~InstanceOwner() {
    if (messenger != VK_NULL_HANDLE) {
      auto destroy = reinterpret_cast<PFN_vkDestroyDebugUtilsMessengerEXT>(
          vkGetInstanceProcAddr(instance, "vkDestroyDebugUtilsMessengerEXT"));
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
    if (device != VK_NULL_HANDLE) vkDestroyDevice(device, nullptr);
  }
};

// ---- Resources -------------------------------------------------------------------------------

struct Texture {
  uint32_t width = 0, height = 0;
  TexelFormat format = TexelFormat::RGBA32F;
  VkImageLayout layout = VK_IMAGE_LAYOUT_UNDEFINED;
  vk::Memory memory;  // declared first: freed after the image and view
  vk::Image image;
  vk::ImageView view;
};

struct Pass {
  PassDesc desc;
  vk::DescriptorSetLayout set_layout;
  vk::PipelineLayout pipeline_layout;
  vk::Pipeline pipeline;
  vk::Memory uniform_memory;
  vk::Buffer uniform_buffer;
  float* uniforms = nullptr;  // persistently mapped, MOBIRT_MAX_PARAM_VEC4S vec4
  vk::DescriptorPool descriptor_pool;
  VkDescriptorSet descriptor_set = VK_NULL_HANDLE;  // freed with the pool
};

// Members are declared in creation order, so they are destroyed in reverse; reset() keeps that
// order too (a memberwise move assignment would free the memory before its buffer).
struct HostBuffer {
  VkDeviceSize size = 0;
  bool coherent = true;
  vk::Memory memory;
  vk::Buffer buffer;
  void* mapped = nullptr;  // persistently mapped; unmapped when the memory is freed

  void reset() {
    mapped = nullptr;
    buffer.reset();
    memory.reset();
    size = 0;
  }
};

struct RenderTarget {
  uint32_t width = 0, height = 0;
  vk::Memory memory;
  vk::Image image;
  vk::ImageView view;
  vk::Framebuffer framebuffer;

  void reset() {
    framebuffer.reset();
    view.reset();
    image.reset();
    memory.reset();
    width = height = 0;
  }
};

// ---- The backend's state ---------------------------------------------------------------------

class Impl {
 public:
  explicit Impl(const BackendOptions& options);
  void save_pipeline_cache();
  std::string pipeline_cache_file(const std::string& dir) const;
  std::vector<char> load_pipeline_cache(const std::string& dir);
  ~Impl();

  DeviceInfo device_info() const;
  TextureHandle create_texture(uint32_t width, uint32_t height, TexelFormat format);
  void upload(TextureHandle texture, const void* data, size_t bytes);
  void destroy(TextureHandle texture);
  PassHandle create_pass(const PassDesc& desc);
  void destroy(PassHandle pass);
  PassTiming run_pass(PassHandle pass, std::span<const TextureHandle> textures,
                      std::span<const float> uniforms, uint32_t width, uint32_t count,
                      std::span<uint32_t> out);
  std::vector<std::string> take_debug_messages();

  // After a fence timed out the device may still be executing: its objects must not be destroyed.
  bool hung() const { return hung_; }
  // Throws the first validation error that no call has reported yet.
  void throw_validation_errors();

 private:
  void create_instance(bool validation, bool sync_validation);
  void pick_physical_device(const std::string& wanted);
  void create_device();
  void create_shared_objects(const std::string& pipeline_cache_dir);

  void usable() const;
  VkResult device_result(VkResult result, const char* call);  // notes VK_ERROR_DEVICE_LOST
  uint32_t memory_type(uint32_t type_bits, VkMemoryPropertyFlags required,
                       VkMemoryPropertyFlags preferred, bool* coherent = nullptr) const;
  vk::Memory allocate(const VkMemoryRequirements& requirements, VkMemoryPropertyFlags required,
                      VkMemoryPropertyFlags preferred, bool* coherent = nullptr);
  HostBuffer create_host_buffer(VkDeviceSize size, VkBufferUsageFlags usage, bool prefer_cached);
  void ensure_staging(VkDeviceSize size);
  void ensure_readback(VkDeviceSize size);
  void ensure_target(uint32_t width, uint32_t height);
  void begin_commands();
  void submit_and_wait(const char* what);
  Texture& texture_ref(TextureHandle handle);
  Pass& pass_ref(PassHandle handle);

  DebugSink sink_;
  ShutdownReport shutdown_report_{&sink_};  // destroyed after the instance: sees its last messages
  InstanceOwner instance_;
  VkPhysicalDevice physical_ = VK_NULL_HANDLE;
  VkPhysicalDeviceProperties properties_{};
  VkPhysicalDeviceMemoryProperties memory_properties_{};
  std::string driver_;
  uint32_t queue_family_ = 0;
  uint32_t timestamp_bits_ = 0;
  DeviceOwner device_;
  VkDevice device = VK_NULL_HANDLE;  // device_.device, for brevity
  VkQueue queue_ = VK_NULL_HANDLE;

  vk::CommandPool command_pool_;
  VkCommandBuffer commands_ = VK_NULL_HANDLE;  // freed with the pool
  vk::Fence fence_;
  vk::QueryPool queries_;
  vk::Sampler sampler_;
  vk::RenderPass render_pass_;
  vk::ShaderModule vertex_shader_;
  vk::PipelineCache pipeline_cache_;
  std::string cache_file_;  // where the pipeline cache is saved, empty = nowhere
  HostBuffer staging_;
  HostBuffer readback_;
  RenderTarget target_;
  std::unordered_map<uint32_t, Texture> textures_;
  std::unordered_map<uint32_t, Pass> passes_;
  uint32_t next_texture_ = 1;
  uint32_t next_pass_ = 1;
  double pending_upload_ms_ = 0.0;
  double timeout_s_ = pass_timeout_seconds();
  bool lost_ = false;
  bool hung_ = false;
};

Impl::Impl(const BackendOptions& options) {
  create_instance(options.validation || options.sync_validation || env_flag("MOBIRT_VALIDATION"),
                  options.sync_validation);
  pick_physical_device(options.device);
  create_device();
  create_shared_objects(options.pipeline_cache_dir);
  throw_validation_errors();
}

Impl::~Impl() {
  if (device != VK_NULL_HANDLE && !hung_) vkDeviceWaitIdle(device);
  // Members go in reverse order: resources, shared objects, the device, then the instance.
}

void Impl::create_instance(bool validation, bool sync_validation) {
  uint32_t loader_version = VK_API_VERSION_1_0;
  if (vkEnumerateInstanceVersion(&loader_version) != VK_SUCCESS || loader_version < VK_API_VERSION_1_1) {
    throw Error(ErrorKind::NoDevice, "the Vulkan loader supports only Vulkan " + version_string(loader_version) +
                                         "; mobirt needs 1.1: update libvulkan1");
  }

  std::vector<const char*> layers, extensions;
  if (validation) {
    uint32_t count = 0;
    vk::check(vkEnumerateInstanceLayerProperties(&count, nullptr), "vkEnumerateInstanceLayerProperties");
    std::vector<VkLayerProperties> available(count);
    vk::check(vkEnumerateInstanceLayerProperties(&count, available.data()), "vkEnumerateInstanceLayerProperties");
    const bool found = std::any_of(available.begin(), available.end(), [](const VkLayerProperties& l) {
      return std::strcmp(l.layerName, "VK_LAYER_KHRONOS_validation") == 0;
    });
    if (!found) {
      throw Error(ErrorKind::Unsupported,
                  "validation was requested (--validation or MOBIRT_VALIDATION=1) but the layer "
                  "VK_LAYER_KHRONOS_validation is not installed: install vulkan-validationlayers");
    }
    layers.push_back("VK_LAYER_KHRONOS_validation");
    extensions.push_back(VK_EXT_DEBUG_UTILS_EXTENSION_NAME);
  }

  VkApplicationInfo app{VK_STRUCTURE_TYPE_APPLICATION_INFO};
  app.pApplicationName = "mobirt";
  app.applicationVersion = VK_MAKE_API_VERSION(0, 0, 1, 0);
  app.pEngineName = "mobirt";
  app.engineVersion = VK_MAKE_API_VERSION(0, 0, 1, 0);
  app.apiVersion = VK_API_VERSION_1_1;

  VkDebugUtilsMessengerCreateInfoEXT messenger_info{VK_STRUCTURE_TYPE_DEBUG_UTILS_MESSENGER_CREATE_INFO_EXT};
  messenger_info.messageSeverity =
      VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT;
  messenger_info.messageType = VK_DEBUG_UTILS_MESSAGE_TYPE_GENERAL_BIT_EXT |
                               VK_DEBUG_UTILS_MESSAGE_TYPE_VALIDATION_BIT_EXT |
                               VK_DEBUG_UTILS_MESSAGE_TYPE_PERFORMANCE_BIT_EXT;
  messenger_info.pfnUserCallback = debug_callback;
  messenger_info.pUserData = &sink_;

  VkInstanceCreateInfo info{VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO};
  info.pNext = validation ? &messenger_info : nullptr;  // also catches vkCreateInstance's messages
  const VkValidationFeatureEnableEXT sync_feature = VK_VALIDATION_FEATURE_ENABLE_SYNCHRONIZATION_VALIDATION_EXT;
  VkValidationFeaturesEXT features{VK_STRUCTURE_TYPE_VALIDATION_FEATURES_EXT};
  if (validation && sync_validation) {  // BackendOptions::sync_validation
    features.enabledValidationFeatureCount = 1;
    features.pEnabledValidationFeatures = &sync_feature;
    features.pNext = info.pNext;  // the messenger's create info stays unchained: it is reused below
    info.pNext = &features;
  }
  info.pApplicationInfo = &app;
  info.enabledLayerCount = uint32_t(layers.size());
  info.ppEnabledLayerNames = layers.data();
  info.enabledExtensionCount = uint32_t(extensions.size());
  info.ppEnabledExtensionNames = extensions.data();
  const VkResult result = vkCreateInstance(&info, nullptr, &instance_.instance);
  if (result == VK_ERROR_INCOMPATIBLE_DRIVER) {
    throw Error(ErrorKind::NoDevice,
                "no Vulkan device: install mesa-vulkan-drivers (lavapipe) or a GPU driver; check "
                "VK_ICD_FILENAMES (vkCreateInstance: VK_ERROR_INCOMPATIBLE_DRIVER)");
  }
  vk::check(result, "vkCreateInstance");

  if (validation) {
    auto create = reinterpret_cast<PFN_vkCreateDebugUtilsMessengerEXT>(
        vkGetInstanceProcAddr(instance_.instance, "vkCreateDebugUtilsMessengerEXT"));
    if (!create) throw Error(ErrorKind::Unsupported, "VK_EXT_debug_utils is missing: install vulkan-validationlayers");
    vk::check(create(instance_.instance, &messenger_info, nullptr, &instance_.messenger),
              "vkCreateDebugUtilsMessengerEXT");
  }
}

void Impl::pick_physical_device(const std::string& wanted) {
  uint32_t count = 0;
  VkResult result = vkEnumeratePhysicalDevices(instance_.instance, &count, nullptr);
  if (result == VK_ERROR_INITIALIZATION_FAILED || (result == VK_SUCCESS && count == 0)) {
    throw Error(ErrorKind::NoDevice,
                "no Vulkan device: install mesa-vulkan-drivers (lavapipe) or a GPU driver; check "
                "VK_ICD_FILENAMES");
  }
  vk::check(result, "vkEnumeratePhysicalDevices");
  std::vector<VkPhysicalDevice> devices(count);
  vk::check(vkEnumeratePhysicalDevices(instance_.instance, &count, devices.data()), "vkEnumeratePhysicalDevices");
  devices.resize(count);

  std::vector<VkPhysicalDeviceProperties> props(devices.size());
  std::string listing;
  for (size_t i = 0; i < devices.size(); ++i) {
    vkGetPhysicalDeviceProperties(devices[i], &props[i]);
    // One line, as every user-facing error: "0: llvmpipe (Vulkan 1.3.230); 1: ...".
    listing.append(i == 0 ? " " : "; ").append(std::to_string(i)).append(": ");
    listing.append(props[i].deviceName).append(" (Vulkan ").append(version_string(props[i].apiVersion)).append(")");
  }
  auto is_lavapipe = [&](size_t i) {
    return props[i].deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU ||
           lower(props[i].deviceName).find("llvmpipe") != std::string::npos;
  };

  size_t chosen = devices.size();
  if (wanted.empty()) {
    for (size_t i = 0; i < devices.size() && chosen == devices.size(); ++i) {
      if (is_lavapipe(i) && props[i].apiVersion >= VK_API_VERSION_1_1) chosen = i;
    }
    for (size_t i = 0; i < devices.size() && chosen == devices.size(); ++i) {
      if (props[i].apiVersion >= VK_API_VERSION_1_1) chosen = i;
    }
    if (chosen == devices.size()) chosen = 0;  // refused below with the reason
  } else {
    const bool numeric = std::all_of(wanted.begin(), wanted.end(), [](char c) { return std::isdigit(static_cast<unsigned char>(c)); });
    if (numeric) {
      const unsigned long index = std::strtoul(wanted.c_str(), nullptr, 10);
      if (index < devices.size()) chosen = size_t(index);
    } else {
      for (size_t i = 0; i < devices.size() && chosen == devices.size(); ++i) {
        if (lower(props[i].deviceName).find(lower(wanted)) != std::string::npos) chosen = i;
      }
    }
    if (chosen == devices.size()) {
      throw Error(ErrorKind::NoDevice, "no Vulkan device matches \"" + wanted +
                                           "\" (an index or part of a name); available devices:" + listing);
    }
  }

  physical_ = devices[chosen];
  properties_ = props[chosen];
  if (properties_.apiVersion < VK_API_VERSION_1_1) {
    throw Error(ErrorKind::Unsupported, std::string("Vulkan device ") + properties_.deviceName + " supports Vulkan " +
                                            version_string(properties_.apiVersion) + "; mobirt needs 1.1");
  }
  vkGetPhysicalDeviceMemoryProperties(physical_, &memory_properties_);

  // Driver name and version: VK_KHR_driver_properties (core in 1.2, but this instance is 1.1).
  uint32_t extension_count = 0;
  vk::check(vkEnumerateDeviceExtensionProperties(physical_, nullptr, &extension_count, nullptr),
            "vkEnumerateDeviceExtensionProperties");
  std::vector<VkExtensionProperties> extensions(extension_count);
  vk::check(vkEnumerateDeviceExtensionProperties(physical_, nullptr, &extension_count, extensions.data()),
            "vkEnumerateDeviceExtensionProperties");
  const bool has_driver_properties =
      std::any_of(extensions.begin(), extensions.end(), [](const VkExtensionProperties& e) {
        return std::strcmp(e.extensionName, VK_KHR_DRIVER_PROPERTIES_EXTENSION_NAME) == 0;
      });
  driver_ = "driver version " + std::to_string(properties_.driverVersion);
  if (has_driver_properties) {
    VkPhysicalDeviceDriverProperties driver{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_DRIVER_PROPERTIES};
    VkPhysicalDeviceProperties2 props2{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_PROPERTIES_2};
    props2.pNext = &driver;
    vkGetPhysicalDeviceProperties2(physical_, &props2);
    driver_ = std::string(driver.driverName) + " / " + driver.driverInfo;
  }

  // The queue: any family with graphics.
  uint32_t family_count = 0;
  vkGetPhysicalDeviceQueueFamilyProperties(physical_, &family_count, nullptr);
  std::vector<VkQueueFamilyProperties> families(family_count);
  vkGetPhysicalDeviceQueueFamilyProperties(physical_, &family_count, families.data());
  bool found = false;
  for (uint32_t i = 0; i < family_count && !found; ++i) {
    if (families[i].queueFlags & VK_QUEUE_GRAPHICS_BIT) {
      queue_family_ = i;
      timestamp_bits_ = families[i].timestampValidBits;
      found = true;
    }
  }
  if (!found) {
    throw Error(ErrorKind::Unsupported, std::string("Vulkan device ") + properties_.deviceName + " has no graphics queue");
  }

  // Formats mobirt cannot do without.
  struct Need { VkFormat format; VkFormatFeatureFlags features; const char* what; };
  const Need needs[] = {
      {VK_FORMAT_R32G32B32A32_SFLOAT, VK_FORMAT_FEATURE_SAMPLED_IMAGE_BIT | VK_FORMAT_FEATURE_TRANSFER_DST_BIT,
       "R32G32B32A32_SFLOAT sampled images"},
      {VK_FORMAT_R32_SFLOAT, VK_FORMAT_FEATURE_SAMPLED_IMAGE_BIT | VK_FORMAT_FEATURE_TRANSFER_DST_BIT,
       "R32_SFLOAT sampled images"},
      {VK_FORMAT_R8G8B8A8_UNORM, VK_FORMAT_FEATURE_SAMPLED_IMAGE_BIT | VK_FORMAT_FEATURE_TRANSFER_DST_BIT,
       "R8G8B8A8_UNORM sampled images"},
      {kTargetFormat, VK_FORMAT_FEATURE_COLOR_ATTACHMENT_BIT | VK_FORMAT_FEATURE_TRANSFER_SRC_BIT,
       "R8G8B8A8_UNORM colour attachments"},
  };
  for (const Need& need : needs) {
    VkFormatProperties format{};
    vkGetPhysicalDeviceFormatProperties(physical_, need.format, &format);
    if ((format.optimalTilingFeatures & need.features) != need.features) {
      throw Error(ErrorKind::Unsupported, std::string("Vulkan device ") + properties_.deviceName +
                                              " does not support " + need.what + " (optimal tiling)");
    }
  }
}

void Impl::create_device() {
  const float priority = 1.0f;
  VkDeviceQueueCreateInfo queue_info{VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO};
  queue_info.queueFamilyIndex = queue_family_;
  queue_info.queueCount = 1;
  queue_info.pQueuePriorities = &priority;
  VkDeviceCreateInfo info{VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO};
  info.queueCreateInfoCount = 1;
  info.pQueueCreateInfos = &queue_info;
  vk::check(vkCreateDevice(physical_, &info, nullptr, &device_.device), "vkCreateDevice");
  device = device_.device;
  vkGetDeviceQueue(device, queue_family_, 0, &queue_);
}

void Impl::create_shared_objects(const std::string& pipeline_cache_dir) {
  VkCommandPoolCreateInfo pool_info{VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO};
  pool_info.flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT;
  pool_info.queueFamilyIndex = queue_family_;
  VkCommandPool pool = VK_NULL_HANDLE;
  vk::check(vkCreateCommandPool(device, &pool_info, nullptr, &pool), "vkCreateCommandPool");
  command_pool_ = vk::CommandPool(device, pool);

  VkCommandBufferAllocateInfo alloc{VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO};
  alloc.commandPool = pool;
  alloc.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
  alloc.commandBufferCount = 1;
  vk::check(vkAllocateCommandBuffers(device, &alloc, &commands_), "vkAllocateCommandBuffers");

  VkFenceCreateInfo fence_info{VK_STRUCTURE_TYPE_FENCE_CREATE_INFO};
  VkFence fence = VK_NULL_HANDLE;
  vk::check(vkCreateFence(device, &fence_info, nullptr, &fence), "vkCreateFence");
  fence_ = vk::Fence(device, fence);

  if (timestamp_bits_ > 0) {
    VkQueryPoolCreateInfo query_info{VK_STRUCTURE_TYPE_QUERY_POOL_CREATE_INFO};
    query_info.queryType = VK_QUERY_TYPE_TIMESTAMP;
    query_info.queryCount = kTimestampCount;
    VkQueryPool query_pool = VK_NULL_HANDLE;
    vk::check(vkCreateQueryPool(device, &query_info, nullptr, &query_pool), "vkCreateQueryPool");
    queries_ = vk::QueryPool(device, query_pool);
  }

  // Shaders read texels with texelFetch: the sampler's filtering never applies, but a sampler is
  // part of a combined image sampler, so one immutable NEAREST / CLAMP_TO_EDGE sampler serves all.
  VkSamplerCreateInfo sampler_info{VK_STRUCTURE_TYPE_SAMPLER_CREATE_INFO};
  sampler_info.magFilter = VK_FILTER_NEAREST;
  sampler_info.minFilter = VK_FILTER_NEAREST;
  sampler_info.mipmapMode = VK_SAMPLER_MIPMAP_MODE_NEAREST;
  sampler_info.addressModeU = VK_SAMPLER_ADDRESS_MODE_CLAMP_TO_EDGE;
  sampler_info.addressModeV = VK_SAMPLER_ADDRESS_MODE_CLAMP_TO_EDGE;
  sampler_info.addressModeW = VK_SAMPLER_ADDRESS_MODE_CLAMP_TO_EDGE;
  sampler_info.maxLod = 0.0f;
  VkSampler sampler = VK_NULL_HANDLE;
  vk::check(vkCreateSampler(device, &sampler_info, nullptr, &sampler), "vkCreateSampler");
  sampler_ = vk::Sampler(device, sampler);

  // One render pass for every pipeline: one RGBA8 colour attachment, contents not loaded (every
  // texel of the render area is written), stored and left ready for the copy to the host.
  VkAttachmentDescription attachment{};
  attachment.format = kTargetFormat;
  attachment.samples = VK_SAMPLE_COUNT_1_BIT;
  attachment.loadOp = VK_ATTACHMENT_LOAD_OP_DONT_CARE;
  attachment.storeOp = VK_ATTACHMENT_STORE_OP_STORE;
  attachment.stencilLoadOp = VK_ATTACHMENT_LOAD_OP_DONT_CARE;
  attachment.stencilStoreOp = VK_ATTACHMENT_STORE_OP_DONT_CARE;
  attachment.initialLayout = VK_IMAGE_LAYOUT_UNDEFINED;
  attachment.finalLayout = VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL;
  VkAttachmentReference color{0, VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL};
  VkSubpassDescription subpass{};
  subpass.pipelineBindPoint = VK_PIPELINE_BIND_POINT_GRAPHICS;
  subpass.colorAttachmentCount = 1;
  subpass.pColorAttachments = &color;
  VkSubpassDependency dependencies[2]{};
  // The previous pass's copy read the image before this pass overwrites it (write after read).
  dependencies[0].srcSubpass = VK_SUBPASS_EXTERNAL;
  dependencies[0].dstSubpass = 0;
  dependencies[0].srcStageMask = VK_PIPELINE_STAGE_TRANSFER_BIT;
  dependencies[0].dstStageMask = VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT;
  dependencies[0].srcAccessMask = 0;
  dependencies[0].dstAccessMask = VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT;
  // The copy to the read-back buffer reads what the pass wrote.
  dependencies[1].srcSubpass = 0;
  dependencies[1].dstSubpass = VK_SUBPASS_EXTERNAL;
  dependencies[1].srcStageMask = VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT;
  dependencies[1].dstStageMask = VK_PIPELINE_STAGE_TRANSFER_BIT;
  dependencies[1].srcAccessMask = VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT;
  dependencies[1].dstAccessMask = VK_ACCESS_TRANSFER_READ_BIT;
  VkRenderPassCreateInfo render_pass_info{VK_STRUCTURE_TYPE_RENDER_PASS_CREATE_INFO};
  render_pass_info.attachmentCount = 1;
  render_pass_info.pAttachments = &attachment;
  render_pass_info.subpassCount = 1;
  render_pass_info.pSubpasses = &subpass;
  render_pass_info.dependencyCount = 2;
  render_pass_info.pDependencies = dependencies;
  VkRenderPass render_pass = VK_NULL_HANDLE;
  vk::check(vkCreateRenderPass(device, &render_pass_info, nullptr, &render_pass), "vkCreateRenderPass");
  render_pass_ = vk::RenderPass(device, render_pass);

  VkShaderModuleCreateInfo module_info{VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO};
  module_info.codeSize = sizeof(spirv_fullscreen_vert);
  module_info.pCode = spirv_fullscreen_vert;
  VkShaderModule module = VK_NULL_HANDLE;
  vk::check(vkCreateShaderModule(device, &module_info, nullptr, &module), "vkCreateShaderModule");
  vertex_shader_ = vk::ShaderModule(device, module);

  VkPipelineCacheCreateInfo cache_info{VK_STRUCTURE_TYPE_PIPELINE_CACHE_CREATE_INFO};
  const std::vector<char> cached = load_pipeline_cache(pipeline_cache_dir);
  cache_info.initialDataSize = cached.size();
  cache_info.pInitialData = cached.empty() ? nullptr : cached.data();
  VkPipelineCache cache = VK_NULL_HANDLE;
  vk::check(vkCreatePipelineCache(device, &cache_info, nullptr, &cache), "vkCreatePipelineCache");
  pipeline_cache_ = vk::PipelineCache(device, cache);
}

// ---- Pipeline cache on disk ------------------------------------------------------------------

std::string Impl::pipeline_cache_file(const std::string& dir) const {
  if (dir.empty()) return {};
  std::string name = "pipelines-";
  char hex[3];
  for (uint8_t byte : properties_.pipelineCacheUUID) {
    std::snprintf(hex, sizeof(hex), "%02x", byte);
    name.append(hex);
  }
  return (std::filesystem::path(dir) / name.append(".bin")).string();
}

std::vector<char> Impl::load_pipeline_cache(const std::string& dir) {
  cache_file_ = pipeline_cache_file(dir);
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
  if (header.headerVersion != VK_PIPELINE_CACHE_HEADER_VERSION_ONE || header.vendorID != properties_.vendorID ||
      header.deviceID != properties_.deviceID ||
      std::memcmp(header.pipelineCacheUUID, properties_.pipelineCacheUUID, VK_UUID_SIZE) != 0) {
    return {};
  }
  return data;
}

void Impl::save_pipeline_cache() {
  if (cache_file_.empty() || !pipeline_cache_.get()) return;
  size_t size = 0;
  if (vkGetPipelineCacheData(device, pipeline_cache_.get(), &size, nullptr) != VK_SUCCESS || size == 0) return;
  std::vector<char> data(size);
  if (vkGetPipelineCacheData(device, pipeline_cache_.get(), &size, data.data()) != VK_SUCCESS) return;
  // Written whole or not at all: a temporary file renamed into place. A cache is an optimisation,
  // so a folder that cannot be written only costs the next run its compile time.
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

void Impl::throw_validation_errors() {
  std::string first;
  size_t count = 0;
  {
    std::lock_guard lock(sink_.mutex);
    if (sink_.unreported_errors.empty()) return;
    first = sink_.unreported_errors.front();
    count = sink_.unreported_errors.size();
    sink_.unreported_errors.clear();
  }
  throw Error(ErrorKind::Internal, std::to_string(count) + " Vulkan validation error(s), the first: " + first);
}

uint32_t Impl::memory_type(uint32_t type_bits, VkMemoryPropertyFlags required,
                           VkMemoryPropertyFlags preferred, bool* coherent) const {
  for (const VkMemoryPropertyFlags wanted : {required | preferred, required}) {
    for (uint32_t i = 0; i < memory_properties_.memoryTypeCount; ++i) {
      const VkMemoryPropertyFlags flags = memory_properties_.memoryTypes[i].propertyFlags;
      if ((type_bits & (1u << i)) && (flags & wanted) == wanted) {
        if (coherent) *coherent = (flags & VK_MEMORY_PROPERTY_HOST_COHERENT_BIT) != 0;
        return i;
      }
    }
  }
  throw Error(ErrorKind::Unsupported, "the Vulkan device has no memory type with the properties mobirt needs");
}

vk::Memory Impl::allocate(const VkMemoryRequirements& requirements, VkMemoryPropertyFlags required,
                          VkMemoryPropertyFlags preferred, bool* coherent) {
  VkMemoryAllocateInfo info{VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO};
  info.allocationSize = requirements.size;
  info.memoryTypeIndex = memory_type(requirements.memoryTypeBits, required, preferred, coherent);
  VkDeviceMemory memory = VK_NULL_HANDLE;
  vk::check(vkAllocateMemory(device, &info, nullptr, &memory), "vkAllocateMemory");
  return vk::Memory(device, memory);
}

HostBuffer Impl::create_host_buffer(VkDeviceSize size, VkBufferUsageFlags usage, bool prefer_cached) {
  HostBuffer result;
  result.size = size;
  VkBufferCreateInfo info{VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO};
  info.size = size;
  info.usage = usage;
  info.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
  VkBuffer buffer = VK_NULL_HANDLE;
  vk::check(vkCreateBuffer(device, &info, nullptr, &buffer), "vkCreateBuffer");
  result.buffer = vk::Buffer(device, buffer);
  VkMemoryRequirements requirements{};
  vkGetBufferMemoryRequirements(device, buffer, &requirements);
  result.memory = allocate(requirements, VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT,
                           prefer_cached ? VK_MEMORY_PROPERTY_HOST_CACHED_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT
                                         : VK_MEMORY_PROPERTY_HOST_COHERENT_BIT,
                           &result.coherent);
  vk::check(vkBindBufferMemory(device, buffer, result.memory.get(), 0), "vkBindBufferMemory");
  vk::check(vkMapMemory(device, result.memory.get(), 0, VK_WHOLE_SIZE, 0, &result.mapped), "vkMapMemory");
  return result;
}

void Impl::ensure_staging(VkDeviceSize size) {
  if (staging_.size >= size) return;
  staging_.reset();
  staging_ = create_host_buffer(std::max(size, VkDeviceSize(1) << 20), VK_BUFFER_USAGE_TRANSFER_SRC_BIT, false);
}

void Impl::ensure_readback(VkDeviceSize size) {
  if (readback_.size >= size) return;
  readback_.reset();
  readback_ = create_host_buffer(size, VK_BUFFER_USAGE_TRANSFER_DST_BIT, true);
}

void Impl::ensure_target(uint32_t width, uint32_t height) {
  if (target_.width >= width && target_.height >= height) return;
  const uint32_t w = std::max(width, target_.width), h = std::max(height, target_.height);
  target_.reset();

  VkImageCreateInfo info{VK_STRUCTURE_TYPE_IMAGE_CREATE_INFO};
  info.imageType = VK_IMAGE_TYPE_2D;
  info.format = kTargetFormat;
  info.extent = {w, h, 1};
  info.mipLevels = 1;
  info.arrayLayers = 1;
  info.samples = VK_SAMPLE_COUNT_1_BIT;
  info.tiling = VK_IMAGE_TILING_OPTIMAL;
  info.usage = VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT | VK_IMAGE_USAGE_TRANSFER_SRC_BIT;
  info.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
  info.initialLayout = VK_IMAGE_LAYOUT_UNDEFINED;
  VkImage image = VK_NULL_HANDLE;
  vk::check(vkCreateImage(device, &info, nullptr, &image), "vkCreateImage");
  RenderTarget target;
  target.image = vk::Image(device, image);
  VkMemoryRequirements requirements{};
  vkGetImageMemoryRequirements(device, image, &requirements);
  target.memory = allocate(requirements, 0, VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT);
  vk::check(vkBindImageMemory(device, image, target.memory.get(), 0), "vkBindImageMemory");

  VkImageViewCreateInfo view_info{VK_STRUCTURE_TYPE_IMAGE_VIEW_CREATE_INFO};
  view_info.image = image;
  view_info.viewType = VK_IMAGE_VIEW_TYPE_2D;
  view_info.format = kTargetFormat;
  view_info.subresourceRange = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 1, 0, 1};
  VkImageView view = VK_NULL_HANDLE;
  vk::check(vkCreateImageView(device, &view_info, nullptr, &view), "vkCreateImageView");
  target.view = vk::ImageView(device, view);

  VkFramebufferCreateInfo framebuffer_info{VK_STRUCTURE_TYPE_FRAMEBUFFER_CREATE_INFO};
  framebuffer_info.renderPass = render_pass_.get();
  framebuffer_info.attachmentCount = 1;
  framebuffer_info.pAttachments = &view;
  framebuffer_info.width = w;
  framebuffer_info.height = h;
  framebuffer_info.layers = 1;
  VkFramebuffer framebuffer = VK_NULL_HANDLE;
  vk::check(vkCreateFramebuffer(device, &framebuffer_info, nullptr, &framebuffer), "vkCreateFramebuffer");
  target.framebuffer = vk::Framebuffer(device, framebuffer);
  target.width = w;
  target.height = h;
  target_ = std::move(target);
}

void Impl::begin_commands() {
  vk::check(vkResetCommandBuffer(commands_, 0), "vkResetCommandBuffer");
  VkCommandBufferBeginInfo begin{VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
  begin.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
  vk::check(vkBeginCommandBuffer(commands_, &begin), "vkBeginCommandBuffer");
}

void Impl::submit_and_wait(const char* what) {
  vk::check(vkEndCommandBuffer(commands_), "vkEndCommandBuffer");
  VkSubmitInfo submit{VK_STRUCTURE_TYPE_SUBMIT_INFO};
  submit.commandBufferCount = 1;
  submit.pCommandBuffers = &commands_;
  VkFence fence = fence_.get();
  vk::check(device_result(vkQueueSubmit(queue_, 1, &submit, fence), "vkQueueSubmit"), "vkQueueSubmit");
  const uint64_t timeout_ns = uint64_t(timeout_s_ * 1e9);
  const VkResult result = device_result(vkWaitForFences(device, 1, &fence, VK_TRUE, timeout_ns), "vkWaitForFences");
  if (result == VK_TIMEOUT) {
    hung_ = true;
    char seconds[32];
    std::snprintf(seconds, sizeof(seconds), "%g", timeout_s_);
    throw Error(ErrorKind::Internal,
                std::string("GPU pass did not finish within ") + seconds + " s (" + what +
                    "): a shader loop without a working cap? The device is still busy, so the backend is "
                    "unusable (MOBIRT_PASS_TIMEOUT_S sets the limit)");
  }
  vk::check(result, "vkWaitForFences");
  vk::check(vkResetFences(device, 1, &fence), "vkResetFences");
}

Texture& Impl::texture_ref(TextureHandle handle) {
  const auto it = textures_.find(handle.id);
  if (it == textures_.end()) throw Error(ErrorKind::Internal, "unknown texture handle " + std::to_string(handle.id));
  return it->second;
}

Pass& Impl::pass_ref(PassHandle handle) {
  const auto it = passes_.find(handle.id);
  if (it == passes_.end()) throw Error(ErrorKind::Internal, "unknown pass handle " + std::to_string(handle.id));
  return it->second;
}

// ---- Backend operations ----------------------------------------------------------------------

DeviceInfo Impl::device_info() const {
  DeviceInfo info;
  info.api = "Vulkan " + version_string(properties_.apiVersion);
  info.device = properties_.deviceName;
  info.driver = driver_;
  info.is_software = properties_.deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU;
  const VkPhysicalDeviceLimits& l = properties_.limits;
  auto add = [&](const char* name, const std::string& value) { info.limits.push_back(std::string(name) + ": " + value); };
  add("maxImageDimension2D", std::to_string(l.maxImageDimension2D));
  add("maxPerStageDescriptorSampledImages", std::to_string(l.maxPerStageDescriptorSampledImages));
  add("maxPerStageDescriptorSamplers", std::to_string(l.maxPerStageDescriptorSamplers));
  add("maxFragmentOutputAttachments", std::to_string(l.maxFragmentOutputAttachments));
  add("maxColorAttachments", std::to_string(l.maxColorAttachments));
  add("maxUniformBufferRange", std::to_string(l.maxUniformBufferRange));
  add("maxMemoryAllocationCount", std::to_string(l.maxMemoryAllocationCount));
  add("timestampPeriod", std::to_string(l.timestampPeriod) + " ns");
  add("timestampComputeAndGraphics", l.timestampComputeAndGraphics ? "true" : "false");
  add("timestampValidBits", std::to_string(timestamp_bits_));
  return info;
}

TextureHandle Impl::create_texture(uint32_t width, uint32_t height, TexelFormat format) {
  usable();
  if (width == 0 || height == 0) {
    throw Error(ErrorKind::Internal, "create_texture: empty texture " + std::to_string(width) + "x" + std::to_string(height));
  }
  const uint32_t limit = properties_.limits.maxImageDimension2D;
  if (width > limit || height > limit) {
    throw Error(ErrorKind::BadInput, "a " + std::to_string(width) + "x" + std::to_string(height) + " " +
                                         format_name(format) + " texture exceeds the device's maxImageDimension2D (" +
                                         std::to_string(limit) + "): the scene is too large for this device");
  }
  Texture texture;
  texture.width = width;
  texture.height = height;
  texture.format = format;

  VkImageCreateInfo info{VK_STRUCTURE_TYPE_IMAGE_CREATE_INFO};
  info.imageType = VK_IMAGE_TYPE_2D;
  info.format = vk_format(format);
  info.extent = {width, height, 1};
  info.mipLevels = 1;
  info.arrayLayers = 1;
  info.samples = VK_SAMPLE_COUNT_1_BIT;
  info.tiling = VK_IMAGE_TILING_OPTIMAL;
  info.usage = VK_IMAGE_USAGE_SAMPLED_BIT | VK_IMAGE_USAGE_TRANSFER_DST_BIT;
  info.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
  info.initialLayout = VK_IMAGE_LAYOUT_UNDEFINED;
  VkImage image = VK_NULL_HANDLE;
  vk::check(vkCreateImage(device, &info, nullptr, &image), "vkCreateImage");
  texture.image = vk::Image(device, image);
  VkMemoryRequirements requirements{};
  vkGetImageMemoryRequirements(device, image, &requirements);
  texture.memory = allocate(requirements, 0, VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT);
  vk::check(vkBindImageMemory(device, image, texture.memory.get(), 0), "vkBindImageMemory");

  VkImageViewCreateInfo view_info{VK_STRUCTURE_TYPE_IMAGE_VIEW_CREATE_INFO};
  view_info.image = image;
  view_info.viewType = VK_IMAGE_VIEW_TYPE_2D;
  view_info.format = info.format;
  view_info.subresourceRange = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 1, 0, 1};
  VkImageView view = VK_NULL_HANDLE;
  vk::check(vkCreateImageView(device, &view_info, nullptr, &view), "vkCreateImageView");
  texture.view = vk::ImageView(device, view);

  throw_validation_errors();
  const uint32_t id = next_texture_++;
  textures_.emplace(id, std::move(texture));
  return TextureHandle{id};
}

void Impl::upload(TextureHandle handle, const void* data, size_t bytes) {
  usable();
  Texture& texture = texture_ref(handle);
  const size_t texel = texel_bytes(texture.format);
  const size_t row_bytes = size_t(texture.width) * texel;
  const size_t total = row_bytes * texture.height;
  if (bytes > total) {
    throw Error(ErrorKind::Internal, "upload of " + std::to_string(bytes) + " bytes into a " + std::to_string(texture.width) +
                                         "x" + std::to_string(texture.height) + " " + format_name(texture.format) +
                                         " texture of " + std::to_string(total) + " bytes");
  }
  if (bytes % texel != 0) {
    throw Error(ErrorKind::Internal, "upload of " + std::to_string(bytes) + " bytes: not a whole number of " +
                                         format_name(texture.format) + " texels");
  }
  if (bytes == 0) return;
  if (!data) throw Error(ErrorKind::Internal, "upload: no data");
  const auto start = Clock::now();

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
    std::memcpy(staging_.mapped, static_cast<const char*>(data) + row * row_bytes, chunk_bytes);
    if (!staging_.coherent) {
      VkMappedMemoryRange range{VK_STRUCTURE_TYPE_MAPPED_MEMORY_RANGE};
      range.memory = staging_.memory.get();
      range.size = VK_WHOLE_SIZE;
      vk::check(vkFlushMappedMemoryRanges(device, 1, &range), "vkFlushMappedMemoryRanges");
    }

    begin_commands();
    VkImageMemoryBarrier barrier{VK_STRUCTURE_TYPE_IMAGE_MEMORY_BARRIER};
    barrier.srcAccessMask = 0;  // earlier reads finished: every submission is waited for
    barrier.dstAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
    barrier.oldLayout = texture.layout;
    barrier.newLayout = VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL;
    barrier.srcQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
    barrier.dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
    barrier.image = texture.image.get();
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
    vkCmdCopyBufferToImage(commands_, staging_.buffer.get(), texture.image.get(), VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL,
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
  pending_upload_ms_ += elapsed_ms(start);
  throw_validation_errors();
}

void Impl::destroy(TextureHandle handle) {
  if (hung_) return;  // the device may still read it
  textures_.erase(handle.id);
}

PassHandle Impl::create_pass(const PassDesc& desc) {
  // The OpenGL ES 2.0 constraints come first: a pass that breaks one is refused before any
  // Vulkan object exists.
  const std::span<const uint32_t> code = shader_code(desc.shader);
  const std::string name = shader_name(desc.shader);
  check_es2_constraints(name, code);
  usable();

  if (desc.texture_bindings.size() > MOBIRT_MAX_SAMPLED_TEXTURES) {
    throw Error(ErrorKind::Constraint, "pass " + name + " binds " + std::to_string(desc.texture_bindings.size()) +
                                           " textures; at most " + std::to_string(MOBIRT_MAX_SAMPLED_TEXTURES) +
                                           " are allowed (GL_MAX_TEXTURE_IMAGE_UNITS)");
  }
  if (desc.uniform_vec4s > MOBIRT_MAX_PARAM_VEC4S) {
    throw Error(ErrorKind::Internal, "pass " + name + " asks for " + std::to_string(desc.uniform_vec4s) +
                                         " uniform vec4; at most " + std::to_string(MOBIRT_MAX_PARAM_VEC4S));
  }
  std::unordered_set<uint32_t> used;
  if (desc.uniform_vec4s > 0) used.insert(MOBIRT_BIND_TRACE_PARAMS);
  for (const uint32_t binding : desc.texture_bindings) {
    if (!used.insert(binding).second) {
      throw Error(ErrorKind::Internal, "pass " + name + ": binding " + std::to_string(binding) +
                                           " is used twice (binding 0 is the uniform block)");
    }
  }
  std::unordered_set<uint32_t> constant_ids;
  for (const Specialization& s : desc.specialization) {
    if (!constant_ids.insert(s.id).second) {
      throw Error(ErrorKind::Internal, "pass " + name + ": specialization constant " + std::to_string(s.id) + " is set twice");
    }
  }

  Pass pass;
  pass.desc = desc;

  // Descriptor set layout: the uniform block, then one combined image sampler per texture.
  const VkSampler immutable_sampler = sampler_.get();
  std::vector<VkDescriptorSetLayoutBinding> bindings;
  if (desc.uniform_vec4s > 0) {
    bindings.push_back({MOBIRT_BIND_TRACE_PARAMS, VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER, 1, VK_SHADER_STAGE_FRAGMENT_BIT, nullptr});
  }
  for (const uint32_t binding : desc.texture_bindings) {
    bindings.push_back({binding, VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER, 1, VK_SHADER_STAGE_FRAGMENT_BIT,
                        &immutable_sampler});
  }
  VkDescriptorSetLayoutCreateInfo set_info{VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO};
  set_info.bindingCount = uint32_t(bindings.size());
  set_info.pBindings = bindings.data();
  VkDescriptorSetLayout set_layout = VK_NULL_HANDLE;
  vk::check(vkCreateDescriptorSetLayout(device, &set_info, nullptr, &set_layout), "vkCreateDescriptorSetLayout");
  pass.set_layout = vk::DescriptorSetLayout(device, set_layout);

  VkPipelineLayoutCreateInfo layout_info{VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO};
  layout_info.setLayoutCount = 1;
  layout_info.pSetLayouts = &set_layout;
  VkPipelineLayout pipeline_layout = VK_NULL_HANDLE;
  vk::check(vkCreatePipelineLayout(device, &layout_info, nullptr, &pipeline_layout), "vkCreatePipelineLayout");
  pass.pipeline_layout = vk::PipelineLayout(device, pipeline_layout);

  // The uniform block: always the full MOBIRT_MAX_PARAM_VEC4S array the shaders declare.
  if (desc.uniform_vec4s > 0) {
    HostBuffer ubo = create_host_buffer(VkDeviceSize(MOBIRT_MAX_PARAM_VEC4S) * 16, VK_BUFFER_USAGE_UNIFORM_BUFFER_BIT, false);
    if (!ubo.coherent) throw Error(ErrorKind::Unsupported, "the Vulkan device has no host-coherent memory for uniforms");
    pass.uniforms = static_cast<float*>(ubo.mapped);
    std::memset(pass.uniforms, 0, size_t(MOBIRT_MAX_PARAM_VEC4S) * 16);
    pass.uniform_memory = std::move(ubo.memory);
    pass.uniform_buffer = std::move(ubo.buffer);
  }

  if (!bindings.empty()) {
    std::vector<VkDescriptorPoolSize> sizes;
    if (desc.uniform_vec4s > 0) sizes.push_back({VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER, 1});
    if (!desc.texture_bindings.empty()) {
      sizes.push_back({VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER, uint32_t(desc.texture_bindings.size())});
    }
    VkDescriptorPoolCreateInfo pool_info{VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO};
    pool_info.maxSets = 1;
    pool_info.poolSizeCount = uint32_t(sizes.size());
    pool_info.pPoolSizes = sizes.data();
    VkDescriptorPool pool = VK_NULL_HANDLE;
    vk::check(vkCreateDescriptorPool(device, &pool_info, nullptr, &pool), "vkCreateDescriptorPool");
    pass.descriptor_pool = vk::DescriptorPool(device, pool);
    VkDescriptorSetAllocateInfo alloc{VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO};
    alloc.descriptorPool = pool;
    alloc.descriptorSetCount = 1;
    alloc.pSetLayouts = &set_layout;
    vk::check(vkAllocateDescriptorSets(device, &alloc, &pass.descriptor_set), "vkAllocateDescriptorSets");
    if (desc.uniform_vec4s > 0) {
      VkDescriptorBufferInfo buffer_info{pass.uniform_buffer.get(), 0, VK_WHOLE_SIZE};
      VkWriteDescriptorSet write{VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET};
      write.dstSet = pass.descriptor_set;
      write.dstBinding = MOBIRT_BIND_TRACE_PARAMS;
      write.descriptorCount = 1;
      write.descriptorType = VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER;
      write.pBufferInfo = &buffer_info;
      vkUpdateDescriptorSets(device, 1, &write, 0, nullptr);
    }
  }

  // The pipeline: a full-screen triangle, the specialised fragment shader, dynamic viewport.
  VkShaderModuleCreateInfo module_info{VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO};
  module_info.codeSize = code.size_bytes();
  module_info.pCode = code.data();
  VkShaderModule module_handle = VK_NULL_HANDLE;
  vk::check(vkCreateShaderModule(device, &module_info, nullptr, &module_handle), "vkCreateShaderModule");
  const vk::ShaderModule fragment_module(device, module_handle);  // only needed until the pipeline exists

  std::vector<VkSpecializationMapEntry> entries;
  std::vector<int32_t> values;
  for (const Specialization& s : desc.specialization) {
    entries.push_back({s.id, uint32_t(values.size() * sizeof(int32_t)), sizeof(int32_t)});
    values.push_back(s.value);
  }
  VkSpecializationInfo specialization{uint32_t(entries.size()), entries.data(), values.size() * sizeof(int32_t),
                                      values.data()};

  VkPipelineShaderStageCreateInfo stages[2]{};
  stages[0].sType = VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO;
  stages[0].stage = VK_SHADER_STAGE_VERTEX_BIT;
  stages[0].module = vertex_shader_.get();
  stages[0].pName = "main";
  stages[1].sType = VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO;
  stages[1].stage = VK_SHADER_STAGE_FRAGMENT_BIT;
  stages[1].module = fragment_module.get();
  stages[1].pName = "main";
  stages[1].pSpecializationInfo = entries.empty() ? nullptr : &specialization;

  VkPipelineVertexInputStateCreateInfo vertex_input{VK_STRUCTURE_TYPE_PIPELINE_VERTEX_INPUT_STATE_CREATE_INFO};
  VkPipelineInputAssemblyStateCreateInfo assembly{VK_STRUCTURE_TYPE_PIPELINE_INPUT_ASSEMBLY_STATE_CREATE_INFO};
  assembly.topology = VK_PRIMITIVE_TOPOLOGY_TRIANGLE_LIST;
  VkPipelineViewportStateCreateInfo viewport{VK_STRUCTURE_TYPE_PIPELINE_VIEWPORT_STATE_CREATE_INFO};
  viewport.viewportCount = 1;
  viewport.scissorCount = 1;
  VkPipelineRasterizationStateCreateInfo raster{VK_STRUCTURE_TYPE_PIPELINE_RASTERIZATION_STATE_CREATE_INFO};
  raster.polygonMode = VK_POLYGON_MODE_FILL;
  raster.cullMode = VK_CULL_MODE_NONE;
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
  pipeline_info.pVertexInputState = &vertex_input;
  pipeline_info.pInputAssemblyState = &assembly;
  pipeline_info.pViewportState = &viewport;
  pipeline_info.pRasterizationState = &raster;
  pipeline_info.pMultisampleState = &multisample;
  pipeline_info.pColorBlendState = &blend;
  pipeline_info.pDynamicState = &dynamic;
  pipeline_info.layout = pipeline_layout;
  pipeline_info.renderPass = render_pass_.get();
  pipeline_info.subpass = 0;
  VkPipeline pipeline = VK_NULL_HANDLE;
  vk::check(vkCreateGraphicsPipelines(device, pipeline_cache_.get(), 1, &pipeline_info, nullptr, &pipeline),
            "vkCreateGraphicsPipelines");
  pass.pipeline = vk::Pipeline(device, pipeline);

  throw_validation_errors();  // before the pass is kept: a refused pass frees its objects
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
  Pass& pass = pass_ref(handle);
  const std::string name = shader_name(pass.desc.shader);
  PassTiming timing;
  timing.upload_ms = pending_upload_ms_;

  check_run_pass_arguments(pass.desc, textures.size(), uniforms.size(), width, count, out.size());
  std::vector<Texture*> bound;
  for (const TextureHandle t : textures) bound.push_back(&texture_ref(t));
  if (count == 0) {
    pending_upload_ms_ = 0.0;
    timing.wall_ms = elapsed_ms(wall_start);
    return timing;
  }
  const uint32_t height = (count + width - 1) / width;
  const uint32_t limit = properties_.limits.maxImageDimension2D;
  if (width > limit || height > limit) {
    throw Error(ErrorKind::BadInput, "pass " + name + ": " + std::to_string(count) + " rays in rows of " +
                                         std::to_string(width) + " need a " + std::to_string(width) + "x" +
                                         std::to_string(height) + " target, beyond maxImageDimension2D (" +
                                         std::to_string(limit) + ")");
  }
  ensure_target(width, height);
  ensure_readback(VkDeviceSize(width) * height * 4);

  // Uniforms and textures. Every earlier submission has finished, so the set is free to update.
  if (pass.uniforms) {
    std::memcpy(pass.uniforms, uniforms.data(), uniforms.size_bytes());
    std::memset(pass.uniforms + uniforms.size(), 0, size_t(MOBIRT_MAX_PARAM_VEC4S) * 16 - uniforms.size_bytes());
  }
  if (!bound.empty()) {
    std::vector<VkDescriptorImageInfo> image_infos(bound.size());
    std::vector<VkWriteDescriptorSet> writes(bound.size());
    for (size_t i = 0; i < bound.size(); ++i) {
      image_infos[i] = {VK_NULL_HANDLE, bound[i]->view.get(), VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL};
      writes[i] = {VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET};
      writes[i].dstSet = pass.descriptor_set;
      writes[i].dstBinding = pass.desc.texture_bindings[i];
      writes[i].descriptorCount = 1;
      writes[i].descriptorType = VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER;
      writes[i].pImageInfo = &image_infos[i];
    }
    vkUpdateDescriptorSets(device, uint32_t(writes.size()), writes.data(), 0, nullptr);
  }

  begin_commands();
  const bool timed = bool(queries_);
  if (timed) vkCmdResetQueryPool(commands_, queries_.get(), 0, kTimestampCount);
  // A texture never uploaded still needs its layout (its contents are undefined).
  std::vector<VkImageMemoryBarrier> first_use;
  for (Texture* t : bound) {
    if (t->layout != VK_IMAGE_LAYOUT_UNDEFINED) continue;
    VkImageMemoryBarrier barrier{VK_STRUCTURE_TYPE_IMAGE_MEMORY_BARRIER};
    barrier.dstAccessMask = VK_ACCESS_SHADER_READ_BIT;
    barrier.oldLayout = VK_IMAGE_LAYOUT_UNDEFINED;
    barrier.newLayout = VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL;
    barrier.srcQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
    barrier.dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
    barrier.image = t->image.get();
    barrier.subresourceRange = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 1, 0, 1};
    first_use.push_back(barrier);
    t->layout = VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL;
  }
  if (!first_use.empty()) {
    vkCmdPipelineBarrier(commands_, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, VK_PIPELINE_STAGE_FRAGMENT_SHADER_BIT, 0, 0,
                         nullptr, 0, nullptr, uint32_t(first_use.size()), first_use.data());
  }
  if (timed) vkCmdWriteTimestamp(commands_, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, queries_.get(), 0);

  VkRenderPassBeginInfo begin{VK_STRUCTURE_TYPE_RENDER_PASS_BEGIN_INFO};
  begin.renderPass = render_pass_.get();
  begin.framebuffer = target_.framebuffer.get();
  begin.renderArea = {{0, 0}, {width, height}};
  vkCmdBeginRenderPass(commands_, &begin, VK_SUBPASS_CONTENTS_INLINE);
  vkCmdBindPipeline(commands_, VK_PIPELINE_BIND_POINT_GRAPHICS, pass.pipeline.get());
  if (pass.descriptor_set != VK_NULL_HANDLE) {
    vkCmdBindDescriptorSets(commands_, VK_PIPELINE_BIND_POINT_GRAPHICS, pass.pipeline_layout.get(), 0, 1,
                            &pass.descriptor_set, 0, nullptr);
  }
  const VkViewport viewport{0.0f, 0.0f, float(width), float(height), 0.0f, 1.0f};
  const VkRect2D scissor{{0, 0}, {width, height}};
  vkCmdSetViewport(commands_, 0, 1, &viewport);
  vkCmdSetScissor(commands_, 0, 1, &scissor);
  vkCmdDraw(commands_, 3, 1, 0, 0);
  vkCmdEndRenderPass(commands_);
  if (timed) vkCmdWriteTimestamp(commands_, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, queries_.get(), 1);

  VkBufferImageCopy region{};
  region.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
  region.imageExtent = {width, height, 1};
  vkCmdCopyImageToBuffer(commands_, target_.image.get(), VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL, readback_.buffer.get(), 1,
                         &region);
  VkBufferMemoryBarrier to_host{VK_STRUCTURE_TYPE_BUFFER_MEMORY_BARRIER};
  to_host.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
  to_host.dstAccessMask = VK_ACCESS_HOST_READ_BIT;
  to_host.srcQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
  to_host.dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
  to_host.buffer = readback_.buffer.get();
  to_host.size = VK_WHOLE_SIZE;
  vkCmdPipelineBarrier(commands_, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_HOST_BIT, 0, 0, nullptr, 1, &to_host,
                       0, nullptr);
  if (timed) vkCmdWriteTimestamp(commands_, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, queries_.get(), 2);

  const auto gpu_start = Clock::now();
  submit_and_wait(name.c_str());
  const double submit_ms = elapsed_ms(gpu_start);

  const auto copy_start = Clock::now();
  if (!readback_.coherent) {
    VkMappedMemoryRange range{VK_STRUCTURE_TYPE_MAPPED_MEMORY_RANGE};
    range.memory = readback_.memory.get();
    range.size = VK_WHOLE_SIZE;
    vk::check(vkInvalidateMappedMemoryRanges(device, 1, &range), "vkInvalidateMappedMemoryRanges");
  }
  std::memcpy(out.data(), readback_.mapped, size_t(count) * 4);
  const double copy_ms = elapsed_ms(copy_start);

  if (timed) {
    uint64_t stamps[kTimestampCount] = {};
    vk::check(device_result(vkGetQueryPoolResults(device, queries_.get(), 0, kTimestampCount, sizeof(stamps), stamps,
                                                  sizeof(uint64_t), VK_QUERY_RESULT_64_BIT | VK_QUERY_RESULT_WAIT_BIT),
                            "vkGetQueryPoolResults"),
              "vkGetQueryPoolResults");
    const uint64_t mask = timestamp_bits_ >= 64 ? ~uint64_t(0) : (uint64_t(1) << timestamp_bits_) - 1;
    const double period_ms = double(properties_.limits.timestampPeriod) * 1e-6;
    timing.gpu_ms = double((stamps[1] - stamps[0]) & mask) * period_ms;
    timing.readback_ms = double((stamps[2] - stamps[1]) & mask) * period_ms + copy_ms;
  } else {
    timing.gpu_ms = submit_ms;  // no timestamps: the whole submission on the CPU clock
    timing.readback_ms = copy_ms;
  }
  timing.bytes_read = uint64_t(count) * 4;
  pending_upload_ms_ = 0.0;
  timing.wall_ms = elapsed_ms(wall_start);
  throw_validation_errors();
  return timing;
}

std::vector<std::string> Impl::take_debug_messages() {
  std::lock_guard lock(sink_.mutex);
  std::vector<std::string> result;
  result.swap(sink_.messages);
  sink_.unreported_errors.clear();
  return result;
}

// ---- The Backend --------------------------------------------------------------------------------

class VulkanBackend final : public Backend {
 public:
  explicit VulkanBackend(const BackendOptions& options) : impl_(std::make_unique<Impl>(options)) {}
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
  void upload(TextureHandle texture, const void* data, size_t bytes) override { impl_->upload(texture, data, bytes); }
  void destroy(TextureHandle texture) override { impl_->destroy(texture); }
  PassHandle create_pass(const PassDesc& desc) override { return impl_->create_pass(desc); }
  void destroy(PassHandle pass) override { impl_->destroy(pass); }
  PassTiming run_pass(PassHandle pass, std::span<const TextureHandle> textures, std::span<const float> uniforms,
                      uint32_t width, uint32_t count, std::span<uint32_t> out) override {
    return impl_->run_pass(pass, textures, uniforms, width, count, out);
  }
  std::vector<std::string> take_debug_messages() override { return impl_->take_debug_messages(); }

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace

std::unique_ptr<Backend> create_vulkan_backend(const BackendOptions& options) {
  return std::make_unique<VulkanBackend>(options);
}

}  // namespace mobirt
