// Whole frames of the full Whitted path: a texture-mapped quad through the atlas reproduces its
// texture, and an animated scene rebuilds its tree and changes the image from frame to frame.
#include <gtest/gtest.h>

#include <OpenImageIO/imageio.h>

#include <cmath>
#include <map>
#include <vector>

#include "backend/backend.h"
#include "raytree/packing.h"
#include "render/cpu_render.h"
#include "render/renderer.h"
#include "scene/animation.h"
#include "scene/atlas.h"
#include "scene/loader.h"
#include "scene/texture_images.h"
#include "test_scenes.h"
#include "test_support.h"
#include "vulkan_fixture.h"

namespace mobirt {
namespace {

class WhittedFrame : public test::VulkanTest {};

// A 64x32 texture on a quad that fills a 64x32 image exactly, lit by ambient light only: every
// pixel shows its texel, decoded from sRGB.
TEST_F(WhittedFrame, TextureMappedQuadShowsItsTexture) {
  const int w = 64, h = 32;
  const std::filesystem::path png = test::temp_dir() / "texture.png";
  std::vector<uint8_t> rgb(size_t(w * h * 3));
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      uint8_t* p = &rgb[size_t((y * w + x) * 3)];
      p[0] = uint8_t(x * 4);
      p[1] = uint8_t(y * 8);
      p[2] = ((x / 8 + y / 8) % 2) ? 220 : 30;
    }
  }
  auto out = OIIO::ImageOutput::create(png.string());
  ASSERT_TRUE(out && out->open(png.string(), OIIO::ImageSpec(w, h, 3, OIIO::TypeDesc::UINT8)));
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, rgb.data()));
  out->close();

  Scene s = test::base_scene("textured-quad");
  Material m;
  m.diffuse = glm::vec3(1.0f);
  m.ambient = 1.0f;
  m.texture = 0;
  s.materials = {m};
  TextureRef t;
  t.name = "texture";
  t.path = png.string();
  t.wrap_s = t.wrap_t = TextureWrap::ClampToEdge;
  s.textures = {t};
  // The quad spans x in [-2, 2], y in [-1, 1] at z = 0; uv (0, 0) at the top left.
  const glm::vec3 a{-2, 1, 0}, b{-2, -1, 0}, c{2, -1, 0}, d{2, 1, 0};
  const glm::vec2 ua{0, 0}, ub{0, 1}, uc{1, 1}, ud{1, 0};
  test::add_triangle(s, a, b, c, 0);
  test::add_triangle(s, a, c, d, 0);
  s.mesh.texcoords = {ua, ub, uc, ua, uc, ud};
  // A camera whose view fits the quad exactly: tan(fov/2) = 1 / distance.
  const float distance = 4.0f;
  const Camera camera{{0, 0, distance}, {0, 0, 0}, {0, 1, 0}, 2.0f * std::atan(1.0f / distance), 0.0f};
  RenderSettings settings;
  settings.width = w;
  settings.height = h;
  Renderer renderer(*backend, settings);
  const Image image = renderer.render(s, camera);
  const TextureImage source = decode_image_file(png.string(), "texture");
  double worst = 0.0;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const uint32_t texel = source.pixels[size_t(y * w + x)];
      for (int ch = 0; ch < 3; ++ch) {
        const float expected = srgb_to_linear(float((texel >> (8 * ch)) & 0xFFu) / 255.0f);
        worst = std::max(worst, double(std::abs(image.at(x, y)[ch] - expected)));
      }
    }
  }
  // Pixel centres meet texel centres: bilinear filtering returns the texel; 8-bit output rounds.
  EXPECT_LE(worst, 1.5 / 255.0) << "largest difference from the texture";
}

