// mobirt accuracy: one frame through the GPU renderer and through the double-precision reference
// tracer (src/reference/), compared pixel by pixel and primary ray by primary ray.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "app/commands.h"
#include "app/options.h"
#include "app/scene_setup.h"
#include "backend/backend.h"
#include "core/error.h"
#include "core/image.h"
#include "reference/reference.h"
#include "render/renderer.h"
#include "scene/animation.h"
#include "scene/loader.h"
#include "scene/view_defaults.h"

namespace mobirt {
namespace {

constexpr const char* kAccuracyAbout = R"(Renders SCENE with the GPU renderer under the given settings and with the reference tracer (the
same Whitted model on the CPU in double precision: watertight intersection over a BVH, textures
from the original images, no 8-bit quantisation), and reports:
  psnr_db          PSNR of the GPU image against the reference (both clamped to [0, 1], as shown)
  max_error        largest channel difference
  share_over_2     share of pixels with a channel off by more than 2/255
  hit_mismatch     share of primary rays whose hit triangle differs from the reference's
  shadow_mismatch  share of primary hits on the same triangle whose shadow masks differ
  frame_ms         GPU frame time (median of --repeat frames after a warm-up frame; frame_min_ms:
                   the fastest of them)
The render options have the same meaning and defaults as for mobirt render.
)";

constexpr const char* kHelp = "mobirt accuracy --help";

const char* offset_name(OffsetMode mode) {
  return mode == OffsetMode::Fixed ? "fixed" : mode == OffsetMode::Scaled ? "scaled" : "normal-ulp";
}
const char* intersect_name(IntersectTest test) { return test == IntersectTest::Watertight ? "watertight" : "mt"; }
const char* precision_name(Precision p) { return p == Precision::Medium ? "mediump" : "highp"; }

Image clamped(const Image& image) {
  Image out = image;
  for (glm::vec3& p : out.pixels) p = glm::clamp(p, 0.0f, 1.0f);
  return out;
}

glm::vec3 heat(float error) {
  const float s = std::clamp(std::log2(1.0f + 255.0f * error) / 8.0f, 0.0f, 1.0f);
  struct Stop {
    float at;
    glm::vec3 color;
  };
  static const Stop stops[] = {{0.0f, {0, 0, 0}},        {0.125f, {0, 0, 1}},  {0.198f, {0, 1, 1}},
                               {0.351f, {0, 1, 0}},      {0.5f, {1, 1, 0}},    {0.75f, {1, 0, 0}},
                               {1.0f, {1, 1, 1}}};
  for (size_t i = 1; i < std::size(stops); ++i) {
    if (s <= stops[i].at) {
      const float f = (s - stops[i - 1].at) / (stops[i].at - stops[i - 1].at);
      return glm::mix(stops[i - 1].color, stops[i].color, f);
    }
  }
  return stops[std::size(stops) - 1].color;
}

}  // namespace

