// The mobirt command line: the commands, and info (render, accuracy and bench have files of their own).
#include <cstdio>
#include <exception>
#include <iostream>
#include <string>
#include <vector>

#include "app/commands.h"
#include "app/options.h"
#include "backend/backend.h"
#include "core/error.h"
#include "core/memory.h"
#include "render/renderer.h"
#include "render/scene_features.h"
#include "scene/animation.h"
#include "scene/loader.h"

namespace mobirt {
namespace {

constexpr const char* kUsage = R"(mobirt: a headless CPU-GPU hybrid Whitted ray tracer (MobiRT on Vulkan)

Usage:
  mobirt render SCENE -o OUT [options]   render a .gltf, .glb, .obj, .nff or .ply scene (or an OBJ
                                         sequence: a folder or a pattern like doll_%02d.obj) to OUT
  mobirt info [SCENE] [options]          what SCENE needs and the choices made for it, the device
                                         and the limits that matter here
  mobirt accuracy SCENE [options]        the GPU image against the double-precision reference
  mobirt bench [SCENE...] [options]      the paper's Table 1 with Embree 3 beside it, stage by stage
  mobirt COMMAND --help                  help on one command
)";

constexpr const char* kInfoAbout = R"(With SCENE, first prints what the scene needs (lights, textures, mirrors, glass, animation) and
every choice derived from it (packing, shader specialisation, passes run, kd-tree rebuilds).
Prints the Vulkan device (or, with --backend gles, the OpenGL ES context, the extensions used and
GL_MAX_TEXTURE_IMAGE_UNITS) mobirt would use and the limits that matter to it.
)";

constexpr const char* kHelp = "mobirt --help";
[[noreturn]] void usage_error(const std::string& message) { cli::usage_error(message, kHelp); }
bool is_help(const std::string& a) { return a == "-h" || a == "--help"; }

int cmd_info(const std::vector<std::string>& args) {
  cli::CommonOptions common;
  cli::CommandLine cl(cli::kInfo, "Usage: mobirt info [SCENE] [--backend gles|vulkan] [--device D] [--validation]",
                      kInfoAbout, kHelp, common);
  if (!cl.parse(args)) return 0;
  std::string scene_path;
  for (const std::string& a : cl.positionals()) {
    if (!scene_path.empty()) usage_error("info: unknown option " + a);
    scene_path = a;
  }
  if (!scene_path.empty()) {
    // The scene's features and every choice derived from them, under the default settings.
    LoadOptions load_options;
    load_options.analytic = common.analytic;
    const AnimatedScene animation = load_animated_scene(scene_path, load_options);
    const SceneFeatures f = analyze_scene(animation, RenderSettings{});
    std::cout << "scene:     " << scene_path << "\n"
              << "triangles: " << f.triangles << "\n"
              << "shapes:    " << f.shapes << " (analytic spheres and cones)\n"
              << "lights:    " << f.lights << "\n"
              << "textures:  " << f.textures << "\n"
              << "materials: " << (f.reflective ? "reflective " : "") << (f.refractive ? "refractive " : "")
              << (!f.reflective && !f.refractive ? "opaque only" : "") << "\n"
              << "animated:  ";
    if (f.animated) std::cout << "yes, " << f.duration << " s\n"; else std::cout << "no\n";
    std::cout
              << "choices:\n";
    for (const std::string& choice : f.choices) std::cout << "  " << choice << "\n";
    std::cout << "\n";
  }
  auto backend = create_backend(common.backend_name, common.backend);
  const DeviceInfo info = backend->device_info();
  std::cout << "api:     " << info.api << "\n"
            << "device:  " << info.device << (info.is_software ? " (software)" : "") << "\n"
            << "driver:  " << info.driver << "\n"
            << "version: " << info.driver_version << ", ray queries: "
            << (info.ray_query ? "yes (VK_KHR_ray_query, VK_KHR_acceleration_structure)" : "no") << "\n"
            << "limits:\n";
  for (const std::string& line : info.limits) std::cout << "  " << line << "\n";
  return 0;
}

int run(int argc, char** argv) {
  if (argc < 2 || is_help(argv[1])) {
    std::cout << kUsage;
    return argc < 2 ? 2 : 0;
  }
  const std::string command = argv[1];
  const std::vector<std::string> args(argv + 2, argv + argc);
  if (command == "render") return cmd_render(args);
  if (command == "info") return cmd_info(args);
  if (command == "accuracy") return cmd_accuracy(args);
  if (command == "bench") return cmd_bench(args);
  usage_error("unknown command '" + command + "'");
}

}  // namespace
}  // namespace mobirt

int main(int argc, char** argv) {
  mobirt::retain_freed_memory();
  mobirt::install_interrupt_handlers();
  try {
    return mobirt::run(argc, argv);
  } catch (const mobirt::Error& e) {
    std::fprintf(stderr, "mobirt: error: %s\n", e.what());
    return e.exit_code();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "mobirt: internal error: %s\n", e.what());
    return 1;
  }
}
