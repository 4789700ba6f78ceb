#include "render/cpu_render.h"

#include <algorithm>
#include <atomic>
#include <chrono>

#include "accel/kdtree.h"
#include "core/parallel.h"
#include "layout.h"
#include "raytree/secondary.h"
#include "raytree/shading_math.h"
#include "render/whitted.h"

namespace mobirt {

glm::vec3 shade_phong(const Scene& scene, const SurfaceHit& hit, const glm::vec3& view, const Atlas& atlas) {
  const Material& m = scene.materials[hit.material];
  glm::vec3 diffuse = m.diffuse;
  if (!atlas.empty() && m.texture >= 0) diffuse *= sample_atlas(atlas, m.texture, hit.texcoord);
  return phong<float>(scene.lights, m, diffuse, hit.position, hit.normal, view, hit.mask);
}

void KdTreeEngine::build(const Scene& scene) { rebuild_kdtree(tree_, scene.mesh.positions, scene.shapes, options_); }

Hit KdTreeEngine::closest(const Ray& ray) const { return traverse_fast(tree_, ray, test_); }

bool KdTreeEngine::occluded(const Ray& ray) const { return occluded_fast(tree_, ray, test_); }

SurfaceHit KdTreeEngine::surface(const Scene& scene, const Ray& ray, const Hit& hit) const {
  return surface_hit(scene, tree_, ray, hit.prim, test_.test);
}

void CpuRayEngine::set_frame_options(unsigned threads, bool quantize) {
  threads_ = threads;
  quantize_ = quantize;
}

void CpuRayEngine::begin_frame(const Scene& scene, const RenderSettings& settings, FrameTimings& frame) {
  shadows_ = settings.shadows;
  shadow_rays_ = settings.shadow_rays;
  colour_ = settings.colour;
  const auto start = std::chrono::steady_clock::now();
  build(scene);
  frame.build_ms = elapsed_ms(start);
  frame.tree_rebuilt = true;
  // Once per set of textures, as the GPU renderer keeps its atlas pages (atlas_key).
  std::string key = atlas_key(scene);
  if (key != atlas_key_) {
    atlas_ = build_atlas(scene);
    atlas_key_ = std::move(key);
  }
}

TracedGeneration CpuRayEngine::trace(const Scene& scene, const RayBatch& rays, GenerationTimings& g) {
  const uint32_t n = rays.count();
  std::vector<Hit> closest_hits(n);
  auto start = std::chrono::steady_clock::now();
  parallel_for(n, threads_, [&](uint32_t i) { closest_hits[i] = closest(rays.ray(i)); });
  g.trace_ms += elapsed_ms(start);

  TracedGeneration traced;
  traced.form = TracedGeneration::Form::Surfaces;
  traced.surfaces.resize(n);  // unwritten: every ray is marked below
  const FlatKdTree& texels = triangles();
  const std::span<const Light> lights(scene.lights);
  // Shadow rays counted per chunk of rays, one atomic add each: an add per hit, from both cores
  // on one cache line, made this stage vary from 5.9 to 7.7 ms on the toaster from run to run.
  constexpr uint32_t kChunk = 64;
  std::atomic<uint64_t> shadow_rays{0};
  start = std::chrono::steady_clock::now();
  parallel_for_chunks(n, kChunk, threads_, [&](uint32_t, uint32_t begin, uint32_t end) {
    uint64_t cast = 0;
    for (uint32_t i = begin; i < end; ++i) {
      if (!closest_hits[i].valid()) {
        traced.surfaces.set_miss(i);
        continue;
      }
      SurfaceHit& h = traced.surfaces.record(i);
      const Ray ray = rays.ray(i);
      h = surface(scene, ray, closest_hits[i]);
      traced.surfaces.set_hit(i);
      if (!shadows_) continue;  // the frame loop lights the hit by every light
      h.mask = shadow_mask_with(texels, lights, closest_hits[i].prim, ray, closest_hits[i].t, shadow_rays_,
                                [&](const Ray& shadow) {
                                  ++cast;
                                  return occluded(shadow);
                                });
    }
    shadow_rays.fetch_add(cast, std::memory_order_relaxed);
  });
  g.shadow_ms += elapsed_ms(start);
  traced.shadow_rays = shadow_rays.load();
  return traced;
}

std::vector<glm::vec3> CpuRayEngine::shade(const Scene& scene, const RayBatch& rays,
                                           const SurfaceHits& hits, GenerationTimings& g) {
  const auto start = std::chrono::steady_clock::now();
  std::vector<glm::vec3> colors(rays.count());
  parallel_for(rays.count(), threads_, [&](uint32_t i) {
    glm::vec3 c = scene.background;
    if (hits[i].valid()) c = shade_phong(scene, hits[i], -glm::normalize(rays.ray(i).direction), atlas_);
    colors[i] = quantize_ ? quantize_colour(c, colour_) : glm::clamp(c, 0.0f, 1.0f);  // the shading pass
  });
  g.shade_ms += elapsed_ms(start);
  return colors;
}

Image render_whitted_cpu(const Scene& scene, const Camera& camera, const RenderSettings& settings,
                         CpuRayEngine& engine, unsigned threads, FrameTimings* timings, bool quantize) {
  engine.set_frame_options(threads, quantize);
  return render_whitted(scene, camera, settings, engine, timings);
}

Image render_on_cpu(const Scene& scene, const Camera& camera, const RenderSettings& settings, bool quantize) {
  KdTreeEngine engine(settings.kd, settings.shadow_rays.ray_test);
  return render_whitted_cpu(scene, camera, settings, engine, 0, nullptr, quantize);
}

}  // namespace mobirt
