// The ray-query peer (src/baseline/ray_query_engine.h): its packed texels must be mobirt's, ray by
// ray, as the CPU kd-tree traversal and the CPU shadow rays compute them, or the bench compares
// different work. Skipped, with the reason, where the driver has no ray queries (Mesa < 24.1).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "backend/shader_constraints.h"
#include "backend/vulkan/vulkan_backend.h"
#include "baseline/ray_query_engine.h"
#include "baseline/ray_query_whitted.h"
#include "core/error.h"
#include "core/parallel.h"
#include "raytree/hits.h"
#include "render/whitted.h"
#include "scene/animation.h"
#include "scene/loader.h"
#include "render_checks.h"
#include "test_support.h"

// SPIR-V built from glsl/ (build/spirv/).
#include "ray_query.frag.h"
#include "shade.frag.h"
#include "trace.frag.h"

namespace mobirt {
namespace {

// The engine, or null with the reason this driver cannot make one.
std::unique_ptr<RayQueryEngine> try_engine(const RayQueryOptions& options, std::string& why) {
  try {
    return std::make_unique<RayQueryEngine>(options);
  } catch (const Error& e) {
    if (e.kind() != ErrorKind::Unsupported && e.kind() != ErrorKind::NoDevice) throw;
    why = e.what();
    return nullptr;
  }
}

// The validation layer on, as every Vulkan test of mobirt runs, with its synchronization
// validation: the engine's barriers are its own.
RayQueryOptions validated(AsBuildMode mode = AsBuildMode::Update) {
  RayQueryOptions options;
  options.validation = true;
  options.sync_validation = true;
  options.build_mode = mode;
  return options;
}

#define MOBIRT_RAY_QUERY_ENGINE(var, options)                \
  std::string var##_why;                                      \
  std::unique_ptr<RayQueryEngine> var = try_engine(options, var##_why); \
  if (!var) GTEST_SKIP() << var##_why

std::string join(const std::vector<std::string>& lines) {
  std::string s;
  for (const std::string& l : lines) s += l + "\n";
  return s;
}

// What mobirt's traversal pass writes for these rays, from the CPU: the full-stack kd-tree walk
// (the pass's oracle) and the CPU's copy of the pass's shadow rays.
std::vector<uint32_t> cpu_texels(const FlatKdTree& tree, const RayBatch& rays, std::span<const Light> lights,
                                 const ShadowSettings& shadows, Packing packing) {
  std::vector<uint32_t> texels(rays.count());
  parallel_for(rays.count(), 2, [&](uint32_t i) {
    const Ray ray = rays.ray(i);
    const Hit hit = traverse(tree, ray);
    texels[i] = hit.valid() ? pack_trace(packing, uint32_t(hit.prim) + 1,
                                         shadow_mask(tree, lights, hit.prim, ray, hit.t, shadows, -1))
                            : pack_trace(packing, 0, 0);
  });
  return texels;
}

struct Agreement {
  uint32_t rays = 0, same = 0, hits = 0, prim_differs = 0, mask_differs = 0, lit = 0;
  // Why hits differ: ties (both triangles are hit at the same t, within 1e-5 t: a shared edge or
  // vertex), edges (one ray/triangle test accepts a triangle the other rejects: the ray grazes its
  // edge), anything else.
  uint32_t ties = 0, edges = 0, other = 0;
  double share() const { return rays ? double(same) / rays : 0.0; }
};

void classify(const FlatKdTree& tree, const Ray& ray, const TraceTexel& got, const TraceTexel& want, Agreement& a) {
  Ray open = ray;
  open.tmin = -kInfinity;
  open.tmax = kInfinity;
  Hit mine, theirs;
  const bool mine_hit = want.hit() && intersect_triangle(tree, want.prim(), open, mine);
  const bool theirs_hit = got.hit() && intersect_triangle(tree, got.prim(), open, theirs);
  if (got.hit() != want.hit() || !theirs_hit) {
    ++a.edges;
  } else if (mine_hit && std::abs(mine.t - theirs.t) <= 1e-5f * std::abs(mine.t)) {
    ++a.ties;
  } else {
    ++a.other;
    std::printf("  ray (%g %g %g) -> (%g %g %g): CPU prim %d t %.9g, ray query prim %d t %.9g\n", ray.origin.x,
                ray.origin.y, ray.origin.z, ray.direction.x, ray.direction.y, ray.direction.z, want.prim(), mine.t,
                got.prim(), theirs.t);
  }
}

Agreement compare(const std::vector<uint32_t>& got, const std::vector<uint32_t>& want, Packing packing,
                  const FlatKdTree& tree, const RayBatch& rays) {
  Agreement a;
  a.rays = uint32_t(want.size());
  for (size_t i = 0; i < want.size(); ++i) {
    const TraceTexel g = unpack_trace(packing, got[i]), w = unpack_trace(packing, want[i]);
    EXPECT_FALSE(g.capped) << "ray " << i << ": the ray-query pass never caps a ray";
    a.same += got[i] == want[i];
    a.hits += w.hit();
    a.lit += w.mask != 0;
    if (g.prim_plus_one != w.prim_plus_one) {
      ++a.prim_differs;
      classify(tree, rays.ray(uint32_t(i)), g, w, a);
    } else if (g.mask != w.mask) {
      ++a.mask_differs;
    }
  }
  return a;
}

using test::random_rays;

Agreement trace_and_compare(RayQueryEngine& engine, const Scene& scene, const RayBatch& rays, const char* what) {
  const FlatKdTree tree = build_kdtree(scene.mesh.positions);
  std::vector<uint32_t> texels(rays.count());
  RayQueryTimings timings;
  const Packing packing = engine.trace(rays, scene.lights, ShadowSettings{}, texels, &timings);
  EXPECT_EQ(packing, choose_packing(scene.mesh.triangle_count(), int(scene.lights.size()), scene.source));
  EXPECT_EQ(timings.rays, rays.count());
  EXPECT_GT(timings.trace_ms, 0.0);
  const Agreement a =
      compare(texels, cpu_texels(tree, rays, scene.lights, ShadowSettings{}, packing), packing, tree, rays);
  std::printf("%s: %u rays, %u hits, %u lit; %u differ in the hit (%u ties, %u edges, %u other), %u in the shadow "
              "mask (%.4f%% identical)\n",
              what, a.rays, a.hits, a.lit, a.prim_differs, a.ties, a.edges, a.other, a.mask_differs, 100.0 * a.share());
  EXPECT_LE(a.other, a.rays / 10000) << "hits that differ neither by a tie nor at an edge";
  return a;
}

TEST(RayQuery, TexelsEqualTheCpuTraversalOnRandomRays) {
  MOBIRT_RAY_QUERY_ENGINE(engine, validated());
  for (const char* name : {"toaster", "fish"}) {
    SCOPED_TRACE(name);
    const Scene scene = load_scene(std::string(MOBIRT_SOURCE_DIR) + "/scenes/" + name + ".gltf");
    ASSERT_TRUE(scene.camera);
    ASSERT_FALSE(scene.lights.empty());
    engine->build(scene);
    const RayBatch rays = random_rays(scene, *scene.camera, 40000, 200, 7);
    const Agreement a = trace_and_compare(*engine, scene, rays, name);
    EXPECT_GT(a.hits, a.rays / 3);  // enough hits and lit hits for the comparison to mean something
    EXPECT_GT(a.lit, a.hits / 4);
    // Differences are rays through a shared edge or vertex (Möller-Trumbore against the driver's
    // own test) and shadow rays that graze an occluder's silhouette.
    EXPECT_GE(a.share(), 0.999);
    // The texels decode as mobirt's do, with the engine's triangle texels.
    std::vector<uint32_t> texels(rays.count());
    const Packing packing = engine->trace(rays, scene.lights, ShadowSettings{}, texels);
    DecodeStats stats;
    const SurfaceHits hits =
        decode_hits(scene, engine->triangles(), rays, texels, packing, scene.lights, ShadowSettings{}, &stats);
    EXPECT_EQ(stats.capped, 0u);
    EXPECT_GE(stats.hits, a.hits - a.prim_differs);
    EXPECT_EQ(hits.size(), rays.count());
  }
  const std::vector<std::string> messages = engine->take_debug_messages();
  EXPECT_TRUE(messages.empty()) << join(messages);
}

// --gpu-timestamps: the peer's build and pass timed on the device's clock or on the CPU's (the
// default on lavapipe, where each timestamp waits for the work), the same texels either way and a
// time for the pass in both.
TEST(RayQuery, TimedOnEitherClock) {
  const Scene scene = load_scene(std::string(MOBIRT_SOURCE_DIR) + "/scenes/toaster.gltf");
  ASSERT_TRUE(scene.camera);
  const RayBatch rays = random_rays(scene, *scene.camera, 5000, 100, 11);
  std::vector<uint32_t> texels[2];
  int made = 0;
  for (const GpuTimestamps mode : {GpuTimestamps::On, GpuTimestamps::Off}) {
    SCOPED_TRACE(gpu_timestamps_name(mode));
    RayQueryOptions options = validated();
    options.timestamps = mode;
    MOBIRT_RAY_QUERY_ENGINE(engine, options);
    AsBuildTimings build;
    engine->build(scene, &build);
    EXPECT_GT(build.wall_ms, 0.0);
    std::vector<uint32_t>& out = texels[made++];
    out.assign(rays.count(), 0u);
    RayQueryTimings timings;
    engine->trace(rays, scene.lights, ShadowSettings{}, out, &timings);
    EXPECT_GT(timings.trace_ms, 0.0);
    EXPECT_GE(timings.readback_ms, 0.0);
    const std::vector<std::string> messages = engine->take_debug_messages();
    EXPECT_TRUE(messages.empty()) << join(messages);
  }
  EXPECT_EQ(texels[0], texels[1]);
}

TEST(RayQuery, PrimaryRaysWithoutShadowsEqualTheCpu) {
  MOBIRT_RAY_QUERY_ENGINE(engine, validated());
  const Scene scene = load_scene(std::string(MOBIRT_SOURCE_DIR) + "/scenes/toaster.gltf");
  engine->build(scene);
  const RayBatch rays = primary_rays(*scene.camera, 400, 240);
  std::vector<uint32_t> texels(rays.count());
  const Packing packing = engine->trace(rays, {}, ShadowSettings{}, texels);
  const FlatKdTree tree = build_kdtree(scene.mesh.positions);
  const Agreement a = compare(texels, cpu_texels(tree, rays, {}, ShadowSettings{}, packing), packing, tree, rays);
  EXPECT_EQ(a.lit, 0u);
  EXPECT_GT(a.hits, a.rays / 2);
  EXPECT_GE(a.share(), 0.999) << a.prim_differs << " rays differ";
  EXPECT_TRUE(engine->take_debug_messages().empty());
}

// An animated scene, frame after frame: updated (the default) and built afresh, both equal to the
// CPU on every frame; updates happen only while the triangle count stays.
TEST(RayQuery, AnimatedSceneFollowsEveryFrame) {
  const AnimatedScene animation = load_animated_scene(std::string(MOBIRT_SOURCE_DIR) + "/scenes/toaster.gltf");
  ASSERT_TRUE(animation.animated());
  for (const AsBuildMode mode : {AsBuildMode::Update, AsBuildMode::Fresh}) {
    SCOPED_TRACE(mode == AsBuildMode::Update ? "update" : "fresh");
    MOBIRT_RAY_QUERY_ENGINE(engine, validated(mode));
    Scene scene;
    std::vector<uint32_t> previous;
    uint32_t changed = 0;
    for (int frame = 0; frame < 4; ++frame) {
      animation.evaluate(0.4 * frame, scene);
      AsBuildTimings build;
      engine->build(scene, &build);
      EXPECT_EQ(build.updated, mode == AsBuildMode::Update && frame > 0) << "frame " << frame;
      EXPECT_EQ(build.triangles, scene.mesh.triangle_count());
      const RayBatch rays = primary_rays(*scene.camera, 200, 120);
      std::vector<uint32_t> texels(rays.count());
      const Packing packing = engine->trace(rays, scene.lights, ShadowSettings{}, texels);
      const FlatKdTree tree = build_kdtree(scene.mesh.positions);
      const Agreement a =
          compare(texels, cpu_texels(tree, rays, scene.lights, ShadowSettings{}, packing), packing, tree, rays);
      EXPECT_GE(a.share(), 0.999) << "frame " << frame << ": " << a.prim_differs << " hits and " << a.mask_differs
                                  << " masks differ";
      if (!previous.empty()) {
        for (size_t i = 0; i < texels.size(); ++i) changed += texels[i] != previous[i];
      }
      previous = texels;
    }
    EXPECT_GT(changed, 100u) << "the toasters hop: the frames must differ";
    const std::vector<std::string> messages = engine->take_debug_messages();
    EXPECT_TRUE(messages.empty()) << join(messages);
  }
}

// A new triangle count cannot be an update: the next build starts afresh.
TEST(RayQuery, ChangedTriangleCountBuildsAfresh) {
  MOBIRT_RAY_QUERY_ENGINE(engine, validated());
  const Scene a = load_scene(std::string(MOBIRT_SOURCE_DIR) + "/scenes/fish.gltf");
  const Scene b = load_scene(std::string(MOBIRT_SOURCE_DIR) + "/scenes/toaster.gltf");
  AsBuildTimings t;
  engine->build(a, &t);
  EXPECT_FALSE(t.updated);
  engine->build(a, &t);
  EXPECT_TRUE(t.updated);
  engine->build(b, &t);
  EXPECT_FALSE(t.updated);
  const RayBatch rays = random_rays(b, *b.camera, 4000, 100, 11);
  EXPECT_GE(trace_and_compare(*engine, b, rays, "toaster after fish").share(), 0.999);
  EXPECT_TRUE(engine->take_debug_messages().empty());
}

TEST(RayQuery, EmptySceneMissesEveryRay) {
  MOBIRT_RAY_QUERY_ENGINE(engine, validated());
  Scene empty;
  empty.source = "empty";
  empty.materials.emplace_back();
  empty.lights.push_back(Light{});
  AsBuildTimings t;
  engine->build(empty, &t);
  EXPECT_EQ(t.triangles, 0u);
  Camera camera;
  camera.eye = glm::vec3(0.0f, 0.0f, 5.0f);
  camera.target = glm::vec3(0.0f);
  RayBatch rays = primary_rays(camera, 37, 5);
  rays.width = 16;  // 185 rays: 11 rows and a partial one, padded with rays that never hit
  std::vector<uint32_t> texels(rays.count(), 0xdeadbeefu);
  engine->trace(rays, empty.lights, ShadowSettings{}, texels);
  for (size_t i = 0; i < texels.size(); ++i) ASSERT_EQ(texels[i], 0u) << "ray " << i;
  // And back to a scene with triangles (4000 rays in rows of 64: a partial last row again).
  const Scene fish = load_scene(std::string(MOBIRT_SOURCE_DIR) + "/scenes/fish.gltf");
  engine->build(fish, &t);
  EXPECT_GE(trace_and_compare(*engine, fish, random_rays(fish, *fish.camera, 4000, 64, 5), "fish after empty").share(),
            0.999);
  const std::vector<std::string> messages = engine->take_debug_messages();
  EXPECT_TRUE(messages.empty()) << join(messages);
}

// The peer's whole frame (RayQueryWhittedEngine): the same primary rays, hit decoding, ray tree and
// shading pass as mobirt's Vulkan frame, only the traversal differs, so the frames agree within
// 45 dB (the rays through shared edges and grazing shadow rays are all that differs).
TEST(RayQuery, WhittedFramesEqualMobirtsVulkanFrames) {
  MOBIRT_RAY_QUERY_ENGINE(rq, validated());
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
    settings.always_rebuild = true;
    Renderer mobirt(*mobirt_backend, settings);
    Renderer shading(*shading_backend, settings);
    RayQueryWhittedEngine peer(*rq, shading);
    Scene scene;
    for (const double t : {0.0, 0.7}) {
      SCOPED_TRACE(std::string(name) + " at " + std::to_string(t) + " s");
      animation.evaluate(t, scene);
      ASSERT_TRUE(scene.camera);
      FrameTimings want_t, got_t;
      const Image want = mobirt.render(scene, *scene.camera, &want_t);
      const Image got = render_whitted(scene, *scene.camera, settings, peer, &got_t);
      test::expect_peer_frame_matches_mobirts(want, want_t, got, got_t, std::string("ray_query_frame_") + name, 0.002);
      EXPECT_GT(got_t.sum.hits, got_t.primary_rays() / 4);
      EXPECT_GT(got_t.sum.shadow_rays, 0u);
      EXPECT_TRUE(got_t.tree_rebuilt);
      EXPECT_EQ(peer.last_build().triangles, scene.mesh.triangle_count());
      bounced += got_t.generations.size() > 1;
    }
  }
  EXPECT_GT(bounced, 0u) << "no scene had secondary rays: depth 2 was not tested";
  for (Backend* b : {mobirt_backend.get(), shading_backend.get()}) {
    const std::vector<std::string> messages = b->take_debug_messages();
    EXPECT_TRUE(messages.empty()) << join(messages);
  }
  const std::vector<std::string> messages = rq->take_debug_messages();
  EXPECT_TRUE(messages.empty()) << join(messages);
}

TEST(RayQuery, RefusesMediumPrecisionAndTraceBeforeBuild) {
  MOBIRT_RAY_QUERY_ENGINE(engine, validated());
  RayBatch rays = primary_rays(Camera{}, 4, 4);
  std::vector<uint32_t> texels(rays.count());
  try {
    engine->trace(rays, {}, ShadowSettings{}, texels);
    ADD_FAILURE() << "trace before build";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::Internal) << e.what();
  }
  engine->build(load_scene(std::string(MOBIRT_SOURCE_DIR) + "/scenes/fish.gltf"));
  ShadowSettings medium;
  medium.ray_test.precision = Precision::Medium;
  try {
    engine->trace(rays, {}, medium, texels);
    ADD_FAILURE() << "mediump accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::Unsupported);
    EXPECT_NE(std::string(e.what()).find("mediump"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(engine->take_debug_messages().empty());
}

// The checker lists by name what a shader breaks: nothing for mobirt's passes, the scene as an
// acceleration structure and the ray queries for the peer's, which mobirt's backend would refuse.
TEST(RayQuery, ConstraintListIsEmptyForMobirtsPassesOnly) {
  EXPECT_TRUE(es2_constraints_broken(spirv_trace_frag).empty()) << join(es2_constraints_broken(spirv_trace_frag));
  EXPECT_TRUE(es2_constraints_broken(spirv_shade_frag).empty()) << join(es2_constraints_broken(spirv_shade_frag));
  EXPECT_EQ(es2_constraints_broken(spirv_ray_query_frag), RayQueryEngine::broken_constraints());
  try {
    check_es2_constraints("ray_query.frag", spirv_ray_query_frag);
    ADD_FAILURE() << "the ray-query pass passed the ES 2.0 check";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::Constraint);
    EXPECT_NE(std::string(e.what()).find("acceleration structure"), std::string::npos) << e.what();
  }
  const uint32_t not_spirv[] = {1, 2, 3, 4, 5, 6};
  EXPECT_EQ(es2_constraints_broken(not_spirv), std::vector<std::string>{"is not a valid SPIR-V module"});
}

// The peer breaks the OpenGL ES 2.0 constraints, and the checker names them (no device needed).
TEST(RayQuery, ConstraintCheckerNamesWhatThePeerBreaks) {
  const std::vector<std::string> broken = RayQueryEngine::broken_constraints();
  ASSERT_EQ(broken.size(), 2u) << join(broken);
  EXPECT_NE(broken[0].find("reads an acceleration structure"), std::string::npos) << broken[0];
  EXPECT_NE(broken[1].find("ray queries"), std::string::npos) << broken[1];
  std::string why;
  std::unique_ptr<RayQueryEngine> engine = try_engine(RayQueryOptions{}, why);
  if (!engine) {
    // Where the driver lacks them, the reason names the extension (and, on lavapipe, the Mesa that has it).
    EXPECT_NE(why.find("VK_KHR_"), std::string::npos) << why;
    GTEST_SKIP() << why;
  }
  EXPECT_EQ(RayQueryEngine::unavailable_reason(), "");
  const std::string info = join(engine->info());
  EXPECT_NE(info.find("breaks the OpenGL ES 2.0 constraints: reads an acceleration structure"), std::string::npos)
      << info;
  EXPECT_NE(info.find("PREFER_FAST_BUILD"), std::string::npos) << info;
}

}  // namespace
}  // namespace mobirt
