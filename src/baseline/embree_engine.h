// The baseline a user would pick instead of mobirt: Embree 3 on the CPU (Debian's libembree-dev),
// behind the same CpuRayEngine interface as mobirt's own CPU kd-tree traversal, so that
// render_whitted_cpu() renders the same frame (camera, lights, materials, shadow rays, ray tree)
// with either. Only `mobirt bench`, its tests and the microbenchmarks link it; the renderer never
// does.
#pragma once

#include <memory>
#include <span>
#include <string>

#include "render/cpu_render.h"

namespace mobirt {

struct EmbreeOptions {
  unsigned threads = 0;  // Embree's build threads (0 = all cores)
  // The BVH a user who rebuilds every frame would ask for: RTC_SCENE_FLAG_DYNAMIC with
  // RTC_BUILD_QUALITY_LOW (Morton build). false: a static scene of MEDIUM quality (binned SAH).
  bool dynamic_low = true;
};

class EmbreeEngine final : public CpuRayEngine {
 public:
  explicit EmbreeEngine(const EmbreeOptions& options = {});
  ~EmbreeEngine() override;
  EmbreeEngine(const EmbreeEngine&) = delete;
  EmbreeEngine& operator=(const EmbreeEngine&) = delete;

  const char* name() const override { return "Embree 3 (CPU)"; }
  // Copies the frame's triangles into Embree's buffers and commits the scene: the BVH build.
  void build(const Scene& scene) override;
  // The same on bare triangles (3 positions per triangle): the build microbenchmark.
  void build(std::span<const glm::vec3> positions);
  Hit closest(const Ray& ray) const override;    // rtcIntersect1
  bool occluded(const Ray& ray) const override;  // rtcOccluded1
  const FlatKdTree& triangles() const override { return triangles_; }

  // "Embree 3.13.5" (the library's own version).
  static std::string version();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  FlatKdTree triangles_;  // texels and box only (no nodes): what the shadow rays are made from
};

}  // namespace mobirt
