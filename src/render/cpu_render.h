// The same frame as Renderer, computed entirely on the CPU in single precision: the kd-tree
// traversal of src/accel, the shadow rays of src/raytree/hits.h, and a C++ transcription of
// glsl/shade.glsl. It is the expectation the GPU image is tested against (it shares the tree and
// the ray tree but none of the shaders), and the CPU column of the benchmarks.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "accel/kdtree.h"
#include "core/camera.h"
#include "core/image.h"
#include "raytree/hits.h"
#include "render/engine.h"
#include "render/renderer.h"
#include "scene/atlas.h"
#include "scene/scene.h"

namespace mobirt {

// Phong with the shadow mask, as glsl/shade.glsl computes it. `view` points towards the viewer;
// `atlas` gives the textures (may be empty).
glm::vec3 shade_phong(const Scene& scene, const SurfaceHit& hit, const glm::vec3& view, const Atlas& atlas);

// What traces the rays of a CPU frame: mobirt's own kd-tree traversal (KdTreeEngine), or the
// baseline a user would pick instead (the Embree engine in src/baseline/). closest() and
// occluded() are called from several threads at once. As a WhittedEngine it traces a generation
// with them (closest hits, then surface records and shadow rays) and shades it with shade_phong().
class CpuRayEngine : public WhittedEngine {
 public:
  // (Re)builds the acceleration structure over scene.mesh, as it is now. Once per frame.
  virtual void build(const Scene& scene) = 0;
  virtual Hit closest(const Ray& ray) const = 0;  // in [ray.tmin, ray.tmax]; prim -1 = miss
  virtual bool occluded(const Ray& ray) const = 0;
  // The triangle texels and the scene box of the last build: the shadow rays and the secondary
  // rays are made from them exactly as for the GPU passes (the box sizes the origin offset).
  virtual const FlatKdTree& triangles() const = 0;
  // The surface record of a closest hit: by default from the engine's own t and barycentrics.
  virtual SurfaceHit surface(const Scene& scene, const Ray& ray, const Hit& hit) const {
    return surface_from_hit(scene, ray, hit);
  }

  // The threads of each stage (0 = all cores), and whether shaded colours are quantised to
  // settings.colour as the shading pass writes them (else clamped to [0, 1]).
  void set_frame_options(unsigned threads, bool quantize);

  void begin_frame(const Scene& scene, const RenderSettings& settings, FrameTimings& frame) override;
  const FlatKdTree& tree() const override { return triangles(); }
  TracedGeneration trace(const Scene& scene, const RayBatch& rays, GenerationTimings& g) override;
  std::vector<glm::vec3> shade(const Scene& scene, const RayBatch& rays, const SurfaceHits& hits,
                               GenerationTimings& g) override;

 private:
  unsigned threads_ = 0;
  bool quantize_ = true;
  bool shadows_ = true;
  ShadowSettings shadow_rays_;
  ColourDepth colour_ = ColourDepth::Bits8;
  Atlas atlas_;                          // the scene's textures
  std::optional<std::string> atlas_key_;  // atlas_key() of the scene atlas_ was built for; none yet
};

// mobirt's binned-SAH kd-tree, traversed with a full stack (src/accel) with the renderer's
// ray/triangle test; surface records recomputed on the hit triangle as hit decoding does.
class KdTreeEngine final : public CpuRayEngine {
 public:
  explicit KdTreeEngine(const KdBuildOptions& options = {}, const RayTest& test = {})
      : options_(options), test_(test) {}
  const char* name() const override { return "mobirt kd-tree (CPU)"; }
  void build(const Scene& scene) override;
  Hit closest(const Ray& ray) const override;
  bool occluded(const Ray& ray) const override;
  const FlatKdTree& triangles() const override { return tree_; }
  SurfaceHit surface(const Scene& scene, const Ray& ray, const Hit& hit) const override;
  const FlatKdTree& tree() const override { return tree_; }

 private:
  KdBuildOptions options_;
  RayTest test_;
  FlatKdTree tree_;
};

// The whole Whitted frame on the CPU with `engine`: the same primary rays, shadow rays, Phong
// (shade_phong) and ray tree as the GPU renderer (render_whitted()); width x height; threads 0 =
// all cores. With quantize, each shaded colour is quantised to settings.colour as the shading pass
// writes it.
Image render_whitted_cpu(const Scene& scene, const Camera& camera, const RenderSettings& settings,
                         CpuRayEngine& engine, unsigned threads = 0, FrameTimings* timings = nullptr,
                         bool quantize = true);

// The renderer's frame on the CPU: render_whitted_cpu with a KdTreeEngine built with settings.kd
// and the same ray/triangle test, offsets and ray tree: the expectation GPU images are tested
// against.
Image render_on_cpu(const Scene& scene, const Camera& camera, const RenderSettings& settings,
                    bool quantize = true);

}  // namespace mobirt
