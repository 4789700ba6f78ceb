#include "backend/vulkan/vk_device.h"

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "backend/vulkan/vk_util.h"
#include "core/error.h"

namespace mobirt::vk {

namespace {

std::string lower(std::string s) {
  for (char& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

bool env_flag(const char* name) {
  const char* value = std::getenv(name);
  return value && *value && std::string(value) != "0";
}

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


}  // namespace

std::string version_string(uint32_t version) {
  return std::to_string(VK_API_VERSION_MAJOR(version)) + "." + std::to_string(VK_API_VERSION_MINOR(version)) +
         "." + std::to_string(VK_API_VERSION_PATCH(version));
}

ShutdownReport::~ShutdownReport() {
  std::lock_guard lock(sink->mutex);
  for (const std::string& message : sink->messages) std::fprintf(stderr, "mobirt: Vulkan %s\n", message.c_str());
}

InstanceOwner::~InstanceOwner() {
  if (messenger != VK_NULL_HANDLE) {
    auto destroy = reinterpret_cast<PFN_vkDestroyDebugUtilsMessengerEXT>(
        vkGetInstanceProcAddr(instance, "vkDestroyDebugUtilsMessengerEXT"));
    if (destroy) destroy(instance, messenger, nullptr);
  }
  if (instance != VK_NULL_HANDLE) vkDestroyInstance(instance, nullptr);
}

DeviceOwner::~DeviceOwner() {
  if (device != VK_NULL_HANDLE) vkDestroyDevice(device, nullptr);
}

Device::Device(const VulkanOptions& options) {
  create_instance(options.validation || options.sync_validation || env_flag("MOBIRT_VALIDATION"),
                  options.sync_validation);
  pick_physical_device(options.device);
  create_device();
  gpu_timestamps_ = takes_gpu_timestamps(options.timestamps, timestamp_bits_,
                                         properties_.deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU);
}

void Device::create_instance(bool validation, bool sync_validation) {
  uint32_t loader_version = VK_API_VERSION_1_0;
  if (vkEnumerateInstanceVersion(&loader_version) != VK_SUCCESS || loader_version < VK_API_VERSION_1_1) {
    throw Error(ErrorKind::NoDevice, "the Vulkan loader supports only Vulkan " + version_string(loader_version) +
                                         "; mobirt needs 1.1: update libvulkan1");
  }

  std::vector<const char*> layers, extensions;
  if (validation) {
    uint32_t count = 0;
    VK_CHECK(vkEnumerateInstanceLayerProperties(&count, nullptr));
    std::vector<VkLayerProperties> available(count);
    VK_CHECK(vkEnumerateInstanceLayerProperties(&count, available.data()));
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
  if (validation && sync_validation) {  // VulkanOptions::sync_validation
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
  VK_CHECK_RESULT(result, "vkCreateInstance");

  if (validation) {
    auto create = reinterpret_cast<PFN_vkCreateDebugUtilsMessengerEXT>(
        vkGetInstanceProcAddr(instance_.instance, "vkCreateDebugUtilsMessengerEXT"));
    if (!create) throw Error(ErrorKind::Unsupported, "VK_EXT_debug_utils is missing: install vulkan-validationlayers");
    VK_CHECK_RESULT(create(instance_.instance, &messenger_info, nullptr, &instance_.messenger),
                           "vkCreateDebugUtilsMessengerEXT");
  }
}

void Device::pick_physical_device(const std::string& wanted) {
  uint32_t count = 0;
  VkResult result = vkEnumeratePhysicalDevices(instance_.instance, &count, nullptr);
  if (result == VK_ERROR_INITIALIZATION_FAILED || (result == VK_SUCCESS && count == 0)) {
    throw Error(ErrorKind::NoDevice,
                "no Vulkan device: install mesa-vulkan-drivers (lavapipe) or a GPU driver; check "
                "VK_ICD_FILENAMES");
  }
  VK_CHECK_RESULT(result, "vkEnumeratePhysicalDevices");
  std::vector<VkPhysicalDevice> devices(count);
  VK_CHECK(vkEnumeratePhysicalDevices(instance_.instance, &count, devices.data()));
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
  VK_CHECK(vkEnumerateDeviceExtensionProperties(physical_, nullptr, &extension_count, nullptr));
  std::vector<VkExtensionProperties> extensions(extension_count);
  VK_CHECK(vkEnumerateDeviceExtensionProperties(physical_, nullptr, &extension_count, extensions.data()));
  auto has_extension = [&](const char* name) {
    return std::any_of(extensions.begin(), extensions.end(),
                       [&](const VkExtensionProperties& e) { return std::strcmp(e.extensionName, name) == 0; });
  };
  // What a ray-query engine needs (lavapipe has both from Mesa 25, neither in 22.3).
  ray_query_ = has_extension(VK_KHR_RAY_QUERY_EXTENSION_NAME) &&
               has_extension(VK_KHR_ACCELERATION_STRUCTURE_EXTENSION_NAME);
  // Buffer device addresses, for --data device-addresses (a measurement variant outside the ES 2.0
  // model: llvmpipe reads through a pointer with an inline gather, where every texel fetch is a call).
  if (has_extension(VK_KHR_BUFFER_DEVICE_ADDRESS_EXTENSION_NAME)) {
    VkPhysicalDeviceBufferDeviceAddressFeaturesKHR address{
        VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_BUFFER_DEVICE_ADDRESS_FEATURES_KHR};
    VkPhysicalDeviceFeatures2 features{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_FEATURES_2};
    features.pNext = &address;
    vkGetPhysicalDeviceFeatures2(physical_, &features);
    device_addresses_ = address.bufferDeviceAddress == VK_TRUE;
  }
  driver_ = "driver version " + std::to_string(properties_.driverVersion);
  driver_version_ = std::to_string(properties_.driverVersion);
  if (has_extension(VK_KHR_DRIVER_PROPERTIES_EXTENSION_NAME)) {
    VkPhysicalDeviceDriverProperties driver{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_DRIVER_PROPERTIES};
    VkPhysicalDeviceProperties2 props2{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_PROPERTIES_2};
    props2.pNext = &driver;
    vkGetPhysicalDeviceProperties2(physical_, &props2);
    driver_ = std::string(driver.driverName) + " / " + driver.driverInfo;
    const std::string mesa = mesa_version(driver.driverInfo);  // "Mesa 25.0.7 (LLVM 15.0.6)"
    driver_version_ = mesa.empty() ? std::string(driver.driverInfo) : mesa;
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
      {VK_FORMAT_R8G8B8A8_SRGB,
       VK_FORMAT_FEATURE_SAMPLED_IMAGE_BIT | VK_FORMAT_FEATURE_SAMPLED_IMAGE_FILTER_LINEAR_BIT |
           VK_FORMAT_FEATURE_TRANSFER_DST_BIT,
       "R8G8B8A8_SRGB sampled images with linear filtering (the atlas pages)"},
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

void Device::create_device() {
  const float priority = 1.0f;
  VkDeviceQueueCreateInfo queue_info{VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO};
  queue_info.queueFamilyIndex = queue_family_;
  queue_info.queueCount = 1;
  queue_info.pQueuePriorities = &priority;
  VkDeviceCreateInfo info{VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO};
  info.queueCreateInfoCount = 1;
  info.pQueueCreateInfos = &queue_info;
  VkPhysicalDeviceBufferDeviceAddressFeaturesKHR address{
      VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_BUFFER_DEVICE_ADDRESS_FEATURES_KHR};
  const char* address_extension = VK_KHR_BUFFER_DEVICE_ADDRESS_EXTENSION_NAME;
  if (device_addresses_) {
    address.bufferDeviceAddress = VK_TRUE;
    info.pNext = &address;
    info.enabledExtensionCount = 1;
    info.ppEnabledExtensionNames = &address_extension;
  }
  VK_CHECK(vkCreateDevice(physical_, &info, nullptr, &device_.device));
  vkGetDeviceQueue(device_.device, queue_family_, 0, &queue_);
  if (device_addresses_) {
    get_buffer_address_ = reinterpret_cast<PFN_vkGetBufferDeviceAddressKHR>(
        vkGetDeviceProcAddr(device_.device, "vkGetBufferDeviceAddressKHR"));
    if (!get_buffer_address_) device_addresses_ = false;
  }
}

VkDeviceAddress Device::buffer_address(VkBuffer buffer) const {
  if (!device_addresses_) throw Error(ErrorKind::Internal, "buffer_address: the device has no buffer device addresses");
  VkBufferDeviceAddressInfoKHR info{VK_STRUCTURE_TYPE_BUFFER_DEVICE_ADDRESS_INFO_KHR};
  info.buffer = buffer;
  return get_buffer_address_(device_.device, &info);
}

void Device::throw_validation_errors() {
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

std::vector<std::string> Device::take_debug_messages() {
  std::lock_guard lock(sink_.mutex);
  std::vector<std::string> result;
  result.swap(sink_.messages);
  sink_.unreported_errors.clear();
  return result;
}

DeviceInfo Device::info() const {
  DeviceInfo info;
  info.api = "Vulkan " + version_string(properties_.apiVersion);
  info.device = properties_.deviceName;
  info.driver = driver_;
  info.driver_version = driver_version_;
  info.ray_query = ray_query_;
  info.texel_buffers = true;  // uniform texel buffers of RGBA32F and R32F are core Vulkan 1.0
  info.device_addresses = device_addresses_;
  info.storage_buffers = true;  // and storage buffers, read from a fragment shader
  info.srgb_textures = true;    // R8G8B8A8_SRGB, checked with linear filtering at device creation
  info.is_software = properties_.deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU;
  info.gpu_timestamps = gpu_timestamps_;
  const VkPhysicalDeviceLimits& l = properties_.limits;
  auto add = [&](const char* name, const std::string& value) { info.limits.push_back(std::string(name) + ": " + value); };
  add("maxImageDimension2D", std::to_string(l.maxImageDimension2D));
  add("maxTexelBufferElements", std::to_string(l.maxTexelBufferElements));
  add("maxPerStageDescriptorSampledImages", std::to_string(l.maxPerStageDescriptorSampledImages));
  add("maxPerStageDescriptorSamplers", std::to_string(l.maxPerStageDescriptorSamplers));
  add("maxFragmentOutputAttachments", std::to_string(l.maxFragmentOutputAttachments));
  add("maxColorAttachments", std::to_string(l.maxColorAttachments));
  add("maxUniformBufferRange", std::to_string(l.maxUniformBufferRange));
  add("maxMemoryAllocationCount", std::to_string(l.maxMemoryAllocationCount));
  add("timestampPeriod", std::to_string(l.timestampPeriod) + " ns");
  add("timestampComputeAndGraphics", l.timestampComputeAndGraphics ? "true" : "false");
  add("timestampValidBits", std::to_string(timestamp_bits_));
  add("bufferDeviceAddress", device_addresses_ ? "true (--data device-addresses)" : "false");
  return info;
}

}  // namespace mobirt::vk
