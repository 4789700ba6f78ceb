// The compute engine as a whole Whitted frame (render/whitted.h): mobirt's own kd-tree, built on
// the CPU as mobirt's frame builds it, traversed by the compute pass (ComputeEngine), which returns
// t, barycentrics and shadow masks (TracedGeneration::Form::Hits), so the CPU makes the surface
// records without intersecting again; everything else is mobirt's: the same primary rays, ray tree
// and Vulkan shading pass (a Renderer on a backend of its own). Its frames equal mobirt's, and what
// differs is what the OpenGL ES 2.0 constraints cost. `mobirt bench` runs it beside mobirt.
#pragma once

#include <vector>

#include <glm/glm.hpp>

#include "baseline/compute_engine.h"
#include "render/engine.h"
#include "render/renderer.h"

namespace mobirt {

class ComputeWhittedEngine final : public ShadedByRenderer {
 public:
  // compute traces; shading's passes shade (a Renderer made with the frame's settings). Neither is owned.
  ComputeWhittedEngine(ComputeEngine& compute, Renderer& shading) : ShadedByRenderer(shading), compute_(compute) {}
  const char* name() const override { return compute_.name(); }

  // The kd-tree built (or kept while no triangle moves, unless settings.always_rebuild) and
  // uploaded to the pass's storage buffers; the scene's materials for the shading pass.
  void begin_frame(const Scene& scene, const RenderSettings& settings, FrameTimings& frame) override;
  const FlatKdTree& tree() const override { return tree_; }
  // The compute pass: one hit record per ray, handed on as hits and masks.
  TracedGeneration trace(const Scene& scene, const RayBatch& rays, GenerationTimings& g) override;
  // As mobirt's passes order them: neighbouring rays walk the same nodes in one SIMD group.
  void order_rays(RayBatch& rays) const override;

 private:
  ComputeEngine& compute_;
  RenderSettings settings_;
  FlatKdTree tree_;
  std::vector<glm::vec3> tree_positions_;  // what tree_ was built on
  bool tree_valid_ = false;
  std::vector<HitRecord> records_;
};

}  // namespace mobirt
