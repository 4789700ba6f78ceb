// The mobirt command line: render, info.
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <csignal>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "app/commands.h"
#include "app/options.h"
#include "backend/backend.h"
#include "core/error.h"
#include "core/image.h"
#include "core/memory.h"
#include "render/renderer.h"
#include "render/scene_features.h"
#include "scene/animation.h"
#include "scene/loader.h"
#include "scene/overrides.h"

namespace mobirt {
namespace {

constexpr const char* kUsage = R"(mobirt: a headless CPU-GPU hybrid Whitted ray tracer (MobiRT on Vulkan)

Usage:
  mobirt render SCENE -o OUT [options]   render a .gltf, .glb or .obj scene (or an OBJ sequence:
                                         a folder or a pattern like doll_%02d.obj) to OUT
  mobirt info [--device D]               print the Vulkan device and the limits that matter here
  mobirt accuracy SCENE [options]        the GPU image against the double-precision reference
  mobirt bench [SCENE...] [options]      the paper's Table 1 with Embree 3 beside it, stage by stage
  mobirt COMMAND --help                  help on one command
)";

constexpr const char* kRenderUsage = R"(Usage: mobirt render SCENE -o OUT [options]

Renders SCENE (.gltf, .glb or .obj) with the paper's passes: CPU kd-tree and primary rays, GPU
traversal with shadow rays, CPU hit decoding, GPU Phong shading. OUT's extension picks the format
(.png, .jpg: 8 bits; .exr, .hdr: float). The file is written whole or not at all.

Options:
  -o, --output FILE       output image (required)
  --size WxH              image size in pixels (default 400x240)
  --depth N               bounces of the ray tree: 0 = ray casting; reflection and refraction
                          rays are made only for materials that reflect or refract (default 2)
  --no-shadows            no shadow rays: every light lights every surface that faces it
  --general               general passes sized for 8 (or 16) lights and 16 textures instead of
                          passes specialised to the scene (same image; for comparisons)
  --always-rebuild        rebuild the kd-tree every frame even when the triangles did not move
  --min-weight W          secondary rays whose weight is below W are not traced (default 1/512)
  --stack N               short-stack entries of the traversal shader, 0 = pure kd-restart
                          (default 4, at most 32)
  --max-steps N           loop cap of one traversal in the shader; rays that reach it are traced
                          on the CPU instead, so the cap costs time, never pixels (default 2048)
  --bins N                SAH bins per axis of the kd-tree build (default 32)
  --build MODE            kd-tree build: fast or quality (exact split clipping) (default fast)
  --leaf-size N           largest leaf the build may make without trying to split (default 1)
  --max-depth N           kd-tree depth limit, -1 = 8 + 1.3 log2(triangles) (default -1)
  --offset MODE           how shadow, mirror and refracted rays leave a surface, along its normal:
                          fixed (--epsilon in scene units), scaled (--epsilon x the scene's
                          size, never below 2 ulps of the hit point) or normal-ulp (Wachter and
                          Binder 2019: 256 x the normal in ulps of each coordinate; ignores
                          --epsilon) (default scaled)
  --epsilon E             the offset of --offset fixed or scaled (default 1e-6)
  --intersect TEST        ray/triangle test of the traversal pass (and of the CPU's): mt
                          (Moller-Trumbore) or watertight (Woop et al. 2013: no ray slips
                          between triangles sharing an edge) (default mt)
  --precision P           float precision of the intersection arithmetic: highp (fp32) or
                          mediump (fp16, emulated by rounding the rays, the vertices and every
                          intermediate result) (default highp)
  --colour 8|16           bits per colour channel the shading pass returns: 8 (one pass) or 16
                          (two passes: high and low bytes) (default 8)
  --light SPEC            replaces the scene's lights (repeat for several):
                            "point pos=X,Y,Z [color=R,G,B] [intensity=I] [range=R]"
                            "spot pos=X,Y,Z dir=X,Y,Z [inner=DEG] [outer=DEG] [color=..] [intensity=..] [range=..]"
                            "directional dir=X,Y,Z [color=R,G,B] [intensity=I]"
  --camera SPEC           replaces the scene's camera: "EX,EY,EZ:TX,TY,TZ:UX,UY,UZ:FOVDEG"
                          (look-from, look-at, up, vertical field of view in degrees)
  --background R,G,B      colour of rays that miss (default 0,0,0)
  --backend gles|vulkan   the API the GPU passes run on: Vulkan, or OpenGL ES 2.0 through EGL
                          without a window (default vulkan)
  --device D              Vulkan device: index or part of its name (default: lavapipe)
  --validation            enable the Khronos validation layer; any message is an error
  --frames A:B            render frames A to B of the animation at --fps into OUT, a pattern
                          such as out/frame_%04d.png; the kd-tree is rebuilt every frame
  --fps F                 frames per second of --frames (default: the scene's, else 24)
  --time T                render the animation at T seconds (default 0)
  --mtl FILE              an OBJ's material library instead of the one it names (mtllib)
  --timings               print the time of each stage of the frame: one warm-up frame (the
                          driver compiles shaders at first use), then the median of --repeat
                          frames
  --repeat N              frames to time with --timings (default 5)
  --timings-json FILE     also write those timings as JSON: every stage of the median frame, in
                          total and per generation of rays (implies --timings)
)";

constexpr const char* kInfoUsage = R"(Usage: mobirt info [SCENE] [--backend gles|vulkan] [--device D] [--validation]

With SCENE, first prints what the scene needs (lights, textures, mirrors, glass, animation) and
every choice derived from it (packing, shader specialisation, passes run, kd-tree rebuilds).
Prints the Vulkan device (or, with --backend gles, the OpenGL ES context, the extensions used and
GL_MAX_TEXTURE_IMAGE_UNITS) mobirt would use and the limits that matter to it.
)";

// SIGINT and SIGTERM: outside an image write the process ends at once (exit 130/143): every file
// already written is complete and no temporary file exists. During write_image (which writes a
// temporary name and renames it) the signal is held until the file is in place, then the render
// stops with that exit code. Either way no half-written or temporary file is left behind.
volatile std::sig_atomic_t g_writing = 0;
volatile std::sig_atomic_t g_signal = 0;

extern "C" void on_interrupt(int sig) {
  if (!g_writing) ::_exit(128 + sig);
  g_signal = sig;
}

void install_interrupt_handlers() {
  struct sigaction action {};
  action.sa_handler = on_interrupt;
  sigemptyset(&action.sa_mask);
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);
}