// Two instants of an animated scene: the tree is rebuilt for each and the image changes.
TEST_F(WhittedFrame, AnimationRebuildsTheTreeAndChangesTheImage) {
  const AnimatedScene animation = load_animated_scene(MOBIRT_SOURCE_DIR "/scenes/toaster.gltf");
  ASSERT_TRUE(animation.animated());
  RenderSettings settings;
  settings.width = 100;
  settings.height = 60;
  Renderer renderer(*backend, settings);
  Scene scene;
  FrameTimings t0, t1;
  animation.evaluate(0.0, scene);
  const std::vector<glm::vec3> positions0 = scene.mesh.positions;
  const Image a = renderer.render(scene, *scene.camera, &t0);
  animation.evaluate(0.7, scene);
  const Image b = renderer.render(scene, *scene.camera, &t1);
  EXPECT_NE(positions0, scene.mesh.positions);
  EXPECT_GT(t0.build_ms, 0.0);
  EXPECT_GT(t1.build_ms, 0.0);
  const ImageDiff d = compare_images(a, b);
  EXPECT_GT(d.share_over, 0.01) << "the toasters moved, so should the image";
  // And each frame is still the CPU expectation of that instant.
  const ImageDiff e = compare_images(b, render_on_cpu(scene, *scene.camera, settings));
  EXPECT_GE(e.psnr, 40.0);
  EXPECT_LE(e.share_over, 0.005);
}

// One renderer through scenes of other sizes, back and forth: its textures grow and shrink and are
// written in place again (the tree's arrays with the light buffers after them, the shading inputs:
// Backend::begin_write). A scene drawn again after others gives its first image bit for bit, and
// the first frame after another scene equals a fresh renderer's. Rasterized primaries with light
// buffers (depth 0: no kd-tree) and traced bounces with a tree (depth 2).
TEST_F(WhittedFrame, ARendererReusedAcrossScenesDrawsWhatAFreshOneDraws) {
  const Scene fish = load_scene(MOBIRT_SOURCE_DIR "/scenes/fish.gltf");
  const Scene toaster = load_scene(MOBIRT_SOURCE_DIR "/scenes/toaster.gltf");
  const Scene marbles = load_scene(MOBIRT_SOURCE_DIR "/scenes/marbles.gltf");
  for (const int depth : {0, 2}) {
    RenderSettings settings;
    settings.width = 80;
    settings.height = 48;
    settings.depth = depth;
    Renderer reused(*backend, settings);
    std::map<const Scene*, Image> first;
    const std::vector<const Scene*> scenes = depth == 0 ? std::vector<const Scene*>{&fish, &toaster, &marbles, &fish, &toaster}
                                                        : std::vector<const Scene*>{&toaster, &fish, &toaster};
    for (size_t frame = 0; frame < scenes.size(); ++frame) {
      const Scene& scene = *scenes[frame];
      SCOPED_TRACE("depth " + std::to_string(depth) + ", frame " + std::to_string(frame) + ": " + scene.source);
      Image image = reused.render(scene, *scene.camera);
      EXPECT_GE(reused.light_buffers_used(), 1) << "the light buffers were written, not only the tree";
      if (frame == 1) {
        EXPECT_EQ(compare_images(image, Renderer(*backend, settings).render(scene, *scene.camera)).max_error, 0.0f);
      }
      const auto [it, new_scene] = first.emplace(&scene, image);
      if (!new_scene) {
        EXPECT_EQ(compare_images(image, it->second).max_error, 0.0f) << "drawn again";
      }
    }
  }
}

