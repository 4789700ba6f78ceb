// The compute engine (src/baseline/compute_engine.h): mobirt's kd-tree walk as a compute shader
// must find, ray by ray, what mobirt's fragment pass finds (the same hit primitive and shadow
// mask), with t and barycentrics that agree with the CPU's intersection of that triangle, and its
// frames must be mobirt's; the loop cap still stops a runaway walk. All under the validation layer.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "backend/shader_constraints.h"
#include "backend/vulkan/vulkan_backend.h"
#include "baseline/compute_engine.h"
#include "baseline/compute_whitted.h"
#include "core/error.h"
#include "raytree/hits.h"
#include "render/renderer.h"
#include "render/whitted.h"
#include "scene/animation.h"
#include "scene/loader.h"
#include "shader_ids.h"
#include "render_checks.h"
#include "test_support.h"

namespace mobirt {
namespace {

VulkanOptions validated() {
  VulkanOptions options;
  options.validation = true;
  options.sync_validation = true;
  return options;
}

std::string join(const std::vector<std::string>& lines) {
  std::string s;
  for (const std::string& l : lines) s += l + "\n";
  return s;
}

Scene project_scene(const std::string& name) {
  return load_scene(std::string(MOBIRT_SOURCE_DIR) + "/scenes/" + name + ".gltf");
}

struct Agreement {
  uint32_t rays = 0, hits = 0, lit = 0, prim_differs = 0, mask_differs = 0, capped = 0;
  uint32_t no_barycentrics = 0, off_cpu = 0;
  uint64_t shadow_rays = 0, cpu_shadow_rays = 0;
};

// The records against the fragment pass's texels for the same rays, tree and lights, and each hit's
// t, u, v against the CPU's test of that triangle (what decode_hits would compute).
Agreement compare(const std::vector<HitRecord>& records, const TraceResult& fragment, const FlatKdTree& tree,
                  const RayBatch& rays, std::span<const Light> lights) {
  Agreement a;
  a.rays = rays.count();
  for (uint32_t i = 0; i < rays.count(); ++i) {
    const HitRecord& r = records[i];
    const TraceTexel want = unpack_trace(fragment.packing, fragment.texels[i]);
    a.capped += r.capped();
    if (r.capped() || want.capped) continue;
    a.hits += r.hit();
    a.lit += r.mask != 0;
    if (r.prim_plus_one != want.prim_plus_one) {
      ++a.prim_differs;
      continue;
    }
    if (!r.hit()) continue;
    a.mask_differs += r.mask != want.mask;
    a.no_barycentrics += (r.flags & MOBIRT_HIT_NO_BARYCENTRICS) != 0;
    Ray open = rays.ray(i);
    open.tmin = -kInfinity;
    open.tmax = kInfinity;
    Hit cpu;
    if (!intersect_triangle(tree, r.prim(), open, cpu)) {
      ++a.off_cpu;
      continue;
    }
    const float scale = std::max(1.0f, std::abs(cpu.t));
    if (std::abs(r.t - cpu.t) > 1e-4f * scale || std::abs(r.u - cpu.u) > 1e-4f || std::abs(r.v - cpu.v) > 1e-4f) {
      ++a.off_cpu;
      if (a.off_cpu <= 5) {
        std::printf("  ray %u prim %d: GPU t %.9g u %.7g v %.7g, CPU t %.9g u %.7g v %.7g\n", i, r.prim(), r.t, r.u,
                    r.v, cpu.t, cpu.u, cpu.v);
      }
    }
    a.shadow_rays += r.shadow_rays;
    a.cpu_shadow_rays += shadow_ray_count(tree, lights, r.prim(), rays.ray(i), r.t, ShadowSettings{});
  }
  return a;
}

// Ray by ray against mobirt's fragment pass (Vulkan, texel buffers) on the project's scenes:
// camera rays and rays from anywhere in the scene box, with shadow rays; the scene read from
// storage buffers and from texel buffers.
class ComputeReads : public ::testing::TestWithParam<ComputeData> {};

// --gpu-timestamps: the dispatch timed on the device's clock or on the CPU's (the default on
// lavapipe, where each timestamp waits for the work): the same records, and a time, either way.
TEST(Compute, TimedOnEitherClock) {
  const Scene scene = project_scene("toaster");
  ASSERT_TRUE(scene.camera);
  const FlatKdTree tree = build_kdtree(scene.mesh.positions);
  const RayBatch rays = test::random_rays(scene, *scene.camera, 5000, 100, 13);
  std::vector<HitRecord> records[2];
  int made = 0;
  for (const GpuTimestamps mode : {GpuTimestamps::On, GpuTimestamps::Off}) {
    SCOPED_TRACE(gpu_timestamps_name(mode));
    VulkanOptions options = validated();
    options.timestamps = mode;
    ComputeEngine engine(options);
    engine.upload_tree(tree);
    std::vector<HitRecord>& out = records[made++];
    out.resize(rays.count());
    ComputeTimings timings;
    engine.trace(rays, scene.lights, ShadowSettings{}, {6, 2048}, out, &timings);
    EXPECT_GT(timings.trace_ms, 0.0);
  }
  ASSERT_EQ(records[0].size(), records[1].size());
  EXPECT_EQ(std::memcmp(records[0].data(), records[1].data(), records[0].size() * sizeof(HitRecord)), 0);
}

TEST_P(ComputeReads, RecordsEqualTheFragmentPassRayByRay) {
  ComputeEngine engine(validated(), GetParam());
  EXPECT_NE(join(engine.info()).find(GetParam() == ComputeData::TexelBuffers ? "texel buffers" : "storage buffers"),
            std::string::npos) << join(engine.info());
  VulkanOptions options;
  options.validation = true;
  const std::unique_ptr<Backend> backend = create_vulkan_backend(options);
  RenderSettings settings;
  Renderer renderer(*backend, settings);
  for (const char* name : {"default", "toaster", "fish"}) {
    SCOPED_TRACE(name);
    const Scene scene = project_scene(name);
    ASSERT_TRUE(scene.camera);
    ASSERT_FALSE(scene.lights.empty());
    const FlatKdTree tree = build_kdtree(scene.mesh.positions);
    engine.upload_tree(tree);
    const RayBatch rays = test::random_rays(scene, *scene.camera, 20000, 200, 3);
    std::vector<HitRecord> records(rays.count());
    ComputeTimings timings;
    engine.trace(rays, scene.lights, ShadowSettings{}, {settings.stack_depth, settings.max_steps}, records, &timings);
    EXPECT_EQ(timings.rays, rays.count());
    EXPECT_EQ(timings.bytes_read, uint64_t(rays.count()) * MOBIRT_HIT_RECORD_BYTES);
    EXPECT_GT(timings.trace_ms, 0.0);
    const TraceResult fragment = renderer.trace(scene, tree, rays);
    const Agreement a = compare(records, fragment, tree, rays, scene.lights);
    std::printf("%s, %s: %u rays, %u hits, %u lit; %u differ in the hit, %u in the mask; %u off the CPU's t/u/v, %u "
                "without barycentrics; %llu shadow rays (CPU: %llu)\n",
                compute_data_name(GetParam()), name, a.rays, a.hits, a.lit, a.prim_differs, a.mask_differs, a.off_cpu, a.no_barycentrics,
                static_cast<unsigned long long>(a.shadow_rays), static_cast<unsigned long long>(a.cpu_shadow_rays));
    EXPECT_GT(a.hits, a.rays / 4);  // enough hits and lit hits for the comparison to mean something
    EXPECT_GT(a.lit, a.hits / 4);
    EXPECT_EQ(a.capped, 0u);
    // The same walk, compiled twice: a differently fused multiply-add may flip a ray through a
    // shared edge, no more.
    EXPECT_LE(a.prim_differs, a.rays / 10000 + 1);
    EXPECT_LE(a.mask_differs, a.rays / 10000 + 1);
    EXPECT_LE(a.off_cpu, a.hits / 10000 + 1);
    EXPECT_NEAR(double(a.shadow_rays), double(a.cpu_shadow_rays), 0.001 * double(a.cpu_shadow_rays) + 2);
  }
  std::vector<std::string> messages = engine.take_debug_messages();
  EXPECT_TRUE(messages.empty()) << join(messages);
  messages = backend->take_debug_messages();
  EXPECT_TRUE(messages.empty()) << join(messages);
}

INSTANTIATE_TEST_SUITE_P(Data, ComputeReads, ::testing::Values(ComputeData::StorageBuffers, ComputeData::TexelBuffers),
                         [](const ::testing::TestParamInfo<ComputeData>& param) {
                           return param.param == ComputeData::TexelBuffers ? "texel_buffers" : "storage_buffers";
                         });

// The whole frame through render_whitted(): mobirt's kd-tree, rays, ray tree and shading pass with
// the compute pass tracing, against mobirt's Vulkan frame.
TEST(Compute, WhittedFramesEqualMobirtsVulkanFrames) {
  ComputeEngine engine(validated());
  VulkanOptions options;
  options.validation = true;
  const std::unique_ptr<Backend> mobirt_backend = create_vulkan_backend(options);
  const std::unique_ptr<Backend> shading_backend = create_vulkan_backend(options);
  size_t bounced = 0;
  for (const char* name : {"toaster", "fish"}) {
    const AnimatedScene animation = load_animated_scene(std::string(MOBIRT_SOURCE_DIR) + "/scenes/" + name + ".gltf");
    RenderSettings settings;
    settings.width = 160;
    settings.height = 96;
    settings.depth = 2;
    Renderer mobirt(*mobirt_backend, settings);
    Renderer shading(*shading_backend, settings);
    ComputeWhittedEngine peer(engine, shading);
    Scene scene;
    for (const double t : {0.0, 0.7}) {
      SCOPED_TRACE(std::string(name) + " at " + std::to_string(t) + " s");
      animation.evaluate(t, scene);
      FrameTimings want_t, got_t;
      const Image want = mobirt.render(scene, *scene.camera, &want_t);
      const Image got = render_whitted(scene, *scene.camera, settings, peer, &got_t);
      test::expect_peer_frame_matches_mobirts(want, want_t, got, got_t, std::string("compute_frame_") + name, 0.001);
      EXPECT_NEAR(double(got_t.sum.hits), double(want_t.sum.hits), 0.001 * want_t.sum.hits + 2);
      EXPECT_NEAR(double(got_t.sum.shadow_rays), double(want_t.sum.shadow_rays), 0.001 * want_t.sum.shadow_rays + 2);
      EXPECT_GE(got_t.sum.bytes_read, uint64_t(got_t.sum.rays) * MOBIRT_HIT_RECORD_BYTES) << "a record per ray";
      bounced += got_t.generations.size() > 1;
    }
  }
  EXPECT_GT(bounced, 0u) << "no scene had secondary rays: depth 2 was not tested";
  for (Backend* b : {mobirt_backend.get(), shading_backend.get()}) {
    const std::vector<std::string> messages = b->take_debug_messages();
    EXPECT_TRUE(messages.empty()) << join(messages);
  }
  const std::vector<std::string> messages = engine.take_debug_messages();
  EXPECT_TRUE(messages.empty()) << join(messages);
}

// A cap so low that many rays reach it: they come back capped, the CPU traces them, and the frame
// is the uncapped one (the cap costs time, never pixels).
TEST(Compute, CappedRaysAreTracedOnTheCpu) {
  ComputeEngine engine(validated());
  VulkanOptions options;
  options.validation = true;
  const std::unique_ptr<Backend> backend = create_vulkan_backend(options);
  const Scene scene = project_scene("toaster");
  RenderSettings settings;
  settings.width = 120;
  settings.height = 72;
  settings.depth = 1;
  Renderer shading(*backend, settings);
  ComputeWhittedEngine uncapped(engine, shading);
  FrameTimings t0, t1;
  const Image want = render_whitted(scene, *scene.camera, settings, uncapped, &t0);
  EXPECT_EQ(t0.sum.capped, 0u);
  settings.max_steps = 24;
  ComputeWhittedEngine capped(engine, shading);
  const Image got = render_whitted(scene, *scene.camera, settings, capped, &t1);
  EXPECT_GT(t1.sum.capped, t1.primary_rays() / 10) << "a cap of 24 steps stops many rays";
  const ImageDiff diff = compare_images(want, got);
  EXPECT_GE(diff.psnr, 60.0) << "max error " << diff.max_error;
  EXPECT_TRUE(engine.take_debug_messages().empty());
  EXPECT_TRUE(backend->take_debug_messages().empty());
}

// A tree whose root is its own child: without a cap the walk never ends. Mesa 25.0's lavapipe no
// longer stops loops on its own (VulkanBackendTest.SpinHonoursTheCap), so the shader's cap is the
// only guard: every ray must come back capped, after the cap's 100,000 steps, not hang.
TEST(Compute, LoopCapEndsARunawayWalk) {
  ComputeEngine engine(validated());
  FlatKdTree cycle;
  cycle.bounds = Aabb{glm::vec3(-1.0f), glm::vec3(1.0f)};
  // Interior node 0: split x = -100, above child 0; rays from x > -100 stay on the above side.
  cycle.nodes = {glm::vec4(-100.0f, 0.0f, 0.0f, 0.0f)};
  cycle.triangles = {glm::vec4(0.0f), glm::vec4(1.0f, 0.0f, 0.0f, 0.0f), glm::vec4(0.0f, 1.0f, 0.0f, 0.0f)};
  engine.upload_tree(cycle);
  RayBatch rays;
  rays.width = 16;
  for (uint32_t i = 0; i < 128; ++i) {
    const float y = -0.5f + float(i) / 128.0f;
    rays.push(Ray{glm::vec3(-2.0f, y, 0.25f), glm::vec3(1.0f, 0.01f * float(i % 7), 0.0f), 0.0f, kInfinity}, i,
              glm::vec3(1.0f));
  }
  std::vector<HitRecord> records(rays.count());
  ComputeTimings timings;
  engine.trace(rays, {}, ShadowSettings{}, {4, 100000}, records, &timings);
  std::printf("runaway walk, cap 100000: %u rays in %.1f ms\n", rays.count(), timings.trace_ms);
  for (uint32_t i = 0; i < rays.count(); ++i) {
    ASSERT_TRUE(records[i].capped()) << "ray " << i << ": flags " << records[i].flags;
    ASSERT_FALSE(records[i].hit()) << "ray " << i;
  }
  EXPECT_TRUE(engine.take_debug_messages().empty());
}

TEST(Compute, RefusesTooManyLightsAndTraceBeforeUpload) {
  ComputeEngine engine(validated());
  RayBatch rays = primary_rays(Camera{}, 4, 4);
  std::vector<HitRecord> records(rays.count());
  try {
    engine.trace(rays, {}, ShadowSettings{}, {}, records);
    ADD_FAILURE() << "trace before upload_tree";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::Internal) << e.what();
  }
  const Scene scene = project_scene("fish");
  engine.upload_tree(build_kdtree(scene.mesh.positions));
  const std::vector<Light> lights(MOBIRT_MAX_LIGHTS + 1, scene.lights[0]);
  test::expect_bad_input([&] { engine.trace(rays, lights, ShadowSettings{}, {}, records); }, {"17 lights"});
  EXPECT_TRUE(engine.take_debug_messages().empty());
}

// The checker names what the compute pass breaks, and nothing for mobirt's own passes.
TEST(Compute, ConstraintCheckerNamesWhatTheComputePassBreaks) {
  const std::vector<std::string> broken = ComputeEngine::broken_constraints();
  EXPECT_EQ(broken, es2_constraints_broken(shader_source(ShaderId::TraverseCompute).spirv));
  const std::string all = join(broken);
  EXPECT_NE(all.find("is a compute shader"), std::string::npos) << all;
  EXPECT_NE(all.find("uses storage buffers"), std::string::npos) << all;
  EXPECT_TRUE(es2_constraints_broken(shader_source(ShaderId::Traverse).spirv).empty());
  EXPECT_FALSE(reflect_spirv(shader_source(ShaderId::Traverse).spirv).compute);
  EXPECT_TRUE(reflect_spirv(shader_source(ShaderId::TraverseCompute).spirv).compute);
  EXPECT_EQ(ComputeEngine::unavailable_reason(), "");
  ComputeEngine engine;
  const std::string info = join(engine.info());
  EXPECT_NE(info.find("breaks the OpenGL ES 2.0 constraints: is a compute shader"), std::string::npos) << info;
}

}  // namespace
}  // namespace mobirt
