#include "baseline/compute_whitted.h"

#include <chrono>

#include "core/error.h"
#include "raytree/packing.h"
#include "raytree/ray_order.h"

namespace mobirt {

void ComputeWhittedEngine::begin_frame(const Scene& scene, const RenderSettings& settings, FrameTimings& frame) {
  shading_.check_shades_like(settings, "ComputeWhittedEngine");
  // The peer traces mobirt's triangle kd-tree: analytic shapes are the caller's to tessellate
  // (scene/tessellate.h), as for Embree and the ray queries.
  if (!scene.shapes.empty()) {
    throw Error(ErrorKind::Internal, "compute engine: the scene's analytic shapes must be tessellated first");
  }
  // The record has room for any count, but the shading pass's mask and the frame's limits are
  // mobirt's: refuse a scene over them before any work, as mobirt's passes do.
  choose_packing(scene.mesh.triangle_count(), settings.shadows ? int(scene.lights.size()) : 0, scene.source);
  settings_ = settings;
  const bool reuse = !settings.always_rebuild && tree_valid_ && tree_positions_ == scene.mesh.positions;
  if (!reuse) {
    const auto start = std::chrono::steady_clock::now();
    tree_valid_ = false;  // rebuilt into the last tree's arrays: no cache until uploaded again
    rebuild_kdtree(tree_, scene.mesh.positions, {}, settings.kd);
    tree_positions_ = scene.mesh.positions;
    frame.build_ms = elapsed_ms(start);
    compute_.upload_tree(tree_);
    tree_valid_ = true;
  }
  frame.tree_rebuilt = !reuse;
  shading_.upload_materials(scene);
}

TracedGeneration ComputeWhittedEngine::trace(const Scene& scene, const RayBatch& rays, GenerationTimings& g) {
  const std::span<const Light> lights =
      settings_.shadows ? std::span<const Light>(scene.lights) : std::span<const Light>();
  records_.resize(rays.count());
  ComputeTimings t;
  compute_.trace(rays, lights, settings_.shadow_rays, {settings_.stack_depth, settings_.max_steps}, records_, &t);
  g.add_trace_pass(t.upload_ms, t.trace_ms, t.readback_ms, t.bytes_read);

  TracedGeneration traced;
  traced.form = TracedGeneration::Form::Hits;
  traced.hits.resize(rays.count());
  traced.masks.resize(rays.count());
  const uint32_t prims = uint32_t(scene.mesh.triangle_count());
  for (uint32_t i = 0; i < rays.count(); ++i) {
    const HitRecord& r = records_[i];
    if (r.capped()) {
      traced.capped.push_back(i);
      continue;
    }
    if (!r.hit()) continue;
    if (r.prim_plus_one > prims) {
      throw Error(ErrorKind::Internal, "the compute pass returned primitive " + std::to_string(r.prim()) +
                                           " of a scene with " + std::to_string(prims));
    }
    traced.shadow_rays += r.shadow_rays;
    traced.masks[i] = r.mask;
    if (r.flags & MOBIRT_HIT_NO_BARYCENTRICS) {
      // The second test on the triangle missed it by a rounding: the CPU intersects it once.
      const SurfaceHit s = surface_hit(scene, tree_, rays.ray(i), r.prim(), settings_.shadow_rays.ray_test.test);
      traced.hits[i] = Hit{s.prim, s.t, s.u, s.v};
    } else {
      traced.hits[i] = Hit{r.prim(), r.t, r.u, r.v};
    }
  }
  return traced;
}

void ComputeWhittedEngine::order_rays(RayBatch& rays) const { order_for_traversal(rays, tree_.bounds); }

}  // namespace mobirt
