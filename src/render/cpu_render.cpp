#include "render/cpu_render.h"

#include <algorithm>
#include <cmath>
#include <thread>

#include "accel/kdtree.h"
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

Image render_on_cpu(const Scene& scene, const Camera& camera, const RenderSettings& settings, bool quantize) {
  const FlatKdTree tree = build_kdtree(scene.mesh.positions, settings.kd);
  const Atlas atlas = build_atlas(scene);
  RayBatch rays = primary_rays(camera, settings.width, settings.height);
  Image image(settings.width, settings.height);
  const std::span<const Light> lights = settings.shadows ? std::span<const Light>(scene.lights)
                                                         : std::span<const Light>();
  const uint32_t all_lights = scene.lights.empty() ? 0u : (2u << (scene.lights.size() - 1)) - 1u;
  const int depth = scene_has_secondary_rays(scene) ? settings.depth : 0;
  const unsigned threads = std::max(1u, std::thread::hardware_concurrency());
  for (int generation = 0; generation <= depth && rays.count() > 0; ++generation) {
    const uint32_t n = rays.count();
    std::vector<SurfaceHit> hits(n);
    std::vector<glm::vec3> colors(n);
    std::vector<std::thread> pool;
    for (unsigned w = 0; w < threads; ++w) {
      pool.emplace_back([&, w] {
        for (uint32_t i = w; i < n; i += threads) {
          const Ray ray = rays.ray(i);
          const Hit h = traverse(tree, ray, -1, settings.shadow_rays.ray_test);
          glm::vec3 c = scene.background;
          if (h.valid()) {
            hits[i] = surface_hit(scene, tree, ray, h.prim, settings.shadow_rays.ray_test.test);
            hits[i].mask = settings.shadows
                               ? shadow_mask(tree, lights, h.prim, ray, h.t, settings.shadow_rays, -1)
                               : all_lights;
            c = shade_phong(scene, hits[i], -glm::normalize(ray.direction), atlas);
          }
          c = quantize ? quantize_colour(c, settings.colour) : glm::clamp(c, 0.0f, 1.0f);  // the shading pass
          colors[i] = c;
        }
      });
    }
    for (std::thread& t : pool) t.join();
    for (uint32_t i = 0; i < n; ++i) image.pixels[rays.pixel[i]] += rays.weight[i] * colors[i];
    if (generation < depth) rays = next_generation(scene, tree.bounds, rays, hits, settings.secondary);
  }
  return image;
}

}  // namespace mobirt
