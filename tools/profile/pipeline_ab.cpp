// Serial against pipelined frames (render/frame_pipeline.h) in one process, frame by frame
// interleaved, so that a loaded machine's drift hits both alike: the same animated scene rendered
// by two renderers on two backends of the same API, one posing and building each frame before its
// passes, the other building frame N+1 on a worker while frame N renders. Prints each mode's median
// frame time, their ratio, how busy the machine's cores were (process CPU time over wall time x
// cores) and the process's CPU time per frame (the same work in both modes: pipelining can only
// fill idle cores), and checks that both modes give the same images.
//
//   mobirt_pipeline_ab SCENE [--frames N] [--warmup N] [--depth N] [--no-shadows] [--size WxH] [--build-threads N]
//                      [--backend vulkan|gles] [--nice N] [--pin-threads on|off]
// LP_NUM_THREADS sets lavapipe's threads, as for mobirt. --nice N lowers the worker thread's
// priority (Linux: nice is per thread), so that the build yields the cores to lavapipe's threads;
// with --build-threads 1 the whole build runs on that thread. --pin-threads as mobirt's (default on).
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "backend/backend.h"
#include "backend/driver_threads.h"
#include "core/cpu_time.h"
#include "core/error.h"
#include "core/memory.h"
#include "render/frame_pipeline.h"
#include "render/renderer.h"
#include "scene/animation.h"
#include "scene/view_defaults.h"

namespace {

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n == 0 ? 0.0 : n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

struct Mode {
  std::vector<double> frame_ms, cpu_ms, busy, build_ms, render_ms, render_cpu_ms, wait_ms;
  void add(double wall, double cpu, double build) {
    frame_ms.push_back(wall);
    cpu_ms.push_back(cpu);
    busy.push_back(cpu / (wall * std::max(1u, std::thread::hardware_concurrency())));
    build_ms.push_back(build);
  }
};

}  // namespace

