// The frame pipeline (render/frame_pipeline.h): frames posed and built ahead on a worker give the
// serial loop's images bit for bit on both backends, the worker really runs during the previous
// frame, a static scene keeps its tree, and a worker's error reaches the caller.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "backend/backend.h"
#include "core/error.h"
#include "core/thread_priority.h"
#include "render/frame_pipeline.h"
#include "render/renderer.h"
#include "scene/animation.h"
#include "test_scenes.h"
#include "test_support.h"
#include "vulkan_fixture.h"

namespace mobirt {
namespace {

enum class Api { Vulkan, Gles };

std::unique_ptr<Backend> make_backend(Api api) {
  const BackendOptions options = test::validated_options();
  return api == Api::Vulkan ? create_vulkan_backend(options) : create_gles_backend(options);
}

class PipelinePerBackend : public ::testing::TestWithParam<Api> {};

// Frame i of the pipeline: `animation` at i / 8 seconds, posed into slots[i % 2]; pipelined.
FramePipeline animation_pipeline(const AnimatedScene& animation, Scene (&slots)[2], size_t frames,
                                 const RenderSettings& settings) {
  return FramePipeline(
      frames,
      [&animation, &slots](int slot, size_t index) {
        animation.evaluate(double(index) / 8.0, slots[slot]);
        return std::make_pair(static_cast<const Scene*>(&slots[slot]), *slots[slot].camera);
      },
      settings.kd, settings.always_rebuild, true);
}

// The fish at depth 2: refraction, reflection, textures and a swimming goldfish (seen through the
// glass); frames 1/8 s apart move it; a tree walked every frame, the pipeline without the renderer's
// settings. The toaster at depth 0: rasterized primaries and no kd-tree, with them, so that its
// light buffer is built on the worker with the tree (and used: the renderer builds none itself).
TEST_P(PipelinePerBackend, PipelinedFramesEqualSerialFrames) {
  for (const int depth : {2, 0}) {
    SCOPED_TRACE("depth " + std::to_string(depth));
    const AnimatedScene animation = load_animated_scene(std::string(MOBIRT_SOURCE_DIR) +
                                                        (depth == 2 ? "/scenes/fish.gltf" : "/scenes/toaster.gltf"));
    ASSERT_TRUE(animation.animated());
    RenderSettings settings;
    settings.width = 64;
    settings.height = 40;
    settings.depth = depth;
    settings.always_rebuild = true;  // as the bench renders
    settings.kd.threads = 2;
    constexpr size_t kFrames = 4;
    auto seconds = [](size_t index) { return double(index) / 8.0; };  // as animation_pipeline

    std::unique_ptr<Backend> serial_backend = make_backend(GetParam());
    std::vector<Image> serial;
    {
      Renderer renderer(*serial_backend, settings);
      Scene scene;
      for (size_t i = 0; i < kFrames; ++i) {
        animation.evaluate(seconds(i), scene);
        serial.push_back(renderer.render(scene, *scene.camera));
      }
      // Serially, the renderer builds each frame's light buffer itself.
      EXPECT_EQ(renderer.light_buffers_built(), kFrames);  // the fish's light has one too
    }

    std::unique_ptr<Backend> backend = make_backend(GetParam());
    Renderer renderer(*backend, settings);
    Scene slots[2];
    FramePipeline pipeline = animation_pipeline(animation, slots, kFrames, settings);
    // With the renderer's settings (as the CLI and the bench give them) the worker builds the light
    // buffers; without (the fish), every frame gets a tree and the renderer builds them.
    if (depth == 0) pipeline.set_render_settings(settings);
    for (size_t i = 0; i < kFrames; ++i) {
      Image image;
      FrameTimings t;
      pipeline.step(i, [&](PreparedFrame& f) {
        EXPECT_EQ(f.index, i);
        EXPECT_TRUE(f.tree_built);
        EXPECT_EQ(f.light_buffers.size(), depth == 0 ? 1u : 0u);
        image = render_prepared(renderer, f, &t);
      });
      EXPECT_TRUE(t.tree_rebuilt);
      EXPECT_EQ(renderer.frame_had_kd_tree(), depth == 2);
      EXPECT_EQ(renderer.light_buffers_used(), 1);
      // Pipelined with the settings, it uses the worker's: a buffer rebuilt here would cost the
      // rendering thread its build, which only timings would show otherwise.
      EXPECT_EQ(renderer.light_buffers_built(), depth == 0 ? 0u : i + 1);
      ASSERT_EQ(image.pixels.size(), serial[i].pixels.size());
      size_t differing = 0;
      for (size_t p = 0; p < image.pixels.size(); ++p) differing += image.pixels[p] != serial[i].pixels[p];
      EXPECT_EQ(differing, 0u) << "frame " << i << ": pixels that differ from the serial loop's";
    }
    // The frames really differ, so that equal images say the right tree reached each frame.
    size_t moved = 0;
    for (size_t p = 0; p < serial[0].pixels.size(); ++p) moved += serial[0].pixels[p] != serial[kFrames - 1].pixels[p];
    EXPECT_GT(moved, 0u);
    for (Backend* b : {serial_backend.get(), backend.get()}) {
      const std::vector<std::string> messages = b->take_debug_messages();
      EXPECT_TRUE(messages.empty()) << test::join(messages);
    }
  }
}

// --tree walks on the toaster at depth 1 (primary hits drawn, shadow rays through the light
// buffer, the floor's mirror rays drawn, the other secondary rays walked): the frames' walks are counted
// as the passes make them (none for drawn primaries whose shadow rays test a buffer; closest hit
// plus one shadow ray per ray where all are traced and no buffer is kept), frames 2 on get trees
// for those walks, smaller than the full tree, and every image is the serial loop's with full
// trees, bit for bit.
TEST_P(PipelinePerBackend, TreesBuiltForTheWalksGiveTheFullTreesImages) {
  const AnimatedScene animation = load_animated_scene(std::string(MOBIRT_SOURCE_DIR) + "/scenes/toaster.gltf");
  RenderSettings settings;
  settings.width = 64;
  settings.height = 40;
  settings.depth = 1;
  settings.always_rebuild = true;
  settings.kd.threads = 2;
  settings.primary = PrimaryHits::Raster;  // auto traces them at this size (more triangles than pixels)
  settings.mirrors = MirrorHits::Raster;
  constexpr size_t kFrames = 5;
  auto seconds = [](size_t index) { return double(index) / 8.0; };  // as animation_pipeline
  Scene scene;
  animation.evaluate(0.0, scene);
  const uint64_t pixels = uint64_t(settings.width) * uint64_t(settings.height);

  std::unique_ptr<Backend> serial_backend = make_backend(GetParam());
  {
    // Every ray traced, no light buffer: each primary ray walks once, and once for the light.
    RenderSettings traced = settings;
    traced.depth = 0;
    traced.primary = PrimaryHits::Trace;
    traced.shadow_cells = 0;
    Renderer renderer(*serial_backend, traced);
    FrameTimings t;
    renderer.render(scene, *scene.camera, &t);
    ASSERT_EQ(scene.lights.size(), 1u);
    EXPECT_EQ(t.sum.walks, 2 * pixels);
  }
  std::vector<Image> serial;
  {
    RenderSettings full = settings;
    full.tree = TreeFit::Full;
    Renderer renderer(*serial_backend, full);
    for (size_t i = 0; i < kFrames; ++i) {
      animation.evaluate(seconds(i), scene);
      serial.push_back(renderer.render(scene, *scene.camera));
    }
    // Serially, the renderer looks for the flat mirrors itself, each frame (the toaster moves).
    EXPECT_EQ(renderer.mirror_plane_searches(), kFrames);
  }
  std::unique_ptr<Backend> backend = make_backend(GetParam());
  Renderer renderer(*backend, settings);
  Scene slots[2];
  FramePipeline pipeline = animation_pipeline(animation, slots, kFrames, settings);
  pipeline.set_render_settings(settings);
  std::vector<int64_t> walks;
  for (size_t i = 0; i < kFrames; ++i) {
    SCOPED_TRACE("frame " + std::to_string(i));
    Image image;
    FrameTimings t;
    ASSERT_EQ(walks.size(), i);  // each earlier frame reported its walks
    pipeline.step(i, [&](PreparedFrame& f) {
      ASSERT_TRUE(f.tree_built);
      // The flat mirrors found with the tree, on the worker: the floor among them.
      EXPECT_TRUE(f.mirror_planes_found);
      EXPECT_FALSE(f.mirror_planes.planes.empty());
      EXPECT_EQ(f.mirror_planes.plane_of.size(), f.scene->mesh.triangle_count());
      const size_t full_nodes = build_kdtree(f.scene->mesh.positions, settings.kd).nodes.size();
      if (i < 2) {
        EXPECT_EQ(f.tree_rays, 0.0);
        EXPECT_EQ(f.tree.nodes.size(), full_nodes);
      } else {
        ASSERT_GT(walks[i - 2], 0);  // the rays off the toaster and the edge misses walk
        EXPECT_EQ(f.tree_rays, double(walks[i - 2]));
        EXPECT_LT(f.tree.nodes.size(), full_nodes);
      }
      image = render_prepared(renderer, f, &t);
      walks.push_back(f.walks);
    });
    ASSERT_EQ(t.generations.size(), 2u);
    EXPECT_EQ(t.generations[0].walks, 0u);  // drawn primaries, shadow rays through the light buffer
    EXPECT_GT(t.generations[1].mirrored, 0u);  // the floor's mirror rays drawn
    EXPECT_EQ(uint64_t(walks.back()), t.sum.walks);
    EXPECT_LT(t.sum.walks, pixels);  // far fewer than a traced frame's 2 per pixel
    ASSERT_EQ(image.pixels.size(), serial[i].pixels.size());
    size_t differing = 0;
    for (size_t p = 0; p < image.pixels.size(); ++p) differing += image.pixels[p] != serial[i].pixels[p];
    EXPECT_EQ(differing, 0u) << "pixels that differ from the full trees' frame";
  }
  // Pipelined with the settings, the renderer used the worker's planes and never looked itself.
  EXPECT_EQ(renderer.mirror_plane_searches(), 0u);
  for (Backend* b : {serial_backend.get(), backend.get()}) {
    const std::vector<std::string> messages = b->take_debug_messages();
    EXPECT_TRUE(messages.empty()) << test::join(messages);
  }
}

INSTANTIATE_TEST_SUITE_P(Backends, PipelinePerBackend, ::testing::Values(Api::Vulkan, Api::Gles),
                         [](const ::testing::TestParamInfo<Api>& p) {
                           return std::string(p.param == Api::Vulkan ? "vulkan" : "gles");
                         });

// `render --frames` pipelines its frames; --serial gives the same files byte for byte.
TEST(FramePipelineCli, RenderFramesPipelinedEqualSerial) {
  namespace fs = std::filesystem;
  const fs::path dir = test::temp_dir();
  for (const char* mode : {"pipelined", "serial"}) {
    fs::create_directory(dir / mode);
    const test::CommandResult r = test::run_mobirt(
        std::string("render " MOBIRT_SOURCE_DIR "/scenes/fish.gltf --size 64x40 --fps 8 --frames 0:2 -o '") +
        (dir / mode / "f_%d.png").string() + "'" + (std::string(mode) == "serial" ? " --serial" : ""));
    ASSERT_EQ(r.exit_code, 0) << r.output;
  }
  auto bytes = [](const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
  };
  for (int f = 0; f <= 2; ++f) {
    const std::string name = "f_" + std::to_string(f) + ".png";
    const std::string pipelined = bytes(dir / "pipelined" / name);
    EXPECT_FALSE(pipelined.empty()) << name;
    EXPECT_EQ(pipelined, bytes(dir / "serial" / name)) << name;
  }
  EXPECT_NE(bytes(dir / "serial" / "f_0.png"), bytes(dir / "serial" / "f_2.png"));  // the fish moved
}

// ---- The pipeline without a GPU ----------------------------------------------------------------

// A scene whose triangles move with the frame index.
struct MovingScene {
  Scene slots[2];
  void pose(int slot, size_t index) {
    Scene& s = slots[slot];
    s = test::box_grid_scene();
    for (glm::vec3& p : s.mesh.positions) p.y += 0.01f * float(index);
  }
  // A pipelined loop whose frame i is this scene at pose position_of[i] (which must outlive it).
  FramePipeline pipeline(const std::vector<size_t>& position_of, bool always_rebuild) {
    return FramePipeline(
        position_of.size(),
        [this, &position_of](int slot, size_t index) {
          pose(slot, position_of[index]);
          return std::make_pair(static_cast<const Scene*>(&slots[slot]), *slots[slot].camera);
        },
        KdBuildOptions{}, always_rebuild, true);
  }
};

// Pipelined, frame i + 1 is posed while frame i renders: the render waits until it has been.
TEST(FramePipeline, PosesTheNextFrameWhileTheFrameRenders) {
  MovingScene moving;
  std::mutex mutex;
  std::condition_variable posed_cv;
  size_t posed = 0;  // frames posed so far
  std::vector<std::thread::id> pose_threads;
  constexpr size_t kFrames = 4;
  FramePipeline pipeline(
      kFrames,
      [&](int slot, size_t index) {
        moving.pose(slot, index);
        const std::lock_guard<std::mutex> lock(mutex);
        EXPECT_EQ(index, posed);
        ++posed;
        pose_threads.push_back(std::this_thread::get_id());
        posed_cv.notify_all();
        return std::make_pair(static_cast<const Scene*>(&moving.slots[slot]), *moving.slots[slot].camera);
      },
      KdBuildOptions{}, true, true);
  for (size_t i = 0; i < kFrames; ++i) {
    pipeline.step(i, [&](PreparedFrame& f) {
      EXPECT_EQ(f.scene, &moving.slots[i % 2]);
      EXPECT_FALSE(f.tree.nodes.empty());
      if (i + 1 == kFrames) return;
      std::unique_lock<std::mutex> lock(mutex);
      const bool ahead = posed_cv.wait_for(lock, std::chrono::seconds(20), [&] { return posed > i + 1; });
      EXPECT_TRUE(ahead) << "frame " << i + 1 << " was not posed while frame " << i << " rendered";
    });
  }
  EXPECT_EQ(posed, kFrames);  // no frame past the list
  ASSERT_EQ(pose_threads.size(), kFrames);
  EXPECT_EQ(pose_threads[0], std::this_thread::get_id());  // the first frame has nothing to hide behind
  for (size_t i = 1; i < kFrames; ++i) EXPECT_NE(pose_threads[i], std::this_thread::get_id()) << i;
  // One worker for the pipeline's life (not a thread started per frame).
  for (size_t i = 2; i < kFrames; ++i) EXPECT_EQ(pose_threads[i], pose_threads[1]) << i;
}

// The worker runs at SCHED_IDLE by default (WorkerPriority::Idle) and at the normal class with
// WorkerPriority::Normal; the calling thread keeps its class either way, and so does a serial
// pipeline's (it prepares on the caller).
TEST(FramePipeline, RunsItsWorkerAtTheClassTheSettingsAsk) {
  for (const WorkerPriority priority : {WorkerPriority::Idle, WorkerPriority::Normal}) {
    for (const bool pipelined : {true, false}) {
      MovingScene moving;
      std::vector<int> idle;  // per frame posed: whether its thread ran at SCHED_IDLE
      FramePipeline pipeline(
          3,
          [&](int slot, size_t index) {
            moving.pose(slot, index);
            idle.push_back(runs_at_idle_priority() ? 1 : 0);
            return std::make_pair(static_cast<const Scene*>(&moving.slots[slot]), *moving.slots[slot].camera);
          },
          KdBuildOptions{}, true, pipelined);
      RenderSettings settings;
      settings.worker = priority;
      pipeline.set_render_settings(settings);
      for (size_t i = 0; i < 3; ++i) pipeline.step(i, [](PreparedFrame&) {});
      SCOPED_TRACE(std::string(worker_priority_name(priority)) + (pipelined ? ", pipelined" : ", serial"));
      ASSERT_EQ(idle.size(), 3u);
      EXPECT_EQ(idle[0], 0);  // the first frame is prepared on the caller
      const bool worker_idle = priority == WorkerPriority::Idle && pipelined;
#if defined(__linux__)
      EXPECT_EQ(idle[1], worker_idle ? 1 : 0);
      EXPECT_EQ(idle[2], worker_idle ? 1 : 0);
      EXPECT_EQ(pipeline.worker_at_idle_priority(), worker_idle);
#else
      EXPECT_FALSE(pipeline.worker_at_idle_priority());
#endif
      EXPECT_FALSE(runs_at_idle_priority());  // the caller's class never changes
    }
  }
}

// A pipeline dropped while its worker still prepares the next frame waits for it and ends its
// thread; one dropped after its last frame ends the idle worker.
TEST(FramePipeline, EndsItsWorkerWhenDropped) {
  MovingScene moving;
  std::atomic<int> posed{0};
  auto pose = [&](int slot, size_t index) {
    if (index == 1) std::this_thread::sleep_for(std::chrono::milliseconds(50));  // still busy when dropped
    moving.pose(slot, index);
    ++posed;
    return std::make_pair(static_cast<const Scene*>(&moving.slots[slot]), *moving.slots[slot].camera);
  };
  {
    FramePipeline pipeline(5, pose, KdBuildOptions{}, true, true);
    pipeline.step(0, [](PreparedFrame&) {});  // starts preparing frame 1
  }
  EXPECT_EQ(posed.load(), 2);  // frame 1's preparation ran to its end before the pipeline went
  posed = 0;
  {
    FramePipeline pipeline(2, pose, KdBuildOptions{}, true, true);
    pipeline.step(0, [](PreparedFrame&) {});
    pipeline.step(1, [](PreparedFrame&) {});
  }
  EXPECT_EQ(posed.load(), 2);
}

// Serial, each frame is posed on the calling thread just before it renders.
TEST(FramePipeline, SerialPreparesEachFrameBeforeItRenders) {
  MovingScene moving;
  size_t posed = 0;
  const std::thread::id caller = std::this_thread::get_id();
  FramePipeline pipeline(
      3,
      [&](int slot, size_t index) {
        EXPECT_EQ(std::this_thread::get_id(), caller);
        moving.pose(slot, index);
        ++posed;
        return std::make_pair(static_cast<const Scene*>(&moving.slots[slot]), *moving.slots[slot].camera);
      },
      KdBuildOptions{}, true, false);
  EXPECT_FALSE(pipeline.pipelined());
  for (size_t i = 0; i < 3; ++i) {
    const PipelineStep s = pipeline.step(i, [&](PreparedFrame& f) {
      EXPECT_EQ(posed, i + 1);  // this frame, and not the next
      EXPECT_EQ(f.index, i);
    });
    EXPECT_EQ(s.ahead_ms, 0.0);
    EXPECT_EQ(s.wait_ms, 0.0);
  }
}

// Without always_rebuild, a frame whose triangles did not move keeps the last tree, as the
// renderer's own cache does; moved triangles build a new one.
TEST(FramePipeline, KeepsTheTreeWhileTheTrianglesStay) {
  MovingScene moving;
  const std::vector<size_t> position_of = {0, 0, 0, 1, 1};  // the frame's pose
  FramePipeline pipeline = moving.pipeline(position_of, false);
  const std::vector<bool> built = {true, false, false, true, false};
  for (size_t i = 0; i < built.size(); ++i) {
    pipeline.step(i, [&](PreparedFrame& f) {
      EXPECT_EQ(f.tree_built, built[i]) << "frame " << i;
      EXPECT_EQ(f.tree.nodes.empty(), !built[i]) << "frame " << i;
    });
  }
}

// With the renderer's settings, a frame that walks no tree (rasterized primaries, a point light's
// shadow rays through its light buffer) gets only the primitives' texels and its light buffers;
// one whose light's lists run long (quads stacked over the light, each in every cell of its face)
// gets its kd-tree on the worker; without shadows no buffer is built.
TEST(FramePipeline, BuildsLightBuffersAndTheTreeOnlyWhereAFrameWalksIt) {
  Scene lit = test::box_grid_scene();
  lit.lights.resize(1);  // the point light at (-4, 9, 6)
  Scene stacked = lit;
  for (int i = 0; i < 120; ++i) {
    const float y = 10.0f + 0.01f * float(i);
    test::add_triangle(stacked, {-30, y, -30}, {30, y, -30}, {30, y, 30}, 0);
    test::add_triangle(stacked, {-30, y, -30}, {30, y, 30}, {-30, y, 30}, 0);
  }
  RenderSettings settings;
  settings.depth = 0;
  settings.primary = PrimaryHits::Raster;
  for (const bool shadows : {true, false}) {
    settings.shadows = shadows;
    const Scene* scenes[2] = {&lit, &stacked};
    FramePipeline pipeline(
        2, [&](int, size_t index) { return std::make_pair(scenes[index], *lit.camera); }, KdBuildOptions{}, true,
        true);
    pipeline.set_render_settings(settings);
    for (size_t i = 0; i < 2; ++i) {
      SCOPED_TRACE(std::string(i == 0 ? "short lists" : "long lists") + (shadows ? "" : ", no shadows"));
      pipeline.step(i, [&](PreparedFrame& f) {
        ASSERT_TRUE(f.tree_built);
        EXPECT_FALSE(f.tree.triangles.empty());
        EXPECT_EQ(f.tree.nodes.empty(), i == 0 || !shadows);
        ASSERT_EQ(f.light_buffers.size(), shadows ? 1u : 0u);
        if (shadows) {
          EXPECT_EQ(light_buffer_pays(f.light_buffers[0]), i == 0);
        }
      });
    }
  }
}

// --tree walks: frame N's kd-tree is built for the walks frame N - 2 reported (the latest frame
// rendered before N is built, pipelined or serial alike, so both loops build the same trees); the
// first two frames, a frame two after one that did not say or walked nothing (no estimate), and
// every frame of --tree full get the full tree; fewer walks, fewer nodes.
TEST(FramePipeline, BuildsEachTreeForTheWalksOfTwoFramesBefore) {
  const Scene scene = test::box_grid_scene();
  const FlatKdTree full = build_kdtree(scene.mesh.positions, KdBuildOptions{});
  const std::vector<int64_t> reported = {3, -1, 100000000, 0, 5, 7};  // each frame's walks (-1: not said)
  for (const TreeFit fit : {TreeFit::Walks, TreeFit::Full}) {
    std::vector<size_t> node_counts[2];  // serial, pipelined: the same trees
    for (const bool pipelined : {true, false}) {
      SCOPED_TRACE(std::string(tree_fit_name(fit)) + (pipelined ? ", pipelined" : ", serial"));
      RenderSettings settings;  // depth 2: every frame walks a tree
      settings.tree = fit;
      FramePipeline pipeline(
          reported.size(), [&](int, size_t) { return std::make_pair(&scene, *scene.camera); }, KdBuildOptions{},
          true, pipelined);
      pipeline.set_render_settings(settings);
      std::vector<size_t>& nodes = node_counts[pipelined ? 1 : 0];
      for (size_t i = 0; i < reported.size(); ++i) {
        pipeline.step(i, [&](PreparedFrame& f) {
          const double expected =
              fit == TreeFit::Walks && i >= 2 && reported[i - 2] > 0 ? double(reported[i - 2]) : 0.0;
          EXPECT_EQ(f.tree_rays, expected) << "frame " << i;
          nodes.push_back(f.tree.nodes.size());
          if (expected == 0.0) {
            EXPECT_EQ(f.tree.nodes, full.nodes) << "frame " << i;
          }
          f.walks = reported[i];
        });
      }
      if (fit == TreeFit::Walks) {
        EXPECT_LT(nodes[2], full.nodes.size());  // for 3 walks
        EXPECT_LE(nodes[2], nodes[4]);           // 3 against 100,000,000
        EXPECT_EQ(nodes[5], full.nodes.size());  // frame 3 walked nothing: no estimate
      }
    }
    EXPECT_EQ(node_counts[0], node_counts[1]);
  }
}

// Without --always-rebuild a tree is kept while the triangles stay: one built for few walks is
// built again (for the walks now reported) once they pass twice what it was built for, so an
// animation that stops does not keep a shallow tree for good.
TEST(FramePipeline, RebuildsAKeptTreeTheWalksOutgrew) {
  MovingScene moving;
  const std::vector<size_t> position_of = {0, 1, 2, 3, 3, 3, 3, 3};  // moves, then stops
  const std::vector<int64_t> reported = {5, 5, 5, 5, 5, 1000, 1000, 1000};
  const std::vector<bool> built = {true, true, true, true, false, false, false, true};
  RenderSettings settings;  // --tree walks, depth 2: every frame walks
  FramePipeline pipeline = moving.pipeline(position_of, false);
  pipeline.set_render_settings(settings);
  for (size_t i = 0; i < position_of.size(); ++i) {
    pipeline.step(i, [&](PreparedFrame& f) {
      EXPECT_EQ(f.tree_built, built[i]) << "frame " << i;
      if (f.tree_built) {
        EXPECT_EQ(f.tree_rays, i >= 2 ? double(reported[i - 2]) : 0.0) << "frame " << i;
      }
      f.walks = reported[i];
    });
  }
}

TEST(FramePipeline, RethrowsTheWorkersErrorAndChecksTheOrder) {
  MovingScene moving;
  FramePipeline pipeline(
      3,
      [&](int slot, size_t index) {
        if (index == 2) throw Error(ErrorKind::BadInput, "frame 2 is broken");
        moving.pose(slot, index);
        return std::make_pair(static_cast<const Scene*>(&moving.slots[slot]), *moving.slots[slot].camera);
      },
      KdBuildOptions{}, true, true);
  int rendered = 0;
  pipeline.step(0, [&](PreparedFrame&) { ++rendered; });
  test::expect_bad_input([&] { pipeline.step(1, [&](PreparedFrame&) { ++rendered; }); }, {"frame 2 is broken"});
  EXPECT_EQ(rendered, 2);  // frame 1 rendered; the error came from preparing frame 2
  // Frame 2 is never rendered from a slot the worker left half-written: preparing it again fails again.
  test::expect_bad_input([&] { pipeline.step(2, [&](PreparedFrame&) { ++rendered; }); }, {"frame 2 is broken"});
  EXPECT_EQ(rendered, 2);

  FramePipeline ordered(
      3,
      [&](int slot, size_t index) {
        moving.pose(slot, index);
        return std::make_pair(static_cast<const Scene*>(&moving.slots[slot]), *moving.slots[slot].camera);
      },
      KdBuildOptions{}, true, true);
  try {
    ordered.step(1, [](PreparedFrame&) {});
    ADD_FAILURE() << "a step out of order was taken";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::Internal);
  }
}

}  // namespace
}  // namespace mobirt