int cmd_accuracy(const std::vector<std::string>& args) {
  std::string json_path, csv_path, label, heatmap_path, gpu_out, ref_out;
  cli::CommonOptions common;
  double ref_epsilon = 1e-9;
  int repeat = 3;
  cli::CommandLine cl(cli::kAccuracy, "Usage: mobirt accuracy SCENE [options] [--json FILE] [--heatmap FILE.png]",
                      kAccuracyAbout, kHelp, common);
  cl.option("--repeat", "N", "frames timed (default 3)", [&](const cli::Value& v) { repeat = v.integer(1, 1000); });
  cl.option("--json", "FILE", "write the numbers as JSON (- = standard output)",
            [&](const cli::Value& v) { json_path = v.text; });
  cl.option("--csv", "FILE",
            "append them as one CSV row (a header first when FILE is new), with\n"
            "--label TEXT in the first column",
            [&](const cli::Value& v) { csv_path = v.text; });
  cl.option("--label", "TEXT", "the first column of --csv", [&](const cli::Value& v) { label = v.text; });
  cl.option("--heatmap", "FILE",
            "the per-pixel error as a picture: black = exact, blue = 1/255,\n"
            "cyan = 2/255, green = 6/255, yellow = 15/255, red = 63/255, white >= 1",
            [&](const cli::Value& v) { heatmap_path = v.text; });
  cl.option("-o,--output", "FILE", "also write the GPU image", [&](const cli::Value& v) { gpu_out = v.text; });
  cl.option("--reference-out", "FILE", "also write the reference image", [&](const cli::Value& v) { ref_out = v.text; });
  cl.option("--ref-epsilon", "E", "the reference's ray-origin offset, times 1 + max|p| (default 1e-9)",
            [&](const cli::Value& v) { ref_epsilon = v.number(0.0, 1.0); });
  if (!cl.parse(args)) return 0;
  RenderSettings& settings = common.settings;
  const std::string scene_path = cl.scene();
  for (const std::string& out : {heatmap_path, gpu_out, ref_out}) {
    if (!out.empty()) check_image_output(out);
  }

  LoadOptions load_options;
  load_options.mtl = common.mtl;
  load_options.analytic = common.analytic;
  const AnimatedScene animation = load_animated_scene(scene_path, load_options);
  apply_file_image_size(animation, common.size_given, settings);
  PosedScene posed(animation, common.edits, settings.width, settings.height);
  const Camera view = posed.at(common.time ? *common.time : 0.0);
  const Scene& scene = posed.scene;

  // The GPU frame: a warm-up frame (shader compilation), then the median of `repeat`.
  auto backend = create_backend("vulkan", common.backend);
  Renderer renderer(*backend, settings);
  Image gpu = renderer.render(scene, view);
  std::vector<double> times;
  for (int r = 0; r < repeat; ++r) {
    FrameTimings t;
    gpu = renderer.render(scene, view, &t);
    times.push_back(t.total_ms);
  }
  std::sort(times.begin(), times.end());
  const double frame_ms = times[times.size() / 2];
  // The fastest frame: on a machine shared with other work, interference only adds time, so the
  // minimum is the steadier figure for comparing settings.
  const double frame_min_ms = times.front();

  // The GPU's primary hits and shadow masks as the frame finds them: the traversal pass over the
  // primary rays, or the raster pass and the shadow pass from its hits (--primary raster).
  const FlatKdTree tree = build_kdtree(scene.mesh.positions, scene.shapes, settings.kd);
  const RayBatch primary = primary_rays(view, settings.width, settings.height);
  const TraceResult traced = renderer.trace_primary(scene, view, tree, primary);
  const std::span<const Light> shadow_lights =
      settings.shadows ? std::span<const Light>(scene.lights) : std::span<const Light>();
  const SurfaceHits hits =
      decode_hits(scene, tree, primary, traced.texels, traced.packing, shadow_lights, settings.shadow_rays);
  for (const std::string& message : backend->take_debug_messages()) {
    throw Error(ErrorKind::Internal, "validation: " + message);
  }

  // The reference traces the surfaces the file describes: NFF spheres and cones analytically even
  // when the GPU frame has them tessellated (--primitives tessellated), so that the tessellation's
  // own error counts. Hits are then in other index spaces and are not compared.
  std::optional<AnimatedScene> exact_animation;
  std::optional<PosedScene> exact;
  if (!common.analytic) {
    load_options.analytic = true;
    exact_animation.emplace(load_animated_scene(scene_path, load_options));
    if (!exact_animation->rest().shapes.empty()) {
      exact.emplace(*exact_animation, common.edits, settings.width, settings.height);
      exact->at(common.time ? *common.time : 0.0);
    }
  }
  const bool same_primitives = !exact;
  ReferenceSettings ref_settings = reference_settings(settings);
  ref_settings.epsilon = ref_epsilon;
  const ReferenceResult ref = render_reference(exact ? exact->scene : scene, view, ref_settings);

  const Image gpu_shown = clamped(gpu), ref_shown = clamped(ref.image);
  const ImageDiff diff = compare_images(gpu_shown, ref_shown);
  size_t prim_mismatch = 0, same_hits = 0, mask_mismatch = 0;
  for (uint32_t i = 0; i < primary.count(); ++i) {
    const uint32_t p = primary.pixel[i];
    if (hits[i].prim != ref.primary_prim[p]) {
      ++prim_mismatch;
    } else if (hits[i].valid()) {
      ++same_hits;
      const uint32_t gpu_mask = settings.shadows ? hits[i].mask : ref.primary_mask[p];
      if (gpu_mask != ref.primary_mask[p]) ++mask_mismatch;
    }
  }
  const double pixels = double(std::max<uint32_t>(1, primary.count()));
  const double not_compared = std::numeric_limits<double>::quiet_NaN();
  const double hit_mismatch = same_primitives ? double(prim_mismatch) / pixels : not_compared;
  const double shadow_mismatch =
      !same_primitives ? not_compared : same_hits ? double(mask_mismatch) / double(same_hits) : 0.0;

  nlohmann::json j;
  j["scene"] = scene_path;
  j["size"] = std::to_string(settings.width) + "x" + std::to_string(settings.height);
  j["triangles"] = scene.mesh.triangle_count();
  j["shapes"] = scene.shapes.size();
  j["lights"] = scene.lights.size();
  j["device"] = backend->device_info().device;
  j["settings"] = {{"depth", settings.depth},
                   {"shadows", settings.shadows},
                   {"primary", primaries_rasterized(scene, settings) ? "raster" : "trace"},
                   {"min_weight", settings.secondary.min_weight},
                   {"stack", settings.stack_depth},
                   {"max_steps", settings.max_steps},
                   {"cpu_walks", settings.cpu_walks},
                   {"epsilon", settings.shadow_rays.offset.epsilon},
                   {"offset", offset_name(settings.shadow_rays.offset.mode)},
                   {"intersect", intersect_name(settings.shadow_rays.ray_test.test)},
                   {"precision", precision_name(settings.shadow_rays.ray_test.precision)},
                   {"colour", int(settings.colour)},
                   {"ref_epsilon", ref_epsilon}};
  j["settings"].update(cli::kd_settings_json(settings.kd));
  j["psnr_db"] = std::isfinite(diff.psnr) ? nlohmann::json(diff.psnr) : nlohmann::json("inf");
  j["max_error"] = diff.max_error;
  j["share_over_2"] = diff.share_over;
  j["hit_mismatch"] = same_primitives ? nlohmann::json(hit_mismatch) : nlohmann::json(nullptr);
  j["shadow_mismatch"] = same_primitives ? nlohmann::json(shadow_mismatch) : nlohmann::json(nullptr);
  j["reference_primitives"] = same_primitives ? "the GPU frame's" : "analytic";
  j["frame_ms"] = frame_ms;
  j["frame_min_ms"] = frame_min_ms;
  j["reference_ms"] = ref.elapsed_ms;

  std::printf("%s: %zu triangles, %zu shapes, %zu lights, %dx%d, depth %d on %s\n", scene_path.c_str(),
              scene.mesh.triangle_count(), scene.shapes.size(), scene.lights.size(), settings.width, settings.height,
              settings.depth, backend->device_info().device.c_str());
  std::printf("psnr             %8.2f dB\n", diff.psnr);
  std::printf("max error        %8.4f   (%.1f/255)\n", diff.max_error, diff.max_error * 255.0);
  std::printf("pixels > 2/255   %8.4f %%\n", 100.0 * diff.share_over);
  if (same_primitives) {
    std::printf("hit mismatch     %8.4f %%  (%zu of %u primary rays)\n", 100.0 * hit_mismatch, prim_mismatch,
                primary.count());
    std::printf("shadow mismatch  %8.4f %%  (%zu of %zu hits on the same triangle)\n", 100.0 * shadow_mismatch,
                mask_mismatch, same_hits);
  } else {
    std::printf("hit mismatch          n/a   (the reference traces the file's shapes analytically)\n");
  }
  std::printf("frame            %8.2f ms (median of %d; fastest %.2f ms)\n", frame_ms, repeat, frame_min_ms);
  std::printf("reference        %8.2f ms\n", ref.elapsed_ms);

  if (!json_path.empty()) {
    if (json_path == "-") {
      std::cout << j.dump(2) << "\n";
    } else {
      if (!write_text_file(json_path, j.dump(2) + "\n")) throw input_error(json_path, "cannot write the JSON report");
    }
  }
  if (!csv_path.empty()) {
    const bool fresh = !std::filesystem::exists(csv_path);
    std::ofstream out(csv_path, std::ios::app);
    if (fresh) {
      out << "label,scene,size,depth,stack,bins,leaf_size,max_depth,epsilon,offset,intersect,precision,colour,"
             "frame_ms,frame_min_ms,psnr_db,max_error,share_over_2,hit_mismatch,shadow_mismatch,reference_ms\n";
    }
    char row[768];
    std::snprintf(row, sizeof(row),
                  "%s,%s,%dx%d,%d,%d,%d,%d,%d,%g,%s,%s,%s,%d,%.3f,%.3f,%.3f,%.5f,%.6f,%.6f,%.6f,%.1f\n", label.c_str(),
                  scene_path.c_str(), settings.width, settings.height, settings.depth, settings.stack_depth,
                  settings.kd.bins, kd_leaf_size(settings.kd), settings.kd.max_depth,
                  double(settings.shadow_rays.offset.epsilon), offset_name(settings.shadow_rays.offset.mode),
                  intersect_name(settings.shadow_rays.ray_test.test),
                  precision_name(settings.shadow_rays.ray_test.precision), int(settings.colour), frame_ms, frame_min_ms,
                  std::isfinite(diff.psnr) ? diff.psnr : 999.0, diff.max_error, diff.share_over, hit_mismatch,
                  shadow_mismatch, ref.elapsed_ms);
    out << row;
    if (!out) throw input_error(csv_path, "cannot write the CSV row");
  }
  if (!heatmap_path.empty()) {
    Image map(gpu.width, gpu.height);
    for (size_t i = 0; i < map.pixels.size(); ++i) {
      const glm::vec3 d = glm::abs(gpu_shown.pixels[i] - ref_shown.pixels[i]);
      map.pixels[i] = heat(std::max(d.x, std::max(d.y, d.z)));
    }
    write_image(heatmap_path, map);
  }
  if (!gpu_out.empty()) write_image(gpu_out, gpu);
  if (!ref_out.empty()) write_image(ref_out, ref.image);
  if (posed.headlit()) note_headlight(posed.scene);
  return 0;
}

}  // namespace mobirt
