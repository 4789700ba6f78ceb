#include <cstdlib>
#include <string>

#include "app/commands.h"
#include "app/options.h"

namespace mobirt {

std::string default_pipeline_cache_dir() {
  if (const char* dir = std::getenv("MOBIRT_PIPELINE_CACHE")) return std::string(dir) == "off" ? "" : dir;
  if (const char* xdg = std::getenv("XDG_CACHE_HOME"); xdg && *xdg) return std::string(xdg) + "/mobirt";
  if (const char* home = std::getenv("HOME"); home && *home) return std::string(home) + "/.cache/mobirt";
  return "";
}

std::unique_ptr<Backend> create_backend(const std::string& name, const VulkanOptions& options,
                                        const std::string& help) {
  if (name == "gles") return create_gles_backend(options);
  if (name == "vulkan") return create_vulkan_backend(options);
  cli::usage_error("--backend " + name + ": expected gles or vulkan", help);
}

std::unique_ptr<Backend> create_backend(const std::string& name, const BackendOptions& options,
                                        const std::string& help) {
  return create_backend(name, VulkanOptions{options}, help);
}

}  // namespace mobirt
