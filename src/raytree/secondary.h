// The CPU ray-tree manager's step from one generation of rays to the next: for every hit on a
// reflective or refractive material, the mirror ray and, by Snell's law, the transmitted ray
// (total internal reflection sends the transmitted share into the mirror ray; entering and leaving
// a medium are told apart by the geometric normal). Each new ray carries its pixel and its weight,
// and the generation is packed densely, so the next pass is sized to the rays that exist.
#pragma once

#include <glm/glm.hpp>

#include <span>
#include <vector>

#include "raytree/hits.h"
#include "raytree/rays.h"
#include "raytree/shading_math.h"  // schlick_fresnel(), refract_direction()
#include "scene/scene.h"

namespace mobirt {

struct SecondarySettings {
  SurfaceOffset offset;            // origin offset along the geometric normal (offset_origin()
                                   // in hits.h)
  float min_weight = 1.0f / 512.0f;  // rays whose largest weight component is below this are not
                                     // traced: they cannot move an 8-bit pixel by half a step
};

struct SecondaryStats {
  uint32_t reflected = 0;
  uint32_t refracted = 0;
  uint32_t total_internal_reflections = 0;
  uint32_t culled = 0;             // rays dropped for a weight under min_weight
};

// The next generation from the hits of this one (hits[i] belongs to ray i). scene_bounds sizes
// the self-intersection offset.
RayBatch next_generation(const Scene& scene, const Aabb& scene_bounds, const RayBatch& rays,
                         const SurfaceHits& hits, const SecondarySettings& settings,
                         SecondaryStats* stats = nullptr);

// True when some material of the scene reflects or refracts: only then is a second generation
// ever made.
bool scene_has_secondary_rays(const Scene& scene);

}  // namespace mobirt
