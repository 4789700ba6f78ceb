// mobirt bench: the MobiRT paper's Table 1 measured on this machine, with the peers a user would
// pick instead (Embree 3 on the CPU, the driver's own ray queries on the same Vulkan driver) and
// mobirt's own CPU traversal of the same kd-tree in the same run, frame by frame interleaved, on
// the same scenes, frames, cores and settings.

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "app/commands.h"
#include "app/options.h"
#include "app/scene_setup.h"
#include "backend/vulkan/vulkan_backend.h"
#include "baseline/compute_engine.h"
#include "baseline/compute_whitted.h"
#include "baseline/embree_engine.h"
#include "baseline/ray_query_engine.h"
#include "baseline/ray_query_whitted.h"
#include "core/cpu_time.h"
#include "core/error.h"
#include "render/cpu_render.h"
#include "render/frame_pipeline.h"
#include "render/renderer.h"
#include "render/whitted.h"
#include "scene/animation.h"
#include "scene/overrides.h"
#include "scene/tessellate.h"

namespace mobirt {
namespace {

constexpr const char* kBenchAbout = R"(The paper's Table 1 on this machine: for each scene, ray casting, + shadow rays, + 1 bounce and
+ 2 bounces, animation playing and the kd-tree rebuilt every frame, warm-up frames and then timed
frames (median and min-max FPS), with every stage of the frame and, in the same run and frame by
frame interleaved, the same frames rendered on the CPU by Embree 3 (rtcIntersect1 / rtcOccluded1
over a dynamic, LOW-quality BVH rebuilt every frame), by mobirt's own kd-tree on the CPU, and by
the driver's own ray queries (lavapipe's BVH built every frame, rayQueryEXT in a fragment pass, the
same ray tree, hit decoding and shading pass as mobirt's; skipped with the reason where the driver
lacks VK_KHR_ray_query), and by mobirt's own kd-tree traversal as a Vulkan compute shader over
storage buffers with a wide hit record (the paper's future work; the same kd-tree, rays, ray tree
and shading pass). Prints the table, the stages, every column's CPU time per frame (all threads,
and the share of the cores it kept busy), and the ratios mobirt / Embree, mobirt / ray query and
mobirt / compute per cell, for the traversal alone (Mrays/s over the same rays), for the build
alone (kd-tree vs Embree BVH) and for the CPU time per frame, then how many cells meet each of
the frame's and the peers' targets (issues 16 and 15). mobirt's frames are pipelined
(frame N+1 posed and its kd-tree built on a worker while frame N renders; the frame time is the
loop's period) unless --serial; pipelined, each GPU column also renders every frame a second time
serially, so that its traversal passes are timed with the cores to themselves, as the peers' are,
and a table gives those passes and their ratios to the peers' (unless --no-serial-twin).

Without SCENE: the paper's scenes (scenes/toaster.gltf 400x240, marbles 240x400, fish 400x240)
and, when ../shared/scenes has them, the real Utah toasters and the wood doll.
)";

constexpr const char* kHelp = "mobirt bench --help";

struct Level {
  const char* key;
  const char* name;
  int depth;
  bool shadows;
};
constexpr Level kLevels[] = {{"cast", "ray casting", 0, false},
                             {"shadow", "+ shadow", 0, true},
                             {"bounce1", "+ 1 bounce", 1, true},
                             {"bounce2", "+ 2 bounces", 2, true}};

// One row of Table 1: a scene, how to load it, and the paper's figures (fps; NaN = none).
struct BenchScene {
  std::string name;
  std::string path;
  int width = 400, height = 240;
  std::string mtl;
  SceneEdits edits;  // the file's lights and camera replaced, as --light and --camera would
  double paper[4] = {NAN, NAN, NAN, NAN};
};

// The paper's Table 1 (the issue's targets are twice these). The paper gives one marbles figure;
// it is compared with ray casting.
std::vector<BenchScene> paper_scenes(const std::filesystem::path& scenes, const std::filesystem::path& shared) {
  std::vector<BenchScene> list;
  list.push_back({"toaster", (scenes / "toaster.gltf").string(), 400, 240, "", {}, {24, 20, 15, 12}});
  list.push_back({"marbles", (scenes / "marbles.gltf").string(), 240, 400, "", {}, {26, NAN, NAN, NAN}});
  list.push_back({"fish", (scenes / "fish.gltf").string(), 400, 240, "", {}, {48, NAN, 26, 20}});
  const std::filesystem::path toasters = shared / "utah-toasters" / "Toasters004.obj";
  if (std::filesystem::exists(toasters)) {
    list.push_back({"Utah toasters", toasters.string(), 400, 240, (scenes / "utah-toasters.mtl").string(),
                    {{parse_light("point pos=150,500,300 intensity=300000")},
                     parse_camera("0,260,480:0,20,0:0,1,0:40"),
                     {}},
                    {NAN, NAN, NAN, NAN}});
  }
  const std::filesystem::path doll = shared / "utah-wooddoll";
  if (std::filesystem::exists(doll / "wooddoll_00.obj")) {
    list.push_back({"Utah wood doll", (doll / "wooddoll_%02d.obj").string(), 400, 240, "",
                    {{parse_light("point pos=5,20,20 intensity=400")}, {}, {}}, {NAN, NAN, NAN, NAN}});
  }
  return list;
}

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

double mrays(double rays, double ms) { return ms > 0 ? rays / (ms * 1e3) : 0.0; }

// Per-frame samples of named stages; medians at the end.
struct Samples {
  std::vector<std::pair<std::string, std::vector<double>>> stages;
  void add(const std::string& stage, double value) {
    for (auto& [name, v] : stages) {
      if (name == stage) {
        v.push_back(value);
        return;
      }
    }
    stages.push_back({stage, {value}});
  }
  double med(const std::string& stage) const {
    for (const auto& [name, v] : stages) {
      if (name == stage) return median(v);
    }
    return 0.0;
  }
  const std::vector<double>& all(const std::string& stage) const {
    static const std::vector<double> none;
    for (const auto& [name, v] : stages) {
      if (name == stage) return v;
    }
    return none;
  }
  nlohmann::json medians() const {
    nlohmann::json j = nlohmann::json::object();
    for (const auto& [name, v] : stages) j[name] = median(v);
    return j;
  }
};

nlohmann::json fps_json(const std::vector<double>& frame_ms) {
  const double med = median(frame_ms);
  const auto [lo, hi] = std::minmax_element(frame_ms.begin(), frame_ms.end());
  return {{"median", med > 0 ? 1000.0 / med : 0.0},
          {"min", *hi > 0 ? 1000.0 / *hi : 0.0},
          {"max", *lo > 0 ? 1000.0 / *lo : 0.0}};
}