// The shading pass shades the hits and one miss, whose texel colours every miss: a quad over the
// left half of the view, a background on the right; all hits, and all misses, as edge cases; 8-
// and 16-bit colour. 96x48 rays: hits in five chunks of the compaction. Every miss shows the
// background as the pass rounds it, and the image is the CPU's expectation (a point light close
// to the quad shades every hit differently, so a hit shaded into another's pixel would show).
TEST_F(WhittedFrame, ShadingPassShadesTheHitsAndOneMiss) {
  const int w = 96, h = 48;
  const float distance = 4.0f;
  const Camera camera{{0, 0, distance}, {0, 0, 0}, {0, 1, 0}, 2.0f * std::atan(1.0f / distance), 0.0f};
  for (const ColourDepth depth : {ColourDepth::Bits8, ColourDepth::Bits16}) {
    // The view spans x in [-2, 2]; quads from the left to x = `right`.
    for (const float right : {0.0f, 2.5f, -3.0f}) {
      SCOPED_TRACE(std::to_string(int(depth)) + " bits, quad to x = " + std::to_string(right));
      Scene s = test::base_scene("half-quad");
      s.background = glm::vec3(0.2f, 0.4f, 0.6f);  // whole steps of 8 and 16 bits: no rounding ties
      Light light;
      light.position = glm::vec3(-0.5f, 0.3f, 1.0f);
      light.intensity = 2.0f;
      s.lights = {light};
      const float left = right > -2.0f ? -2.5f : -4.0f;  // right = -3: the quad is out of view
      test::add_triangle(s, {left, 1.5f, 0}, {left, -1.5f, 0}, {right, -1.5f, 0}, 1);
      test::add_triangle(s, {left, 1.5f, 0}, {right, -1.5f, 0}, {right, 1.5f, 0}, 1);
      RenderSettings settings;
      settings.width = w;
      settings.height = h;
      settings.depth = 0;
      settings.colour = depth;
      Renderer renderer(*backend, settings);
      FrameTimings t;
      const Image image = renderer.render(s, camera, &t);
      ASSERT_EQ(t.generations.size(), 1u);
      const GenerationTimings& g = t.generations[0];
      const uint32_t misses = g.rays - g.hits;
      EXPECT_EQ(g.shaded, g.hits + (misses > 0 ? 1u : 0u));
      if (right == 0.0f) {
        EXPECT_EQ(g.hits, uint32_t(w * h / 2)) << "the left half hit";
      } else if (right == 2.5f) {
        EXPECT_EQ(misses, 0u);
      } else {
        EXPECT_EQ(g.hits, 0u);
      }
      const glm::vec3 background = quantize_colour(s.background, depth);
      int background_pixels = 0;
      for (int y = 0; y < h; ++y) {
        for (int x = 0; x < w; ++x) {
          if (image.at(x, y) == background) ++background_pixels;
        }
      }
      EXPECT_EQ(background_pixels, int(misses));
      const ImageDiff e = compare_images(image, render_on_cpu(s, camera, settings));
      EXPECT_GE(e.psnr, 40.0);
      EXPECT_LE(e.share_over, 0.005);
    }
  }
}

// Small generations walked on the CPU (RenderSettings::cpu_walks) against every generation in a
// traversal pass: the same image bit for bit and the same walks counted (so that the next frame's
// tree is the same), on both APIs, the toaster posed over frames (its shadow rays through light
// buffers) and the fish (glass), under both ray tests (the light buffers' CPU test takes the
// pass's). Generations the CPU walked read no traversal result back from the GPU. Under mediump
// every generation runs its pass.
class CpuWalks : public test::PerBackendTest {};

