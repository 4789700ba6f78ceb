// What drives one Whitted frame (src/render/whitted.h): an engine traces each generation of rays
// into hits and shadow masks and shades the decoded hits; the loop around it (primary rays,
// decoding, accumulation, the ray tree) is the same for every engine. Implemented by the GPU
// fragment passes of every backend (Renderer), by mobirt's CPU kd-tree (KdTreeEngine) and by
// Embree (src/baseline). A new engine (a compute pass, the driver's ray queries) implements this
// interface and returns hits in whichever form it has; the loop does not change.
#pragma once

#include <glm/glm.hpp>

#include <cstdint>
#include <span>
#include <vector>

#include "accel/kdtree.h"
#include "core/camera.h"
#include "raytree/hits.h"
#include "raytree/packing.h"
#include "raytree/rays.h"
#include "scene/scene.h"

namespace mobirt {

struct RenderSettings;

// One generation of rays: where its time went (milliseconds) and what it traced. Each engine
// fills the stages it has; the others stay 0.
struct GenerationTimings {
  uint32_t rays = 0;
  uint32_t hits = 0;
  uint32_t capped = 0;          // rays the loop cap handed back to the CPU
  uint64_t shadow_rays = 0;     // shadow rays cast
  // Walks of the kd-tree in the passes: each closest-hit ray traced (not drawn), plus one per ray
  // and shadow light without a light buffer (an upper bound: a miss casts none). What the next
  // frames' trees are built for (KdBuildOptions::rays, FramePipeline).
  uint64_t walks = 0;
  uint32_t cpu_walked = 0;      // closest-hit rays walked on the CPU instead of a pass (--cpu-walks)
  uint32_t mirrored = 0;        // mirror rays handed to a raster pass of the mirrored scene (--mirrors;
                                // one it drew nothing for is a miss); its CPU work counts as upload
  double upload_ms = 0;         // textures uploaded for the passes (generation 0: the tree too)
  double trace_ms = 0;          // closest hits (GPU timestamps; CPU engines: wall clock), with the
                                // shadow rays where the engine casts them in the same pass
  double trace_readback_ms = 0; // the traversal result back to the CPU
  double shadow_ms = 0;         // CPU engines: surface records and shadow rays after the hits
  double decode_ms = 0;         // hit decoding, capped rays retraced (CPU)
  double shade_ms = 0;          // shading (GPU timestamps or CPU wall clock)
  double shade_readback_ms = 0;
  double accumulate_ms = 0;     // colours into the float frame with the rays' weights (CPU)
  double secondary_ms = 0;      // the next generation's rays (CPU)
  uint32_t shaded = 0;          // rays a shading pass shaded: the hits and, when any ray missed, one
                                // miss, whose colour is every miss's (Renderer::shade)
  uint64_t bytes_read = 0;      // bytes that left the GPU: 4 per ray and pass

  GenerationTimings& operator+=(const GenerationTimings& g);
  // One GPU pass of the generation's tracing: its uploads, its time, its read-back and bytes.
  void add_trace_pass(double pass_upload_ms, double pass_ms, double readback_ms, uint64_t bytes) {
    upload_ms += pass_upload_ms;
    trace_ms += pass_ms;
    trace_readback_ms += readback_ms;
    bytes_read += bytes;
  }
};

// Where one frame's time went, stage by stage (milliseconds); the per-generation stages summed.
struct FrameTimings {
  double build_ms = 0;          // acceleration structure build (CPU); 0 when the tree was kept
  bool tree_rebuilt = false;
  double rays_ms = 0;           // primary ray generation (CPU)
  GenerationTimings sum;        // all generations together (add() keeps it)
  std::vector<GenerationTimings> generations;
  double total_ms = 0;          // wall clock of the whole frame

  uint32_t primary_rays() const { return generations.empty() ? 0 : generations[0].rays; }
  // The one place a generation joins the frame: appended and summed.
  void add(const GenerationTimings& g);
};

// What an engine's trace of one generation returns, one entry per ray, in one of three forms.
struct TracedGeneration {
  enum class Form {
    // The fragment passes: one packed texel per ray (hit index and shadow mask, glsl/layout.h),
    // decoded on the CPU against WhittedEngine::tree(), which intersects the hit triangle again
    // and retraces the rays the loop cap stopped.
    PackedTexels,
    // Engines that know t and barycentrics (a compute pass, ray queries): `hits` and `masks`;
    // the surface records are made from them without intersecting again; `capped` rays are traced
    // on the CPU.
    Hits,
    // Engines that made the surface records themselves, shadow masks included (the CPU engines).
    Surfaces,
  };
  Form form = Form::Surfaces;
  std::vector<uint32_t> texels;  // PackedTexels
  Packing packing = Packing::Bits24_8;
  std::vector<Hit> hits;         // Hits
  std::vector<uint32_t> masks;   // Hits: shadow bits per ray
  std::vector<uint32_t> capped;  // Hits: rays the loop cap stopped, traced on the CPU against tree()
  SurfaceHits surfaces;          // Surfaces: every ray marked by the engine, a record for each hit
  uint64_t shadow_rays = 0;      // Hits and Surfaces: shadow rays the engine cast
};

class WhittedEngine {
 public:
  virtual ~WhittedEngine() = default;
  virtual const char* name() const = 0;