// One frame of any column, GPU passes or CPU engine: each stage the engine does not have stays 0.
// `step`: the frame came from a frame pipeline (render/frame_pipeline.h), whose step's wall clock
// is the frame's time; pipelined, its animate and build stages ran on the worker during the
// previous frame, so they are not parts of it. cpu_ms: the process's CPU time (all its threads:
// the driver's, the build worker's, TBB's) in the frame, its posing included.
void add_frame(Samples& s, double animate_ms, const FrameTimings& t, double cpu_ms,
               const PipelineStep* step = nullptr) {
  const GenerationTimings& g = t.sum;
  s.add("animate", animate_ms);
  s.add("cpu", cpu_ms);
  if (step) {
    s.add("render", step->render_ms);
    s.add("render_cpu", step->render_cpu_ms);
    s.add("ahead", step->ahead_ms);
    s.add("build_wait", step->wait_ms);
  }
  s.add("build", t.build_ms);
  s.add("rays", t.rays_ms);
  s.add("upload", g.upload_ms);
  s.add("trace", g.trace_ms);
  s.add("shadow", g.shadow_ms);
  s.add("readback", g.trace_readback_ms + g.shade_readback_ms);
  s.add("decode", g.decode_ms);
  s.add("shade", g.shade_ms);
  s.add("accumulate", g.accumulate_ms);
  s.add("secondary", g.secondary_ms);
  s.add("frame", step ? step->period_ms : animate_ms + t.total_ms);
  s.add("traced_rays", double(g.rays));
  s.add("shadow_rays", double(g.shadow_rays));
  s.add("shaded_rays", double(g.shaded));
  s.add("bytes_read", double(g.bytes_read));
  // The CPU engines cast their shadow rays after the closest hits; the passes, in the same pass.
  s.add("trace_mrays", mrays(double(g.rays + g.shadow_rays), g.trace_ms + g.shadow_ms));
  for (size_t k = 0; k < t.generations.size(); ++k) {
    const GenerationTimings& x = t.generations[k];
    const std::string p = "pass" + std::to_string(k) + "_";
    s.add(p + "rays", double(x.rays));
    s.add(p + "shadow_rays", double(x.shadow_rays));
    s.add(p + "trace_ms", x.trace_ms + x.shadow_ms);
    s.add(p + "mrays", mrays(double(x.rays + x.shadow_rays), x.trace_ms + x.shadow_ms));
    s.add(p + "shaded_rays", double(x.shaded));
    s.add(p + "bytes_read", double(x.bytes_read));
  }
}

struct BenchOptions {
  int frames = 30;
  int warmup = 3;
  std::vector<int> levels = {0, 1, 2, 3};
  unsigned threads = 0;
  bool baseline = true;
  bool cpu = true;
  ComputeData compute_data = ComputeData::StorageBuffers;  // how the compute peer reads the scene
  bool analytic = true;  // --primitives
  std::vector<std::string> backends = {"vulkan", "gles"};
  // mobirt's columns through the frame pipeline: frame N+1 posed and its kd-tree built on a worker
  // (in an arena of build_threads) while frame N renders; --serial: one after the other.
  bool pipelined = true;
  // Pipelined, every GPU column also renders each frame a second time, serially (pose, build, then
  // the passes, with the cores to themselves as the peers have them): its traversal passes are not
  // slowed by the next frame's build beside them, so their Mrays/s compare with the peers' on equal
  // terms (--no-serial-twin: not).
  bool serial_twin = true;
  unsigned build_threads = 0;  // 0: --threads
  VulkanOptions backend_options;  // the pipeline cache is Vulkan's
  RenderSettings settings;  // kd, stack, max_steps
};

// The GPU peers' columns: the driver's BVH and rayQueryEXT pass, mobirt's kd-tree as a compute
// pass, and a Vulkan backend of their own for mobirt's shading pass (so that the mobirt columns'
// textures and passes stay theirs). Made once per run; a peer is absent where the driver lacks it,
// both with --no-baseline.
struct GpuPeers {
  std::unique_ptr<RayQueryEngine> rq;
  std::unique_ptr<ComputeEngine> compute;
  std::unique_ptr<Backend> shading;  // when either is there
};

// Throws when a Vulkan context of the run reported validation messages.
void check_messages(std::vector<std::string> messages) {
  for (const std::string& m : messages) throw Error(ErrorKind::Internal, "validation: " + m);
}

struct CellResult {
  nlohmann::json json;
};

std::string cell_fps(const nlohmann::json& fps) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.1f [%.1f-%.1f]", fps["median"].get<double>(), fps["min"].get<double>(),
                fps["max"].get<double>());
  return buf;
}

// The GPU columns: one backend each, under the JSON key "mobirt" (Vulkan) or "mobirt_gles".
struct GpuColumn {
  std::string key;
  std::unique_ptr<Backend> backend;
};

