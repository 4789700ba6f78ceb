#include "render/frame_pipeline.h"

#include <chrono>
#include <string>
#include <utility>

#include "core/cpu_time.h"
#include "core/error.h"
#include "core/thread_priority.h"

namespace mobirt {

FramePipeline::FramePipeline(size_t frames, Pose pose, const KdBuildOptions& kd, bool always_rebuild, bool pipelined)
    : frames_(frames), pose_(std::move(pose)), kd_(kd), always_rebuild_(always_rebuild), pipelined_(pipelined),
      walks_(frames, -1) {}

FramePipeline::~FramePipeline() {
  if (ahead_.valid()) ahead_.wait();  // its error, if any, dies with the pipeline
  if (worker_.joinable()) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stop_ = true;
    }
    wake_.notify_one();
    worker_.join();
  }
}

void FramePipeline::worker_loop(WorkerPriority priority) {
  if (priority == WorkerPriority::Idle) worker_idle_.store(lower_to_idle_priority(), std::memory_order_release);
  for (;;) {
    std::packaged_task<double()> job;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      wake_.wait(lock, [this] { return stop_ || job_.valid(); });
      if (!job_.valid()) return;  // stopped with nothing left to run
      job = std::move(job_);
    }
    job();  // its result or error goes to ahead_
  }
}

void FramePipeline::start_ahead(size_t index) {
  std::packaged_task<double()> job([this, index] { return prepare(index); });
  ahead_ = job.get_future();
  {
    std::lock_guard<std::mutex> lock(mutex_);
    job_ = std::move(job);
  }
  if (!worker_.joinable()) {
    const WorkerPriority priority = settings_ ? settings_->worker : WorkerPriority::Normal;
    worker_ = std::thread([this, priority] { worker_loop(priority); });
  } else {
    wake_.notify_one();
  }
}

double FramePipeline::prepare(size_t index) {
  const auto start = std::chrono::steady_clock::now();
  PreparedFrame& f = slots_[index % 2];
  auto [scene, camera] = pose_(int(index % 2), index);
  f.index = index;
  f.scene = scene;
  f.camera = camera;
  f.pose_ms = elapsed_ms(start);
  const auto build_start = std::chrono::steady_clock::now();
  f.tree_rays = 0.0;
  // What a tree built now is for (KdBuildOptions::rays; 0: a full tree): with --tree walks, the
  // walks frame index - 2 reported, where it walked at all (a frame that walked nothing, or did
  // not say, gives no estimate: the full tree; a frame whose light buffer turns out not to pay
  // may walk where the last ones did not).
  const double fit_rays =
      settings_ && settings_->tree == TreeFit::Walks && index >= 2 && walks_[index - 2] > 0 ? double(walks_[index - 2])
                                                                                           : 0.0;
  // A kept tree (the triangles did not move) that was built for fewer rays than are walking now is
  // built again for them: a shallow tree is not kept for good once an animation stops.
  const bool outgrown = built_tree_rays_ > 0.0 && (fit_rays == 0.0 || fit_rays > 2.0 * built_tree_rays_);
  f.tree_built = always_rebuild_ || !built_any_ || built_positions_ != scene->mesh.positions ||
                 built_shapes_ != scene->shapes || outgrown;
  // Into the slot's tree, which holds the arrays of an older tree (render_prepared swaps them
  // out of the renderer): their memory is reused. A frame without a build carries no tree, its
  // arrays emptied but their memory kept.
  // The light buffers first: a frame planned without a kd-tree whose light's lists run long
  // (light_buffer_pays) walks for that light, so it gets its tree here rather than on the
  // rendering thread (Renderer::Engine::begin_frame builds one where a buffer fails later still).
  bool walks = !settings_ || frame_walks_tree(*scene, *settings_);
  if (f.tree_built && settings_) {
    frame_light_buffers(*scene, *settings_, f.light_buffers, &f.posed_parts);  // one per shadow light
    for (const LightBuffer& lb : f.light_buffers) walks = walks || !light_buffer_pays(lb);
  } else {
    f.light_buffers.clear();
    f.posed_parts = PosedParts{};
  }
  // The flat mirrors the frame's first bounce may draw, found on the worker rather than on the
  // rendering thread (the chrome toaster's 11,102 reflecting triangles: 0.3 ms a frame there).
  // Serially this is the rendering thread: the renderer's own search keeps its planes while the
  // triangles stay (a still mesh rebuilt every frame looks once).
  f.mirror_planes_found = pipelined_ && f.tree_built && settings_ && frame_may_draw_mirrors(*scene, *settings_);
  if (f.mirror_planes_found) f.mirror_planes = find_mirror_planes(*scene);
  if (f.tree_built && !walks) {
    flatten_primitives(f.tree, scene->mesh.positions, scene->shapes);
    built_tree_rays_ = 0.0;
  } else if (f.tree_built) {
    KdBuildOptions kd = kd_;
    kd.rays = fit_rays;
    f.tree_rays = kd.rays;
    rebuild_kdtree(f.tree, scene->mesh.positions, scene->shapes, kd);
    built_tree_rays_ = kd.rays;
  } else {
    f.tree.clear();
  }
  f.build_ms = f.tree_built ? elapsed_ms(build_start) : 0.0;
  if (f.tree_built && !always_rebuild_) {
    built_positions_ = scene->mesh.positions;
    built_shapes_ = scene->shapes;
  }
  built_any_ = true;
  return elapsed_ms(start);
}

