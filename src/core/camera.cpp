#include "core/camera.h"

#include <cmath>

namespace mobirt {

CameraBasis::CameraBasis(const Camera& camera, int width_px, int height_px)
    : eye(camera.eye),
      forward(glm::normalize(camera.target - camera.eye)),
      right(glm::normalize(glm::cross(forward, camera.up))),
      up(glm::cross(right, forward)),
      tan_half(std::tan(0.5f * camera.yfov)),
      aspect(float(width_px) / float(height_px)),
      width(float(width_px)),
      height(float(height_px)),
      znear(camera.znear) {}

Ray camera_ray(const Camera& camera, int width, int height, float x, float y) {
  return CameraBasis(camera, width, height).ray(x, y);
}

Camera frame_box(const Aabb& box, float yfov, float aspect) {
  Camera camera;
  camera.yfov = yfov;
  if (box.empty()) return camera;
  const glm::vec3 center = box.center();
  const float radius = std::max(0.5f * glm::length(box.extent()), 1e-6f);
  // Distance at which a sphere of this radius fits both the vertical and horizontal view.
  const float half = 0.5f * yfov * std::min(1.0f, aspect);
  const float distance = radius / std::sin(half);
  const glm::vec3 direction = glm::normalize(glm::vec3(0.0f, 0.35f, 1.0f));
  camera.eye = center + distance * direction;
  camera.target = center;
  camera.up = glm::vec3(0.0f, 1.0f, 0.0f);
  return camera;
}

}  // namespace mobirt
