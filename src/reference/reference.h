// The reference tracer: the oracle of every accuracy number. The same Whitted model as the GPU
// renderer (camera, KHR_lights_punctual lights with falloff and spot cones, Phong, shadow rays,
// mirror and refracted rays with Fresnel or fixed coefficients and total internal reflection,
// base-colour textures), traced on the CPU entirely in double precision:
//
// - camera rays computed in double from the camera's parameters (same pixel centres);
// - a median-split BVH built in double over the triangles (the scene's float vertices, widened);
// - the watertight ray/triangle test of Woop, Benthin and Wald (JCGT 2013) in double: a ray
//   through a shared edge or vertex of a closed mesh hits at least one of the triangles there,
//   never none;
// - shadow and secondary rays start at the hit point offset along the geometric normal by
//   epsilon * (1 + max |p|) (default 1e-9, relative to the point's magnitude) and never hit the
//   triangle they leave (a planar triangle cannot occlude or re-hit itself);
// - textures are sampled from the ORIGINAL decoded images (not the atlas: an image that the
//   atlas pages had to downscale is read at full resolution), at the texture coordinate the
//   material's KHR_texture_transform gives, bilinear at texel centres with the sampler's wrap
//   modes, each texel sRGB-decoded in double before the blend, as atlas.glsl does;
// - no 8-bit quantisation anywhere. What the reference does keep is the model's own definition of
//   a ray's colour: each shaded colour (Phong of one hit, or the background of a miss) is clamped
//   to [0, 1], exactly as the shading pass clamps it, because that clamp is part of the Whitted
//   model mobirt implements (colour per ray, weights per ray), not a precision artefact. The
//   clamped value stays in double; the weighted sum over a pixel's ray tree is not clamped.
// - every secondary ray of positive weight up to `depth` bounces is traced (no min-weight cull,
//   which is a renderer approximation), unless min_weight is set.
#pragma once

#include <glm/glm.hpp>

#include <cstdint>
#include <vector>

#include "core/camera.h"
#include "core/image.h"
#include "render/renderer.h"
#include "scene/scene.h"

namespace mobirt {

struct ReferenceSettings {
  int width = 400;
  int height = 240;
  int depth = 2;              // bounces, as RenderSettings::depth
  bool shadows = true;        // false: every light lights every surface facing it
  double epsilon = 1e-9;      // ray-origin offset along the geometric normal, times 1 + max |p|
  double min_weight = 0.0;    // secondary rays weighing less are not traced (0: all are)
  unsigned threads = 0;       // 0: one per core
};

// The reference settings that correspond to a renderer's: size, depth and shadows.
ReferenceSettings reference_settings(const RenderSettings& settings);

struct ReferenceResult {
  Image image;                         // linear RGB, the weighted sum of each pixel's ray tree
  std::vector<int32_t> primary_prim;   // per pixel: the primary ray's triangle, -1 = miss
  std::vector<uint32_t> primary_mask;  // per pixel: lights visible from the primary hit (bit i)
  double elapsed_ms = 0.0;
};

// Renders `scene` from `camera`. Throws Error(BadInput) for a non-finite vertex position, an
// undecodable texture, or more than 32 lights.
ReferenceResult render_reference(const Scene& scene, const Camera& camera, const ReferenceSettings& settings);

}  // namespace mobirt

namespace mobirt {

// The watertight ray/triangle test (Woop, Benthin and Wald 2013) in double. On a hit with
// t in [tmin, tmax] returns true with t and the barycentric weights u (of b) and v (of c).
// Degenerate triangles (zero determinant) and NaN never hit.
bool intersect_watertight(const glm::dvec3& origin, const glm::dvec3& direction, const glm::dvec3& a,
                          const glm::dvec3& b, const glm::dvec3& c, double tmin, double tmax, double& t,
                          double& u, double& v);

}  // namespace mobirt