PipelineStep FramePipeline::step(size_t index, const std::function<void(PreparedFrame&)>& render) {
  if (index != next_ || index >= frames_) {
    throw Error(ErrorKind::Internal, "frame pipeline: step " + std::to_string(index) + " asked where " +
                                         std::to_string(next_) + " of " + std::to_string(frames_) + " is next");
  }
  const auto start = std::chrono::steady_clock::now();
  PipelineStep s;
  // The first frame, every frame of the serial loop and one whose preparation on the worker
  // failed are prepared here; the others were prepared on the worker during the previous step.
  if (ready_ != index) prepare(index);
  ++next_;
  if (pipelined_ && next_ < frames_) start_ahead(next_);
  const auto render_start = std::chrono::steady_clock::now();
  const double render_cpu_start = thread_cpu_ms();
  slots_[index % 2].walks = -1;
  try {
    render(slots_[index % 2]);
  } catch (...) {
    if (ahead_.valid()) ahead_.wait();  // the worker writes the other slot: let it finish first
    throw;
  }
  s.render_ms = elapsed_ms(render_start);
  walks_[index] = slots_[index % 2].walks;
  s.render_cpu_ms = thread_cpu_ms() - render_cpu_start;
  if (ahead_.valid()) {
    const auto wait_start = std::chrono::steady_clock::now();
    s.ahead_ms = ahead_.get();  // rethrows the worker's error
    s.wait_ms = elapsed_ms(wait_start);
    ready_ = next_;
  }
  s.period_ms = elapsed_ms(start);
  return s;
}

Image render_prepared(Renderer& renderer, PreparedFrame& f, FrameTimings* timings) {
  FrameTimings own;
  FrameTimings* t = timings ? timings : &own;
  // The planes are swapped in: the slot then holds the renderer's older ones, no longer this frame's.
  MirrorPlanes* planes = std::exchange(f.mirror_planes_found, false) ? &f.mirror_planes : nullptr;
  Image image = f.tree_built ? renderer.render(*f.scene, f.camera, f.tree, f.build_ms, t, &f.light_buffers, &f.posed_parts,
                                               planes)
                             : renderer.render(*f.scene, f.camera, t);
  f.walks = int64_t(t->sum.walks);
  return image;
}

}  // namespace mobirt
