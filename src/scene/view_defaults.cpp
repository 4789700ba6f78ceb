#include "scene/view_defaults.h"

#include <algorithm>
#include <cmath>
#include <iostream>

namespace mobirt {

namespace {

// Rodrigues' rotation taking unit vector `from` onto unit vector `to`, applied to `v`.
glm::vec3 rotate_onto(const glm::vec3& from, const glm::vec3& to, const glm::vec3& v) {
  const float c = glm::dot(from, to);
  glm::vec3 axis = glm::cross(from, to);
  const float s = glm::length(axis);
  if (s < 1e-7f) {
    if (c > 0.0f) return v;
    // Opposite: half a turn about any axis perpendicular to `from`.
    axis = glm::normalize(glm::cross(from, std::abs(from.x) < 0.9f ? glm::vec3(1, 0, 0) : glm::vec3(0, 0, 1)));
    return 2.0f * glm::dot(axis, v) * axis - v;
  }
  axis /= s;
  return v * c + glm::cross(axis, v) * s + axis * glm::dot(axis, v) * (1.0f - c);
}

}  // namespace

Camera framing_camera(const Scene& scene, float aspect, float yfov) {
  Camera camera = frame_box(scene.bounds(), yfov, aspect);
  const float len = glm::length(scene.up);
  if (!(len > 0.0f) || !std::isfinite(len)) return camera;
  const glm::vec3 up = scene.up / len;
  const glm::vec3 y(0.0f, 1.0f, 0.0f);
  camera.eye = camera.target + rotate_onto(y, up, camera.eye - camera.target);
  camera.up = up;
  return camera;
}

Camera default_camera(const Scene& scene, float aspect) {
  return scene.camera ? *scene.camera : framing_camera(scene, aspect);
}

bool add_headlight(Scene& scene, const Camera& view) {
  if (!scene.lights.empty()) return false;
  Light light;
  light.type = LightType::Point;
  light.position = view.eye;
  const glm::vec3 d = view.target - view.eye;
  light.intensity = std::max(glm::dot(d, d), 1e-12f);
  scene.lights.push_back(light);
  return true;
}

void note_headlight(const Scene& scene) {
  std::cerr << "mobirt: note: " << (scene.source.empty() ? "" : scene.source + ": ")
            << "the scene has no lights: a headlight at the camera lit it (--light gives others)\n";
}

}  // namespace mobirt
