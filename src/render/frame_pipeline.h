// Frames made ready ahead of their passes, as the paper's CPU-GPU split intends: while frame N is
// rendered, a worker thread poses frame N+1 and builds its kd-tree. The rendering thread spends
// much of a frame waiting on a fence while the driver's own threads run the passes (lavapipe's
// rasterizer threads, LP_NUM_THREADS); the build runs in that time instead of after it. It pays
// only where a core idles meanwhile: on 2 cores lavapipe's threads already hold both during the
// passes, and the measured gain is within the noise (README, "Frames pipelined against serial").
//
// The worker can run at Linux's SCHED_IDLE (RenderSettings::worker; --worker idle, the CLI's
// default): lavapipe's rasterizer threads are pinned one per CPU (--pin-threads), and a worker of
// the normal class that held the CPU of one of them kept it waiting up to a scheduler slice (about
// 1 ms, perf sched timehist) at every pass, while the other CPU idled. At SCHED_IDLE a woken
// rasterizer thread takes the CPU at once and the worker's own share of the build fills only time
// nothing else wants (TBB's helper threads that run its tasks stay in the normal class; README,
// "The pipeline's worker at idle priority").
//
// Two slots, so that frame N's scene and tree are never written while frame N uses them. The GPU
// side needs no second copy: the next frame's tree is uploaded by the rendering thread in its
// begin_frame, after frame N's last pass finished (every pass is waited for). The backends' contexts
// are only ever used by the rendering thread (an OpenGL ES context is bound to one).
//
// Every frame's image is the serial loop's, bit for bit: posing is a pure function of the frame's
// time, the build gives the same tree for any thread count (accel/kdtree.h), and the passes see the
// same tree and scene (tests/frame_pipeline_test.cpp).
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <future>
#include <mutex>
#include <optional>
#include <thread>
#include <utility>
#include <vector>

#include "accel/kdtree.h"
#include "accel/light_buffer.h"
#include "core/camera.h"
#include "core/image.h"
#include "render/engine.h"
#include "render/renderer.h"
#include "scene/scene.h"

namespace mobirt {

// One frame ready for the passes.
struct PreparedFrame {
  size_t index = 0;             // in the pipeline's frame list
  const Scene* scene = nullptr; // posed; owned by the caller's slot
  Camera camera;
  FlatKdTree tree;              // over scene->mesh.positions when tree_built (or only the
                                // primitives' texels: FramePipeline::set_walks_tree), else empty; after
                                // render_prepared, the renderer's previous tree (its memory for
                                // the slot's next build)
  bool tree_built = false;      // false: the triangles did not move since the last tree built
  // With tree_built and set_render_settings: the shadow lights' light buffers (frame_light_buffers),
  // built with the tree; handed to the renderer as the tree is.
  std::vector<LightBuffer> light_buffers;
  // With them: the closed parts as posed for them (none where no buffer posed them), handed on to
  // the raster passes as the buffers are (Renderer::render).
  PosedParts posed_parts;
  // Pipelined, with tree_built, where the frame may draw its mirror rays (frame_may_draw_mirrors):
  // its flat mirrors, found on the worker with the tree (mirror_planes_found), handed to the
  // renderer as the tree is (render_prepared; mirror_planes_found is false once handed over).
  // Serially the renderer finds them itself, keeping them while the triangles stay.
  MirrorPlanes mirror_planes;
  bool mirror_planes_found = false;
  double pose_ms = 0.0;         // posing the scene
  double build_ms = 0.0;        // the kd-tree's, light buffers' and mirror planes' making, wall
                                // clock; pipelined, on the worker while the previous frame
                                // rendered, so not part of this frame's time
  double tree_rays = 0.0;       // the rays its kd-tree was built for (KdBuildOptions::rays; 0: a full
                                // tree, or none: tree_built false or only the primitives' texels)
  // Set by render_prepared: the frame's walks of the kd-tree (GenerationTimings::walks, all
  // generations); -1 where the render callback did not say. With --tree walks, frame N + 2's tree
  // is built for them.
  int64_t walks = -1;
};

// What one step cost, on the rendering thread's clock (milliseconds).
struct PipelineStep {
  // The step's wall clock: this frame rendered and the next one ready. Pipelined, the steady-state
  // period of the frame loop (its fps); serial, posing + build + frame.
  double period_ms = 0.0;
  double render_ms = 0.0;      // the render callback
  double render_cpu_ms = 0.0;  // the rendering thread's own CPU time in it; the rest of render_ms
                               // it waited: on fences while the driver's threads ran the passes,
                               // or for the helper threads of its parallel loops
  double wait_ms = 0.0;    // waiting for the worker after the render: the preparation not hidden
  double ahead_ms = 0.0;   // posing and building the next frame on the worker (0 when serial)
};

class FramePipeline {
 public:
  // Poses frame `index` of the list into the caller's scene of `slot` (0 or 1) and returns that
  // scene and the view. Called for each index once, in order, one call at a time (on the worker
  // when pipelined); a slot is posed again only after the frame that used it was rendered.
  using Pose = std::function<std::pair<const Scene*, Camera>(int slot, size_t index)>;

