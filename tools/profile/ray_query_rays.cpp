// mobirt_ray_query_rays: the driver's own ray queries (src/baseline/ray_query_engine.h) against
// mobirt's traversal pass on the same rays, in one process, interleaved round by round so that
// both see the same load:
//   AS build     the driver's BLAS + TLAS over the animation's frames, built afresh every frame
//                (PREFER_FAST_BUILD) and updated (ALLOW_UPDATE, mode UPDATE); GPU timestamps
//   primary      the primary rays, closest hit only (no lights)
//   +shadow      the primary rays and one shadow ray per light from their hits (the pass's work)
// Trace figures are the fragment pass alone (GPU timestamps), Mrays/s over every ray it traced;
// mobirt's is Renderer::trace's traversal pass (the `trace` stage of `mobirt render --timings`).
//
// Usage: mobirt_ray_query_rays SCENE [--camera SPEC] [--light SPEC]... [--mtl F] [--size WxH]
//        [--repeat N] [--frames N] [--shuffle]
// --shuffle puts the triangles in a random order first (the same for every frame): mobirt's SAH
// kd-tree does not depend on their order, a driver's BVH builder may.
#include <algorithm>
#include <cstdio>
#include <numeric>
#include <random>
#include <cstring>
#include <string>
#include <vector>

#include "backend/backend.h"
#include "baseline/ray_query_engine.h"
#include "raytree/hits.h"
#include "raytree/rays.h"
#include "render/renderer.h"
#include "profile_scene.h"