  // Once per frame, first of all: an engine may start work here that runs beside begin_frame's and
  // the primary rays' (the fragment passes' raster pass of the primary hits). Nothing by default.
  virtual void start_frame(const Scene&, const Camera&, const RenderSettings&) {}

  // Once per frame, before the first generation: builds (or keeps) the acceleration structure over
  // scene.mesh as it is now and uploads what the passes read; fills frame.build_ms and
  // frame.tree_rebuilt. A scene over one of the engine's limits is refused here, before any work.
  virtual void begin_frame(const Scene& scene, const RenderSettings& settings, FrameTimings& frame) = 0;

  // The frame's triangle texels and scene box (nodes too where hits come as PackedTexels): hits are
  // decoded and the shadow and secondary rays offset against it.
  virtual const FlatKdTree& tree() const = 0;

  // One generation of rays: closest hits and, with settings.shadows, shadow masks (without, the
  // loop lights every hit by every light). Fills the stages it runs in g.
  virtual TracedGeneration trace(const Scene& scene, const RayBatch& rays, GenerationTimings& g) = 0;

  // The first generation, the primary rays through `camera` (primary_rays(): one per pixel, in
  // pixel order), which an engine may find another way than by tracing them (the fragment passes'
  // --primary raster); by default traced as every generation is.
  virtual TracedGeneration trace_primary(const Scene& scene, const Camera&, const RayBatch& rays,
                                         GenerationTimings& g) {
    return trace(scene, rays, g);
  }

  // A generation of secondary rays (generation 1: the primary hits' mirror and refracted rays),
  // which an engine may find partly another way (the fragment passes' --mirrors raster: the mirror
  // rays off a flat mirror drawn as the scene mirrored in it); by default traced as every
  // generation is.
  virtual TracedGeneration trace_secondary(const Scene& scene, const Camera&, int /*generation*/, const RayBatch& rays,
                                           GenerationTimings& g) {
    return trace(scene, rays, g);
  }

  // One colour per ray for the decoded hits (a miss: the background), quantised as the shading pass
  // writes it. Fills the stages it runs in g.
  virtual std::vector<glm::vec3> shade(const Scene& scene, const RayBatch& rays,
                                       const SurfaceHits& hits, GenerationTimings& g) = 0;

  // Whether the engine shades a frame's generations all at once after its last (queue_shade for
  // each, then shade_queued) instead of one at a time (shade()): the fragment passes then run one
  // shading pass a frame instead of one a generation, and pay a pass's fixed cost (its submission,
  // the driver's threads woken, the wait, the read-back) once. The colours are the same either way,
  // and the frame adds them to the image in the same order. False by default.
  virtual bool shades_at_end() const { return false; }

  // shades_at_end(): a generation's decoded hits kept for the frame's shading (the fragment passes:
  // its inputs written where the pass reads them). Fills the stages it runs in g.
  virtual void queue_shade(const Scene& scene, const RayBatch& rays, const SurfaceHits& hits, GenerationTimings& g);

  // shades_at_end(): the colours of the generations queued since the last call, one array per
  // generation in the order queued, each as shade() would return it; fills the stages it runs in
  // g[k] for the k-th of them (a pass shared by several split among them by the texels each had
  // shaded: its hits, and the miss where it is the first of them with one). Empties the queue.
  virtual std::vector<std::vector<glm::vec3>> shade_queued(const Scene& scene, std::span<GenerationTimings> g);

  // After a generation is shaded (queued, where the engine shades at the end), before its colours
  // are added and the next generation is made
  // (only where one follows): an engine may start work for the next generation here that runs
  // beside that (the fragment passes: the mirror raster of the primary hits' flat mirror; its CPU
  // time goes to this generation's stages, its pass to the next's). Nothing by default.
  virtual void shaded(const Scene&, const Camera&, int /*generation*/, const RayBatch& /*rays*/,
                      const SurfaceHits& /*hits*/, GenerationTimings& /*g*/) {}

  // Once per frame, after its last generation (also when the frame throws): an engine ends what it
  // started for a generation that never came (a mirror raster started ahead of mirror rays that
  // were not made). Nothing by default.
  virtual void end_frame() {}

  // The order of a new generation's rays that suits the engine (the fragment passes: neighbouring
  // rays in one SIMD group); by default as the ray tree made them.
  virtual void order_rays(RayBatch&) const {}
};

}  // namespace mobirt
