#include "baseline/ray_query_whitted.h"


#include "raytree/ray_order.h"

namespace mobirt {

void RayQueryWhittedEngine::begin_frame(const Scene& scene, const RenderSettings& settings, FrameTimings& frame) {
  shading_.check_shades_like(settings, "RayQueryWhittedEngine");
  // Refuse a scene over a packing limit before any work, as mobirt's passes do.
  choose_packing(scene.mesh.triangle_count(), settings.shadows ? int(scene.lights.size()) : 0, scene.source);
  shadows_ = settings.shadows;
  shadow_rays_ = settings.shadow_rays;
  build_ = {};
  rq_.build(scene, &build_);
  frame.build_ms = build_.wall_ms;
  frame.tree_rebuilt = true;
  shading_.upload_materials(scene);
}

TracedGeneration RayQueryWhittedEngine::trace(const Scene& scene, const RayBatch& rays, GenerationTimings& g) {
  const std::span<const Light> lights = shadows_ ? std::span<const Light>(scene.lights) : std::span<const Light>();
  TracedGeneration traced;
  traced.form = TracedGeneration::Form::PackedTexels;
  traced.texels.resize(rays.count());
  RayQueryTimings t;
  traced.packing = rq_.trace(rays, lights, shadow_rays_, traced.texels, &t);
  g.add_trace_pass(t.upload_ms, t.trace_ms, t.readback_ms, t.bytes_read);
  return traced;
}

void RayQueryWhittedEngine::order_rays(RayBatch& rays) const { order_for_traversal(rays, rq_.triangles().bounds); }

}  // namespace mobirt