nlohmann::json run_cell(std::vector<GpuColumn>& columns, GpuPeers& peers, const BenchScene& bs,
                        const AnimatedScene& animation, const Level& level, const BenchOptions& o) {
  RenderSettings settings = o.settings;
  settings.width = bs.width;
  settings.height = bs.height;
  settings.depth = level.depth;
  settings.shadows = level.shadows;
  settings.always_rebuild = true;  // the paper's model: a new kd-tree every frame
  std::vector<std::unique_ptr<Renderer>> renderers;
  for (GpuColumn& c : columns) renderers.push_back(std::make_unique<Renderer>(*c.backend, settings));
  std::optional<EmbreeEngine> embree;
  std::optional<KdTreeEngine> kd;
  if (o.baseline) embree.emplace(EmbreeOptions{o.threads, true});
  if (o.baseline && o.cpu) kd.emplace(settings.kd, settings.shadow_rays.ray_test);
  std::optional<Renderer> rq_shading, compute_shading;
  std::optional<RayQueryWhittedEngine> ray_query;
  std::optional<ComputeWhittedEngine> compute;
  if (peers.rq) ray_query.emplace(*peers.rq, rq_shading.emplace(*peers.shading, settings));
  if (peers.compute) compute.emplace(*peers.compute, compute_shading.emplace(*peers.shading, settings));

  PosedScene posed(animation, bs.edits, bs.width, bs.height);
  const Scene& scene = posed.scene;
  std::vector<Samples> gpu(columns.size());
  Samples emb, cpu, rqs, cps;
  const double fps = animation.fps() > 0 ? animation.fps() : 24.0;
  // Each GPU column's frames go through a frame pipeline of its own (serial with --serial), posing
  // into two scenes of its own, one per slot; the peers render the shared posed scene.
  std::vector<std::unique_ptr<PosedScene>> slots;
  const auto make_pipeline = [&](bool pipelined) {
    PosedScene* mine[2];
    for (PosedScene*& p : mine) p = slots.emplace_back(std::make_unique<PosedScene>(animation, bs.edits, bs.width, bs.height)).get();
    auto pipeline = std::make_unique<FramePipeline>(
        size_t(o.warmup + o.frames),
        [mine, fps](int slot, size_t index) {
          const Camera view = mine[slot]->at(double(index) / fps);
          return std::make_pair(static_cast<const Scene*>(&mine[slot]->scene), view);
        },
        settings.kd, settings.always_rebuild, pipelined);
    pipeline->set_render_settings(settings);
    return pipeline;
  };
  std::vector<std::unique_ptr<FramePipeline>> pipelines;
  for (size_t c = 0; c < columns.size(); ++c) pipelines.push_back(make_pipeline(o.pipelined));
  // The serial twins (BenchOptions::serial_twin): a renderer and a serial pipeline of their own per
  // GPU column, on the column's backend, rendering the same frames.
  const bool twins = o.pipelined && o.serial_twin;
  std::vector<std::unique_ptr<Renderer>> twin_renderers;
  std::vector<std::unique_ptr<FramePipeline>> twin_pipelines;
  std::vector<Samples> twin(columns.size());
  for (size_t c = 0; twins && c < columns.size(); ++c) {
    twin_renderers.push_back(std::make_unique<Renderer>(*columns[c].backend, settings));
    twin_pipelines.push_back(make_pipeline(false));
  }
  KdBuildStats kd_stats;
  // Embree and the driver's ray queries take triangles only: they get the analytic shapes
  // tessellated (the triangles --primitives tessellated loads), made outside the timed frames.
  std::optional<Scene> tessellated;
  bool any_kd_tree = false;  // some timed frame of a GPU column had a kd-tree
  for (int f = 0; f < o.warmup + o.frames; ++f) {
    const bool timed = f >= o.warmup;
    const double t = double(f) / fps;
    auto start = std::chrono::steady_clock::now();
    const double pose_cpu_start = process_cpu_ms();
    const Camera view = posed.at(t);
    const double animate_ms = elapsed_ms(start);
    const double animate_cpu_ms = process_cpu_ms() - pose_cpu_start;  // part of every peer's frame
    if (!scene.shapes.empty() && (ray_query || compute || embree) && (!tessellated || animation.animated())) {
      tessellated = scene;
      tessellate_shapes(*tessellated);
    }
    const Scene& triangles_only = tessellated ? *tessellated : scene;

    // Frame f of GPU column c through a pipeline and a renderer of the column's backend.
    const auto gpu_frame = [&](size_t c, FramePipeline& pipeline, Renderer& renderer, Samples& samples) {
      FrameTimings ft;
      double pose_ms = 0, tree_rays = 0;
      const double cpu_start = process_cpu_ms();
      const PipelineStep step = pipeline.step(size_t(f), [&](PreparedFrame& prepared) {
        render_prepared(renderer, prepared, &ft);
        pose_ms = prepared.pose_ms;
        tree_rays = prepared.tree_built ? prepared.tree_rays : 0.0;
      });
      const double cpu_ms = process_cpu_ms() - cpu_start;
      check_messages(columns[c].backend->take_debug_messages());
      if (timed) {
        add_frame(samples, pose_ms, ft, cpu_ms, &step);
        // mobirt's columns only: the kd-tree's walks in the passes (GenerationTimings::walks), the
        // mirror rays drawn (--mirrors), what the frame's kd-tree was built for (--tree; 0: a full
        // tree, or none where the frame built no kd-tree: the cell's kd_tree_built).
        samples.add("walks", double(ft.sum.walks));
        samples.add("mirrored", double(ft.sum.mirrored));
        samples.add("cpu_walked", double(ft.sum.cpu_walked));
        samples.add("tree_rays", tree_rays);
      }
      // What the frame had, not what was planned: a light whose buffer does not pay, or a capped
      // ray, makes a frame planned without a kd-tree build one (Renderer::Engine).
      if (timed && renderer.frame_had_kd_tree()) any_kd_tree = true;
    };
    for (size_t c = 0; c < columns.size(); ++c) {
      gpu_frame(c, *pipelines[c], *renderers[c], gpu[c]);
      // The same frame again, serially (the pipelined step returned after its worker finished).
      if (twins) gpu_frame(c, *twin_pipelines[c], *twin_renderers[c], twin[c]);
    }
    // A GPU peer's frame: mobirt's loop with the peer tracing, its validation messages checked.
    auto peer_frame = [&](WhittedEngine& engine, std::vector<std::string> messages, Samples& samples) {
      FrameTimings ft;
      const double cpu_start = process_cpu_ms();
      render_whitted(triangles_only, view, settings, engine, &ft);
      const double cpu_ms = animate_cpu_ms + process_cpu_ms() - cpu_start;
      check_messages(std::move(messages));
      check_messages(peers.shading->take_debug_messages());
      if (timed) add_frame(samples, animate_ms, ft, cpu_ms);
    };
    if (ray_query) peer_frame(*ray_query, peers.rq->take_debug_messages(), rqs);
    if (compute) peer_frame(*compute, peers.compute->take_debug_messages(), cps);
    if (embree) {
      FrameTimings ct;
      const double cpu_start = process_cpu_ms();
      render_whitted_cpu(triangles_only, view, settings, *embree, o.threads, &ct);
      const double cpu_ms = animate_cpu_ms + process_cpu_ms() - cpu_start;
      if (timed) add_frame(emb, animate_ms, ct, cpu_ms);
    }
    if (kd) {
      FrameTimings ct;
      const double cpu_start = process_cpu_ms();
      render_whitted_cpu(scene, view, settings, *kd, o.threads, &ct);
      const double cpu_ms = animate_cpu_ms + process_cpu_ms() - cpu_start;
      if (timed) add_frame(cpu, animate_ms, ct, cpu_ms);
      kd_stats = kd->tree().stats;
    }
  }

  nlohmann::json cell;
  cell["scene"] = bs.name;
  cell["path"] = bs.path;
  cell["size"] = std::to_string(bs.width) + "x" + std::to_string(bs.height);
  cell["level"] = level.key;
  cell["level_name"] = level.name;
  cell["depth"] = level.depth;
  cell["shadows"] = level.shadows;
  cell["triangles"] = scene.mesh.triangle_count();
  cell["primary"] = primaries_rasterized(scene, settings) ? "raster" : "trace";  // what --primary chose
  // False where no timed frame had a kd-tree (frame_walks_tree, and no light's buffer or capped ray
  // made one needed): the frames' "build" is then only the primitives' texels (flatten_primitives)
  // and the light buffers, not a kd-tree, and no build ratio is given.
  const bool tree_built = any_kd_tree;
  cell["kd_tree_built"] = tree_built;
  cell["shapes"] = scene.shapes.size();
  cell["lights"] = scene.lights.size();
  cell["animated"] = animation.animated();
  const double paper = bs.paper[&level - kLevels];
  cell["paper_fps"] = std::isnan(paper) ? nlohmann::json(nullptr) : nlohmann::json(paper);
  cell["target_fps"] = std::isnan(paper) ? nlohmann::json(nullptr) : nlohmann::json(2 * paper);
  double best_fps = 0;
  for (size_t c = 0; c < columns.size(); ++c) {
    const std::string& key = columns[c].key;
    cell[key] = {{"fps", fps_json(gpu[c].all("frame"))}, {"stages_ms", gpu[c].medians()}, {"pipelined", o.pipelined}};
    // Whether the column's pipelined worker ran at SCHED_IDLE (--worker idle, where Linux granted it).
    if (o.pipelined) cell[key]["worker_idle"] = pipelines[c]->worker_at_idle_priority();
    const double gpu_fps = cell[key]["fps"]["median"];
    best_fps = std::max(best_fps, gpu_fps);
    // fps over a peer's fps; a stage's median over the peer's (traversal: Mrays/s on the same rays).
    auto fps_over = [&](const Samples& peer_samples) {
      return gpu_fps / (1000.0 / std::max(median(peer_samples.all("frame")), 1e-9));
    };
    auto stage_over = [](const Samples& mine, const Samples& peer_samples, const char* stage) {
      return mine.med(stage) / std::max(peer_samples.med(stage), 1e-9);
    };
    auto traversal_over = [&](const Samples& peer_samples) { return stage_over(gpu[c], peer_samples, "trace_mrays"); };
    if (embree) {
      cell["ratios"][key] = {{"fps_over_embree", fps_over(emb)},
                             {"traversal_over_embree", traversal_over(emb)},
                             {"build_over_embree", tree_built ? nlohmann::json(stage_over(gpu[c], emb, "build"))
                                                              : nlohmann::json(nullptr)},
                             {"cpu_over_embree", stage_over(gpu[c], emb, "cpu")}};
    }
    if (ray_query) {
      cell["ratios"][key]["fps_over_ray_query"] = fps_over(rqs);
      cell["ratios"][key]["traversal_over_ray_query"] = traversal_over(rqs);
    }
    if (compute) {
      cell["ratios"][key]["fps_over_compute"] = fps_over(cps);
      cell["ratios"][key]["traversal_over_compute"] = traversal_over(cps);
    }
    if (twins) {
      cell[key]["serial"] = {
          {"fps", fps_json(twin[c].all("frame"))}, {"stages_ms", twin[c].medians()}, {"pipelined", false}};
      // The serial twin's traversal passes over a peer's, on the same rays; its build over
      // Embree's, both with the cores to themselves; the pipelined fps over the twin's (what
      // pipelining buys).
      auto serial_traversal_over = [&](const Samples& peer_samples) {
        return stage_over(twin[c], peer_samples, "trace_mrays");
      };
      cell[key]["serial"]["pipelined_fps_over_serial"] =
          gpu_fps / std::max(cell[key]["serial"]["fps"]["median"].get<double>(), 1e-9);
      if (embree) {
        cell["ratios"][key]["serial_traversal_over_embree"] = serial_traversal_over(emb);
        cell["ratios"][key]["serial_build_over_embree"] =
            tree_built ? nlohmann::json(stage_over(twin[c], emb, "build")) : nlohmann::json(nullptr);
      }
      if (ray_query) cell["ratios"][key]["serial_traversal_over_ray_query"] = serial_traversal_over(rqs);
      if (compute) cell["ratios"][key]["serial_traversal_over_compute"] = serial_traversal_over(cps);
    }
  }
  cell["meets_target"] = std::isnan(paper) ? nlohmann::json(nullptr) : nlohmann::json(best_fps >= 2 * paper);
  if (embree) cell["embree"] = {{"fps", fps_json(emb.all("frame"))}, {"stages_ms", emb.medians()}};
  if (ray_query) cell["ray_query"] = {{"fps", fps_json(rqs.all("frame"))}, {"stages_ms", rqs.medians()}};
  if (compute) cell["compute"] = {{"fps", fps_json(cps.all("frame"))}, {"stages_ms", cps.medians()}};
  if (kd) {
    cell["cpu_kd"] = {{"fps", fps_json(cpu.all("frame"))}, {"stages_ms", cpu.medians()}};
    cell["kd_tree"] = {{"sah_cost", kd_stats.sah_cost},
                       {"nodes", kd_stats.nodes},
                       {"leaves", kd_stats.leaves},
                       {"prim_references", kd_stats.prim_references},
                       {"max_depth", kd_stats.max_depth_reached},
                       {"max_leaf", kd_stats.max_leaf_size}};
  }
  return cell;
}

