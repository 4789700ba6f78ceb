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

// Primary ray through the centre of pixel (x, y) of a width x height image; y = 0 is the top row.
Ray camera_ray(const Camera& camera, int width, int height, float x, float y);

// A camera that frames a box from the front-above, for scenes without one.
Camera frame_box(const Aabb& box, float yfov, float aspect);

}  // namespace mobirt
