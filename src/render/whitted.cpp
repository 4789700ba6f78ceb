#include "render/whitted.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <exception>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "core/error.h"
#include "core/parallel.h"
#include "raytree/secondary.h"

namespace mobirt {

GenerationTimings& GenerationTimings::operator+=(const GenerationTimings& g) {
  rays += g.rays;
  hits += g.hits;
  capped += g.capped;
  shadow_rays += g.shadow_rays;
  walks += g.walks;
  mirrored += g.mirrored;
  cpu_walked += g.cpu_walked;
  upload_ms += g.upload_ms;
  trace_ms += g.trace_ms;
  trace_readback_ms += g.trace_readback_ms;
  shadow_ms += g.shadow_ms;
  decode_ms += g.decode_ms;
  shade_ms += g.shade_ms;
  shade_readback_ms += g.shade_readback_ms;
  accumulate_ms += g.accumulate_ms;
  secondary_ms += g.secondary_ms;
  shaded += g.shaded;
  bytes_read += g.bytes_read;
  return *this;
}

void WhittedEngine::queue_shade(const Scene&, const RayBatch&, const SurfaceHits&, GenerationTimings&) {
  throw Error(ErrorKind::Internal, std::string(name()) + ": queue_shade on an engine that shades each generation");
}

std::vector<std::vector<glm::vec3>> WhittedEngine::shade_queued(const Scene&, std::span<GenerationTimings>) {
  throw Error(ErrorKind::Internal, std::string(name()) + ": shade_queued on an engine that shades each generation");
}

void FrameTimings::add(const GenerationTimings& g) {
  generations.push_back(g);
  sum += g;
}

uint32_t all_lights_mask(const Scene& scene) {
  return scene.lights.empty() ? 0u : (2u << (scene.lights.size() - 1)) - 1u;
}

SurfaceHits decode_generation(const Scene& scene, const RenderSettings& settings, const FlatKdTree& tree,
                              const RayBatch& rays, TracedGeneration&& traced, GenerationTimings& g) {
  const std::span<const Light> lights = settings.shadows ? std::span<const Light>(scene.lights)
                                                         : std::span<const Light>();
  const uint32_t all_lights = all_lights_mask(scene);
  SurfaceHits hits;
  switch (traced.form) {
    case TracedGeneration::Form::PackedTexels: {
      DecodeStats stats;
      // Without shadows the pass cast no shadow rays and every mask is 0: every light is made
      // visible while decoding, not by a pass of its own.
      hits = decode_hits(scene, tree, rays, traced.texels, traced.packing, lights, settings.shadow_rays, &stats,
                         settings.shadows ? 0u : all_lights);
      g.hits += stats.hits;  // the pass's hits, counted as decoded
      g.capped += stats.capped;
      g.shadow_rays += stats.shadow_rays;
      break;
    }
    case TracedGeneration::Form::Hits:
      hits.resize(rays.count());  // unwritten: every ray is marked here
      // On all cores, as decode_hits() decodes the packed texels.
      parallel_for(rays.count(), 0, [&](uint32_t i) {
        if (!traced.hits[i].valid()) {
          hits.set_miss(i);
          return;
        }
        SurfaceHit& h = hits.record(i);
        h = surface_from_hit(scene, rays.ray(i), traced.hits[i]);
        h.mask = traced.masks[i];
        hits.set_hit(i);
      }, 256);
      parallel_for(uint32_t(traced.capped.size()), 0, [&](uint32_t k) {
        const uint32_t i = traced.capped[k];
        hits.set(i, retrace_capped(scene, tree, rays.ray(i), lights, settings.shadow_rays));
      }, 16);
      g.capped += uint32_t(traced.capped.size());
      g.shadow_rays += traced.shadow_rays;
      break;
    case TracedGeneration::Form::Surfaces:
      hits = std::move(traced.surfaces);
      g.shadow_rays += traced.shadow_rays;
      break;
  }
  // The other forms: their hits counted, and every light visible without shadows, on all cores
  // (a serial pass over the records cost about 1 ms a generation, the records cold).
  if (traced.form != TracedGeneration::Form::PackedTexels) {
    constexpr uint32_t kChunk = 4096;
    const uint32_t n = uint32_t(hits.size());
    std::atomic<uint32_t> valid{0};
    parallel_for_chunks(n, kChunk, 0, [&](uint32_t, uint32_t begin, uint32_t end) {
      uint32_t chunk_valid = 0;
      for (uint32_t i = begin; i < end; ++i) {
        if (!hits.hit(i)) continue;
        ++chunk_valid;
        if (!settings.shadows) hits.record(i).mask = all_lights;
      }
      valid.fetch_add(chunk_valid, std::memory_order_relaxed);
    });
    g.hits += valid.load();
  }
  if (hits.size() != rays.count()) throw Error(ErrorKind::Internal, "decode_generation: not one surface record per ray");
  return hits;
}

// Each ray's weighted colour added to its pixel, in ray order for any pixel: on all cores when no
// pixel has two rays in the batch (a serial loop over the primary rays was about 1 ms a frame at
// 400x240, as long as the shading pass), else one after the other.
namespace {
void accumulate(Image& image, const RayBatch& rays, std::span<const glm::vec3> colors) {
  const auto add = [&](uint32_t i) { image.pixels[rays.pixel[i]] += rays.weight[i] * colors[i]; };
  if (rays.unique_pixels) {
    parallel_for(rays.count(), 0, add, 4096);
  } else {
    for (uint32_t i = 0; i < rays.count(); ++i) add(i);
  }
}
}  // namespace

Image render_whitted(const Scene& scene, const Camera& camera, const RenderSettings& settings,
                     WhittedEngine& engine, FrameTimings* timings) {
  FrameTimings t;
  const std::chrono::steady_clock::time_point frame_start = std::chrono::steady_clock::now();
  // A frame that throws still ends (WhittedEngine::end_frame), its own error the one that counts.
  struct EndOnThrow {
    WhittedEngine& engine;
    int exceptions = std::uncaught_exceptions();
    ~EndOnThrow() {
      if (std::uncaught_exceptions() <= exceptions) return;
      try {
        engine.end_frame();
      } catch (...) {
      }
    }
  } end_on_throw{engine};
  engine.start_frame(scene, camera, settings);
  engine.begin_frame(scene, settings, t);
  const FlatKdTree& tree = engine.tree();

  std::chrono::steady_clock::time_point stage = std::chrono::steady_clock::now();
  RayBatch rays = primary_rays(camera, settings.width, settings.height);
  t.rays_ms = elapsed_ms(stage);

  // Work a scene does not need is never done: no second generation without mirrors or glass.
  const int depth = scene_has_secondary_rays(scene) ? settings.depth : 0;
  Image image(settings.width, settings.height);
  // An engine that shades at the end keeps each generation's rays (their pixels and weights) and
  // timings until its colours come; the image gets them in the same order as when each generation
  // is shaded at once, so the same sums, bit for bit.
  const bool at_end = engine.shades_at_end();
  std::vector<RayBatch> queued_rays;
  std::vector<GenerationTimings> queued;
  for (int generation = 0; generation <= depth && rays.count() > 0; ++generation) {
    GenerationTimings g;
    g.rays = rays.count();
    TracedGeneration traced = generation == 0 ? engine.trace_primary(scene, camera, rays, g)
                                               : engine.trace_secondary(scene, camera, generation, rays, g);

    stage = std::chrono::steady_clock::now();
    const SurfaceHits hits = decode_generation(scene, settings, tree, rays, std::move(traced), g);
    g.decode_ms += elapsed_ms(stage);

    std::vector<glm::vec3> colors;
    if (at_end) {
      engine.queue_shade(scene, rays, hits, g);
    } else {
      colors = engine.shade(scene, rays, hits, g);
    }
    if (generation < depth) engine.shaded(scene, camera, generation, rays, hits, g);

    if (!at_end) {
      stage = std::chrono::steady_clock::now();
      accumulate(image, rays, colors);
      g.accumulate_ms += elapsed_ms(stage);
    }

    RayBatch next;
    if (generation < depth) {
      stage = std::chrono::steady_clock::now();
      next = next_generation(scene, tree.bounds, rays, hits, settings.secondary);
      engine.order_rays(next);
      g.secondary_ms += elapsed_ms(stage);
    }
    if (at_end) {
      queued_rays.push_back(std::move(rays));
      queued.push_back(g);
    } else {
      t.add(g);
    }
    rays = std::move(next);
  }
  if (at_end && !queued.empty()) {
    const std::vector<std::vector<glm::vec3>> colors = engine.shade_queued(scene, queued);
    if (colors.size() != queued.size()) {
      throw Error(ErrorKind::Internal, std::string(engine.name()) + ": shade_queued returned " +
                                           std::to_string(colors.size()) + " generations of " +
                                           std::to_string(queued.size()));
    }
    for (size_t k = 0; k < queued.size(); ++k) {
      stage = std::chrono::steady_clock::now();
      accumulate(image, queued_rays[k], colors[k]);
      queued[k].accumulate_ms += elapsed_ms(stage);
      t.add(queued[k]);
    }
  }
  engine.end_frame();
  t.total_ms = elapsed_ms(frame_start);
  if (timings) *timings = t;
  return image;
}

}  // namespace mobirt
