// Procedural scenes for tests that must run without any file: built in memory, deterministic.
#pragma once

#include <glm/glm.hpp>

#include <random>

#include "scene/scene.h"

namespace mobirt::test {

inline void add_triangle(Scene& s, glm::vec3 a, glm::vec3 b, glm::vec3 c, uint32_t material) {
  const glm::vec3 n = glm::normalize(glm::cross(b - a, c - a));
  for (const glm::vec3& p : {a, b, c}) {
    s.mesh.positions.push_back(p);
    s.mesh.normals.push_back(n);
  }
  s.mesh.material_ids.push_back(material);
}

inline void add_box(Scene& s, glm::vec3 lo, glm::vec3 hi, uint32_t material) {
  const glm::vec3 p[8] = {{lo.x, lo.y, lo.z}, {hi.x, lo.y, lo.z}, {hi.x, hi.y, lo.z}, {lo.x, hi.y, lo.z},
                          {lo.x, lo.y, hi.z}, {hi.x, lo.y, hi.z}, {hi.x, hi.y, hi.z}, {lo.x, hi.y, hi.z}};
  const int q[6][4] = {{0, 3, 2, 1}, {4, 5, 6, 7}, {0, 1, 5, 4}, {3, 7, 6, 2}, {0, 4, 7, 3}, {1, 2, 6, 5}};
  for (const auto& f : q) {
    add_triangle(s, p[f[0]], p[f[1]], p[f[2]], material);
    add_triangle(s, p[f[0]], p[f[2]], p[f[3]], material);
  }
}

inline Scene base_scene(const char* name) {
  Scene s;
  s.source = name;
  Material floor;
  floor.name = "floor";
  floor.diffuse = glm::vec3(0.7f);
  Material shiny;
  shiny.name = "shiny";
  shiny.diffuse = glm::vec3(0.8f, 0.3f, 0.2f);
  shiny.specular = glm::vec3(0.5f);
  shiny.shininess = 40.0f;
  s.materials = {floor, shiny};
  return s;
}

// A floor with a grid of boxes under two lights: many shadow edges, axis-aligned planes that sit
// exactly on kd-tree split candidates.
inline Scene box_grid_scene() {
  Scene s = base_scene("box-grid");
  add_triangle(s, {-10, 0, -10}, {-10, 0, 10}, {10, 0, 10}, 0);
  add_triangle(s, {-10, 0, -10}, {10, 0, 10}, {10, 0, -10}, 0);
  for (int i = -3; i <= 3; ++i) {
    for (int j = -3; j <= 3; ++j) {
      const float h = 0.5f + 0.25f * float((i * 7 + j * 3 + 21) % 5);
      add_box(s, {i * 2.0f - 0.5f, 0.0f, j * 2.0f - 0.5f}, {i * 2.0f + 0.5f, h, j * 2.0f + 0.5f}, 1);
    }
  }
  Light key;
  key.position = {-4, 9, 6};
  key.intensity = 80.0f;
  Light sun;
  sun.type = LightType::Directional;
  sun.direction = glm::normalize(glm::vec3(0.6f, -1.0f, -0.3f));
  sun.intensity = 0.5f;
  s.lights = {key, sun};
  s.camera = Camera{{0, 9, 14}, {0, 0, 0}, {0, 1, 0}, 0.8f, 0.0f};
  return s;
}

// The box grid under nine point lights in a row: more than the 24/8 packing's 8, so the passes
// pack 16/16.
inline Scene nine_lights_scene() {
  Scene s = box_grid_scene();
  s.lights.clear();
  for (int i = 0; i < 9; ++i) {
    Light light;
    light.position = glm::vec3(-8.0f + 2.0f * float(i), 6.0f, 3.0f);
    light.intensity = 6.0f;
    s.lights.push_back(light);
  }
  return s;
}

// Random small triangles in a cube above a floor, lit by a spot and a point light: a deep tree
// with many leaves and thin, overlapping triangles.
inline Scene random_soup_scene(int triangles = 20000, uint32_t seed = 7) {
  Scene s = base_scene("random-soup");
  add_triangle(s, {-6, -3, -6}, {-6, -3, 6}, {6, -3, 6}, 0);
  add_triangle(s, {-6, -3, -6}, {6, -3, 6}, {6, -3, -6}, 0);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> pos(-2.5f, 2.5f), off(-0.3f, 0.3f);
  for (int i = 0; i < triangles; ++i) {
    const glm::vec3 c(pos(rng), pos(rng), pos(rng));
    add_triangle(s, c + glm::vec3(off(rng), off(rng), off(rng)), c + glm::vec3(off(rng), off(rng), off(rng)),
                 c + glm::vec3(off(rng), off(rng), off(rng)), 1);
  }
  Light spot;
  spot.type = LightType::Spot;
  spot.position = {0, 8, 2};
  spot.direction = glm::normalize(glm::vec3(0, -1, -0.2f));
  spot.outer_cone = 0.6f;
  spot.inner_cone = 0.4f;
  spot.intensity = 120.0f;
  Light point;
  point.position = {5, 2, 5};
  point.intensity = 30.0f;
  s.lights = {spot, point};
  s.camera = Camera{{0, 2, 9}, {0, -0.5f, 0}, {0, 1, 0}, 0.9f, 0.0f};
  return s;
}

inline Shape sphere_shape(glm::vec3 centre, float radius, uint32_t material) {
  Shape s;
  s.base = centre;
  s.base_radius = radius;
  s.material = material;
  return s;
}

inline Shape cone_shape(glm::vec3 base, float base_radius, glm::vec3 apex, float apex_radius, uint32_t material) {
  Shape s;
  s.kind = ShapeKind::Cone;
  s.base = base;
  s.base_radius = base_radius;
  s.apex = apex;
  s.apex_radius = apex_radius;
  s.material = material;
  return s;
}

// Analytic primitives beside triangles: a mirror sphere, a glass sphere, an open cylinder and a
// pointed cone on a floor, under a point light (Haines' NFF shapes, issue 17).
inline Scene shapes_scene() {
  Scene s = base_scene("shapes");
  add_triangle(s, {-10, -1, -10}, {-10, -1, 10}, {10, -1, 10}, 0);
  add_triangle(s, {-10, -1, -10}, {10, -1, 10}, {10, -1, -10}, 0);
  Material mirror;
  mirror.name = "mirror";
  mirror.diffuse = glm::vec3(0.2f, 0.3f, 0.8f);
  mirror.specular = glm::vec3(0.6f);
  mirror.reflectance = 0.5f;
  Material glass;
  glass.name = "glass";
  glass.diffuse = glm::vec3(0.1f);
  glass.transmittance = 0.8f;
  glass.reflectance = 0.1f;
  glass.ior = 1.5f;
  s.materials.push_back(mirror);
  s.materials.push_back(glass);
  s.shapes.push_back(sphere_shape({0, 0, 0}, 1.0f, 2));
  s.shapes.push_back(sphere_shape({1.2f, -0.4f, 2.0f}, 0.6f, 3));
  s.shapes.push_back(cone_shape({3, -1, 0}, 0.5f, {3, 1, 0}, 0.5f, 1));
  s.shapes.push_back(cone_shape({-3, -1, 0}, 1.0f, {-3, 1.2f, 0.3f}, 0.0f, 1));
  Light key;
  key.position = {2, 8, 6};
  key.intensity = 90.0f;
  s.lights = {key};
  s.camera = Camera{{0, 2, 9}, {0, 0, 0}, {0, 1, 0}, 0.8f, 0.0f};
  return s;
}

}  // namespace mobirt::test