int main(int argc, char** argv) {
  using namespace mobirt;
  if (argc < 2) {
    std::fprintf(stderr, "usage: mobirt_pipeline_ab SCENE [--frames N] [--warmup N] [--depth N] [--size WxH] "
                         "[--build-threads N] [--backend vulkan|gles]\n");
    return 2;
  }
  retain_freed_memory();
  int frames = 12, warmup = 2, build_threads = 0, nice = 0;
  bool pin = true;
  std::string backend_name = "vulkan";
  RenderSettings settings;
  settings.always_rebuild = true;  // as the bench: a new tree every frame
  for (int i = 2; i < argc; ++i) {
    const std::string key = argv[i];
    if (key == "--no-shadows") {
      settings.shadows = false;  // the bench's ray casting
      continue;
    }
    if (i + 1 >= argc) {
      std::fprintf(stderr, "%s needs a value\n", key.c_str());
      return 2;
    }
    const char* value = argv[++i];
    if (key == "--frames") {
      frames = std::atoi(value);
    } else if (key == "--warmup") {
      warmup = std::atoi(value);
    } else if (key == "--depth") {
      settings.depth = std::atoi(value);
    } else if (key == "--build-threads") {
      build_threads = std::atoi(value);
    } else if (key == "--backend") {
      backend_name = value;
    } else if (key == "--nice") {
      nice = std::atoi(value);
    } else if (key == "--pin-threads") {
      pin = std::string(value) != "off";
    } else if (key == "--size") {
      std::sscanf(value, "%dx%d", &settings.width, &settings.height);
    } else {
      std::fprintf(stderr, "unknown option %s\n", key.c_str());
      return 2;
    }
  }
  settings.kd.threads = build_threads;
  try {
    const AnimatedScene animation = load_animated_scene(argv[1]);
    const double fps = animation.fps() > 0 ? animation.fps() : 24.0;
    const Camera fallback = framing_camera(animation.rest(), float(settings.width) / float(settings.height));
    auto view_of = [&](const Scene& s) { return s.camera ? *s.camera : fallback; };
    auto make_backend = [&] {
      return backend_name == "gles" ? create_gles_backend(BackendOptions{}) : create_vulkan_backend(BackendOptions{});
    };
    std::unique_ptr<Backend> serial_backend = make_backend(), pipelined_backend = make_backend();
    if (pin) pin_driver_threads();  // as mobirt does (--pin-threads on)
    Renderer serial(*serial_backend, settings), pipelined(*pipelined_backend, settings);
    Scene serial_scene, slots[2];
    const size_t total = size_t(warmup + frames);
    FramePipeline pipeline(
        total,
        [&](int slot, size_t index) {
          if (nice) setpriority(PRIO_PROCESS, id_t(syscall(SYS_gettid)), nice);
          animation.evaluate(double(index) / fps, slots[slot]);
          return std::make_pair(static_cast<const Scene*>(&slots[slot]), view_of(slots[slot]));
        },
        settings.kd, settings.always_rebuild, true);
    // Both sides build what the frame walks (no tree where the primaries are rasterized and no ray walks one).
    pipeline.set_render_settings(settings);
    Mode s, p;
    size_t differing = 0;
    for (size_t f = 0; f < total; ++f) {
      const bool timed = f >= size_t(warmup);
      // Serial: pose, build (in begin_frame), passes.
      auto start = std::chrono::steady_clock::now();
      double cpu = process_cpu_ms(), render_cpu = thread_cpu_ms();
      animation.evaluate(double(f) / fps, serial_scene);
      FrameTimings st;
      const auto render_start = std::chrono::steady_clock::now();
      const Image a = serial.render(serial_scene, view_of(serial_scene), &st);
      const double serial_render_ms = elapsed_ms(render_start) - st.build_ms;  // as the pipeline's render
      if (timed) {
        s.add(elapsed_ms(start), process_cpu_ms() - cpu, st.build_ms);
        s.render_ms.push_back(serial_render_ms);
        s.render_cpu_ms.push_back(thread_cpu_ms() - render_cpu);
        s.wait_ms.push_back(0.0);
      }
      // Pipelined: this frame's tree was built during the previous step.
      start = std::chrono::steady_clock::now();
      cpu = process_cpu_ms();
      FrameTimings pt;
      Image b;
      const PipelineStep step = pipeline.step(f, [&](PreparedFrame& prepared) { b = render_prepared(pipelined, prepared, &pt); });
      if (timed) {
        p.add(elapsed_ms(start), process_cpu_ms() - cpu, pt.build_ms);
        p.render_ms.push_back(step.render_ms);
        p.render_cpu_ms.push_back(step.render_cpu_ms);
        p.wait_ms.push_back(step.wait_ms);
      }
      for (size_t i = 0; i < a.pixels.size(); ++i) differing += a.pixels[i] != b.pixels[i];
    }
    const char* lp = std::getenv("LP_NUM_THREADS");
    std::printf("%s, %dx%d, depth %d%s, %s, LP_NUM_THREADS=%s, build threads %s, worker nice %d, %d frames after %d "
                "warm-up, %u cores\n",
                argv[1], settings.width, settings.height, settings.depth, settings.shadows ? "" : " without shadows",
                backend_name.c_str(), lp ? lp : "(all)",
                build_threads ? std::to_string(build_threads).c_str() : "(all)", nice, frames, warmup,
                std::thread::hardware_concurrency());
    std::printf("%-10s %9s %9s %9s %9s %9s %7s %9s\n", "mode", "frame ms", "build ms", "render", "render cpu", "wait",
                "busy", "cpu ms");
    for (const auto& [name, m] : {std::pair<const char*, const Mode*>{"serial", &s}, {"pipelined", &p}}) {
      std::printf("%-10s %9.2f %9.2f %9.2f %9.2f %9.2f %6.0f%% %9.2f\n", name, median(m->frame_ms), median(m->build_ms),
                  median(m->render_ms), median(m->render_cpu_ms), median(m->wait_ms), 100.0 * median(m->busy),
                  median(m->cpu_ms));
    }
    std::printf("pipelined fps / serial fps: %.3f (median frame times); pixels differing: %zu\n",
                median(s.frame_ms) / std::max(median(p.frame_ms), 1e-9), differing);
    return differing == 0 ? 0 : 1;
  } catch (const Error& e) {
    std::fprintf(stderr, "mobirt_pipeline_ab: %s\n", e.what());
    return 2;
  }
}
