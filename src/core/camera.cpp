#include "core/camera.h"

#include <cmath>

namespace mobirt {

Ray camera_ray(const Camera& camera, int width, int height, float x, float y) {
  const glm::vec3 forward = glm::normalize(camera.target - camera.eye);
  const glm::vec3 right = glm::normalize(glm::cross(forward, camera.up));
  const glm::vec3 up = glm::cross(right, forward);
  const float tan_half = std::tan(0.5f * camera.yfov);
  const float aspect = float(width) / float(height);
  const float sx = (2.0f * x / float(width) - 1.0f) * tan_half * aspect;
  const float sy = (1.0f - 2.0f * y / float(height)) * tan_half;
  Ray ray;
  ray.origin = camera.eye;
  ray.direction = glm::normalize(forward + sx * right + sy * up);
  ray.tmin = camera.znear;
  return ray;
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
