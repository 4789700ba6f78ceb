// Shaders specialised to the scene (light count, texture count, packing) render the same image as
// general ones sized for the most a pass supports; the specialised ones only drop work.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "render/renderer.h"
#include "scene/loader.h"
#include "test_scenes.h"
#include "test_support.h"
#include "vulkan_fixture.h"

namespace mobirt {
namespace {

class Specialisation : public test::VulkanTest {};

void expect_same_image(Backend& backend, const Scene& scene, const Camera& camera, int width,
                       int height, int depth, bool shadows, const std::string& what) {
  SCOPED_TRACE(what);
  // The traversal pass of the traced primaries, and the passes of the default (--primary auto:
  // rasterized primaries and the shadow pass from their hits at these sizes).
  for (PrimaryHits primary : {PrimaryHits::Trace, PrimaryHits::Auto}) {
  SCOPED_TRACE(primary_hits_name(primary));
  RenderSettings settings;
  settings.width = width;
  settings.height = height;
  settings.depth = depth;
  settings.shadows = shadows;
  settings.primary = primary;
  Renderer specialised(backend, settings);
  settings.specialize = false;
  Renderer general(backend, settings);
  const Image a = specialised.render(scene, camera);
  const Image b = general.render(scene, camera);
  const ImageDiff d = compare_images(a, b, 0.5f / 255.0f);
  EXPECT_LE(d.max_error, 1.0 / 255.0 + 1e-6) << "PSNR " << d.psnr;
  EXPECT_LE(d.share_over, 0.001) << "share of pixels that differ";
  if (d.max_error > 1.0 / 255.0 + 1e-6) {
    write_image(test::output_path(what + "-diff.png").string(), difference_image(a, b));
  }
  }
}

TEST_F(Specialisation, ProjectScenesRenderTheSameImage) {
  for (const char* name : {"default", "toaster", "marbles", "fish"}) {
    const Scene scene = load_scene(std::string(MOBIRT_SOURCE_DIR "/scenes/") + name + ".gltf");
    ASSERT_TRUE(scene.camera);
    for (int depth : {0, 2}) {
      expect_same_image(*backend, scene, *scene.camera, 120, 72, depth, true,
                        std::string(name) + "-depth" + std::to_string(depth));
    }
    expect_same_image(*backend, scene, *scene.camera, 120, 72, 0, false, std::string(name) + "-noshadows");
  }
}

TEST_F(Specialisation, NineLightsUseTheWidePackingInBothVariants) {
  const Scene scene = test::nine_lights_scene();
  expect_same_image(*backend, scene, *scene.camera, 96, 64, 0, true, "nine-lights");
}

}  // namespace
}  // namespace mobirt

namespace mobirt {
namespace {

// The pipeline cache goes to disk when the backend closes (whole, by rename) and comes back on the
// next start; a file from another device or a broken one is ignored, never handed to the driver.
TEST(PipelineCache, SavedOnCloseAndReloaded) {
  const std::filesystem::path dir = test::temp_dir();
  VulkanOptions options{test::validated_options()};
  options.pipeline_cache_dir = dir.string();
  const Scene scene = test::box_grid_scene();
  RenderSettings settings;
  settings.width = 32;
  settings.height = 24;
  for (int run = 0; run < 2; ++run) {
    auto backend = create_vulkan_backend(options);
    {
      Renderer renderer(*backend, settings);
      renderer.render(scene, *scene.camera);
    }
    EXPECT_TRUE(backend->take_debug_messages().empty());
  }
  std::vector<std::filesystem::path> files;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) files.push_back(entry.path());
  ASSERT_EQ(files.size(), 1u) << "one cache file, no temporary left";
  EXPECT_EQ(files[0].filename().string().rfind("pipelines-", 0), 0u);
  EXPECT_GE(std::filesystem::file_size(files[0]), 32u);  // at least VkPipelineCacheHeaderVersionOne
  // A corrupt file is ignored.
  { std::ofstream(files[0], std::ios::binary | std::ios::trunc) << "not a pipeline cache"; }
  auto backend = create_vulkan_backend(options);
  EXPECT_TRUE(backend->take_debug_messages().empty());
}

}  // namespace
}  // namespace mobirt

namespace mobirt {
namespace {

class PassesNotNeeded : public test::VulkanTest {};

// Work a scene does not need is not done: a static scene keeps its kd-tree, an opaque scene makes
// one generation, a scene without lights casts no shadow rays.
TEST_F(PassesNotNeeded, StaticTreeKeptOpaqueSceneOneGenerationNoLightsNoShadowRays) {
  Scene scene = test::box_grid_scene();
  RenderSettings settings;
  settings.width = 48;
  settings.height = 32;
  settings.depth = 3;
  Renderer renderer(*backend, settings);
  FrameTimings first, second;
  const Image a = renderer.render(scene, *scene.camera, &first);
  const Image b = renderer.render(scene, *scene.camera, &second);
  EXPECT_TRUE(first.tree_rebuilt);
  EXPECT_FALSE(second.tree_rebuilt);
  EXPECT_EQ(compare_images(a, b).max_error, 0.0);
  EXPECT_EQ(first.generations.size(), 1u) << "no mirrors or glass: no second generation";
  EXPECT_GT(first.sum.shadow_rays, 0u);
  // Moving one triangle rebuilds; --always-rebuild rebuilds anyway.
  scene.mesh.positions[0].y += 0.01f;
  FrameTimings moved;
  renderer.render(scene, *scene.camera, &moved);
  EXPECT_TRUE(moved.tree_rebuilt);
  settings.always_rebuild = true;
  Renderer always(*backend, settings);
  FrameTimings x, y;
  always.render(scene, *scene.camera, &x);
  always.render(scene, *scene.camera, &y);
  EXPECT_TRUE(y.tree_rebuilt);
  // No lights: no shadow rays at all.
  scene.lights.clear();
  FrameTimings dark;
  renderer.render(scene, *scene.camera, &dark);
  EXPECT_EQ(dark.sum.shadow_rays, 0u);
}

}  // namespace
}  // namespace mobirt
