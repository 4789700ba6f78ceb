// mobirt render: one frame, or a sequence of frames, of a scene to image files.
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <system_error>
#include <vector>

#include <nlohmann/json.hpp>

#include "app/commands.h"
#include "app/options.h"
#include "app/scene_setup.h"
#include "backend/backend.h"
#include "core/error.h"
#include "core/image.h"
#include "render/frame_pipeline.h"
#include "render/renderer.h"
#include "scene/loader.h"
#include "scene/view_defaults.h"

namespace mobirt {
namespace {

constexpr const char* kRenderAbout = R"(Renders SCENE (.gltf, .glb, .obj, .nff or .ply) with the paper's passes: CPU kd-tree and
primary rays, GPU traversal with shadow rays, CPU hit decoding, GPU Phong shading. OUT's
extension picks the format (.png, .jpg: 8 bits; .exr, .hdr: float). The file is written whole
or not at all.
)";

constexpr const char* kHelp = "mobirt --help";
[[noreturn]] void usage_error(const std::string& message) { cli::usage_error(message, kHelp); }

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

}  // namespace

void install_interrupt_handlers() {
  struct sigaction action {};
  action.sa_handler = on_interrupt;
  sigemptyset(&action.sa_mask);
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);
}

bool write_text_file(const std::string& path, const std::string& text) {
  const std::string tmp = path + ".tmp";
  {
    std::ofstream out(tmp, std::ios::binary);
    out << text;
    out.flush();
    if (!out) {
      std::error_code ignored;
      std::filesystem::remove(tmp, ignored);
      return false;
    }
  }
  std::error_code error;
  std::filesystem::rename(tmp, path, error);
  if (!error) return true;
  std::error_code ignored;
  std::filesystem::remove(tmp, ignored);
  return false;
}