TEST_P(CpuWalks, SmallGenerationsOnTheCpuDrawWhatThePassDraws) {
  for (const char* name : {"toaster.gltf", "fish.gltf"}) {
    const AnimatedScene animation = load_animated_scene(std::string(MOBIRT_SOURCE_DIR "/scenes/") + name);
    for (const RayTest test : {RayTest{IntersectTest::MollerTrumbore, Precision::High},
                               RayTest{IntersectTest::Watertight, Precision::High},
                               RayTest{IntersectTest::MollerTrumbore, Precision::Medium}}) {
      SCOPED_TRACE(std::string(name) + (test.test == IntersectTest::Watertight ? ", watertight" : ", mt") +
                   (test.precision == Precision::Medium ? ", mediump" : ", highp"));
      RenderSettings settings;
      settings.width = 96;
      settings.height = 64;
      settings.depth = 2;
      settings.shadow_rays.ray_test = test;
      settings.cpu_walks = 0;
      RenderSettings on_cpu = settings;
      on_cpu.cpu_walks = 1 << 24;
      Renderer passes(*backend, settings);
      Renderer cpu(*backend, on_cpu);
      uint64_t walked_on_cpu = 0;
      Scene posed;
      for (int frame = 0; frame < 2; ++frame) {
        SCOPED_TRACE("frame " + std::to_string(frame));
        animation.evaluate(0.4 * frame, posed);
        FrameTimings a, b;
        const Image ia = passes.render(posed, *posed.camera, &a);
        const Image ib = cpu.render(posed, *posed.camera, &b);
        EXPECT_EQ(compare_images(ia, ib).max_error, 0.0f);
        EXPECT_EQ(a.sum.walks, b.sum.walks);
        EXPECT_EQ(a.sum.hits, b.sum.hits);
        EXPECT_EQ(a.sum.shadow_rays, b.sum.shadow_rays);
        EXPECT_EQ(a.sum.cpu_walked, 0u);
        ASSERT_EQ(a.generations.size(), b.generations.size());
        for (size_t g = 1; g < b.generations.size(); ++g) {
          if (b.generations[g].mirrored > 0) continue;  // drawn by the mirror raster
          EXPECT_EQ(b.generations[g].cpu_walked, test.precision == Precision::High ? b.generations[g].rays : 0u);
          if (b.generations[g].cpu_walked == 0) continue;
          // The pass read back a texel a ray; the CPU walk nothing (both read back the shading).
          EXPECT_EQ(a.generations[g].bytes_read - b.generations[g].bytes_read, 4u * uint64_t(a.generations[g].rays));
          walked_on_cpu += b.generations[g].rays;
        }
      }
      if (test.precision == Precision::High) {
        EXPECT_GT(walked_on_cpu, 0u) << "no generation was walked on the CPU";
      }
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Backends, CpuWalks, ::testing::Values(test::Api::Vulkan, test::Api::Gles),
                         test::api_param_name);

// One shading pass a frame (ShadingPasses::Frame, the default) against one a generation: the same
// image bit for bit, on both APIs, 8- and 16-bit colour, the fish's three generations (mirror and
// glass). A new renderer's first frame opens the inputs' textures with room for the primary hits
// alone, so its later generations do not fit: the generations queued so far are shaded by a pass
// of their own first; the next frames open with the last frame's room (one pass).
class FrameShading : public test::PerBackendTest {};

TEST_P(FrameShading, OnePassAFrameDrawsWhatAPassAGenerationDraws) {
  const Scene fish = load_scene(MOBIRT_SOURCE_DIR "/scenes/fish.gltf");
  for (const ColourDepth colour : {ColourDepth::Bits8, ColourDepth::Bits16}) {
    SCOPED_TRACE(std::to_string(int(colour)) + "-bit colour");
    RenderSettings settings;
    settings.width = 96;
    settings.height = 64;
    settings.depth = 2;
    settings.colour = colour;
    RenderSettings per_generation = settings;
    per_generation.shading = ShadingPasses::Generation;
    Renderer at_end(*backend, settings);
    Renderer each(*backend, per_generation);
    for (int frame = 0; frame < 3; ++frame) {
      SCOPED_TRACE("frame " + std::to_string(frame));
      FrameTimings t_end, t_each;
      const size_t passes_end = at_end.shading_passes(), passes_each = each.shading_passes();
      const Image a = at_end.render(fish, *fish.camera, &t_end);
      const Image b = each.render(fish, *fish.camera, &t_each);
      EXPECT_EQ(compare_images(a, b).max_error, 0.0f);
      ASSERT_EQ(t_end.generations.size(), 3u) << "the fish has three generations";
      ASSERT_EQ(t_each.generations.size(), 3u);
      EXPECT_EQ(each.shading_passes() - passes_each, 3u);
      const size_t passes = at_end.shading_passes() - passes_end;
      if (frame == 0) {
        EXPECT_GE(passes, 2u) << "the first frame's later generations did not fit: shaded early";
      } else {
        EXPECT_EQ(passes, 1u);
      }
      // Every generation's hits shaded, and one miss a pass for all the misses before it.
      uint32_t hits = 0, rays = 0;
      for (size_t k = 0; k < 3; ++k) {
        EXPECT_EQ(t_end.generations[k].hits, t_each.generations[k].hits);
        EXPECT_GE(t_end.generations[k].shaded, t_end.generations[k].hits);
        if (t_end.generations[k].shaded > 0) {
          EXPECT_GT(t_end.generations[k].shade_ms, 0.0) << "a share of the pass that shaded it";
        }
        hits += t_end.generations[k].hits;
        rays += t_end.generations[k].rays;
      }
      ASSERT_LT(hits, rays) << "the fish's rays miss too";
      EXPECT_GE(t_end.sum.shaded, hits + 1);
      EXPECT_LE(t_end.sum.shaded, hits + passes) << "a miss texel a pass at most";
      EXPECT_EQ(t_end.sum.bytes_read - t_each.sum.bytes_read,
                uint64_t(colour == ColourDepth::Bits16 ? 8 : 4) * (int64_t(t_end.sum.shaded) - int64_t(t_each.sum.shaded)));
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Backends, FrameShading, ::testing::Values(test::Api::Vulkan, test::Api::Gles),
                         test::api_param_name);

}  // namespace
}  // namespace mobirt
