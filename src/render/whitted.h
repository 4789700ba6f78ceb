// The Whitted frame, once for every engine (src/render/engine.h): primary rays; then per
// generation trace, decode, shade, accumulate and the ray tree's next generation (mirror and
// refracted rays, src/raytree/secondary.h), up to settings.depth bounces.
#pragma once

#include "core/camera.h"
#include "core/image.h"
#include "render/engine.h"
#include "render/renderer.h"
#include "scene/scene.h"

namespace mobirt {

// The light mask of a hit that every light lights (rendering without shadow rays).
uint32_t all_lights_mask(const Scene& scene);

// The surface records of one traced generation, whatever form the engine returned them in; with
// settings.shadows off every hit gets all_lights_mask(). Fills g.hits, g.capped, g.shadow_rays.
SurfaceHits decode_generation(const Scene& scene, const RenderSettings& settings, const FlatKdTree& tree,
                              const RayBatch& rays, TracedGeneration&& traced, GenerationTimings& g);

// One frame of width x height with `engine`.
Image render_whitted(const Scene& scene, const Camera& camera, const RenderSettings& settings,
                     WhittedEngine& engine, FrameTimings* timings = nullptr);

}  // namespace mobirt
