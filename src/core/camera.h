// A pinhole camera: look-from, look-at, up and vertical field of view.
#pragma once

#include <glm/glm.hpp>

#include "core/geometry.h"

namespace mobirt {

struct Camera {
  glm::vec3 eye{0.0f, 0.0f, 5.0f};
  glm::vec3 target{0.0f};
  glm::vec3 up{0.0f, 1.0f, 0.0f};
  float yfov = 0.7854f;  // radians
  float znear = 0.0f;    // rays start this far along the view axis (0: at the eye)
};

// The camera's frame for one image size, computed once per frame instead of once per ray.
struct CameraBasis {
  CameraBasis(const Camera& camera, int width, int height);
  // Primary ray through image point (x, y) (pixel centres at + 0.5); y = 0 is the top row.
  // Inline: primary_rays() calls it once per pixel, and out of line the call and the returned Ray
  // had cost 26 ns of CPU a ray.
  Ray ray(float x, float y) const {
    // The operations of the per-ray formula this replaced, so every primary ray keeps its floats.
    const float sx = (2.0f * x / width - 1.0f) * tan_half * aspect;
    const float sy = row_offset(y);
    Ray r;
    r.origin = eye;
    r.direction = glm::normalize(forward + sx * right + sy * up);
    r.tmin = znear;
    return r;
  }

  // The vertical offset of image row y on the image plane (a multiple of `up`), shared with
  // primary_rays()' four-pixel path, which computes it once per row.
  float row_offset(float y) const { return (1.0f - 2.0f * y / height) * tan_half; }

  glm::vec3 eye, forward, right, up;
  float tan_half, aspect, width, height, znear;
};

// Primary ray through the centre of pixel (x, y) of a width x height image; y = 0 is the top row.
// The same floats as CameraBasis(camera, width, height).ray(x, y).
Ray camera_ray(const Camera& camera, int width, int height, float x, float y);

// A camera that frames a box from the front-above, for scenes without one.
Camera frame_box(const Aabb& box, float yfov, float aspect);

}  // namespace mobirt