std::string opt(const nlohmann::json& j, const char* key, const char* fmt) {
  if (!j.contains(key) || j[key].is_null()) return "-";
  char buf[32];
  std::snprintf(buf, sizeof buf, fmt, j[key].get<double>());
  return buf;
}

const char* column_title(const std::string& key) {
  return key == "mobirt" ? "Vulkan" : key == "mobirt_gles" ? "GLES 2.0" : key == "compute" ? "compute" : "ray query";
}

// A cell's row label: "scene, level".
std::string cell_label(const nlohmann::json& c) {
  return c["scene"].get<std::string>() + ", " + c["level_name"].get<std::string>();
}

// mobirt's frame loop: what the rendering thread did and, pipelined, what the worker did beside it.
void print_frame_loop(const nlohmann::json& cells, const std::vector<std::string>& gpus, bool pipelined) {
  std::printf("\nmobirt's frame loop, %s, ms (median): render = upload, passes, decoding and ray tree on\n"
              "the rendering thread; cpu = its own CPU time in them (the rest it waits: on fences while the\n"
              "driver's threads run the passes, or for its decoding threads); ahead = posing + kd-tree build\n"
              "of the next frame on the worker meanwhile; wait = the rendering thread waiting for the worker\n"
              "afterwards (the build not hidden); frame = the loop's period.%s\n",
              pipelined ? "pipelined" : "serial",
              pipelined ? "\nIn the stage tables above, anim and build are the worker's, not parts of the frame." : "");
  std::printf("%-28s %-8s %7s %7s %7s %7s %7s\n", "scene, level", "backend", "render", "cpu", "ahead", "wait", "frame");
  for (const nlohmann::json& c : cells) {
    for (const std::string& g : gpus) {
      const nlohmann::json& s = c[g]["stages_ms"];
      std::printf("%-28s %-8s %7.2f %7.2f %7.2f %7.2f %7.2f\n",
                  cell_label(c).c_str(),
                  column_title(g), s["render"].get<double>(), s["render_cpu"].get<double>(), s["ahead"].get<double>(),
                  s["build_wait"].get<double>(), s["frame"].get<double>());
    }
  }
}

// The serial twins (BenchOptions::serial_twin): the traversal passes with the cores to themselves.
void print_serial_twins(const nlohmann::json& cells, const std::vector<std::string>& gpus, bool baseline,
                        bool ray_query, bool compute) {
  if (gpus.empty() || !cells[0][gpus[0]].contains("serial")) return;
  std::string peers;
  for (const auto& [on, name] : {std::pair<bool, const char*>{baseline, "Embree's (trc/emb)"},
                                 {ray_query, "the ray queries' (trc/rq)"},
                                 {compute, "the compute pass's (trc/cp)"}}) {
    if (on) peers += std::string(peers.empty() ? "" : ", ") + name;
  }
  std::printf("\nmobirt's frames again, serial: each GPU column renders every frame a second time, posing, build\n"
              "and passes one after the other, as the peers render theirs, so that nothing else runs beside\n"
              "its traversal passes (pipelined, the next frame's build does). fps and pipe/ser: the serial\n"
              "loop's frame rate and the pipelined one's over it; trace: the traversal passes, ms and Mrays/s%s.\n",
              peers.empty() ? "" : (";\nthen those Mrays/s over each peer's on the same rays: " + peers).c_str());
  std::printf("%-28s", "scene, level");
  for (const std::string& g : gpus) {
    std::printf(" | %-8s %6s %8s %7s %7s", column_title(g), "fps", "pipe/ser", "trace", "Mrays/s");
    if (baseline) std::printf(" %7s", "trc/emb");
    if (ray_query) std::printf(" %7s", "trc/rq");
    if (compute) std::printf(" %7s", "trc/cp");
  }
  std::printf("\n");
  for (const nlohmann::json& c : cells) {
    std::printf("%-28s", cell_label(c).c_str());
    for (const std::string& g : gpus) {
      const nlohmann::json& serial = c[g]["serial"];
      std::printf(" | %-8s %6.1f %7.2fx %7.2f %7.2f", "", serial["fps"]["median"].get<double>(),
                  serial["pipelined_fps_over_serial"].get<double>(), serial["stages_ms"]["trace"].get<double>(),
                  serial["stages_ms"]["trace_mrays"].get<double>());
      if (!baseline && !ray_query && !compute) continue;
      const nlohmann::json& r = c["ratios"][g];
      if (baseline) std::printf(" %6.2fx", r["serial_traversal_over_embree"].get<double>());
      if (ray_query) std::printf(" %6.2fx", r["serial_traversal_over_ray_query"].get<double>());
      if (compute) std::printf(" %6.2fx", r["serial_traversal_over_compute"].get<double>());
    }
    std::printf("\n");
  }
}

