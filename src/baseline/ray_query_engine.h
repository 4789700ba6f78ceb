// The GPU-native peer a user would pick instead of mobirt: the driver's own ray tracing
// (VK_KHR_acceleration_structure + VK_KHR_ray_query; lavapipe has them from Mesa 24.1). Each frame
// the driver builds its BVH over the scene's triangles (one BLAS, a TLAS with one instance), and a
// fragment pass with rayQueryEXT (glsl/ray_query.frag) traces the same ray textures as mobirt's
// traversal pass and writes the same texel: hit primitive index + 1 and the shadow mask, with the
// same shadow rays (glsl/offset.glsl, the same light tests). Its texels go through the same
// decode_hits(), ray tree and shading as mobirt's.
//
// Self-contained: its own Vulkan instance and device (only when the driver has the extensions),
// none of the Renderer's state. It is a peer, not mobirt: it breaks the OpenGL ES 2.0 constraints
// mobirt keeps, and says which (broken_constraints()).
//
// One generation of a frame, as a Whitted loop would drive it:
//   RayQueryEngine rq;                  // once; Error(Unsupported) where the driver lacks ray queries
//   rq.build(scene, &build_timings);    // every frame
//   std::vector<uint32_t> texels(rays.count());
//   const Packing packing = rq.trace(rays, lights, settings.shadow_rays, texels, &trace_timings);
//   hits = decode_hits(scene, rq.triangles(), rays, texels, packing, lights, settings.shadow_rays);
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "accel/kdtree.h"
#include "backend/backend.h"
#include "raytree/hits.h"
#include "raytree/packing.h"
#include "raytree/rays.h"
#include "scene/scene.h"

namespace mobirt {

// How the BLAS follows an animated scene. Fresh: a PREFER_FAST_BUILD build every frame. Update:
// built once with ALLOW_UPDATE, then refitted (mode UPDATE) while the triangle count stays; a new
// count builds afresh. On lavapipe of Mesa 25.0.7 both cost the same within 5 % (its builder
// rebuilds either way), the update marginally less (README: the ray-query peer), hence the default.
//
// The BLAS gets the triangles in Scene::mesh order. lavapipe's builder splits the list in the middle
// in the order given, without sorting, so its BVH is as good as that order: the toaster's triangles
// shuffled trace 80x slower (tools/profile: mobirt_ray_query_rays --shuffle). A Morton presort on
// the CPU was tried and traced no faster (toaster 2x slower, fish and the Utah toasters the same):
// the peer is the driver as a user gets it.
enum class AsBuildMode { Fresh, Update };

struct RayQueryOptions {
  std::string device;        // a Vulkan device index or part of its name; empty = lavapipe
  bool validation = false;   // Khronos validation layer (also MOBIRT_VALIDATION=1); see take_debug_messages()
  bool sync_validation = false;  // with validation: also the layer's synchronization validation
  AsBuildMode build_mode = AsBuildMode::Update;
  // Timestamps around the build and the pass, or the CPU's clock, as mobirt's passes
  // (GpuTimestamps, backend/backend.h: on lavapipe each timestamp waits for the work).
  GpuTimestamps timestamps = GpuTimestamps::Auto;
};

// One build(): milliseconds. gpu: timestamps around the driver's work; wall: the whole call.
struct AsBuildTimings {
  double upload_ms = 0;     // vertices and triangle texels into the device's buffers (CPU copies)
  double blas_ms = 0;       // BLAS build or update (GPU timestamps; 0 without them: see wall_ms)
  double tlas_ms = 0;       // TLAS build (GPU timestamps; 0 without them)
  double wall_ms = 0;
  bool updated = false;     // the BLAS was updated, not built afresh
  uint32_t triangles = 0;
};

// One trace(): milliseconds.
struct RayQueryTimings {
  double upload_ms = 0;     // ray textures: CPU copy + GPU copy (timestamps; without them the CPU copy)
  double trace_ms = 0;      // the fragment pass (GPU timestamps; without them the submission until its
                            // fence on the CPU's clock, the rays' copies and the read-back's copy
                            // on the device included): the figure beside mobirt's trace_ms
  double readback_ms = 0;   // RGBA8 texels back to the host (GPU copy + CPU copy)
  double wall_ms = 0;
  uint32_t rays = 0;
  uint64_t bytes_read = 0;  // 4 per ray, as mobirt's passes
};

class RayQueryEngine {
 public:
  // Throws Error(Unsupported) naming what the driver lacks, e.g. "lavapipe of Mesa 22.3.6 lacks
  // VK_KHR_ray_query; Mesa >= 24.1 has it", Error(NoDevice) without a Vulkan device.
  explicit RayQueryEngine(const RayQueryOptions& options = {});
  ~RayQueryEngine();
  RayQueryEngine(const RayQueryEngine&) = delete;
  RayQueryEngine& operator=(const RayQueryEngine&) = delete;

  const char* name() const { return "driver ray query (Vulkan)"; }
  // Device, driver, build mode and the OpenGL ES 2.0 constraints the pass breaks, one per line.
  std::vector<std::string> info() const;

  // The acceleration structures over scene.mesh as it is now (once per frame), and the triangle
  // texels the shadow rays read.
  void build(const Scene& scene, AsBuildTimings* timings = nullptr);

  // The traversal pass over `rays` (laid out as the renderer uploads them: ray i at (i mod
  // rays.width, i div rays.width)): one packed texel per ray into out[0, rays.count()), with shadow
  // rays to `lights` (none: no shadow rays, mask 0) made as `shadows` says. Only shadows.offset is
  // used: the driver's own ray/triangle test replaces shadows.ray_test (Precision::Medium is
  // refused: the driver has no fp16 test). Returns the packing (choose_packing(), as the renderer's).
  Packing trace(const RayBatch& rays, std::span<const Light> lights, const ShadowSettings& shadows,
                std::span<uint32_t> out, RayQueryTimings* timings = nullptr);

  // The triangle texels and scene box of the last build (no kd-tree nodes): what decode_hits()
  // and the shadow rays of the CPU need beside the texels (the pass never caps a ray).
  const FlatKdTree& triangles() const;

  // Every validation message since the last call (tests assert there are none).
  std::vector<std::string> take_debug_messages();

  // The OpenGL ES 2.0 constraints glsl/ray_query.frag breaks, by name (shader_constraints.h).
  static std::vector<std::string> broken_constraints();

  // Empty when a RayQueryEngine can be made with these options, else the reason it cannot (the
  // message its constructor would throw). Makes and drops a Vulkan instance.
  static std::string unavailable_reason(const RayQueryOptions& options = {});

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace mobirt
