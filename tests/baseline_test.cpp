// The Embree baseline of `mobirt bench`: it must render the same frame as mobirt's own CPU path
// (same rays, shadow rays, shading and ray tree), or the benchmark ratios compare different work.
#include <gtest/gtest.h>

#include <random>

#include "baseline/embree_engine.h"
#include "render/cpu_render.h"
#include "render/whitted.h"
#include "scene/loader.h"
#include "test_scenes.h"
#include "test_support.h"

namespace mobirt {
namespace {

// Share of rays whose closest hit (primitive) the two engines agree on.
double hit_agreement(const CpuRayEngine& a, const CpuRayEngine& b, const RayBatch& rays) {
  uint32_t same = 0;
  for (uint32_t i = 0; i < rays.count(); ++i) same += a.closest(rays.ray(i)).prim == b.closest(rays.ray(i)).prim;
  return double(same) / rays.count();
}

TEST(Baseline, EmbreeFindsTheBruteForceClosestHit) {
  const Scene scene = test::random_soup_scene(3000);
  EmbreeEngine embree(EmbreeOptions{2, true});
  embree.build(scene);
  KdTreeEngine kd;
  kd.build(scene);
  std::mt19937 rng(3);
  int agree = 0, hits = 0;
  const int n = 4000;
  for (int i = 0; i < n; ++i) {
    const glm::vec3 eye(0, 2, 9);
    const glm::vec3 target = 3.0f * test::random_direction(rng);  // inside the soup's cube, or near it
    const Ray ray{eye, target - eye, 0.0f, kInfinity};
    const Hit want = brute_force(kd.tree(), ray);
    const Hit got = embree.closest(ray);
    hits += want.valid();
    if (got.prim == want.prim) {
      ++agree;
      if (want.valid()) {
        EXPECT_NEAR(got.t, want.t, 1e-4f * want.t);
        EXPECT_NEAR(got.u, want.u, 1e-3f);
        EXPECT_NEAR(got.v, want.v, 1e-3f);
      }
    }
    EXPECT_EQ(embree.occluded(ray), want.valid()) << "ray " << i;
  }
  EXPECT_GT(hits, n / 2);
  EXPECT_GE(agree, n - 2);  // ties on shared edges may go either way
}

TEST(Baseline, EmbreeAndKdTreeRenderTheSameFrame) {
  for (const char* name : {"toaster", "fish"}) {
    SCOPED_TRACE(name);
    const Scene scene = load_scene(std::string(MOBIRT_SOURCE_DIR) + "/scenes/" + name + ".gltf");
    RenderSettings settings;
    settings.width = 160;
    settings.height = 96;
    settings.depth = 2;
    EmbreeEngine embree(EmbreeOptions{2, true});
    KdTreeEngine kd(settings.kd);
    FrameTimings te, tk;
    const Image a = render_whitted_cpu(scene, *scene.camera, settings, embree, 2, &te);
    const Image b = render_whitted_cpu(scene, *scene.camera, settings, kd, 2, &tk);
    const ImageDiff d = compare_images(a, b);
    EXPECT_GT(d.psnr, 45.0);
    EXPECT_LT(d.share_over, 0.002);
    EXPECT_EQ(te.primary_rays(), tk.primary_rays());
    EXPECT_EQ(te.generations.size(), tk.generations.size());
    EXPECT_NEAR(double(te.sum.rays), double(tk.sum.rays), 0.002 * double(tk.sum.rays));
    EXPECT_NEAR(double(te.sum.shadow_rays), double(tk.sum.shadow_rays), 0.002 * double(tk.sum.shadow_rays) + 2);
    EXPECT_GT(te.sum.shadow_rays, 0u);
    EXPECT_GE(hit_agreement(embree, kd, primary_rays(*scene.camera, settings.width, settings.height)), 0.999);
  }
}

TEST(Baseline, RenderOnCpuIsTheKdTreeEngine) {
  const Scene scene = test::box_grid_scene();
  RenderSettings settings;
  settings.width = 80;
  settings.height = 48;
  KdTreeEngine kd(settings.kd);
  const ImageDiff d = compare_images(render_on_cpu(scene, *scene.camera, settings),
                                     render_whitted_cpu(scene, *scene.camera, settings, kd, 1));
  EXPECT_EQ(d.max_error, 0.0);  // any thread count, same image
}

TEST(Baseline, EmbreeRebuildsWhenTrianglesMoveAndHandlesEmptyScenes) {
  Scene scene = test::box_grid_scene();
  EmbreeEngine embree(EmbreeOptions{1, true});
  embree.build(scene);
  const float lowest = embree.triangles().bounds.lo.y;
  const Ray down{glm::vec3(0.01f, 5, 0.01f), glm::vec3(0, -1, 0), 0.0f, kInfinity};
  const Hit before = embree.closest(down);
  ASSERT_TRUE(before.valid());
  for (glm::vec3& p : scene.mesh.positions) p.y -= 1.0f;  // same count: the same buffers, refilled
  embree.build(scene);
  const Hit after = embree.closest(down);
  ASSERT_TRUE(after.valid());
  EXPECT_NEAR(after.t, before.t + 1.0f, 1e-4f);
  EXPECT_EQ(embree.triangles().bounds.lo.y, lowest - 1.0f);

  Scene empty = test::base_scene("empty");
  embree.build(empty);
  EXPECT_FALSE(embree.closest(down).valid());
  EXPECT_FALSE(embree.occluded(down));
  RenderSettings settings;
  settings.width = 8;
  settings.height = 8;
  const Image image = render_whitted_cpu(empty, Camera{}, settings, embree, 2);
  for (const glm::vec3& p : image.pixels) EXPECT_EQ(p, empty.background);
}

// An engine that hands back t and barycentrics instead of surface records (as a compute pass or
// ray queries would): the frame loop must make the same records from them as the engine does.
class HitsFormEngine final : public WhittedEngine {
 public:
  explicit HitsFormEngine(CpuRayEngine& inner) : inner_(inner) {}
  const char* name() const override { return "hits form"; }
  void begin_frame(const Scene& scene, const RenderSettings& settings, FrameTimings& frame) override {
    settings_ = settings;
    inner_.begin_frame(scene, settings, frame);
  }
  const FlatKdTree& tree() const override { return inner_.tree(); }
  TracedGeneration trace(const Scene& scene, const RayBatch& rays, GenerationTimings&) override {
    TracedGeneration traced;
    traced.form = TracedGeneration::Form::Hits;
    for (uint32_t i = 0; i < rays.count(); ++i) {
      const Ray ray = rays.ray(i);
      const Hit h = inner_.closest(ray);
      traced.hits.push_back(h);
      traced.masks.push_back(!h.valid() || !settings_.shadows
                                 ? 0u
                                 : shadow_mask_with(inner_.tree(), scene.lights, h.prim, ray, h.t,
                                                    settings_.shadow_rays, [&](const Ray& shadow) {
                                                      ++traced.shadow_rays;
                                                      return inner_.occluded(shadow);
                                                    }));
    }
    return traced;
  }
  std::vector<glm::vec3> shade(const Scene& scene, const RayBatch& rays, const SurfaceHits& hits,
                               GenerationTimings& g) override {
    return inner_.shade(scene, rays, hits, g);
  }

 private:
  CpuRayEngine& inner_;
  RenderSettings settings_;
};

TEST(Baseline, TheFrameLoopDecodesHitRecordsAsTheEngineDoes) {
  const Scene scene = load_scene(std::string(MOBIRT_SOURCE_DIR) + "/scenes/toaster.gltf");
  RenderSettings settings;
  settings.width = 96;
  settings.height = 64;
  settings.depth = 2;
  EmbreeEngine embree(EmbreeOptions{2, true});  // its surface records come from t and barycentrics
  FrameTimings own, from_hits;
  const Image a = render_whitted_cpu(scene, *scene.camera, settings, embree, 2, &own);
  HitsFormEngine hits_form(embree);
  const Image b = render_whitted(scene, *scene.camera, settings, hits_form, &from_hits);
  EXPECT_EQ(compare_images(a, b).max_error, 0.0);
  EXPECT_EQ(own.sum.rays, from_hits.sum.rays);
  EXPECT_EQ(own.sum.hits, from_hits.sum.hits);
  EXPECT_GT(from_hits.sum.hits, 0u);
  EXPECT_EQ(own.sum.shadow_rays, from_hits.sum.shadow_rays);
}

}  // namespace
}  // namespace mobirt
