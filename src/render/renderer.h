// One frame through the paper's passes: CPU kd-tree build and primary rays, the GPU traversal pass
// (closest hit + shadow rays), CPU hit decoding, the GPU shading pass. The backend is only seen
// through src/backend/backend.h, so the same renderer drives Vulkan and OpenGL ES.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "accel/kdtree.h"
#include "backend/backend.h"
#include "core/camera.h"
#include "core/image.h"
#include "raytree/hits.h"
#include "raytree/packing.h"
#include "raytree/rays.h"
#include "scene/scene.h"

namespace mobirt {

struct RenderSettings {
  int width = 400;
  int height = 240;
  int stack_depth = 4;      // short-stack entries in the traversal shader, 0 = pure kd-restart
  int max_steps = 2048;     // loop cap of one traversal in the shader (see README: "Loop cap")
  KdBuildOptions kd;
  ShadowSettings shadows;
};

// Where one frame's time went, stage by stage (milliseconds).
struct FrameTimings {
  double build_ms = 0;          // kd-tree build + flattening (CPU)
  double rays_ms = 0;           // primary ray generation (CPU)
  double upload_ms = 0;         // tree, rays and shading inputs into textures
  double trace_ms = 0;          // traversal pass (GPU timestamps)
  double trace_readback_ms = 0; // its RGBA8 result back to the CPU
  double decode_ms = 0;         // hit decoding, capped rays retraced (CPU)
  double shade_ms = 0;          // shading pass (GPU timestamps)
  double shade_readback_ms = 0;
  double accumulate_ms = 0;     // RGBA8 colours into the float frame (CPU)
  double total_ms = 0;          // wall clock of the whole frame
  uint32_t rays = 0;
  uint32_t hits = 0;
  uint32_t capped = 0;          // rays the loop cap handed back to the CPU
  uint64_t shadow_rays = 0;     // shadow rays the traversal pass cast

  // Rays per second of the traversal pass: primary rays only, and all rays it traced.
  double trace_mrays_per_s() const { return trace_ms > 0 ? rays / (trace_ms * 1e3) : 0.0; }
  double trace_all_mrays_per_s() const {
    return trace_ms > 0 ? double(rays + shadow_rays) / (trace_ms * 1e3) : 0.0;
  }
};

// The read-back result of one traversal pass.
struct TraceResult {
  std::vector<uint32_t> texels;  // one packed texel per ray
  Packing packing = Packing::Bits24_8;
  PassTiming timing;
};

class Renderer {
 public:
  Renderer(Backend& backend, const RenderSettings& settings);
  ~Renderer();
  Renderer(const Renderer&) = delete;
  Renderer& operator=(const Renderer&) = delete;

  // Ray casting with shadows: one image of width x height.
  Image render(const Scene& scene, const Camera& camera, FrameTimings* timings = nullptr);

  // The traversal pass alone over the given rays (for tests and benchmarks). The tree must have
  // been built from scene.mesh.
  TraceResult trace(const Scene& scene, const FlatKdTree& tree, const RayBatch& rays);

  const RenderSettings& settings() const { return settings_; }

 private:
  struct Data;  // textures and passes, kept across frames and resized when they are too small
  TextureHandle ensure_texture(TextureHandle& handle, uint32_t& capacity_rows, uint32_t width,
                               uint32_t rows, TexelFormat format);
  PassHandle trace_pass(int lights, Packing packing);
  PassHandle shade_pass(int lights);
  void upload_tree(const FlatKdTree& tree);
  void upload_rays(const RayBatch& rays);

  Backend& backend_;
  RenderSettings settings_;
  std::unique_ptr<Data> data_;
};

// The traversal and shading uniforms (vec4 arrays, indices in glsl/layout.h).
std::vector<float> trace_uniforms(const FlatKdTree& tree, const Scene& scene, const ShadowSettings& s);
std::vector<float> shade_uniforms(const Scene& scene);

}  // namespace mobirt
