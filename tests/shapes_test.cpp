// Analytic spheres, cylinders and cones beside triangles (issue 17): rays hit them where the
// analytic answer says on the CPU mirror, on both GPU backends and in the double-precision
// reference; their shadows and surface records; Vulkan and GLES agree; a scene without them gets
// no code for them, and the specialised pass renders what the general one does.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "accel/kdtree.h"
#include "backend/backend.h"
#include "raytree/hits.h"
#include "raytree/rays.h"
#include "reference/reference.h"
#include "render/cpu_render.h"
#include "render/renderer.h"
#include "render/scene_features.h"
#include "scene/animation.h"
#include "scene/tessellate.h"
#include "test_scenes.h"
#include "test_support.h"
#include "vulkan_fixture.h"

namespace mobirt {
namespace {

using test::cone_shape;
using test::sphere_shape;

// A unit sphere at the origin, an open cylinder of radius 0.5 along z at x = 4 (z in [-1, 1]) and
// a pointed cone at x = 8 (radius 1 at z = -1, 0 at z = 1): primitives 0, 1, 2.
Scene three_shapes() {
  Scene s = test::base_scene("three-shapes");
  s.shapes = {sphere_shape({0, 0, 0}, 1.0f, 0), cone_shape({4, 0, -1}, 0.5f, {4, 0, 1}, 0.5f, 0),
              cone_shape({8, 0, -1}, 1.0f, {8, 0, 1}, 0.0f, 1)};
  return s;
}

struct Case {
  const char* what;
  Ray ray;
  int32_t prim;  // -1: a miss
  float t;
};

// Each hit from the equations by hand.
std::vector<Case> analytic_cases() {
  const float inf = kInfinity;
  return {
      {"sphere, head on", {{0, 0, 5}, {0, 0, -1}, 0, inf}, 0, 4.0f},
      {"sphere, off centre: z = sqrt(1 - 0.36)", {{0.6f, 0, 5}, {0, 0, -1}, 0, inf}, 0, 4.2f},
      {"sphere, a direction of length 2 halves t", {{0, 0, 5}, {0, 0, -2}, 0, inf}, 0, 2.0f},
      {"sphere, from its centre: the far side", {{0, 0, 0}, {1, 0, 0}, 0, inf}, 0, 1.0f},
      {"sphere, just outside the silhouette", {{1.001f, 0, 5}, {0, 0, -1}, 0, inf}, -1, 0.0f},
      {"sphere, behind the ray", {{0, 0, 5}, {0, 0, 1}, 0, inf}, -1, 0.0f},
      {"sphere, tmax before it", {{0, 0, 5}, {0, 0, -1}, 0, 3.9f}, -1, 0.0f},
      {"cylinder, side on", {{4, -5, 0}, {0, 1, 0}, 0, inf}, 1, 4.5f},
      {"cylinder, off axis: y = -sqrt(0.25 - 0.09)", {{4.3f, -5, 0.5f}, {0, 1, 0}, 0, inf}, 1, 4.6f},
      {"cylinder, above its top", {{4, -5, 1.5f}, {0, 1, 0}, 0, inf}, -1, 0.0f},
      {"cylinder, down its axis: open ends", {{4, 0, 5}, {0, 0, -1}, 0, inf}, -1, 0.0f},
      {"cylinder, into the top, the inside wall", {{4, 0, 3}, {0, 0.2f, -1}, 0, inf}, 1, 2.5f},
      {"cone, half way up: radius 0.5", {{8, -5, 0}, {0, 1, 0}, 0, inf}, 2, 4.5f},
      {"cone, near the apex: radius 0.05", {{8, -5, 0.9f}, {0, 1, 0}, 0, inf}, 2, 4.95f},
      {"cone, from above: radius 0.25 at z = 0.5", {{8, 0.25f, 5}, {0, 0, -1}, 0, inf}, 2, 4.5f},
      {"cone, below its base", {{8, -5, -1.2f}, {0, 1, 0}, 0, inf}, -1, 0.0f},
  };
}

TEST(Shapes, CpuMirrorHitsWhereTheAnalyticAnswerSays) {
  const Scene s = three_shapes();
  const FlatKdTree tree = build_kdtree({}, s.shapes);
  ASSERT_EQ(tree.triangles.size(), 3u * MOBIRT_TEXELS_PER_TRIANGLE);
  for (const RayTest test : {RayTest{}, RayTest{IntersectTest::Watertight, Precision::High}}) {
    for (const Case& c : analytic_cases()) {
      SCOPED_TRACE(c.what);
      const Hit h = traverse(tree, c.ray, 4, test);
      EXPECT_EQ(h.prim, c.prim);
      if (c.prim >= 0) {
        EXPECT_NEAR(h.t, c.t, 2e-6f * c.t);
      }
      EXPECT_EQ(brute_force(tree, c.ray, test).prim, c.prim);
      EXPECT_EQ(occluded(tree, c.ray, 4, test), c.prim >= 0);
    }
  }
}

TEST(Shapes, SurfaceRecordsHaveTheShapesNormalsAndTextureCoordinates) {
  Scene s = three_shapes();
  const FlatKdTree tree = build_kdtree({}, s.shapes);
  // Sphere from above at (0.6, 0, 0.8): the radial normal; u = atan2(z, x) / 2 pi, v = acos(y) / pi.
  const Ray down{{0.6f, 0, 5}, {0, 0, -1}, 0, kInfinity};
  const SurfaceHit a = surface_hit(s, tree, down, 0);
  test::expect_vec3(a.position, {0.6f, 0, 0.8f}, 1e-5f);
  test::expect_vec3(a.normal, {0.6f, 0, 0.8f}, 1e-5f);
  EXPECT_TRUE(a.entering);
  EXPECT_NEAR(a.texcoord.x, std::atan2(0.8, 0.6) / (2.0 * 3.141592653589793), 1e-6);
  EXPECT_NEAR(a.texcoord.y, 0.5f, 1e-6f);
  EXPECT_EQ(a.material, 0u);
  // From the centre outwards: leaving, the normal turned to face the ray.
  const SurfaceHit b = surface_hit(s, tree, Ray{{0, 0, 0}, {1, 0, 0}, 0, kInfinity}, 0);
  EXPECT_FALSE(b.entering);
  test::expect_vec3(b.normal, {-1, 0, 0}, 1e-6f);
  // An inside-visible sphere (NFF's negative radius) is entered from its inside.
  s.shapes[0].inside = true;
  EXPECT_TRUE(surface_hit(s, tree, Ray{{0, 0, 0}, {1, 0, 0}, 0, kInfinity}, 0).entering);
  // The cone's normal leans towards the apex by the slope (radius 1 over height 2).
  const SurfaceHit c = surface_hit(s, tree, Ray{{8, -5, 0}, {0, 1, 0}, 0, kInfinity}, 2);
  test::expect_vec3(c.normal, glm::normalize(glm::vec3(0, -1, 0.5f)), 1e-5f);
  EXPECT_EQ(c.material, 1u);
  EXPECT_NEAR(c.texcoord.y, 0.5f, 1e-6f);  // half way up
}

// The double-precision reference sees the sphere exactly where the analytic silhouette is, and
// the shapes where the CPU mirror sees them.
TEST(Shapes, ReferenceHitsWhereTheAnalyticAnswerSays) {
  Scene s = three_shapes();
  const Camera camera{{4, 0, 7}, {4, 0, 0}, {0, 1, 0}, 0.9f, 0.0f};
  const int w = 96, h = 32;
  ReferenceSettings settings;
  settings.width = w;
  settings.height = h;
  settings.depth = 0;
  const ReferenceResult ref = render_reference(s, camera, settings);
  const FlatKdTree tree = build_kdtree({}, s.shapes);
  const RayBatch rays = primary_rays(camera, w, h);
  size_t sphere = 0, checked = 0, agree = 0;
  for (uint32_t i = 0; i < rays.count(); ++i) {
    const Ray r = rays.ray(i);
    const glm::dvec3 o(r.origin), d = glm::normalize(glm::dvec3(r.direction));
    const double dist = glm::length(glm::cross(-o, d));  // the ray's distance from the centre
    if (std::abs(dist - 1.0) > 1e-4) {
      ++checked;
      EXPECT_EQ(ref.primary_prim[i] == 0, dist < 1.0) << "pixel " << i << ", distance " << dist;
      sphere += dist < 1.0;
    }
    agree += ref.primary_prim[i] == traverse(tree, r).prim;
  }
  EXPECT_GT(sphere, 50u);
  EXPECT_GT(checked, rays.count() * 9 / 10);
  EXPECT_GE(agree, rays.count() - rays.count() / 100) << "reference against the CPU mirror";
}

TEST(Shapes, TrianglesAndShapesShareTheIndexSpace) {
  Scene s = test::shapes_scene();
  const FlatKdTree tree = build_kdtree(s.mesh.positions, s.shapes);
  EXPECT_EQ(tree.triangles.size(), s.primitive_count() * MOBIRT_TEXELS_PER_TRIANGLE);
  EXPECT_FALSE(is_analytic(tree, 0));
  EXPECT_TRUE(is_analytic(tree, 2));
  // The mirror sphere, seen head on, is primitive 2 (after the floor's two triangles).
  EXPECT_EQ(traverse(tree, Ray{{0, 0, 5}, {0, 0, -1}, 0, kInfinity}).prim, 2);
  // The floor below the sphere is in its shadow; beside it, lit.
  const std::span<const Light> lights(s.lights);
  const ShadowSettings shadows;
  const Ray under{{0.2f, 5, 0.3f}, {0, -1, 0}, 0, kInfinity};
  const Hit top = traverse(tree, under);
  ASSERT_EQ(top.prim, 2);
  EXPECT_EQ(shadow_mask(tree, lights, top.prim, under, top.t, shadows, -1), 1u) << "the sphere's top is lit";
  const Ray floor{{-0.2f, -0.99f, -0.1f}, {0, -1, 0}, 0, kInfinity};  // from under the sphere
  const Hit f = traverse(tree, floor);
  ASSERT_GE(f.prim, 0);
  ASSERT_LT(f.prim, 2);
  EXPECT_EQ(shadow_mask(tree, lights, f.prim, floor, f.t, shadows, -1), 0u) << "the sphere shadows the floor";
  // The same tree tessellated renders nearly the same picture: the shapes are where the triangles are.
  Scene tessellated = s;
  tessellate_shapes(tessellated);
  EXPECT_TRUE(tessellated.shapes.empty());
  // The pointed cone has one triangle per segment.
  EXPECT_EQ(tessellated.mesh.triangle_count(),
            2 + 2 * sphere_triangle_count({}) + cone_triangle_count({}) + cone_triangle_count({}) / 2);
  RenderSettings settings;
  settings.width = 80;
  settings.height = 48;
  const ImageDiff d = compare_images(render_on_cpu(s, *s.camera, settings),
                                     render_on_cpu(tessellated, *tessellated.camera, settings));
  EXPECT_GE(d.psnr, 28.0) << "analytic against tessellated";
}

TEST(Shapes, OnlyScenesWithShapesGetTheirCode) {
  RenderSettings settings;
  auto choices = [&](const Scene& s) {
    std::string all;
    for (const std::string& c : analyze_scene(AnimatedScene(Scene(s), nullptr, 0.0, 24.0), settings).choices) {
      all += c + "\n";
    }
    return all;
  };
  EXPECT_NE(choices(test::box_grid_scene()).find("ANALYTIC 0"), std::string::npos);
  EXPECT_NE(choices(test::shapes_scene()).find("ANALYTIC 1"), std::string::npos);
}

// ---- The GPU passes, both backends -----------------------------------------------------------

enum class Api { Vulkan, Gles };

class ShapesOnGpu : public ::testing::TestWithParam<Api> {
 protected:
  void SetUp() override {
    const BackendOptions options = test::validated_options();
    backend = GetParam() == Api::Vulkan ? create_vulkan_backend(options) : create_gles_backend(options);
  }
  void TearDown() override {
    if (backend) {
      const std::vector<std::string> messages = backend->take_debug_messages();
      EXPECT_TRUE(messages.empty()) << test::join(messages);
    }
  }
  std::unique_ptr<Backend> backend;
};

TEST_P(ShapesOnGpu, TraversalPassHitsWhereTheAnalyticAnswerSays) {
  const Scene s = three_shapes();
  const FlatKdTree tree = build_kdtree({}, s.shapes);
  const std::vector<Case> cases = analytic_cases();
  RayBatch rays;
  rays.width = 8;
  for (size_t i = 0; i < cases.size(); ++i) rays.push(cases[i].ray, uint32_t(i), glm::vec3(1.0f));
  for (const bool specialize : {true, false}) {
    RenderSettings settings;
    settings.specialize = specialize;
    Renderer renderer(*backend, settings);
    const TraceResult traced = renderer.trace(s, tree, rays);
    for (size_t i = 0; i < cases.size(); ++i) {
      SCOPED_TRACE(std::string(cases[i].what) + (specialize ? "" : ", general pass"));
      const TraceTexel t = unpack_trace(traced.packing, traced.texels[i]);
      EXPECT_FALSE(t.capped);
      EXPECT_EQ(t.prim(), cases[i].prim);
    }
  }
}

// Every precision and test the pass is specialised to traces the shapes as the CPU mirror does,
// operation for operation (mediump: each intermediate rounded to fp16 on both).
TEST_P(ShapesOnGpu, TraversalPassMatchesTheCpuMirrorUnderEveryRayTest) {
  const Scene s = test::shapes_scene();
  const FlatKdTree tree = build_kdtree(s.mesh.positions, s.shapes);
  const RayBatch rays = primary_rays(*s.camera, 96, 64);
  for (const RayTest test : {RayTest{}, RayTest{IntersectTest::Watertight, Precision::High},
                             RayTest{IntersectTest::MollerTrumbore, Precision::Medium}}) {
    SCOPED_TRACE(test.precision == Precision::Medium ? "mediump" : "highp");
    RenderSettings settings;
    settings.shadows = false;
    settings.shadow_rays.ray_test = test;
    Renderer renderer(*backend, settings);
    const TraceResult traced = renderer.trace(s, tree, rays);
    size_t same = 0, shapes = 0;
    for (uint32_t i = 0; i < rays.count(); ++i) {
      const int32_t cpu = traverse(tree, rays.ray(i), settings.stack_depth, test).prim;
      same += unpack_trace(traced.packing, traced.texels[i]).prim() == cpu;
      shapes += cpu >= 2;
    }
    EXPECT_GT(shapes, rays.count() / 10);
    EXPECT_GE(same, rays.count() - rays.count() / 500) << "of " << rays.count() << " primary rays";
  }
}

// The frame the image tests render: small, two bounces (the mirror and the glass sphere).
RenderSettings frame_settings() {
  RenderSettings settings;
  settings.width = 96;
  settings.height = 64;
  settings.depth = 2;
  return settings;
}

// The whole frame: against the CPU frame (the same tree and ray tree, C++ shading), the other
// backend (parity_test's thresholds) and the reference.
TEST_P(ShapesOnGpu, FrameMatchesTheCpuFrameAndTheReference) {
  const Scene s = test::shapes_scene();
  RenderSettings settings = frame_settings();
  Renderer renderer(*backend, settings);
  const Image image = renderer.render(s, *s.camera);
  const ImageDiff cpu = compare_images(image, render_on_cpu(s, *s.camera, settings), 1.0f / 255.0f);
  EXPECT_GE(cpu.psnr, 45.0);
  EXPECT_LE(cpu.share_over, 0.005);
  const ReferenceResult ref = render_reference(s, *s.camera, reference_settings(settings));
  Image clamped = ref.image;
  for (glm::vec3& p : clamped.pixels) p = glm::clamp(p, 0.0f, 1.0f);
  // Against the reference a few silhouette pixels (0.1 % at this size) flip between float and
  // double, each by up to 0.7: hence the share of pixels, not a PSNR of 45 dB at 96x64.
  const ImageDiff r = compare_images(image, clamped, 2.0f / 255.0f);
  EXPECT_GE(r.psnr, 35.0) << "against the reference";
  EXPECT_LE(r.share_over, 0.005) << "against the reference: pixels off by more than 2/255";
  if (r.share_over > 0.005) {
    const std::string name = std::string("shapes-") + (GetParam() == Api::Vulkan ? "vulkan" : "gles");
    write_image(test::output_path(name + ".png").string(), image);
    write_image(test::output_path(name + "-reference-diff.png").string(), difference_image(image, clamped));
  }
  // Specialised (ANALYTIC 1) and general passes render the same image.
  settings.specialize = false;
  Renderer general(*backend, settings);
  const ImageDiff g = compare_images(image, general.render(s, *s.camera), 0.5f / 255.0f);
  EXPECT_LE(g.max_error, 1.0 / 255.0 + 1e-6);
}

INSTANTIATE_TEST_SUITE_P(Backends, ShapesOnGpu, ::testing::Values(Api::Vulkan, Api::Gles),
                         [](const ::testing::TestParamInfo<Api>& p) { return p.param == Api::Vulkan ? "vulkan" : "gles"; });

// Vulkan and GLES 2.0 render the shapes alike (the traversal pass from one GLSL source).
TEST(ShapesParity, GlesMatchesVulkan) {
  const Scene s = test::shapes_scene();
  RenderSettings settings = frame_settings();
  auto vk = create_vulkan_backend(test::validated_options());
  auto gl = create_gles_backend(test::validated_options());
  Renderer a(*vk, settings), b(*gl, settings);
  const RayBatch primary = primary_rays(*s.camera, settings.width, settings.height);
  const FlatKdTree tree = build_kdtree(s.mesh.positions, s.shapes, settings.kd);
  const TraceResult ta = a.trace(s, tree, primary), tb = b.trace(s, tree, primary);
  size_t same = 0;
  for (size_t i = 0; i < ta.texels.size(); ++i) same += ta.texels[i] == tb.texels[i];
  EXPECT_GE(same, ta.texels.size() - ta.texels.size() / 1000) << "hit index and shadow mask";
  const ImageDiff d = compare_images(a.render(s, *s.camera), b.render(s, *s.camera), 1.0f / 255.0f);
  EXPECT_GE(d.psnr, 45.0);
  EXPECT_LE(d.share_over, 0.005);
}

}  // namespace
}  // namespace mobirt