namespace mobirt {
namespace {

// The scene's triangles in the order `order` (order[i] = the triangle that goes to place i).
void reorder(Scene& scene, const std::vector<uint32_t>& order) {
  TriangleMesh& m = scene.mesh;
  TriangleMesh out;
  for (const uint32_t t : order) {
    for (uint32_t k = 0; k < 3; ++k) {
      out.positions.push_back(m.positions[3 * t + k]);
      if (!m.normals.empty()) out.normals.push_back(m.normals[3 * t + k]);
      if (!m.texcoords.empty()) out.texcoords.push_back(m.texcoords[3 * t + k]);
    }
    out.material_ids.push_back(m.material_ids[t]);
  }
  m = std::move(out);
}

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

int run(int argc, char** argv) {
  int frames = 12;
  bool shuffle = false;
  std::vector<char*> args;
  for (int i = 0; i < argc; ++i) {
    if (std::strcmp(argv[i], "--shuffle") == 0) {
      shuffle = true;
    } else if (std::strcmp(argv[i], "--frames") == 0 && i + 1 < argc) {
      frames = std::max(2, std::atoi(argv[++i]));
    } else {
      args.push_back(argv[i]);
    }
  }
  const char* usage =
      "usage: mobirt_ray_query_rays SCENE [--camera SPEC] [--light SPEC]... [--mtl F] [--size WxH] [--repeat N] "
      "[--frames N] [--shuffle]";
  profile::ProfileScene p = profile::load_profile_scene(int(args.size()), args.data(), usage);
  std::vector<uint32_t> order(p.scene.mesh.triangle_count());
  std::iota(order.begin(), order.end(), 0u);
  if (shuffle) {
    std::shuffle(order.begin(), order.end(), std::mt19937(1));
    reorder(p.scene, order);
    p.tree = build_kdtree(p.scene.mesh.positions);
  }
  const int repeat = std::max(1, p.repeat);

  RayQueryOptions update_options, fresh_options;
  update_options.build_mode = AsBuildMode::Update;
  fresh_options.build_mode = AsBuildMode::Fresh;
  // The BLAS and TLAS builds' own times come from the device's clock (timestamps), whatever the
  // device (--gpu-timestamps auto turns them off on lavapipe, where each one waits for the work).
  update_options.timestamps = fresh_options.timestamps = GpuTimestamps::On;
  RayQueryEngine updated(update_options), fresh(fresh_options);

  // AS builds over the animation (the rest scene again and again when it does not move), the two
  // engines in alternating order; then each traces the frame's primary and shadow rays, as a
  // refitted BVH may trace slower than a fresh one once the triangles have moved.
  const AnimatedScene animation = load_animated_scene(p.path);
  struct Mode {
    RayQueryEngine* engine;
    std::vector<double> blas, tlas, wall, trace;
  } modes[2] = {{&fresh, {}, {}, {}, {}}, {&updated, {}, {}, {}, {}}};
  Scene evaluated, frame_scene;
  std::vector<uint32_t> frame_texels;
  for (int f = 0; f <= frames; ++f) {
    animation.evaluate(animation.animated() ? double(f) / animation.fps() : 0.0, evaluated);
    frame_scene = evaluated;  // evaluate() keeps the static parts it finds: reorder a copy
    if (shuffle) reorder(frame_scene, order);
    const RayBatch frame_rays = primary_rays(frame_scene.camera ? *frame_scene.camera : p.camera, p.width, p.height);
    frame_texels.resize(frame_rays.count());
    for (int k = 0; k < 2; ++k) {
      Mode& m = modes[(f + k) % 2];
      AsBuildTimings b;
      m.engine->build(frame_scene, &b);
      RayQueryTimings t;
      m.engine->trace(frame_rays, frame_scene.lights, ShadowSettings{}, frame_texels, &t);
      if (f == 0) continue;  // the first build of either is a fresh one, and the first trace compiles
      if (b.updated != (m.engine == &updated)) throw Error(ErrorKind::Internal, "a build did not do as its mode says");
      m.blas.push_back(b.blas_ms);
      m.tlas.push_back(b.tlas_ms);
      m.wall.push_back(b.wall_ms);
      m.trace.push_back(t.trace_ms);
    }
  }

  // The pass's rays on the rest scene: the primaries, and how many shadow rays their hits cast.
  updated.build(p.scene);
  const RayBatch rays = primary_rays(p.camera, p.width, p.height);
  uint64_t shadow_rays = 0;
  for (uint32_t i = 0; i < rays.count(); ++i) {
    const Hit hit = traverse(p.tree, rays.ray(i), p.stack);
    if (hit.valid()) shadow_rays += shadow_ray_count(p.tree, p.scene.lights, hit.prim, rays.ray(i), hit.t,
                                                     ShadowSettings{});
  }

  const std::unique_ptr<Backend> backend = create_vulkan_backend(BackendOptions{});
  RenderSettings with_shadows, without_shadows;
  with_shadows.shadow_cells = without_shadows.shadow_cells = 0;  // the kd-tree walk, as the column says
  with_shadows.width = without_shadows.width = p.width;
  with_shadows.height = without_shadows.height = p.height;
  with_shadows.stack_depth = without_shadows.stack_depth = p.stack;
  without_shadows.shadows = false;
  Renderer mobirt_shadows(*backend, with_shadows), mobirt_primary(*backend, without_shadows);

  struct Column {
    std::vector<double> rq, kd;
    uint64_t same = 0;
  } primary, shadowed;
  std::vector<uint32_t> texels(rays.count());
  const std::vector<Light> no_lights;
  for (int r = 0; r <= repeat; ++r) {  // round 0 compiles the pipelines and warms up
    for (Column* c : {&primary, &shadowed}) {
      const bool shadows = c == &shadowed;
      RayQueryTimings t;
      updated.trace(rays, shadows ? p.scene.lights : no_lights, ShadowSettings{}, texels, &t);
      const TraceResult kd = (shadows ? mobirt_shadows : mobirt_primary).trace(p.scene, p.tree, rays);
      if (r == 0) {
        for (size_t i = 0; i < texels.size(); ++i) c->same += texels[i] == kd.texels[i];
        continue;
      }
      c->rq.push_back(t.trace_ms);
      c->kd.push_back(kd.timing.gpu_ms);
    }
  }

  std::printf("%s: %zu triangles, %dx%d, %u primary rays, %llu shadow rays; %s; median of %d rounds\n", p.path.c_str(),
              p.scene.mesh.triangle_count(), p.width, p.height, rays.count(),
              static_cast<unsigned long long>(shadow_rays), updated.info().front().c_str(), repeat);
  for (const Mode& m : modes) {
    std::printf("AS build %-6s over %d frames%s: BLAS %.2f + TLAS %.2f ms (GPU), build() %.2f ms; then +shadow trace "
                "%.2f ms\n",
                m.engine == &updated ? "update" : "fresh", frames,
                animation.animated() ? " of the animation" : " (static)", median(m.blas), median(m.tlas),
                median(m.wall), median(m.trace));
  }
  for (const Column* c : {&primary, &shadowed}) {
    const double n = double(rays.count()) + (c == &shadowed ? double(shadow_rays) : 0.0);
    const double rq = median(c->rq), kd = median(c->kd);
    std::printf("%-8s ray query %7.2f ms %6.2f Mrays/s | mobirt traversal pass %7.2f ms %6.2f Mrays/s | mobirt "
                "%.2fx the ray query's speed | texels identical %.3f%%\n",
                c == &shadowed ? "+shadow" : "primary", rq, n / (rq * 1e3), kd, n / (kd * 1e3), rq / kd,
                100.0 * double(c->same) / double(rays.count()));
  }
  return 0;
}

}  // namespace
}  // namespace mobirt

int main(int argc, char** argv) {
  return mobirt::profile::run_tool("mobirt_ray_query_rays", argc, argv, mobirt::run);
}