// write_image with SIGINT/SIGTERM held off; returns the exit code of a signal that came meanwhile.
int write_output(const std::string& path, const Image& image) {
  g_writing = 1;
  try {
    write_image(path, image);
  } catch (...) {
    g_writing = 0;
    throw;
  }
  g_writing = 0;
  return g_signal ? 128 + int(g_signal) : 0;
}

constexpr const char* kHelp = "mobirt --help";
[[noreturn]] void usage_error(const std::string& message) { cli::usage_error(message, kHelp); }
int parse_int(const std::string& o, const std::string& v, int lo, int hi) { return cli::parse_int(o, v, lo, hi, kHelp); }
float parse_float(const std::string& o, const std::string& v, float lo, float hi) {
  return cli::parse_float(o, v, lo, hi, kHelp);
}

glm::vec3 parse_color(const std::string& option, const std::string& value) {
  glm::vec3 c;
  char extra = 0;
  if (std::sscanf(value.c_str(), "%f,%f,%f%c", &c.x, &c.y, &c.z, &extra) != 3 ||
      !(c.x >= 0 && c.y >= 0 && c.z >= 0 && c.x < 1e30f && c.y < 1e30f && c.z < 1e30f)) {
    usage_error(option + " " + value + ": expected three non-negative numbers R,G,B");
  }
  return c;
}

