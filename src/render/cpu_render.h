// The same frame as Renderer, computed entirely on the CPU in single precision: the kd-tree
// traversal of src/accel, the shadow rays of src/raytree/hits.h, and a C++ transcription of
// glsl/shade.glsl. It is the expectation the GPU image is tested against (it shares the tree and
// the ray tree but none of the shaders), and the CPU column of the benchmarks.
#pragma once

#include "core/camera.h"
#include "core/image.h"
#include "raytree/hits.h"
#include "render/renderer.h"
#include "scene/atlas.h"
#include "scene/scene.h"

namespace mobirt {

// Phong with the shadow mask, as glsl/shade.glsl computes it. `view` points towards the viewer;
// `atlas` gives the textures (may be empty).
glm::vec3 shade_phong(const Scene& scene, const SurfaceHit& hit, const glm::vec3& view, const Atlas& atlas);

// The renderer's frame on the CPU: the same ray/triangle test, offsets and ray tree; each shaded
// colour quantised to settings.colour as the shading pass writes it (unless quantize is false).
Image render_on_cpu(const Scene& scene, const Camera& camera, const RenderSettings& settings,
                    bool quantize = true);

}  // namespace mobirt
