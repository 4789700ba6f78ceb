// Planar mirrors: the flat, reflective parts of a scene, and the triangles a raster pass would draw
// to find their mirror rays' closest hits.
//
// A mirror ray leaves a plane P from the point X where a primary ray E + t d met it, along d
// reflected in P. Reflected in P itself, that ray is the rest of the primary ray's line beyond X:
// so the scene mirrored in P and seen from the camera shows, at every pixel whose primary hit lies
// on P, what that pixel's mirror ray hits first, as long as only what lay on P's front side is
// drawn (the mirrored half-space beyond X). This is the classic planar reflection of real-time
// rendering; docs/performance-history.md (*Session 36*) measured that 92-98 % of the first
// secondary generation of the toaster, the marbles and the Utah toasters leaves such a floor.
// Renderer::trace_mirrored (--mirrors) draws them with the raster pass of --primary raster (README,
// *Flat mirrors rasterized*); tests/mirror_planes_test.cpp checks both parts against traced rays.
//
// A triangle belongs to a mirror plane when its material reflects and does not refract
// (reflectance > 0, transmittance 0: secondary.cpp then emits the mirror ray alone), it is not
// degenerate, its three corners lie on the plane (within a millionth of the scene's largest
// coordinate) and its three shading normals are the plane's normal (within 1e-6 in each
// component): then mirror_direction() reflects in the plane itself.
#pragma once

#include <glm/glm.hpp>

#include <cstdint>
#include <span>
#include <vector>

#include "core/camera.h"
#include "raytree/rays.h"
#include "scene/scene.h"

namespace mobirt {

struct MirrorPlane {
  glm::dvec3 normal{0.0};   // unit; the side the mirror faces (its shading normals)
  double offset = 0.0;      // normal . p for the points p of the plane
  uint32_t triangles = 0;   // the scene's reflective triangles on it
  double area = 0.0;        // their area
};

struct MirrorPlanes {
  std::vector<MirrorPlane> planes;  // the largest area first
  std::vector<int32_t> plane_of;    // per triangle of the mesh: its plane, -1 where none
};

// The planar mirrors of `scene` as posed (planes with their reflective triangles).
MirrorPlanes find_mirror_planes(const Scene& scene);

// The triangles of `positions` (three vertices each) mirrored in `plane`, for a raster pass from
// the camera: each triangle's part on the plane's front side (normal . p - offset > margin, with
// margin = 1e-6 of the largest coordinate, so that the mirror's own triangles and whatever lies
// in the plane stay out), mirrored, as one triangle or, where the plane cuts it, one or two.
// Appends to `out` four floats per vertex, x, y, z and the source triangle's index + 1 (exact
// in float below 2^24), as Renderer::start_raster writes the primary raster's vertices. A
// triangle t with skip[t] set is left out (skip empty: none is).
void mirrored_raster_vertices(std::span<const glm::vec3> positions, const MirrorPlane& plane, std::vector<float>& out,
                              std::span<const uint8_t> skip = {});

// Which of a frame's mirror planes sent each ray of its first secondary generation, as
// Renderer::trace_mirrored needs it: ray i is a mirror ray off plane p when it starts on p (its
// origin within on_plane of it), leaves it on its front side, and its reflection in p is the
// primary ray through the centre of its pixel (rays.pixel[i] of a width x height image through
// `basis`: on the image plane within 1e-5 of the pixel's coordinates), the pixel the raster pass
// of the scene mirrored in p samples. The planes are tried in order, the first that passes wins.
struct MirrorRayTest {
  std::span<const MirrorPlane> planes;  // each turned to face the eye; at most 254
  CameraBasis basis;
  uint32_t width = 0, height = 0;
  double on_plane = 0.0;
};
constexpr uint8_t kNoMirrorPlane = 0xFF;
// The index of ray i's plane, or kNoMirrorPlane: the reference, one ray at a time.
uint8_t mirror_ray_plane(const MirrorRayTest& test, const RayBatch& rays, uint32_t i);
// mirror_ray_plane of rays [begin, end) into plane_of[begin, end): the same answers, four rays at
// a time in double-precision vector lanes on AVX2 CPUs (the same operations in the same order;
// the file is built with -ffp-contract=off, so no product is fused into a sum in either), one at
// a time elsewhere.
void mirror_ray_planes(const MirrorRayTest& test, const RayBatch& rays, uint32_t begin, uint32_t end, uint8_t* plane_of);
// Whether mirror_ray_planes runs vector lanes on this CPU (AVX2), or the reference one ray at a time.
bool mirror_ray_lanes();

}  // namespace mobirt
