#include "render/cpu_render.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <thread>

#include "accel/kdtree.h"
#include "core/parallel.h"
#include "layout.h"
#include "raytree/secondary.h"

namespace mobirt {

namespace {

float light_attenuation(float distance2, float range) {
  float window = 1.0f;
  if (range > 0.0f) {
    const float r = distance2 / (range * range);
    window = std::clamp(1.0f - r * r, 0.0f, 1.0f);
    window *= window;
  }
  return window / std::max(distance2, 1e-8f);
}

}  // namespace

glm::vec3 shade_phong(const Scene& scene, const SurfaceHit& hit, const glm::vec3& view, const Atlas& atlas) {
  const Material& m = scene.materials[hit.material];
  glm::vec3 diffuse = m.diffuse;
  if (!atlas.empty() && m.texture >= 0) diffuse *= sample_atlas(atlas, m.texture, hit.texcoord);
  glm::vec3 color = m.ambient * diffuse;
  for (size_t l = 0; l < scene.lights.size(); ++l) {
    if (!(hit.mask & (1u << l))) continue;
    const Light& light = scene.lights[l];
    glm::vec3 to_light = -light.direction;
    float falloff = 1.0f;
    if (light.type != LightType::Directional) {
      to_light = light.position - hit.position;
      falloff = light_attenuation(glm::dot(to_light, to_light), light.range);
    }
    const glm::vec3 l_dir = glm::normalize(to_light);
    if (light.type == LightType::Spot) {
      const float cos_outer = std::cos(light.outer_cone);
      const float cos_inner = std::cos(light.inner_cone);
      const float cone = std::clamp((glm::dot(-l_dir, light.direction) - cos_outer) /
                                        std::max(cos_inner - cos_outer, 1e-4f),
                                    0.0f, 1.0f);
      falloff *= cone * cone;
    }
    const float n_dot_l = glm::dot(hit.normal, l_dir);
    if (n_dot_l <= 0.0f) continue;
    const glm::vec3 r = 2.0f * n_dot_l * hit.normal - l_dir;
    const float spec = m.shininess > 0.0f ? std::pow(std::max(glm::dot(r, view), 0.0f), m.shininess) : 0.0f;
    color += falloff * light.color * light.intensity * (diffuse * n_dot_l + m.specular * spec);
  }
  return color;
}

void KdTreeEngine::build(const Scene& scene) { tree_ = build_kdtree(scene.mesh.positions, options_); }

Hit KdTreeEngine::closest(const Ray& ray) const { return traverse(tree_, ray, -1, test_); }

bool KdTreeEngine::occluded(const Ray& ray) const { return mobirt::occluded(tree_, ray, -1, test_); }

SurfaceHit KdTreeEngine::surface(const Scene& scene, const Ray& ray, const Hit& hit) const {
  return surface_hit(scene, tree_, ray, hit.prim, test_.test);
}

namespace {

using Clock = std::chrono::steady_clock;

double ms_since(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

}  // namespace

Image render_whitted_cpu(const Scene& scene, const Camera& camera, const RenderSettings& settings,
                         CpuRayEngine& engine, unsigned threads, CpuFrameTimings* timings, bool quantize) {
  CpuFrameTimings t;
  const Clock::time_point frame_start = Clock::now();
  if (threads == 0) threads = std::max(1u, std::thread::hardware_concurrency());

  Clock::time_point start = Clock::now();
  engine.build(scene);
  t.build_ms = ms_since(start);
  const FlatKdTree& triangles = engine.triangles();
  const Atlas atlas = build_atlas(scene);

  start = Clock::now();
  RayBatch rays = primary_rays(camera, settings.width, settings.height);
  t.rays_ms = ms_since(start);
  t.primary_rays = rays.count();

  Image image(settings.width, settings.height);
  const std::span<const Light> lights = settings.shadows ? std::span<const Light>(scene.lights)
                                                         : std::span<const Light>();
  const uint32_t all_lights = scene.lights.empty() ? 0u : (2u << (scene.lights.size() - 1)) - 1u;
  const int depth = scene_has_secondary_rays(scene) ? settings.depth : 0;
  std::atomic<uint64_t> shadow_rays{0};
  for (int generation = 0; generation <= depth && rays.count() > 0; ++generation) {
    const uint32_t n = rays.count();
    t.rays += n;
    ++t.generations;
    std::vector<Hit> closest(n);
    start = Clock::now();
    parallel_for(n, threads, [&](uint32_t i) { closest[i] = engine.closest(rays.ray(i)); });
    t.trace_ms += ms_since(start);

    std::vector<SurfaceHit> hits(n);
    start = Clock::now();
    parallel_for(n, threads, [&](uint32_t i) {
      if (!closest[i].valid()) return;
      const Ray ray = rays.ray(i);
      hits[i] = engine.surface(scene, ray, closest[i]);
      if (!settings.shadows) {
        hits[i].mask = all_lights;
        return;
      }
      uint64_t cast = 0;
      hits[i].mask = shadow_mask_with(triangles, lights, closest[i].prim, ray, closest[i].t,
                                      settings.shadow_rays, [&](const Ray& shadow) {
                                        ++cast;
                                        return engine.occluded(shadow);
                                      });
      shadow_rays.fetch_add(cast, std::memory_order_relaxed);
    });
    t.shadow_ms += ms_since(start);

    start = Clock::now();
    std::vector<glm::vec3> colors(n);
    parallel_for(n, threads, [&](uint32_t i) {
      glm::vec3 c = scene.background;
      if (hits[i].valid()) c = shade_phong(scene, hits[i], -glm::normalize(rays.ray(i).direction), atlas);
      c = quantize ? quantize_colour(c, settings.colour) : glm::clamp(c, 0.0f, 1.0f);  // the shading pass
      colors[i] = c;
    });
    for (uint32_t i = 0; i < n; ++i) image.pixels[rays.pixel[i]] += rays.weight[i] * colors[i];
    t.shade_ms += ms_since(start);

    if (generation < depth) {
      start = Clock::now();
      rays = next_generation(scene, triangles.bounds, rays, hits, settings.secondary);
      t.secondary_ms += ms_since(start);
    }
  }
  t.shadow_rays = shadow_rays.load();
  t.total_ms = ms_since(frame_start);
  if (timings) *timings = t;
  return image;
}

Image render_on_cpu(const Scene& scene, const Camera& camera, const RenderSettings& settings, bool quantize) {
  KdTreeEngine engine(settings.kd, settings.shadow_rays.ray_test);
  return render_whitted_cpu(scene, camera, settings, engine, 0, nullptr, quantize);
}

}  // namespace mobirt