  // `kd.threads` is the build's share of the CPU (its TBB arena); `always_rebuild` as
  // RenderSettings' (else a frame whose triangles did not move keeps the last tree).
  // `pipelined` false: each step prepares its frame and then renders it, on the calling thread.
  FramePipeline(size_t frames, Pose pose, const KdBuildOptions& kd, bool always_rebuild, bool pipelined);
  ~FramePipeline();  // waits for the worker
  FramePipeline(const FramePipeline&) = delete;
  FramePipeline& operator=(const FramePipeline&) = delete;

  // Renders frame `index` with `render` while frame index + 1 is prepared on the worker. Steps go
  // in order 0, 1, 2, ...; the PreparedFrame is valid during the callback only. An error of the
  // worker is rethrown here, after the render.
  PipelineStep step(size_t index, const std::function<void(PreparedFrame&)>& render);

  bool pipelined() const { return pipelined_; }

  // The renderer's settings: a frame gets a kd-tree where frame_walks_tree says it walks one, else
  // only the primitives' texels (flatten_primitives), and its light buffers (frame_light_buffers)
  // are built with it; with --tree walks (RenderSettings::tree), frame N's kd-tree is built for
  // the walks frame N - 2 reported (the latest frame rendered before it is built, pipelined or
  // not, so that both loops build the same trees; the full tree where it walked nothing or did
  // not say), and a tree kept while the triangles stay is built again once the walks outgrow it
  // (more than twice what it was built for); pipelined, the worker also finds the flat mirrors
  // of a frame that may draw its mirror rays (PreparedFrame::mirror_planes). Without, every frame
  // gets a full kd-tree and no light buffer is built ahead. Set before the first step.
  // Its worker's class (RenderSettings::worker) comes from them too: the normal class without.
  void set_render_settings(const RenderSettings& settings) { settings_ = settings; }

  // Whether the worker runs at SCHED_IDLE (WorkerPriority::Idle, where Linux granted it); false
  // before the first pipelined step started it.
  bool worker_at_idle_priority() const { return worker_idle_.load(std::memory_order_acquire); }

 private:
  double prepare(size_t index);  // into slots_[index % 2]; returns its milliseconds

  size_t frames_;
  Pose pose_;
  KdBuildOptions kd_;
  bool always_rebuild_;
  bool pipelined_;
  std::optional<RenderSettings> settings_;  // empty: every frame walks a tree, no light buffers ahead
  std::vector<int64_t> walks_;     // per frame, as its render reported them (-1: not, or not yet)
  double built_tree_rays_ = 0.0;   // what the last kd-tree built was for (0: a full tree, or none)
  PreparedFrame slots_[2];
  std::vector<glm::vec3> built_positions_;  // of the last tree built (when not always_rebuild)
  std::vector<Shape> built_shapes_;         // and its analytic shapes
  bool built_any_ = false;
  size_t next_ = 0;                // the index the next step must have
  size_t ready_ = SIZE_MAX;        // the index the worker prepared, once it finished without error
  std::future<double> ahead_;      // the worker preparing frame next_

  // The worker: one thread for the pipeline's life, started by the first pipelined step, that
  // runs one preparation at a time. (A thread started per frame cost its start and, on its first
  // build, TBB's registration of a new external thread, every frame.)
  void start_ahead(size_t index);
  void worker_loop(WorkerPriority priority);
  std::atomic<bool> worker_idle_{false};
  std::thread worker_;
  std::mutex mutex_;
  std::condition_variable wake_;
  std::packaged_task<double()> job_;  // valid while a preparation waits for the worker
  bool stop_ = false;
};

// Frame `f` through `renderer`: with the tree built ahead (swapped into the renderer, f.tree then
// holding the renderer's previous one), or, when the triangles did not move, with the renderer's
// own tree.
Image render_prepared(Renderer& renderer, PreparedFrame& f, FrameTimings* timings = nullptr);

}  // namespace mobirt
