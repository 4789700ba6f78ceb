#include <cstdlib>
#include <string>

#include "app/commands.h"
#include "app/options.h"
#include "backend/driver_threads.h"

namespace mobirt {

std::string default_pipeline_cache_dir() {
  if (const char* dir = std::getenv("MOBIRT_PIPELINE_CACHE")) return std::string(dir) == "off" ? "" : dir;
  if (const char* xdg = std::getenv("XDG_CACHE_HOME"); xdg && *xdg) return std::string(xdg) + "/mobirt";
  if (const char* home = std::getenv("HOME"); home && *home) return std::string(home) + "/.cache/mobirt";
  return "";
}

std::unique_ptr<Backend> create_backend(const std::string& name, const VulkanOptions& options,
                                        const std::string& help) {
  std::unique_ptr<Backend> backend;
  if (name == "gles") {
    backend = create_gles_backend(options);
  } else if (name == "vulkan") {
    backend = create_vulkan_backend(options);
  } else {
    cli::usage_error("--backend " + name + ": expected gles or vulkan", help);
  }
  pin_driver_threads(options);
  return backend;
}

int pin_driver_threads(const BackendOptions& options) { return options.pin_threads ? pin_driver_threads() : 0; }

std::unique_ptr<Backend> create_backend(const std::string& name, const BackendOptions& options,
                                        const std::string& help) {
  return create_backend(name, VulkanOptions{options}, help);
}

}  // namespace mobirt
