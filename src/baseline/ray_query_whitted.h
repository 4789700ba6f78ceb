// The ray-query peer as a whole Whitted frame (render/whitted.h): the driver's BVH and rayQueryEXT
// trace (RayQueryEngine), and everything else is mobirt's: the same primary rays, hit decoding of
// the same packed texels, ray tree, and mobirt's own shading pass on a Vulkan backend (the same
// Phong), so that its frames equal mobirt's and only the traversal differs. `mobirt bench` runs it
// beside mobirt on the same frames.
#pragma once

#include "baseline/ray_query_engine.h"
#include "render/engine.h"
#include "render/renderer.h"

namespace mobirt {

class RayQueryWhittedEngine final : public ShadedByRenderer {
 public:
  // rq traces; shading's passes shade (a Renderer on a Vulkan backend, made with the frame's
  // settings: its colour depth and specialisation are the frame's). Neither is owned.
  RayQueryWhittedEngine(RayQueryEngine& rq, Renderer& shading) : ShadedByRenderer(shading), rq_(rq) {}
  const char* name() const override { return rq_.name(); }

  // The driver's BLAS + TLAS, built every frame (frame.build_ms: the whole build() call, vertex
  // upload included), and the scene's materials for the shading pass.
  void begin_frame(const Scene& scene, const RenderSettings& settings, FrameTimings& frame) override;
  const FlatKdTree& tree() const override { return rq_.triangles(); }
  // The ray-query pass: one packed texel per ray, as mobirt's traversal pass writes it.
  TracedGeneration trace(const Scene& scene, const RayBatch& rays, GenerationTimings& g) override;
  // As mobirt's passes order them: neighbouring rays in one SIMD group suit a fragment pass either way.
  void order_rays(RayBatch& rays) const override;

  // The last begin_frame's build, split into upload, BLAS and TLAS.
  const AsBuildTimings& last_build() const { return build_; }

 private:
  RayQueryEngine& rq_;
  bool shadows_ = true;
  ShadowSettings shadow_rays_;
  AsBuildTimings build_;
};

}  // namespace mobirt