// Command-line arguments as a queue with "option needs a value" errors.
class Args {
 public:
  Args(int argc, char** argv, int first) : args_(argv + first, argv + argc) {}
  bool empty() const { return next_ >= args_.size(); }
  std::string take() { return args_[next_++]; }
  std::string value(const std::string& option) {
    if (empty()) usage_error(option + " needs a value");
    return take();
  }

 private:
  std::vector<std::string> args_;
  size_t next_ = 0;
};

// The output file of one frame: OUT's single printf integer conversion (%d, %04d, ...) filled in.
std::string frame_path(const std::string& pattern, int frame) {
  std::string result;
  bool converted = false;
  for (size_t i = 0; i < pattern.size(); ++i) {
    if (pattern[i] != '%') {
      result.push_back(pattern[i]);
      continue;
    }
    if (i + 1 < pattern.size() && pattern[i + 1] == '%') {
      result.push_back('%');
      ++i;
      continue;
    }
    size_t j = i + 1;
    bool zero = j < pattern.size() && pattern[j] == '0';
    if (zero) ++j;
    int width = 0;
    while (j < pattern.size() && std::isdigit(static_cast<unsigned char>(pattern[j])) && width < 100) {
      width = width * 10 + (pattern[j++] - '0');
    }
    if (j >= pattern.size() || pattern[j] != 'd' || converted) {
      usage_error("-o " + pattern + ": the frame pattern needs exactly one %d (e.g. frame_%04d.png)");
    }
    std::string number = std::to_string(frame);
    if (int(number.size()) < width) number.insert(0, size_t(width) - number.size(), zero ? '0' : ' ');
    result.append(number);
    converted = true;
    i = j;
  }
  if (!converted) usage_error("-o " + pattern + ": the frame pattern needs one %d (e.g. frame_%04d.png)");
  return result;
}

bool is_help(const std::string& a) { return a == "-h" || a == "--help"; }