namespace {

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

// built_ahead: the frames came pipelined, their trees built on a worker during the previous frame.
// period_ms: --frames' loop period (posing and build included), else negative.
void print_timings(const FrameTimings& t, bool built_ahead, double period_ms) {
  const GenerationTimings& s = t.sum;
  auto mrays = [](double rays, double ms) { return ms > 0 ? rays / (ms * 1e3) : 0.0; };
  std::printf("stage                   ms\n");
  std::printf("kd-tree build      %9.2f%s\n", t.build_ms,
              built_ahead ? "   (on a worker while the previous frame rendered: not part of the frame)" : "");
  std::printf("primary rays       %9.2f\n", t.rays_ms);
  std::printf("upload             %9.2f   (tree, rays, shading inputs)\n", s.upload_ms);
  std::printf("traversal passes   %9.2f   %.2f Mrays/s (%u rays + %llu shadow rays)\n", s.trace_ms,
              mrays(double(s.rays + s.shadow_rays), s.trace_ms), s.rays,
              static_cast<unsigned long long>(s.shadow_rays));
  std::printf("read-back          %9.2f   (%llu bytes from the GPU, 4 per ray and pass)\n",
              s.trace_readback_ms + s.shade_readback_ms, static_cast<unsigned long long>(s.bytes_read));
  std::printf("hit decoding       %9.2f   (%u hits, %u capped rays traced on the CPU)\n", s.decode_ms,
              s.hits, s.capped);
  std::printf("shading passes     %9.2f   (%u rays: the hits, and one miss for every miss)\n", s.shade_ms, s.shaded);
  std::printf("accumulate         %9.2f\n", s.accumulate_ms);
  std::printf("secondary rays     %9.2f\n", s.secondary_ms);
  std::printf("frame              %9.2f   (%.1f fps)\n", t.total_ms, t.total_ms > 0 ? 1000.0 / t.total_ms : 0.0);
  if (period_ms >= 0) {
    std::printf("frame loop period  %9.2f   (%.1f fps; %s)\n", period_ms, period_ms > 0 ? 1000.0 / period_ms : 0.0,
                built_ahead ? "pipelined: the next frame posed and built meanwhile" : "serial: posing, build and frame");
  }
  if (t.generations.size() > 1) {
    std::printf("generation   rays   shadow   traversal ms  Mrays/s   shading ms\n");
    for (size_t g = 0; g < t.generations.size(); ++g) {
      const GenerationTimings& x = t.generations[g];
      std::printf("%10zu %6u %8llu %14.2f %8.2f %12.2f%s\n", g, x.rays,
                  static_cast<unsigned long long>(x.shadow_rays), x.trace_ms,
                  mrays(double(x.rays + x.shadow_rays), x.trace_ms), x.shade_ms,
                  x.cpu_walked > 0 ? "   walked on the CPU (--cpu-walks)" : "");
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
                          {"cpu_walked", g.cpu_walked},
                          {"upload_ms", g.upload_ms},
                          {"trace_ms", g.trace_ms},
                          {"trace_mrays", g.trace_ms > 0 ? double(g.rays + g.shadow_rays) / (g.trace_ms * 1e3) : 0.0},
                          {"trace_readback_ms", g.trace_readback_ms},
                          {"decode_ms", g.decode_ms},
                          {"shade_ms", g.shade_ms},
                          {"shade_readback_ms", g.shade_readback_ms},
                          {"shaded", g.shaded},
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

}  // namespace

int cmd_render(const std::vector<std::string>& args) {
  cli::CommonOptions common;
  std::string output;
  bool timings = false;
  bool serial = false;
  std::string timings_json_path;
  int repeat = 5;
  std::optional<double> fps;
  std::optional<std::pair<int, int>> frames;
  cli::CommandLine cl(cli::kRender, "Usage: mobirt render SCENE -o OUT [options]", kRenderAbout, kHelp, common);
  cl.option("-o,--output", "FILE", "output image (required)", [&](const cli::Value& v) { output = v.text; });
  cl.option("--frames", "A:B",
            "render frames A to B of the animation at --fps into OUT, a pattern\n"
            "such as out/frame_%04d.png; each frame posed anew (its kd-tree rebuilt\n"
            "where a ray walks one), the next posed and built while one renders",
            [&](const cli::Value& v) {
              int first = 0, last = 0;
              char extra = 0;
              if (std::sscanf(v.text.c_str(), "%d:%d%c", &first, &last, &extra) != 2 || first < 0 || last < first ||
                  last - first > 100000) {
                usage_error("--frames " + v.text + ": expected A:B with 0 <= A <= B, e.g. 0:28");
              }
              frames = std::make_pair(first, last);
            });
  cl.flag("--serial",
          "with --frames: pose each frame and build its kd-tree after the previous\n"
          "frame rendered, instead of on a worker while it renders (same images)",
          [&] { serial = true; });
  cl.option("--fps", "F", "frames per second of --frames (default: the scene's, else 24)",
            [&](const cli::Value& v) { fps = v.real(0.001f, 10000.0f); });
  cl.flag("--timings",
          "print the time of each stage of the frame: one warm-up frame (the\n"
          "driver compiles shaders at first use), then the median of --repeat\n"
          "frames",
          [&] { timings = true; });
  cl.option("--repeat", "N", "frames to time with --timings (default 5)",
            [&](const cli::Value& v) { repeat = v.integer(1, 1000); });
  cl.option("--timings-json", "FILE",
            "also write those timings as JSON: every stage of the median frame, in\n"
            "total and per generation of rays (implies --timings)",
            [&](const cli::Value& v) {
              timings_json_path = v.text;
              timings = true;
            });
  if (!cl.parse(args)) return 0;
  RenderSettings& settings = common.settings;
  const std::string scene_path = cl.scene();
  common.backend.pipeline_cache_dir = default_pipeline_cache_dir();
  if (frames && common.time) usage_error("render: --frames and --time exclude each other");
  if (output.empty()) usage_error("render: no output given: add -o OUT.png");
  check_image_output(output);

  LoadOptions load_options;
  load_options.mtl = common.mtl;
  load_options.analytic = common.analytic;
  if (fps) load_options.fps = *fps;
  const AnimatedScene animation = load_animated_scene(scene_path, load_options);
  const double frame_rate = fps ? *fps : animation.fps();
  apply_file_image_size(animation, common.size_given, settings);
  // One camera for the whole sequence: the file's (animated with it), --camera, or one framing
  // the scene at rest, so that the view does not jump from frame to frame.
  PosedScene posed(animation, common.edits, settings.width, settings.height);
  const Scene& scene = posed.scene;
  if (settings.primary == PrimaryHits::Raster && !primaries_rasterized(scene, settings)) {
    std::fprintf(stderr,
                 "mobirt: note: %s has %zu analytic shapes (spheres, cylinders, cones), which the raster pass "
                 "cannot draw: its primary rays are traced (--primitives tessellated rasterizes them as "
                 "triangles)\n",
                 scene_path.c_str(), scene.shapes.size());
  }

  std::vector<int> frame_list;
  if (frames) {
    if (output.find('%') == std::string::npos && frames->second > frames->first) {
      usage_error("-o " + output + ": several frames need a pattern with a frame number, e.g. out/frame_%04d.png");
    }
    for (int f = frames->first; f <= frames->second; ++f) frame_list.push_back(f);
  }
  auto output_for = [&](int frame) { return frames ? frame_path(output, frame) : output; };
  check_image_output(output_for(frames ? frames->first : 0));

  // Frames of an animation pose the triangles anew: each builds a tree (--primary auto counts it).
  settings.tree_per_frame = frames && animation.animated();
  auto backend = create_backend(common.backend_name, common.backend);
  Renderer renderer(*backend, settings);
  std::vector<FrameTimings> measured;
  std::vector<double> periods;  // --frames: the frame loop's period, posing and build included
  auto check_messages = [&] {
    for (const std::string& message : backend->take_debug_messages()) {
      throw Error(ErrorKind::Internal, "validation: " + message);
    }
  };
  if (!frames) {
    const Camera view = posed.at(common.time ? *common.time : 0.0);
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
    // Frame i + 1 is posed into the other scene and its tree built while frame i renders.
    PosedScene ahead(animation, common.edits, settings.width, settings.height);
    PosedScene* slots[2] = {&posed, &ahead};
    FramePipeline pipeline(
        frame_list.size(),
        [&](int slot, size_t index) {
          const Camera view = slots[slot]->at(double(frame_list[index]) / frame_rate);
          return std::make_pair(static_cast<const Scene*>(&slots[slot]->scene), view);
        },
        settings.kd, settings.always_rebuild, !serial);
    pipeline.set_render_settings(settings);
    for (size_t i = 0; i < frame_list.size(); ++i) {
      const int frame = frame_list[i];
      FrameTimings t;
      Image image;
      const PipelineStep step = pipeline.step(i, [&](PreparedFrame& f) { image = render_prepared(renderer, f, &t); });
      if (i > 0 || frame_list.size() == 1) {
        measured.push_back(t);
        periods.push_back(step.period_ms);
      }
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
  if (posed.headlit()) note_headlight(scene);  // the pipeline's other slot poses the same scene
  if (timings && !measured.empty()) {
    std::printf("%s: %zu triangles, %zu shapes, %zu lights, %dx%d, depth %d, primary hits %s on %s\n",
                scene_path.c_str(), scene.mesh.triangle_count(), scene.shapes.size(), scene.lights.size(),
                settings.width, settings.height, settings.depth,
                primaries_rasterized(scene, settings) ? "rasterized" : "traced",
                backend->device_info().device.c_str());
    if (frames) {
      std::printf("median of %zu frames (the first frame, which compiles the shaders, left out)\n", measured.size());
    } else {
      std::printf("median of %d frames after one warm-up frame\n", repeat);
    }
    const FrameTimings median = median_timings(measured);
    double period = -1.0;
    if (!periods.empty()) {
      std::nth_element(periods.begin(), periods.begin() + long(periods.size() / 2), periods.end());
      period = periods[periods.size() / 2];
    }
    print_timings(median, frames && !serial, period);
    if (!timings_json_path.empty()) {
      nlohmann::json j{{"scene", scene_path},
                       {"triangles", scene.mesh.triangle_count()},
                       {"shapes", scene.shapes.size()},
                       {"lights", scene.lights.size()},
                       {"width", settings.width},
                       {"height", settings.height},
                       {"depth", settings.depth},
                       {"primary", primaries_rasterized(scene, settings) ? "raster" : "trace"},
                       {"stack", settings.stack_depth},
                       {"max_steps", settings.max_steps},
                       {"cpu_walks", settings.cpu_walks},
                       {"device", backend->device_info().device},
                       {"backend", common.backend_name},
                       {"frames", measured.size()},
                       {"median", timings_json(median)}};
      j.update(cli::kd_settings_json(settings.kd));
      if (frames) {
        j["pipelined"] = !serial;
        j["median"]["period_ms"] = period;
      }
      if (!write_text_file(timings_json_path, j.dump(2) + "\n")) {
        throw Error(ErrorKind::BadInput, "--timings-json " + timings_json_path + ": cannot write the file");
      }
    }
  }
  return 0;
}

}  // namespace mobirt