// The targets of the frame issue and the peers issue (issues 16 and 15), over the run's cells: how
// many cells meet each (the exact ratio, not its rounding), its smallest and largest ratio, and
// the same per scene in the order the scenes ran. A target whose ratio no cell has (a peer left
// out) is left out. The README's targets tables are this, from one run.
struct BenchTarget {
  const char* column;  // "mobirt" (Vulkan) or "mobirt_gles"
  const char* ratio;   // a key of cell.ratios.<column>
  double at_least;
  const char* label;
};
constexpr BenchTarget kBenchTargets[] = {
    {"mobirt", "fps_over_embree", 1.0, "Vulkan frame >= 1.0x Embree's"},
    {"mobirt_gles", "fps_over_embree", 0.8, "GLES frame >= 0.8x Embree's"},
    {"mobirt", "traversal_over_embree", 1.0, "traversal >= 1.0x Embree's, same rays, pipelined"},
    {"mobirt", "serial_traversal_over_embree", 1.0, "the same, the passes alone (serial twin)"},
    {"mobirt", "fps_over_ray_query", 1.0, "Vulkan frame >= 1.0x the ray queries'"},
    {"mobirt", "traversal_over_ray_query", 2.0, "traversal >= 2.0x the ray queries', pipelined"},
};

nlohmann::json target_summary(const nlohmann::json& cells) {
  nlohmann::json out = nlohmann::json::array();
  for (const BenchTarget& t : kBenchTargets) {
    size_t counted = 0, met = 0;
    double lo = 0.0, hi = 0.0;
    nlohmann::json scenes = nlohmann::json::array();  // {scene, min, max} in the order the scenes ran
    for (const nlohmann::json& c : cells) {
      if (!c.contains("ratios") || !c["ratios"].contains(t.column)) continue;
      const nlohmann::json& r = c["ratios"][t.column];
      if (!r.contains(t.ratio) || !r[t.ratio].is_number()) continue;
      const double v = r[t.ratio].get<double>();
      lo = counted == 0 ? v : std::min(lo, v);
      hi = counted == 0 ? v : std::max(hi, v);
      ++counted;
      if (v >= t.at_least) ++met;
      const std::string scene = c["scene"].get<std::string>();
      auto it = std::find_if(scenes.begin(), scenes.end(), [&](const nlohmann::json& e) { return e["scene"] == scene; });
      if (it == scenes.end()) {
        scenes.push_back({{"scene", scene}, {"min", v}, {"max", v}});
      } else {
        (*it)["min"] = std::min((*it)["min"].get<double>(), v);
        (*it)["max"] = std::max((*it)["max"].get<double>(), v);
      }
    }
    if (counted == 0) continue;
    out.push_back({{"target", t.label}, {"column", t.column}, {"ratio", t.ratio}, {"at_least", t.at_least},
                   {"cells", counted}, {"met", met}, {"min", lo}, {"max", hi}, {"scenes", scenes}});
  }
  return out;
}

void print_targets(const nlohmann::json& targets) {
  if (targets.empty()) return;
  std::printf("\nTargets (issues 15 and 16) over this run's cells: how many meet each (the exact ratio), its range,\n"
              "and per scene the range over its levels\n");
  for (const nlohmann::json& t : targets) {
    std::printf("%s: %zu of %zu cells (%.2f-%.2fx;", t["target"].get<std::string>().c_str(), t["met"].get<size_t>(),
                t["cells"].get<size_t>(), t["min"].get<double>(), t["max"].get<double>());
    const char* sep = " ";
    for (const nlohmann::json& e : t["scenes"]) {
      std::printf("%s%s %.2f-%.2fx", sep, e["scene"].get<std::string>().c_str(), e["min"].get<double>(),
                  e["max"].get<double>());
      sep = ", ";
    }
    std::printf(")\n");
  }
}