int cmd_info(Args args) {
  BackendOptions options;
  std::string scene_path;
  std::string backend_name = "vulkan";
  while (!args.empty()) {
    const std::string a = args.take();
    if (is_help(a)) {
      std::cout << kInfoUsage;
      return 0;
    } else if (a == "--device") {
      options.device = args.value(a);
    } else if (a == "--backend") {
      backend_name = args.value(a);
    } else if (a == "--validation") {
      options.validation = true;
    } else if (!a.empty() && a[0] != '-' && scene_path.empty()) {
      scene_path = a;
    } else {
      usage_error("info: unknown option " + a);
    }
  }
  if (!scene_path.empty()) {
    // The scene's features and every choice derived from them, under the default settings.
    LoadOptions load_options;
    const AnimatedScene animation = load_animated_scene(scene_path, load_options);
    const SceneFeatures f = analyze_scene(animation, RenderSettings{});
    std::cout << "scene:     " << scene_path << "\n"
              << "triangles: " << f.triangles << "\n"
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
  auto backend = create_backend(backend_name, options);
  const DeviceInfo info = backend->device_info();
  std::cout << "api:     " << info.api << "\n"
            << "device:  " << info.device << (info.is_software ? " (software)" : "") << "\n"
            << "driver:  " << info.driver << "\n"
            << "limits:\n";
  for (const std::string& line : info.limits) std::cout << "  " << line << "\n";
  return 0;
}

// Stage by stage median over frames (each stage's own median).
FrameTimings median_timings(const std::vector<FrameTimings>& frames) {
  auto median = [&](auto get) {
    std::vector<double> v;
    for (const FrameTimings& f : frames) v.push_back(get(f));
    std::nth_element(v.begin(), v.begin() + long(v.size() / 2), v.end());
    return v[v.size() / 2];
  };
  FrameTimings m = frames.back();
  m.build_ms = median([](const FrameTimings& f) { return f.build_ms; });
  m.rays_ms = median([](const FrameTimings& f) { return f.rays_ms; });
  m.total_ms = median([](const FrameTimings& f) { return f.total_ms; });
  for (double GenerationTimings::*field :
       {&GenerationTimings::upload_ms, &GenerationTimings::trace_ms, &GenerationTimings::trace_readback_ms,
        &GenerationTimings::decode_ms, &GenerationTimings::shade_ms, &GenerationTimings::shade_readback_ms,
        &GenerationTimings::accumulate_ms, &GenerationTimings::secondary_ms}) {
    m.sum.*field = median([&](const FrameTimings& f) { return f.sum.*field; });
    for (size_t g = 0; g < m.generations.size(); ++g) {
      m.generations[g].*field = median([&](const FrameTimings& f) {
        return g < f.generations.size() ? f.generations[g].*field : 0.0;
      });
    }
  }
  return m;
}

void print_timings(const FrameTimings& t) {
  const GenerationTimings& s = t.sum;
  auto mrays = [](double rays, double ms) { return ms > 0 ? rays / (ms * 1e3) : 0.0; };
  std::printf("stage                   ms\n");
  std::printf("kd-tree build      %9.2f\n", t.build_ms);
  std::printf("primary rays       %9.2f\n", t.rays_ms);
  std::printf("upload             %9.2f   (tree, rays, shading inputs)\n", s.upload_ms);
  std::printf("traversal passes   %9.2f   %.2f Mrays/s (%u rays + %llu shadow rays)\n", s.trace_ms,
              mrays(double(s.rays + s.shadow_rays), s.trace_ms), s.rays,
              static_cast<unsigned long long>(s.shadow_rays));
  std::printf("read-back          %9.2f   (%llu bytes from the GPU, 4 per ray and pass)\n",
              s.trace_readback_ms + s.shade_readback_ms, static_cast<unsigned long long>(s.bytes_read));
  std::printf("hit decoding       %9.2f   (%u hits, %u capped rays traced on the CPU)\n", s.decode_ms,
              s.hits, s.capped);
  std::printf("shading passes     %9.2f\n", s.shade_ms);
  std::printf("accumulate         %9.2f\n", s.accumulate_ms);
  std::printf("secondary rays     %9.2f\n", s.secondary_ms);
  std::printf("frame              %9.2f   (%.1f fps)\n", t.total_ms, t.total_ms > 0 ? 1000.0 / t.total_ms : 0.0);
  if (t.generations.size() > 1) {
    std::printf("generation   rays   shadow   traversal ms  Mrays/s   shading ms\n");
    for (size_t g = 0; g < t.generations.size(); ++g) {
      const GenerationTimings& x = t.generations[g];
      std::printf("%10zu %6u %8llu %14.2f %8.2f %12.2f\n", g, x.rays,
                  static_cast<unsigned long long>(x.shadow_rays), x.trace_ms,
                  mrays(double(x.rays + x.shadow_rays), x.trace_ms), x.shade_ms);
    }
  }
}

// The numbers print_timings() shows, as JSON (for tools/profile/).
nlohmann::json timings_json(const FrameTimings& t) {
  auto generation = [](const GenerationTimings& g) {
    return nlohmann::json{{"rays", g.rays},
                          {"shadow_rays", g.shadow_rays},
                          {"hits", g.hits},
                          {"capped", g.capped},
                          {"upload_ms", g.upload_ms},
                          {"trace_ms", g.trace_ms},
                          {"trace_mrays", g.trace_ms > 0 ? double(g.rays + g.shadow_rays) / (g.trace_ms * 1e3) : 0.0},
                          {"trace_readback_ms", g.trace_readback_ms},
                          {"decode_ms", g.decode_ms},
                          {"shade_ms", g.shade_ms},
                          {"shade_readback_ms", g.shade_readback_ms},
                          {"accumulate_ms", g.accumulate_ms},
                          {"secondary_ms", g.secondary_ms},
                          {"bytes_read", g.bytes_read}};
  };
  nlohmann::json j = generation(t.sum);
  j["build_ms"] = t.build_ms;
  j["tree_rebuilt"] = t.tree_rebuilt;
  j["rays_ms"] = t.rays_ms;
  j["frame_ms"] = t.total_ms;
  j["generations"] = nlohmann::json::array();
  for (const GenerationTimings& g : t.generations) j["generations"].push_back(generation(g));
  return j;
}

int cmd_render(Args args) {
  std::string scene_path, output;
  RenderSettings settings;
  BackendOptions backend_options;
  std::string backend_name = "vulkan";
  std::vector<Light> lights;
  std::optional<Camera> camera;
  std::optional<glm::vec3> background;
  bool timings = false;
  std::string timings_json_path;
  int repeat = 5;
  std::string mtl;
  std::optional<double> fps, time;
  std::optional<std::pair<int, int>> frames;
  while (!args.empty()) {
    const std::string a = args.take();
    if (is_help(a)) {
      std::cout << kRenderUsage;
      return 0;
    } else if (a == "-o" || a == "--output") {
      output = args.value(a);
    } else if (cli::parse_render_setting(a, [&] { return args.value(a); }, settings, kHelp)) {
    } else if (a == "--general") {
      settings.specialize = false;
    } else if (a == "--always-rebuild") {
      settings.always_rebuild = true;
    } else if (a == "--light") {
      lights.push_back(parse_light(args.value(a)));
    } else if (a == "--camera") {
      camera = parse_camera(args.value(a));
    } else if (a == "--background") {
      background = parse_color(a, args.value(a));
    } else if (a == "--device") {
      backend_options.device = args.value(a);
    } else if (a == "--backend") {
      backend_name = args.value(a);
    } else if (a == "--validation") {
      backend_options.validation = true;
    } else if (a == "--mtl") {
      mtl = args.value(a);
    } else if (a == "--fps") {
      fps = parse_float(a, args.value(a), 0.001f, 10000.0f);
    } else if (a == "--time") {
      time = parse_float(a, args.value(a), -1e6f, 1e6f);
    } else if (a == "--frames") {
      const std::string v = args.value(a);
      int first = 0, last = 0;
      char extra = 0;
      if (std::sscanf(v.c_str(), "%d:%d%c", &first, &last, &extra) != 2 || first < 0 || last < first ||
          last - first > 100000) {
        usage_error("--frames " + v + ": expected A:B with 0 <= A <= B, e.g. 0:28");
      }
      frames = std::make_pair(first, last);
    } else if (a == "--timings") {
      timings = true;
    } else if (a == "--timings-json") {
      timings_json_path = args.value(a);
      timings = true;
    } else if (a == "--repeat") {
      repeat = parse_int(a, args.value(a), 1, 1000);
    } else if (!a.empty() && a[0] == '-') {
      usage_error("render: unknown option " + a);
    } else if (scene_path.empty()) {
      scene_path = a;
    } else {
      usage_error("render: more than one scene given ('" + scene_path + "' and '" + a + "')");
    }
  }
  if (scene_path.empty()) usage_error("render: no scene given");
  backend_options.pipeline_cache_dir = default_pipeline_cache_dir();
  if (frames && time) usage_error("render: --frames and --time exclude each other");
  if (output.empty()) usage_error("render: no output given: add -o OUT.png");
  check_image_output(output);

  LoadOptions load_options;
  load_options.mtl = mtl;
  if (fps) load_options.fps = *fps;
  const AnimatedScene animation = load_animated_scene(scene_path, load_options);
  const double frame_rate = fps ? *fps : animation.fps();
  Scene scene = animation.rest();
  // One camera for the whole sequence: the file's (animated with it), --camera, or one framing
  // the scene at rest, so that the view does not jump from frame to frame.
  const Camera fallback_camera =
      frame_box(scene.bounds(), 0.7854f, float(settings.width) / float(settings.height));
  auto scene_at = [&](double seconds) {
    if (animation.animated()) animation.evaluate(seconds, scene);
    apply_overrides(scene, lights, camera);
    if (background) scene.background = *background;
    return scene.camera ? *scene.camera : fallback_camera;
  };

  std::vector<int> frame_list;
  if (frames) {
    if (output.find('%') == std::string::npos && frames->second > frames->first) {
      usage_error("-o " + output + ": several frames need a pattern with a frame number, e.g. out/frame_%04d.png");
    }
    for (int f = frames->first; f <= frames->second; ++f) frame_list.push_back(f);
  }
  auto output_for = [&](int frame) { return frames ? frame_path(output, frame) : output; };
  check_image_output(output_for(frames ? frames->first : 0));

  auto backend = create_backend(backend_name, backend_options);
  Renderer renderer(*backend, settings);
  std::vector<FrameTimings> measured;
  auto check_messages = [&] {
    for (const std::string& message : backend->take_debug_messages()) {
      throw Error(ErrorKind::Internal, "validation: " + message);
    }
  };
  if (!frames) {
    const Camera view = scene_at(time ? *time : 0.0);
    FrameTimings t;
    Image image = renderer.render(scene, view, &t);
    if (timings) {  // the first frame paid for shader compilation: time the next ones
      for (int i = 0; i < repeat; ++i) {
        image = renderer.render(scene, view, &t);
        measured.push_back(t);
      }
    }
    check_messages();
    if (const int code = write_output(output, image)) return code;
  } else {
    const bool tty = isatty(2);
    const auto start = std::chrono::steady_clock::now();
    for (size_t i = 0; i < frame_list.size(); ++i) {
      const int frame = frame_list[i];
      const Camera view = scene_at(double(frame) / frame_rate);
      FrameTimings t;
      const Image image = renderer.render(scene, view, &t);
      if (i > 0 || frame_list.size() == 1) measured.push_back(t);
      check_messages();
      if (const int code = write_output(output_for(frame), image)) return code;
      if (tty) {
        const double seconds = elapsed_ms(start) / 1000.0;
        const int width = 30, done = int(width * double(i + 1) / double(frame_list.size()));
        std::fprintf(stderr, "\r[%s%s] %zu/%zu frames, %.1f frames/s", std::string(size_t(done), '#').c_str(),
                     std::string(size_t(width - done), ' ').c_str(), i + 1, frame_list.size(),
                     double(i + 1) / seconds);
      }
    }
    if (tty) std::fprintf(stderr, "\n");
  }
  if (timings && !measured.empty()) {
    std::printf("%s: %zu triangles, %zu lights, %dx%d, depth %d on %s\n", scene_path.c_str(),
                scene.mesh.triangle_count(), scene.lights.size(), settings.width, settings.height,
                settings.depth, backend->device_info().device.c_str());
    if (frames) {
      std::printf("median of %zu frames (the first frame, which compiles the shaders, left out)\n", measured.size());
    } else {
      std::printf("median of %d frames after one warm-up frame\n", repeat);
    }
    const FrameTimings median = median_timings(measured);
    print_timings(median);
    if (!timings_json_path.empty()) {
      nlohmann::json j{{"scene", scene_path},
                       {"triangles", scene.mesh.triangle_count()},
                       {"lights", scene.lights.size()},
                       {"width", settings.width},
                       {"height", settings.height},
                       {"depth", settings.depth},
                       {"stack", settings.stack_depth},
                       {"max_steps", settings.max_steps},
                       {"bins", settings.kd.bins},
                       {"device", backend->device_info().device},
                       {"backend", backend_name},
                       {"frames", measured.size()},
                       {"median", timings_json(median)}};
      std::ofstream file(timings_json_path);
      file << j.dump(2) << "\n";
      if (!file) throw Error(ErrorKind::BadInput, "--timings-json " + timings_json_path + ": cannot write the file");
    }
  }
  return 0;
}

int run(int argc, char** argv) {
  if (argc < 2 || is_help(argv[1])) {
    std::cout << kUsage;
    return argc < 2 ? 2 : 0;
  }
  const std::string command = argv[1];
  if (command == "render") return cmd_render(Args(argc, argv, 2));
  if (command == "info") return cmd_info(Args(argc, argv, 2));
  if (command == "accuracy") return cmd_accuracy(std::vector<std::string>(argv + 2, argv + argc));
  if (command == "bench") return cmd_bench(std::vector<std::string>(argv + 2, argv + argc));
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
