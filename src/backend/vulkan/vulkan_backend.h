// The Vulkan backend's own settings and diagnostics beyond backend.h.
#pragma once

#include <memory>
#include <string>

#include "backend/backend.h"

namespace mobirt {

// BackendOptions plus what only Vulkan has.
struct VulkanOptions : BackendOptions {
  bool sync_validation = false;  // with validation: also the layer's synchronization validation
  // A folder where the pipeline cache is kept between runs (one file per device and driver, named
  // by the cache UUID), so that a known scene's first frame does not compile again. Empty: no cache
  // on disk.
  std::string pipeline_cache_dir;
  // Data textures as optimally tiled images filled through a staging buffer and a copy command,
  // the path of a device without host-mapped linear images that sample as optimal ones do; off:
  // linear images written in place where the device has them (lavapipe). Tests compare the two.
  bool staged_images = false;
};

std::unique_ptr<Backend> create_vulkan_backend(const VulkanOptions& options);

// Vulkan objects (images, buffers, memory, pipelines, ...) currently owned by every Vulkan backend
// of this process; returns to its earlier value when textures and passes are destroyed.
long vulkan_live_objects();

}  // namespace mobirt