void print_tables(const nlohmann::json& result) {
  const nlohmann::json& cells = result["cells"];
  if (cells.empty()) return;
  std::vector<std::string> gpus;
  for (const char* key : {"mobirt", "mobirt_gles"}) {
    if (cells[0].contains(key)) gpus.push_back(key);
  }
  const bool baseline = cells[0].contains("embree");
  const bool cpu = cells[0].contains("cpu_kd");
  const bool ray_query = cells[0].contains("ray_query");
  const bool compute = cells[0].contains("compute");

  std::printf("\nTable 1: frames per second, median [min-max]; paper = the MobiRT paper, target = 2x paper; mobirt's\n"
              "frames %s\n", result["settings"]["pipelined"].get<bool>() ? "pipelined (next frame posed and built meanwhile)"
                                                                         : "serial (--serial)");
  std::printf("%-28s %-8s %5s %6s", "scene, level", "size", "paper", "target");
  for (const std::string& g : gpus) std::printf("  %-18s", (std::string("mobirt ") + column_title(g)).c_str());
  if (ray_query) std::printf("  %-18s", "ray query (Vulkan)");
  if (compute) std::printf("  %-18s", "compute (Vulkan)");
  if (baseline) std::printf("  %-18s", "Embree 3");
  if (cpu) std::printf("  %-18s", "CPU kd-tree");
  std::printf("\n");
  for (const nlohmann::json& c : cells) {
    std::printf("%-28s %-8s %5s %6s", cell_label(c).c_str(), c["size"].get<std::string>().c_str(),
                opt(c, "paper_fps", "%.0f").c_str(), opt(c, "target_fps", "%.0f").c_str());
    for (const std::string& g : gpus) std::printf("  %-18s", cell_fps(c[g]["fps"]).c_str());
    if (ray_query) std::printf("  %-18s", cell_fps(c["ray_query"]["fps"]).c_str());
    if (compute) std::printf("  %-18s", cell_fps(c["compute"]["fps"]).c_str());
    if (baseline) std::printf("  %-18s", cell_fps(c["embree"]["fps"]).c_str());
    if (cpu) std::printf("  %-18s", cell_fps(c["cpu_kd"]["fps"]).c_str());
    std::printf("\n");
  }

  // The GPU peers have the same stages as mobirt's passes: their build (the driver's BVH, or
  // mobirt's kd-tree), their traversal pass, and mobirt's decoding, shading pass and ray tree.
  std::vector<std::string> staged = gpus;
  if (ray_query) staged.push_back("ray_query");
  if (compute) staged.push_back("compute");
  for (const std::string& g : staged) {
    const std::string title = g == "ray_query" ? "The driver's ray query"
                              : g == "compute" ? "mobirt's kd-tree as a compute pass"
                                               : "mobirt on " + std::string(column_title(g));
    std::printf("\n%s, per stage, ms (median): animate, %s build, primary rays, upload, traversal\n"
                "passes, read-back, hit decoding, shading passes, accumulate, secondary rays, frame; Mrays/s of\n"
                "the traversal passes (closest-hit + shadow rays); KB that left the GPU (4 bytes per ray and pass;\n"
                "the compute pass: %d per ray)\n",
                title.c_str(), g == "ray_query" ? "BLAS + TLAS" : "kd-tree", MOBIRT_HIT_RECORD_BYTES);
    std::printf("%-28s %6s %6s %5s %6s %7s %6s %6s %6s %5s %6s %7s %7s %6s\n", "scene, level", "anim", "build",
                "rays", "upload", "trace", "rdback", "decode", "shade", "accum", "second", "frame", "Mrays/s", "KB");
    for (const nlohmann::json& c : cells) {
      const nlohmann::json& s = c[g]["stages_ms"];
      std::printf("%-28s %6.2f %6.2f %5.2f %6.2f %7.2f %6.2f %6.2f %6.2f %5.2f %6.2f %7.2f %7.2f %6.0f\n",
                  cell_label(c).c_str(), s["animate"].get<double>(), s["build"].get<double>(), s["rays"].get<double>(),
                  s["upload"].get<double>(), s["trace"].get<double>(), s["readback"].get<double>(),
                  s["decode"].get<double>(), s["shade"].get<double>(), s["accumulate"].get<double>(),
                  s["secondary"].get<double>(), s["frame"].get<double>(), s["trace_mrays"].get<double>(),
                  s["bytes_read"].get<double>() / 1024.0);
    }
    std::printf("traversal passes, median per pass [generation] rays+shadow rays, ms, Mrays/s, KB read back:\n");
    for (const nlohmann::json& c : cells) {
      const nlohmann::json& s = c[g]["stages_ms"];
      std::printf("%-28s", cell_label(c).c_str());
      for (int k = 0; s.contains("pass" + std::to_string(k) + "_rays"); ++k) {
        const std::string p = "pass" + std::to_string(k) + "_";
        std::printf("  [%d] %.0f+%.0f %.1f ms %.2f %.0f", k, s[p + "rays"].get<double>(),
                    s[p + "shadow_rays"].get<double>(), s[p + "trace_ms"].get<double>(),
                    s[p + "mrays"].get<double>(), s[p + "bytes_read"].get<double>() / 1024.0);
      }
      std::printf("\n");
    }
  }
  print_frame_loop(cells, gpus, result["settings"]["pipelined"].get<bool>());
  print_serial_twins(cells, gpus, baseline, ray_query, compute);

  // What each column costs the machine: on a machine whose cores every column keeps busy, the
  // frame rate follows the CPU time a frame needs.
  std::vector<std::string> engines = staged;
  for (const char* key : {"embree", "cpu_kd"}) {
    if (cells[0].contains(key)) engines.push_back(key);
  }
  const unsigned cores = std::max(1u, result["machine"]["cores"].get<unsigned>());
  std::printf("\nCPU time per frame, ms (median): every thread of the process during the column's frame (the\n"
              "driver's, the kd-tree worker's, the pools'), posing included; busy = CPU time / (frame x %u cores)\n",
              cores);
  std::printf("%-28s", "scene, level");
  for (const std::string& e : engines) {
    const std::string title = e == "embree" ? "Embree" : e == "cpu_kd" ? "CPU kd" : column_title(e);
    std::printf("  %9s %5s", title.c_str(), "busy");
  }
  std::printf("\n");
  for (const nlohmann::json& c : cells) {
    std::printf("%-28s", cell_label(c).c_str());
    for (const std::string& e : engines) {
      const nlohmann::json& s = c[e]["stages_ms"];
      const double frame = s["frame"].get<double>();
      std::printf("  %9.2f %4.0f%%", s["cpu"].get<double>(),
                  frame > 0 ? 100.0 * s["cpu"].get<double>() / (frame * cores) : 0.0);
    }
    std::printf("\n");
  }
  if (!baseline) return;

  std::printf("\nEmbree 3 and the CPU kd-tree on %u threads, per stage, ms (median): build, primary rays, closest\n"
              "hits, shadow rays, shading + accumulate, secondary rays, frame; Mrays/s of closest + shadow rays\n",
              result["machine"]["threads"].get<unsigned>());
  std::printf("%-28s %-7s %6s %5s %7s %7s %6s %6s %7s %7s\n", "scene, level", "engine", "build", "rays", "closest",
              "shadow", "shade", "second", "frame", "Mrays/s");
  for (const nlohmann::json& c : cells) {
    for (const char* key : {"embree", "cpu_kd"}) {
      if (!c.contains(key)) continue;
      const nlohmann::json& s = c[key]["stages_ms"];
      std::printf("%-28s %-7s %6.2f %5.2f %7.2f %7.2f %6.2f %6.2f %7.2f %7.2f\n", cell_label(c).c_str(),
                  std::string(key) == "embree" ? "Embree" : "CPU kd", s["build"].get<double>(),
                  s["rays"].get<double>(), s["trace"].get<double>(), s["shadow"].get<double>(),
                  s["shade"].get<double>() + s["accumulate"].get<double>(), s["secondary"].get<double>(),
                  s["frame"].get<double>(),
                  s["trace_mrays"].get<double>());
    }
  }

  std::printf("\nRatios mobirt / Embree, the same frames: fps; traversal alone (Mrays/s on the same rays: GPU\n"
              "traversal passes, and the CPU walks of generations of at most --cpu-walks rays, vs rtcIntersect1 +\n"
              "rtcOccluded1); build alone (kd-tree build ms / Embree BVH\n"
              "build ms, >1 = slower; the serial twin's build where it ran: the pipelined worker's wall clock\n"
              "spreads over the idle time of its frame); cpu (CPU time per frame, all threads, >1 = more);\n"
              "%s%sSAH cost of the kd-tree built\n",
              ray_query ? "mobirt / ray query (fps/rq, trc/rq): fps, traversal alone\n(Mrays/s on the same rays); "
                        : "",
              compute ? "mobirt / compute (fps/cp, trc/cp): the same; " : "");
  std::printf("%-28s", "scene, level");
  for (const std::string& g : gpus) {
    std::printf(" | %-8s %7s %7s %7s %7s", column_title(g), "fps", "trace", "build", "cpu");
    if (ray_query) std::printf(" %7s %7s", "fps/rq", "trc/rq");
    if (compute) std::printf(" %7s %7s", "fps/cp", "trc/cp");
  }
  std::printf(" | %8s\n", "SAH");
  for (const nlohmann::json& c : cells) {
    std::printf("%-28s", cell_label(c).c_str());
    for (const std::string& g : gpus) {
      const nlohmann::json& r = c["ratios"][g];
      char build[16] = "      -";  // no kd-tree built (rasterized primaries, no ray walks one)
      // The serial twin's build, with the cores to itself, where it ran: the pipelined worker runs
      // at idle priority (--worker), so its wall clock is the idle time it found, not its cost.
      const nlohmann::json& build_ratio =
          r.contains("serial_build_over_embree") ? r["serial_build_over_embree"] : r["build_over_embree"];
      if (!build_ratio.is_null()) std::snprintf(build, sizeof build, "%6.1fx", build_ratio.get<double>());
      std::printf(" | %-8s %6.2fx %6.2fx %s %6.2fx", "", r["fps_over_embree"].get<double>(),
                  r["traversal_over_embree"].get<double>(), build, r["cpu_over_embree"].get<double>());
      if (ray_query) {
        std::printf(" %6.2fx %6.2fx", r["fps_over_ray_query"].get<double>(),
                    r["traversal_over_ray_query"].get<double>());
      }
      if (compute) {
        std::printf(" %6.2fx %6.2fx", r["fps_over_compute"].get<double>(), r["traversal_over_compute"].get<double>());
      }
    }
    std::printf(" | %8s\n", cpu ? opt(c["kd_tree"], "sah_cost", "%.1f").c_str() : "-");
  }
}

// One line on stderr per finished cell, so that a run of minutes shows where it is: the cell, how
// many of the run's cells are done, and each column's median fps in it.
void print_progress(const nlohmann::json& cell, size_t done, size_t total, double seconds) {
  std::string line = "bench: [" + std::to_string(done) + "/" + std::to_string(total) + "] " +
                     cell_label(cell) + " (primary " + cell.value("primary", std::string("trace")) + "):";
  for (const auto& [key, title] : {std::pair<const char*, const char*>{"mobirt", "Vulkan"},
                                   {"mobirt_gles", "GLES 2.0"}, {"ray_query", "ray query"}, {"compute", "compute"},
                                   {"embree", "Embree 3"}, {"cpu_kd", "CPU kd-tree"}}) {
    if (!cell.contains(key)) continue;
    char buf[64];
    std::snprintf(buf, sizeof buf, " %s %.1f fps,", title, cell[key]["fps"]["median"].get<double>());
    line += buf;
  }
  line.pop_back();
  char buf[48];
  std::snprintf(buf, sizeof buf, " (%.0f s so far)\n", seconds);
  std::fputs((line + buf).c_str(), stderr);
}

