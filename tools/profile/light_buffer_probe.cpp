// mobirt_light_buffer_probe: what a light buffer (src/accel/light_buffer.h) would make of the
// primary hits' shadow rays against the kd-tree walk, on the CPU: per point light and resolution,
// its build time and size, the entries each shadow ray reads (the whole cell, and up to the first
// whose nearest distance to the light is past the ray's end) and the triangles it tests (those
// whose part of the cell holds the ray's direction: LightBuffer::sub), against the kd-tree's node
// steps and triangle tests for the same rays (kdtree_traverse.cpp, the traversal pass's CPU twin);
// every ray's answer checked against the walk's. Measurement only (the renderer's passes run
// light_buffer_occluded's shader twin). Each resolution is built twice: every face listed, and the
// faces of the mesh's closed parts turned away from the light left out (the renderer's default,
// src/accel/closed_parts.h); every answer is checked against the walk both times.
//
// Usage: mobirt_light_buffer_probe SCENE [profile_scene.h options] [--res N,N,...]
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "accel/closed_parts.h"
#include "accel/light_buffer.h"
#include "profile_scene.h"
#include "raytree/rays.h"

namespace mobirt {
namespace {

int run(int argc, char** argv) {
  std::vector<int> resolutions = {16, 32, 64, 128};
  std::vector<char*> args;
  for (int i = 0; i < argc; ++i) {
    if (std::string(argv[i]) == "--res" && i + 1 < argc) {
      resolutions.clear();
      std::stringstream ss(argv[++i]);
      for (std::string r; std::getline(ss, r, ',');) resolutions.push_back(std::stoi(r));
    } else {
      args.push_back(argv[i]);
    }
  }
  const profile::ProfileScene p = profile::load_profile_scene(int(args.size()), args.data(),
                                                              "usage: mobirt_light_buffer_probe SCENE [options] [--res N,...]");
  const Scene& scene = p.scene;
  const RayBatch rays = primary_rays(p.camera, p.width, p.height);
  const float scale = glm::length(p.tree.bounds.hi - p.tree.bounds.lo);
  std::printf("%s: %zu triangles, %dx%d, %zu lights\n", p.path.c_str(), scene.mesh.triangle_count(), p.width,
              p.height, scene.lights.size());
  for (size_t li = 0; li < scene.lights.size(); ++li) {
    const Light& light = scene.lights[li];
    if (light.type == LightType::Directional) {
      std::printf("light %zu: directional, skipped\n", li);
      continue;
    }
    // The shadow rays: from each primary hit, offset along the normal towards the viewer, to the light.
    std::vector<Ray> shadow;
    for (uint32_t i = 0; i < rays.count(); ++i) {
      const Ray r = rays.ray(i);
      const Hit h = traverse(p.tree, r);
      if (!h.valid()) continue;
      const glm::vec3* v = &scene.mesh.positions[3 * size_t(h.prim)];
      glm::vec3 n = glm::normalize(glm::cross(v[1] - v[0], v[2] - v[0]));
      if (glm::dot(n, r.direction) > 0.0f) n = -n;
      const glm::vec3 o = r.origin + h.t * r.direction + n * (1e-4f * scale);
      if (glm::dot(n, light.position - o) <= 0.0f) continue;  // faces away: no ray cast
      shadow.push_back(Ray{o, light.position - o, 0.0f, 1.0f});
    }
    TraversalStats walk;
    std::vector<uint8_t> walk_answer(shadow.size());
    const auto w0 = std::chrono::steady_clock::now();
    for (size_t i = 0; i < shadow.size(); ++i) {
      TraversalStats one;  // each call starts its counters at 0
      walk_answer[i] = occluded(p.tree, shadow[i], p.stack, one, -1) ? 1 : 0;
      walk += one;
    }
    const double walk_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - w0).count();
    const double nrays = double(std::max<size_t>(1, shadow.size()));
    std::printf("light %zu at (%g, %g, %g): %zu shadow rays, %.1f %% occluded; kd-tree walk per ray: %.2f steps, "
                "%.2f nodes, %.2f triangle tests (CPU %.2f ms)\n",
                li, light.position.x, light.position.y, light.position.z, shadow.size(),
                100.0 * double(std::count(walk_answer.begin(), walk_answer.end(), 1)) / nrays,
                double(walk.steps) / nrays, double(walk.nodes_visited) / nrays, double(walk.triangles_tested) / nrays,
                walk_ms);
    std::printf("  res  back faces  cells  refs/tri  build ms  entries/ray (whole cell)  entries/ray (to the ray's end)  "
                "tests/ray (in their parts)  max cell  answers differing  CPU ms  mean list\n");
    std::vector<std::pair<int, bool>> cases;
    for (int res : resolutions) {
      cases.emplace_back(res, false);
      cases.emplace_back(res, true);
    }
    // Each resolution twice: every face listed, and the faces of closed parts turned away from the
    // light left out (src/accel/closed_parts.h; light_windings' time counted in the build).
    for (const auto& [res, cull] : cases) {
      const auto b0 = std::chrono::steady_clock::now();
      std::vector<int8_t> winding;
      if (cull && scene.closed_parts) light_windings(*scene.closed_parts, scene.mesh.positions, light.position, winding);
      LightBuffer lb;
      build_light_buffer(scene.mesh.positions, light.position, res, lb, 0, winding);
      const double build_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - b0).count();
      uint64_t whole = 0, cut = 0, tested = 0;
      size_t differ = 0;
      uint32_t max_cell = 0;
      for (size_t c = 0; c < lb.cells(); ++c) max_cell = std::max(max_cell, lb.first[c + 1] - lb.first[c]);
      const auto t0 = std::chrono::steady_clock::now();
      for (size_t i = 0; i < shadow.size(); ++i) {
        const Ray& r = shadow[i];
        const uint32_t c = light_buffer_cell(lb, -r.direction);
        whole += c == kLightBufferOutside ? 0 : lb.first[c + 1] - lb.first[c];
        uint32_t tests = 0, entries = 0;
        const bool hit = light_buffer_occluded(lb, p.tree, r.origin, &tests, &entries);
        cut += entries;
        tested += tests;
        differ += hit != (walk_answer[i] != 0) ? 1 : 0;
      }
      const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
      std::printf("  %3d %11s %6zu %9.2f %9.2f %25.2f %31.2f %27.2f %9u %18zu %7.2f %10.1f\n", res,
                  cull ? (std::to_string(lb.left_out) + " out").c_str() : "listed", lb.cells(),
                  double(lb.prims.size()) / double(std::max<size_t>(1, scene.mesh.triangle_count())), build_ms,
                  double(whole) / nrays, double(cut) / nrays, double(tested) / nrays, max_cell, differ, ms,
                  lb.mean_list());
    }
  }
  return 0;
}

}  // namespace
}  // namespace mobirt

int main(int argc, char** argv) { return mobirt::profile::run_tool("mobirt_light_buffer_probe", argc, argv, mobirt::run); }
