// The compute path the paper names as its future work ("the use of OpenCL will provide faster and
// more efficient ray tracing"): mobirt's own kd-tree traversal, the same FlatKdTree, rays, shadow
// rays, short stack and loop cap as the fragment pass, as a Vulkan compute shader
// (glsl/trace_compute.comp over glsl/traverse.glsl) reading read-only storage buffers and writing
// one wide hit record per ray (HitRecord, glsl/texels.h): t, barycentrics, primitive, shadow mask,
// shadow rays cast. The CPU then makes the surface record without intersecting again.
//
// It is a peer, there to measure what the OpenGL ES 2.0 constraints cost: it breaks them (storage
// buffers and writes, a compute shader, 32 bytes per ray) and says which (broken_constraints()).
// Its Vulkan instance and device are the backend's own code (vk::Device), a context of its own.
//
//   ComputeEngine engine;                   // once; Error(NoDevice) without a Vulkan device
//   engine.upload_tree(tree);               // each time the kd-tree is built
//   std::vector<HitRecord> records(rays.count());
//   engine.trace(rays, lights, settings, records, &timings);
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "accel/kdtree.h"
#include "backend/vulkan/vulkan_backend.h"
#include "raytree/hits.h"
#include "raytree/rays.h"
#include "scene/scene.h"
#include "texels.h"

namespace mobirt {

// What one trace() spends, milliseconds.
struct ComputeTimings {
  double upload_ms = 0;    // the rays and uniforms into the mapped storage buffers (CPU copies)
  double trace_ms = 0;     // the dispatch (GPU timestamps; without them its submission until its fence
                           // on the CPU's clock): the figure beside mobirt's trace_ms
  double readback_ms = 0;  // the hit records out of the mapped buffer (CPU copy)
  double wall_ms = 0;
  uint32_t rays = 0;
  uint64_t bytes_read = 0;  // MOBIRT_HIT_RECORD_BYTES per ray
};

// How the pass walks the tree: the fragment pass's settings (RenderSettings), so both trace alike.
struct ComputeTraversal {
  int stack_depth = 6;   // short-stack entries, 0 = pure kd-restart (RenderSettings::stack_depth)
  int max_steps = 2048;  // the loop cap; a capped ray comes back with MOBIRT_HIT_CAPPED
};

// How the pass reads the scene data (nodes, leaf entries, triangles): read-only storage buffers
// (glsl/trace_compute.comp), or uniform texel buffers as mobirt's fragment pass reads them
// (trace_compute_texel_buffers.comp), which tells the cost of the stage from the cost of the reads.
enum class ComputeData { StorageBuffers, TexelBuffers };

// "storage-buffers" / "texel-buffers"; parse_compute_data returns false for any other text.
const char* compute_data_name(ComputeData data);
bool parse_compute_data(std::string_view text, ComputeData& data);

class ComputeEngine {
 public:
  // options: the device, validation (also MOBIRT_VALIDATION=1); its pipeline cache stays in memory.
  explicit ComputeEngine(const VulkanOptions& options = {}, ComputeData data = ComputeData::StorageBuffers);
  ~ComputeEngine();
  ComputeEngine(const ComputeEngine&) = delete;
  ComputeEngine& operator=(const ComputeEngine&) = delete;

  const char* name() const { return "mobirt kd-tree, compute (Vulkan)"; }
  // Device, driver, the storage the pass reads and writes, and the OpenGL ES 2.0 constraints it
  // breaks, one per line.
  std::vector<std::string> info() const;

  // The tree's nodes, leaf entries and triangles into the pass's buffers; returns the
  // milliseconds it took (CPU copies into mapped memory). Throws Error(BadInput) for an array over
  // 2^23 elements (the shaders' narrow index conversion; its pass is not specialised to
  // WIDE_INDICES, as mobirt's fragment passes are for larger buffers).
  double upload_tree(const FlatKdTree& tree);

  // One hit record per ray of `rays` into out[0, rays.count()), against the last uploaded tree,
  // with shadow rays to `lights` (none: no shadow rays, mask 0) made as `shadows` says. Throws
  // Error(BadInput) for more than MOBIRT_MAX_LIGHTS lights, Error(Internal) before upload_tree().
  void trace(const RayBatch& rays, std::span<const Light> lights, const ShadowSettings& shadows,
             const ComputeTraversal& traversal, std::span<HitRecord> out, ComputeTimings* timings = nullptr);

  // Every validation message since the last call (tests assert there are none).
  std::vector<std::string> take_debug_messages();

  // The OpenGL ES 2.0 constraints glsl/trace_compute.comp breaks, by name (shader_constraints.h).
  static std::vector<std::string> broken_constraints();

  // Empty when an engine can be made with these options, else why not (its constructor's message).
  static std::string unavailable_reason(const VulkanOptions& options = {});

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace mobirt