// The project's scenes: ./scenes when run from the repository, else the source tree's.
std::filesystem::path default_scenes_dir() {
  if (std::filesystem::exists("scenes/toaster.gltf")) return "scenes";
  return MOBIRT_SOURCE_SCENES;
}

}  // namespace

int cmd_bench(const std::vector<std::string>& args) {
  BenchOptions o;
  std::string json_path;
  std::filesystem::path scenes_dir, shared_dir;
  int width = 400, height = 240;
  cli::CommonOptions common;
  cli::CommandLine cl(cli::kBench, "Usage: mobirt bench [SCENE...] [options]", kBenchAbout, kHelp, common);
  cl.option("--frames", "N", "timed frames per cell (default 30)",
            [&](const cli::Value& v) { o.frames = v.integer(1, 100000); });
  cl.option("--warmup", "N", "frames before timing starts, per cell (default 3)",
            [&](const cli::Value& v) { o.warmup = v.integer(0, 100000); });
  cl.option("--levels", "LIST", "the columns, any of cast,shadow,bounce1,bounce2 (default all four)",
            [&](const cli::Value& v) {
              o.levels.clear();
              size_t p = 0;
              while (p <= v.text.size()) {
                const size_t q = std::min(v.text.find(',', p), v.text.size());
                const std::string key = v.text.substr(p, q - p);
                int found = -1;
                for (int k = 0; k < 4; ++k) found = key == kLevels[k].key ? k : found;
                if (found < 0) {
                  cli::usage_error("--levels: unknown level '" + key + "' (cast, shadow, bounce1, bounce2)", kHelp);
                }
                o.levels.push_back(found);
                p = q + 1;
              }
            });
  cl.option("--size", "WxH", "image size for SCENEs given on the command line (default 400x240)",
            [&](const cli::Value& v) { std::tie(width, height) = cli::parse_size(v.option, v.text, kHelp); });
  cl.option("--threads", "N",
            "CPU threads of the Embree and CPU kd-tree columns and of the kd-tree build\n"
            "(default: all cores); lavapipe's threads are set by LP_NUM_THREADS",
            [&](const cli::Value& v) { o.threads = unsigned(v.integer(1, 1024)); });
  cl.option("--build-threads", "N",
            "threads of mobirt's kd-tree build (its TBB arena; default --threads): its\n"
            "share of the CPU beside lavapipe's LP_NUM_THREADS when pipelined",
            [&](const cli::Value& v) { o.build_threads = unsigned(v.integer(1, 1024)); });
  cl.flag("--serial",
          "mobirt's frames one stage after the other (pose, build, passes) instead of\n"
          "pipelined (frame N+1 posed and built on a worker while frame N renders)",
          [&] { o.pipelined = false; });
  cl.flag("--no-serial-twin",
          "pipelined: render each frame once, without the second, serial rendering and\n"
          "its table (mobirt's frames again, serial); the run takes about a third less time",
          [&] { o.serial_twin = false; });
  cl.flag("--no-baseline", "leave out the peers: the ray-query, compute, Embree and CPU kd-tree columns",
          [&] { o.baseline = false; });
  cl.flag("--no-cpu", "leave out the CPU kd-tree column only", [&] { o.cpu = false; });
  cl.option("--compute-data", "READS",
            "how the compute column reads the scene: storage-buffers (default) or\n"
            "texel-buffers (as mobirt's fragment pass reads it)",
            [&](const cli::Value& v) {
              if (!parse_compute_data(v.text, o.compute_data)) {
                cli::usage_error("--compute-data " + v.text + ": expected storage-buffers or texel-buffers", kHelp);
              }
            });
  cl.option("--json", "FILE", "every number as JSON (- = standard output)",
            [&](const cli::Value& v) { json_path = v.text; });
  cl.option("--scenes", "DIR", "the project's scenes (default: ./scenes, else the source tree's)",
            [&](const cli::Value& v) { scenes_dir = v.text; });
  cl.option("--shared", "DIR", "the shared real scenes (default: ../shared/scenes beside that folder's parent)",
            [&](const cli::Value& v) { shared_dir = v.text; });
  cl.option("--backend", "B",
            "the GPU columns: vulkan, gles or both (default both: Vulkan and OpenGL ES 2.0\n"
            "on the same frames)",
            [&](const cli::Value& v) {
              if (v.text != "vulkan" && v.text != "gles" && v.text != "both") {
                cli::usage_error("--backend " + v.text + ": expected vulkan, gles or both", kHelp);
              }
              o.backends = v.text == "both" ? std::vector<std::string>{"vulkan", "gles"}
                                            : std::vector<std::string>{v.text};
            });
  if (!cl.parse(args)) return 0;
  const std::vector<std::string>& paths = cl.positionals();
  o.settings = common.settings;  // each cell sets its size, depth, shadows and rebuilds
  o.analytic = common.analytic;
  o.backend_options = common.backend;
  if (o.threads == 0) o.threads = std::max(1u, std::thread::hardware_concurrency());
  if (scenes_dir.empty()) scenes_dir = default_scenes_dir();
  if (shared_dir.empty()) shared_dir = (scenes_dir / ".." / ".." / "shared" / "scenes").lexically_normal();

  std::vector<BenchScene> list;
  if (paths.empty()) {
    if (!std::filesystem::exists(scenes_dir / "toaster.gltf")) {
      throw Error(ErrorKind::BadInput, (scenes_dir / "toaster.gltf").string() +
                                           ": the project's scenes are not there: give --scenes DIR (the "
                                           "repository's scenes/ folder) or scene files");
    }
    list = paper_scenes(scenes_dir, shared_dir);
  }
  for (const std::string& p : paths) {
    BenchScene s;
    s.name = std::filesystem::path(p).stem().string();
    s.path = p;
    s.width = width;
    s.height = height;
    list.push_back(s);
  }

  // The output file is checked before the long run, and written whole at the end.
  if (!json_path.empty() && json_path != "-") {
    const std::filesystem::path parent = std::filesystem::absolute(json_path).parent_path();
    if (!std::filesystem::is_directory(parent)) {
      throw Error(ErrorKind::BadInput, "--json " + json_path + ": folder " + parent.string() + " does not exist");
    }
  }

  o.backend_options.pipeline_cache_dir = default_pipeline_cache_dir();
  // The kd-tree build gets the cores the CPU columns get, unless --build-threads says otherwise.
  o.settings.kd.threads = int(o.build_threads ? o.build_threads : o.threads);
  std::vector<GpuColumn> columns;
  for (const std::string& b : o.backends) {
    columns.push_back({b == "vulkan" ? "mobirt" : "mobirt_gles", create_backend(b, o.backend_options, kHelp)});
  }
  // The GPU peers where the driver has them; else one line each says why and the run goes on.
  GpuPeers peers;
  std::string rq_skipped = "--no-baseline", compute_skipped = "--no-baseline";
  if (o.baseline) {
    RayQueryOptions ro;
    ro.device = o.backend_options.device;
    ro.validation = o.backend_options.validation;
    ro.sync_validation = o.backend_options.sync_validation;
    ro.timestamps = o.backend_options.timestamps;
    rq_skipped = o.settings.shadow_rays.ray_test.precision == Precision::Medium
                     ? "it traces in fp32 only, and --precision mediump was asked for"
                     : RayQueryEngine::unavailable_reason(ro);
    if (rq_skipped.empty()) {
      peers.rq = std::make_unique<RayQueryEngine>(ro);
    } else {
      std::fputs(("bench: ray-query peer skipped: " + rq_skipped + "\n").c_str(), stderr);
    }
    compute_skipped = ComputeEngine::unavailable_reason(o.backend_options);
    if (compute_skipped.empty()) {
      peers.compute = std::make_unique<ComputeEngine>(o.backend_options, o.compute_data);
    } else {
      std::fputs(("bench: compute peer skipped: " + compute_skipped + "\n").c_str(), stderr);
    }
    if (peers.rq || peers.compute) peers.shading = create_vulkan_backend(o.backend_options);
  }
  // Every device made: all their rasterizer threads pinned (create_backend pinned the columns').
  const int pinned = pin_driver_threads(o.backend_options);
  const DeviceInfo info = columns[0].backend->device_info();
  // Whether the Vulkan passes are timed on the device's clock (--gpu-timestamps): mobirt's Vulkan
  // column says, or without one (--backend gles) the peers' own Vulkan device.
  const auto vulkan = std::find_if(columns.begin(), columns.end(), [](const GpuColumn& c) { return c.key == "mobirt"; });
  const Backend* timed = vulkan != columns.end() ? vulkan->backend.get() : peers.shading.get();
  const bool gpu_timestamps = timed && timed->device_info().gpu_timestamps;
  const char* lp = std::getenv("LP_NUM_THREADS");
  nlohmann::json result;
  result["machine"] = {{"cores", std::thread::hardware_concurrency()},
                       {"api", info.api},
                       {"device", info.device},
                       {"driver", info.driver},
                       {"backends", o.backends},
                       {"lp_num_threads", lp ? std::string(lp) : std::string("default (all cores)")},
                       {"embree", EmbreeEngine::version()},
                       {"ray_query", peers.rq ? nlohmann::json(peers.rq->info())
                                              : nlohmann::json::object({{"skipped", rq_skipped}})},
                       {"compute", peers.compute ? nlohmann::json(peers.compute->info())
                                                 : nlohmann::json::object({{"skipped", compute_skipped}})},
                       {"threads", o.threads}};
  result["settings"] = {{"frames", o.frames},
                        {"warmup", o.warmup},
                        {"stack", o.settings.stack_depth},
                        {"max_steps", o.settings.max_steps},
                        {"cpu_walks", o.settings.cpu_walks},
                        {"compute_data", compute_data_name(o.compute_data)},
                        {"kd_rebuilt_every_frame", true},
                        {"primary", primary_hits_name(o.settings.primary)},
                        {"mirrors", mirror_hits_name(o.settings.mirrors)},
                        {"tree", tree_fit_name(o.settings.tree)},
                        {"shading", shading_passes_name(o.settings.shading)},
                        {"worker", worker_priority_name(o.settings.worker)},
                        {"pipelined", o.pipelined},
                        {"serial_twin", o.pipelined && o.serial_twin},
                        {"build_threads", o.settings.kd.threads},
                        {"driver_threads_pinned", pinned},
                        {"gpu_timestamps", gpu_timestamps}};
  result["settings"].update(cli::kd_settings_json(o.settings.kd));
  std::printf("mobirt bench: %d frames per cell after %d warm-up frames, animation playing, kd-tree rebuilt every frame\n",
              o.frames, o.warmup);
  std::printf("%s; kd-tree build on %d threads\n",
              o.pipelined ? (std::string("mobirt's frames pipelined: frame N+1 posed and its kd-tree built on a worker while\n"
                                         "frame N renders (--serial: one after the other), the worker at ") +
                             (o.settings.worker == WorkerPriority::Idle ? "idle priority\n(SCHED_IDLE: --worker)"
                                                                         : "normal priority\n(--worker normal)") +
                             (o.serial_twin ? "; every frame also rendered a second time,\nserially (--no-serial-twin: not)" : ""))
                                .c_str()
                          : "mobirt's frames serial (--serial): pose, build, passes, one after the other",
              o.settings.kd.threads);
  if (o.settings.primary != PrimaryHits::Trace) {
    std::printf("--primary %s: mobirt's primary hits rasterized (a depth-tested draw of the triangles)%s, not\n"
                "traced as in the paper and as every peer traces them (--primary trace: as the paper); no kd-tree\n"
                "in a frame without secondary rays whose shadow rays all test light buffers (--shadow-cells; each\n"
                "cell's \"kd_tree_built\" in the JSON); where rasterized, mobirt's \"traversal\" is the raster\n"
                "pass plus the shadow pass from its hits\n",
                primary_hits_name(o.settings.primary),
                o.settings.primary == PrimaryHits::Auto ? " where that pays (each cell's \"primary\" in the JSON)" : "");
  }
  if (o.settings.mirrors != MirrorHits::Trace) {
    std::printf("--mirrors %s: the first bounce's mirror rays off a flat mirror found by a raster pass of the scene\n"
                "mirrored in it%s, not traced as in the paper and as every peer traces them (--mirrors trace: as the\n"
                "paper); where drawn, mobirt's \"traversal\" of that generation includes that pass\n",
                mirror_hits_name(o.settings.mirrors),
                o.settings.mirrors == MirrorHits::Auto ? " where that pays (a quarter of the pixels' rays or more)" : "");
  }
  if (o.settings.tree == TreeFit::Walks) {
    std::printf("--tree walks: each frame's kd-tree built for the walks of the tree two frames before (a shallow\n"
                "tree where most rays are drawn or test light buffers; each cell's \"tree_rays\" and \"walks\" in the\n"
                "JSON; --tree full: every tree for unboundedly many rays, as the paper and the CPU kd-tree column)\n");
  }
  std::printf("machine: %u cores; %s, %s, %s, LP_NUM_THREADS=%s, %d rasterizer threads pinned one per CPU%s; %s on %u threads\n",
              std::thread::hardware_concurrency(), info.api.c_str(), info.device.c_str(), info.driver.c_str(),
              lp ? lp : "(all cores)", pinned, o.backend_options.pin_threads ? "" : " (--pin-threads off)",
              EmbreeEngine::version().c_str(), o.threads);
  std::printf("Vulkan passes timed on the %s (--gpu-timestamps %s%s)\n",
              gpu_timestamps ? "device's clock: timestamp queries around each pass's commands"
                             : "CPU's clock: each submission until its fence (a raster started ahead: until\nthe fence was seen signalled, the CPU's work meanwhile included)",
              gpu_timestamps_name(o.backend_options.timestamps),
              o.backend_options.timestamps == GpuTimestamps::Auto
                  ? (gpu_timestamps ? ": a GPU"
                                    : ": a CPU device, where each timestamp waits for the work, or one without timestamps")
                  : "");
  std::fflush(stdout);

  nlohmann::json cells = nlohmann::json::array();
  const size_t total = list.size() * o.levels.size();
  const auto start = std::chrono::steady_clock::now();
  for (const BenchScene& bs : list) {
    LoadOptions load;
    load.mtl = bs.mtl;
    load.analytic = o.analytic;
    const AnimatedScene animation = load_animated_scene(bs.path, load);
    for (int k : o.levels) {
      cells.push_back(run_cell(columns, peers, bs, animation, kLevels[k], o));
      print_progress(cells.back(), cells.size(), total, elapsed_ms(start) / 1000.0);
    }
  }
  result["cells"] = cells;
  result["targets"] = target_summary(cells);
  print_tables(result);
  print_targets(result["targets"]);

  if (!json_path.empty()) {
    const std::string text = result.dump(2) + "\n";
    if (json_path == "-") {
      std::cout << text;
    } else {
      if (!write_text_file(json_path, text)) throw Error(ErrorKind::BadInput, "--json " + json_path + ": cannot write");
    }
  }
  return 0;
}

}  // namespace mobirt
