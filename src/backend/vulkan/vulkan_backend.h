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
  // and the passes' output rendered into an optimal image copied to a read-back buffer: the path
  // of a device without host-mapped linear images that sample (or are rendered into) as optimal
  // ones do; off: linear images written and read in place where the device has them (lavapipe).
  // Tests compare the two.
  bool staged_images = false;
};

std::unique_ptr<Backend> create_vulkan_backend(const VulkanOptions& options);

// Vulkan objects (images, buffers, memory, pipelines, ...) currently owned by every Vulkan backend
// of this process; returns to its earlier value when textures and passes are destroyed.
long vulkan_live_objects();

// Whether `backend` is a Vulkan backend whose current render target (made by its first pass that
// renders anything, made anew when a pass outgrows it) is a linear image in host-cached memory that
// the host reads in place (the default where the device has one, as lavapipe does), rather than an
// optimal image copied to a read-back buffer (staged_images, other devices). False before a pass.
bool vulkan_reads_target_in_place(const Backend& backend);

}  // namespace mobirt
