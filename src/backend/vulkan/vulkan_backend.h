// Vulkan-specific extras beyond backend.h: diagnostics that tests use.
#pragma once

namespace mobirt {

// Vulkan objects (images, buffers, memory, pipelines, ...) currently owned by every Vulkan backend
// of this process; returns to its earlier value when textures and passes are destroyed.
long vulkan_live_objects();

}  // namespace mobirt
