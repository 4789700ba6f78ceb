// The commands of the mobirt command line that live outside main.cpp. Each takes the arguments
// after the command's name and returns the exit code; errors are thrown as mobirt::Error.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "backend/backend.h"
#include "backend/vulkan/vulkan_backend.h"

namespace mobirt {

// Where compiled pipelines are kept between runs: $MOBIRT_PIPELINE_CACHE ("off" for none), else
// $XDG_CACHE_HOME/mobirt, else ~/.cache/mobirt.
std::string default_pipeline_cache_dir();

// --backend gles|vulkan: the API the passes run on; `help` names where the option is described.
// GLES takes the common part of the options; without VulkanOptions, Vulkan gets its defaults.
std::unique_ptr<Backend> create_backend(const std::string& name, const VulkanOptions& options,
                                        const std::string& help = "mobirt --help");
std::unique_ptr<Backend> create_backend(const std::string& name, const BackendOptions& options,
                                        const std::string& help = "mobirt --help");
// --pin-threads: pin_driver_threads() (backend/driver_threads.h) unless options.pin_threads is off;
// create_backend calls it, and a command that makes other devices too calls it after them.
// Returns how many threads it pinned.
int pin_driver_threads(const BackendOptions& options);

// mobirt render SCENE -o OUT [options]: one frame or a sequence of frames to image files.
int cmd_render(const std::vector<std::string>& args);

// Writes `text` to `path` whole or not at all (a temporary file beside it, renamed over it); false
// when it could not be written, and then nothing is left behind.
bool write_text_file(const std::string& path, const std::string& text);

// SIGINT and SIGTERM end the process at once, except during an image write (render.cpp), which
// completes first: no half-written or temporary file is ever left behind.
void install_interrupt_handlers();

// mobirt bench [SCENE...] [options]: the paper's Table 1 with the Embree baseline beside it.
int cmd_bench(const std::vector<std::string>& args);

// mobirt accuracy SCENE [render options] [--json FILE] [--heatmap FILE.png]: the GPU renderer
// against the double-precision reference tracer (src/reference/).
int cmd_accuracy(const std::vector<std::string>& args);

}  // namespace mobirt
