// The Vulkan passes against the CPU: the traversal pass finds the same hits and shadow masks as
// the CPU traversal of the same flattened tree, and the rendered image matches the CPU
// expectation. The Khronos validation layer is on in every test; any message fails it.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <sstream>
#include <vector>

#include "backend/backend.h"
#include "core/error.h"
#include "raytree/hits.h"
#include "render/cpu_render.h"
#include "render/renderer.h"
#include "render_checks.h"
#include "scene/loader.h"
#include "test_scenes.h"
#include "test_support.h"
#include "vulkan_fixture.h"

namespace mobirt {
namespace {

class VulkanRender : public test::VulkanTest {};

struct Agreement {
  size_t rays = 0;
  size_t same_prim = 0;
  size_t near_ties = 0;      // different triangles at (almost) the same distance
  size_t grazing = 0;        // hit on one side, miss on the other, at a triangle's edge
  size_t other = 0;          // anything else: a real disagreement
  size_t masks_compared = 0;
  size_t masks_equal = 0;
  size_t capped = 0;
  std::string first_other;
};

// Smallest barycentric coordinate of the ray's hit on prim (negative when outside).
float edge_distance(const FlatKdTree& tree, const Ray& ray, int32_t prim) {
  Hit h;
  Ray open = ray;
  open.tmin = -kInfinity;
  open.tmax = kInfinity;
  if (!intersect_triangle(tree, prim, open, h)) return -1.0f;
  return std::min({h.u, h.v, 1.0f - h.u - h.v});
}

Agreement compare_with_cpu(const Scene& scene, const FlatKdTree& tree, const RayBatch& rays,
                           const TraceResult& gpu, int stack_depth) {
  Agreement a;
  const ShadowSettings shadows;
  for (uint32_t i = 0; i < rays.count(); ++i) {
    ++a.rays;
    const Ray ray = rays.ray(i);
    const TraceTexel texel = unpack_trace(gpu.packing, gpu.texels[i]);
    if (texel.capped) {
      ++a.capped;
      continue;
    }
    const Hit cpu = traverse(tree, ray, stack_depth);
    const int32_t gpu_prim = texel.hit() ? texel.prim() : -1;
    if (gpu_prim == cpu.prim) {
      ++a.same_prim;
      if (cpu.valid()) {
        ++a.masks_compared;
        const uint32_t mask = shadow_mask(tree, scene.lights, cpu.prim, ray, cpu.t, shadows, stack_depth);
        if (mask == texel.mask) ++a.masks_equal;
      }
      continue;
    }
    if (gpu_prim >= 0 && cpu.valid()) {
      Hit g;
      Ray open = ray;
      open.tmin = -kInfinity;
      open.tmax = kInfinity;
      const bool hit = intersect_triangle(tree, gpu_prim, open, g);
      if (hit && std::abs(g.t - cpu.t) <= 1e-4f * std::max(1.0f, cpu.t)) {
        ++a.near_ties;
        continue;
      }
    } else {
      const int32_t prim = gpu_prim >= 0 ? gpu_prim : cpu.prim;
      if (edge_distance(tree, ray, prim) < 1e-4f) {
        ++a.grazing;
        continue;
      }
    }
    if (a.other++ == 0) {
      std::ostringstream s;
      s << "ray " << i << ": gpu prim " << gpu_prim << ", cpu prim " << cpu.prim << " at t " << cpu.t;
      a.first_other = s.str();
    }
  }
  return a;
}

void expect_agreement(const Agreement& a, const std::string& what) {
  SCOPED_TRACE(what);
  const double same = double(a.same_prim) / double(a.rays - a.capped);
  EXPECT_GE(same, 0.999) << a.same_prim << " of " << a.rays << " rays agree";
  EXPECT_EQ(a.other, 0u) << "disagreements that are not near-ties: " << a.other << "; first: "
                         << a.first_other;
  EXPECT_EQ(a.capped, 0u) << "rays stopped by the loop cap";
  EXPECT_GT(a.masks_compared, 0u);
  // The shadow rays are the same rays on both sides; only a float rounding on a grazing shadow
  // edge may flip one.
  EXPECT_GE(double(a.masks_equal), 0.999 * double(a.masks_compared))
      << a.masks_equal << " of " << a.masks_compared << " shadow masks agree";
  std::printf("[ agreement ] %s: %zu rays, %zu same, %zu near-ties, %zu grazing, masks %zu/%zu\n",
              what.c_str(), a.rays, a.same_prim, a.near_ties, a.grazing, a.masks_equal, a.masks_compared);
}

void check_scene(Backend& backend, const Scene& scene, int width, int height, int stack_depth) {
  RenderSettings settings;
  settings.width = width;
  settings.height = height;
  settings.stack_depth = stack_depth;
  Renderer renderer(backend, settings);
  const FlatKdTree tree = build_kdtree(scene.mesh.positions, settings.kd);
  const Camera camera = scene.camera ? *scene.camera
                                     : frame_box(scene.bounds(), 0.8f, float(width) / float(height));
  const RayBatch rays = primary_rays(camera, width, height);
  const TraceResult gpu = renderer.trace(scene, tree, rays);
  expect_agreement(compare_with_cpu(scene, tree, rays, gpu, stack_depth),
                   scene.source + " stack " + std::to_string(stack_depth));
}

TEST_F(VulkanRender, TraversalMatchesCpuOnTheDefaultScene) {
  const Scene scene = load_scene(MOBIRT_SOURCE_DIR "/scenes/default.gltf");
  check_scene(*backend, scene, 200, 120, 4);
}

TEST_F(VulkanRender, TraversalMatchesCpuOnABoxGrid) {
  check_scene(*backend, test::box_grid_scene(), 160, 120, 4);
}

TEST_F(VulkanRender, TraversalMatchesCpuOnARandomSoup) {
  check_scene(*backend, test::random_soup_scene(), 128, 96, 4);
}

TEST_F(VulkanRender, TraversalMatchesCpuOnUtahToasters) {
  MOBIRT_REQUIRE_SHARED(path, "utah-toasters/Toasters004.obj");
  Scene scene = load_scene(path.string());
  Light light;
  const Aabb box = scene.bounds();
  light.position = box.center() + glm::vec3(0.3f, 1.5f, 0.8f) * glm::length(box.extent());
  light.intensity = 10.0f;
  scene.lights = {light};
  check_scene(*backend, scene, 200, 120, 4);
}

// Every short-stack depth, pure kd-restart included, finds the same hits.
TEST_F(VulkanRender, EveryStackDepthMatchesCpu) {
  const Scene scene = test::box_grid_scene();
  for (int depth : {0, 1, 2, 8, 32}) check_scene(*backend, scene, 96, 64, depth);
}

// A loop cap too small for the scene costs time, never pixels (see render_checks.h).
TEST_F(VulkanRender, CappedRaysAreTracedOnTheCpu) {
  test::expect_capped_rays_traced_on_the_cpu(*backend, 5000, 96, 64);
}

// The GPU image against the CPU expectation (same tree and hits, shading transcribed to C++).
TEST_F(VulkanRender, DefaultSceneImageMatchesCpuExpectation) {
  FrameTimings timings;
  const auto [gpu, cpu] = test::render_default_scene(*backend, &timings);
  const ImageDiff d = compare_images(gpu, cpu);
  // Lit pixels exist and shadows exist: the image is not blank or uniformly lit.
  size_t bright = 0, dark_floor = 0;
  for (const glm::vec3& p : gpu.pixels) {
    if (p.x + p.y + p.z > 0.6f) ++bright;
    if (p.x + p.y + p.z > 0.0f && p.x + p.y + p.z < 0.3f) ++dark_floor;
  }
  EXPECT_GT(bright, gpu.pixels.size() / 10);
  EXPECT_GT(dark_floor, gpu.pixels.size() / 50);
  if (d.psnr < 40.0 || d.share_over > 0.005) {
    write_image(test::output_path("default-gpu.png").string(), gpu);
    write_image(test::output_path("default-cpu.png").string(), cpu);
    write_image(test::output_path("default-diff.png").string(), difference_image(gpu, cpu));
    ADD_FAILURE() << "GPU image differs from the CPU expectation: PSNR " << d.psnr << " dB, "
                  << 100.0 * d.share_over << "% of pixels off by more than 2/255; see "
                  << test::output_path("default-diff.png");
  }
}

}  // namespace
}  // namespace mobirt
