// Vulkan and OpenGL ES 2.0 side by side. The same kd-tree, texel layouts, ray-tree manager and hit
// decoding feed both; only the backend differs. Per backend (one test body, parameterised over
// {vulkan, gles}): the traversal pass agrees with the CPU traversal and the image with the CPU
// expectation. Across backends, for every project scene and effect level: the same hit index and
// shadow mask on >= 99.9% of rays, final images within 1/255 (2/255 with textures: the filters
// differ) on >= 99.5% of pixels and PSNR >= 45 dB; a failing comparison writes its diff image and names it.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <sstream>
#include <string>
#include <utility>
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

enum class Api { Vulkan, Gles };

const char* api_name(Api api) { return api == Api::Vulkan ? "vulkan" : "gles"; }

// Validation on: the Khronos layer on Vulkan, a KHR_debug context on GLES.
std::unique_ptr<Backend> make_backend(Api api) {
  const BackendOptions options = test::validated_options();
  return api == Api::Vulkan ? create_vulkan_backend(options) : create_gles_backend(options);
}

void expect_no_messages(Backend& backend, const char* what) {
  const std::vector<std::string> messages = backend.take_debug_messages();
  EXPECT_TRUE(messages.empty()) << what << " debug messages:\n" << test::join(messages);
}

Camera scene_camera(const Scene& scene, int width, int height) {
  return scene.camera ? *scene.camera : frame_box(scene.bounds(), 0.8f, float(width) / float(height));
}

// ---- One test body per backend ----------------------------------------------------------------

class PerBackend : public ::testing::TestWithParam<Api> {
 protected:
  void SetUp() override { backend = make_backend(GetParam()); }
  void TearDown() override {
    if (backend) expect_no_messages(*backend, api_name(GetParam()));
  }
  std::unique_ptr<Backend> backend;
};

// The traversal pass against the CPU traversal of the same tree: same primitive (or a tie at the
// same distance, or a grazing edge) and the same shadow mask.
void check_traversal_against_cpu(Backend& backend, const Scene& scene, int width, int height,
                                 RenderSettings settings = {}) {
  settings.width = width;
  settings.height = height;
  const RayTest& test = settings.shadow_rays.ray_test;
  Renderer renderer(backend, settings);
  const FlatKdTree tree = build_kdtree(scene.mesh.positions, settings.kd);
  const RayBatch rays = primary_rays(scene_camera(scene, width, height), width, height);
  const TraceResult gpu = renderer.trace(scene, tree, rays);
  size_t same = 0, tolerated = 0, capped = 0, masks = 0, masks_equal = 0;
  for (uint32_t i = 0; i < rays.count(); ++i) {
    const Ray ray = rays.ray(i);
    const TraceTexel texel = unpack_trace(gpu.packing, gpu.texels[i]);
    if (texel.capped) {
      ++capped;
      continue;
    }
    const Hit cpu = traverse(tree, ray, settings.stack_depth, test);
    const int32_t prim = texel.hit() ? texel.prim() : -1;
    if (prim == cpu.prim) {
      ++same;
      if (cpu.valid()) {
        ++masks;
        const uint32_t mask =
            shadow_mask(tree, scene.lights, cpu.prim, ray, cpu.t, settings.shadow_rays, settings.stack_depth);
        if (mask == texel.mask) ++masks_equal;
      }
      continue;
    }
    // A tie in t with another triangle, or a hit on one side and a miss on the other at an edge.
    Ray open = ray;
    open.tmin = -kInfinity;
    open.tmax = kInfinity;
    Hit h;
    const int32_t other = prim >= 0 ? prim : cpu.prim;
    if (intersect_triangle(tree, other, open, h, test) &&
        ((prim >= 0 && cpu.valid() && std::abs(h.t - cpu.t) <= 1e-4f * std::max(1.0f, cpu.t)) ||
         std::min({h.u, h.v, 1.0f - h.u - h.v}) < 1e-4f)) {
      ++tolerated;
    }
  }
  const size_t decided = rays.count() - capped;
  EXPECT_EQ(capped, 0u);
  EXPECT_GE(double(same), 0.999 * double(decided)) << same << " of " << decided << " rays agree";
  EXPECT_EQ(same + tolerated, decided) << "disagreements that are neither ties nor grazing edges";
  EXPECT_GT(masks, 0u);
  EXPECT_GE(double(masks_equal), 0.999 * double(masks)) << masks_equal << " of " << masks << " masks agree";
}

TEST_P(PerBackend, TraversalMatchesCpuOnTheDefaultScene) {
  check_traversal_against_cpu(*backend, load_scene(MOBIRT_SOURCE_DIR "/scenes/default.gltf"), 200, 120);
}

TEST_P(PerBackend, TraversalMatchesCpuOnABoxGrid) {
  check_traversal_against_cpu(*backend, test::box_grid_scene(), 160, 120);
}

// Short stacks and pure kd-restart on both backends. A restart at the previous restart point
// sends ties at tmin to the far side, as the CPU's walk does (the shader keeps that rule in tmin,
// one ulp up; without it the box grid's walks restart at the same point until the cap).
TEST_P(PerBackend, TraversalMatchesCpuAtSmallStackDepths) {
  for (int depth : {0, 1, 2}) {
    SCOPED_TRACE(depth);
    RenderSettings settings;
    settings.stack_depth = depth;
    check_traversal_against_cpu(*backend, test::box_grid_scene(), 96, 64, settings);
  }
}

TEST_P(PerBackend, TraversalMatchesCpuOnTheToaster) {
  check_traversal_against_cpu(*backend, load_scene(MOBIRT_SOURCE_DIR "/scenes/toaster.gltf"), 200, 120);
}

// Every accuracy knob of the traversal pass has its CPU twin: the intersection tests, the emulated
// mediump, the offsets.
TEST_P(PerBackend, TraversalMatchesCpuUnderEveryAccuracyKnob) {
  const Scene scene = load_scene(MOBIRT_SOURCE_DIR "/scenes/default.gltf");
  struct Knob {
    IntersectTest test;
    Precision precision;
    OffsetMode offset;
  };
  for (const Knob& k : {Knob{IntersectTest::Watertight, Precision::High, OffsetMode::Scaled},
                        Knob{IntersectTest::MollerTrumbore, Precision::Medium, OffsetMode::Scaled},
                        Knob{IntersectTest::Watertight, Precision::Medium, OffsetMode::Fixed},
                        Knob{IntersectTest::MollerTrumbore, Precision::High, OffsetMode::NormalUlp}}) {
    SCOPED_TRACE(::testing::Message() << "intersect " << int(k.test) << ", precision " << int(k.precision)
                                      << ", offset " << int(k.offset));
    RenderSettings settings;
    settings.shadow_rays.ray_test = {k.test, k.precision};
    settings.shadow_rays.offset.mode = k.offset;
    settings.shadow_rays.offset.epsilon = k.offset == OffsetMode::Fixed ? 1e-4f : 1e-6f;
    check_traversal_against_cpu(*backend, scene, 200, 120, settings);
  }
}

TEST_P(PerBackend, DefaultSceneImageMatchesCpuExpectation) {
  const auto [gpu, cpu] = test::render_default_scene(*backend);
  const ImageDiff d = compare_images(gpu, cpu);
  if (d.psnr < 40.0 || d.share_over > 0.005) {
    const std::string diff = std::string("parity-") + api_name(GetParam()) + "-vs-cpu-diff.png";
    write_image(test::output_path(diff).string(), difference_image(gpu, cpu));
    ADD_FAILURE() << api_name(GetParam()) << " image differs from the CPU expectation: PSNR " << d.psnr << " dB, "
                  << 100.0 * d.share_over << "% of pixels off by more than 2/255; see " << test::output_path(diff);
  }
}

// 16-bit colour: two shading passes (high and low bytes) of the same shading. Each 8-bit colour
// is that colour rounded to 8 bits (ray casting, so one shaded colour per pixel): within half an
// 8-bit step of the 16-bit one (Vulkan's UNORM conversion rounds to nearest; llvmpipe's OpenGL ES
// conversion strays up to 0.56 of a step), and the 16-bit image equals the CPU expectation
// quantised to 16 bits far more closely than 8 bits can.
TEST_P(PerBackend, SixteenBitColourRefinesTheEightBitImage) {
  const Scene scene = load_scene(MOBIRT_SOURCE_DIR "/scenes/default.gltf");
  RenderSettings settings;
  settings.width = 200;
  settings.height = 120;
  settings.depth = 0;
  settings.primary = PrimaryHits::Trace;  // every hit the CPU's: the 16-bit bound leaves no edge pixel
  const Image eight = Renderer(*backend, settings).render(scene, *scene.camera);
  settings.colour = ColourDepth::Bits16;
  const Image sixteen = Renderer(*backend, settings).render(scene, *scene.camera);
  float worst = 0.0f;
  for (size_t i = 0; i < eight.pixels.size(); ++i) {
    const glm::vec3 steps = glm::abs(sixteen.pixels[i] - eight.pixels[i]) * 255.0f;
    worst = std::max({worst, steps.x, steps.y, steps.z});
  }
  EXPECT_LE(worst, GetParam() == Api::Vulkan ? 0.5f + 255.0f / 65535.0f : 0.6f) << "8-bit steps";
  const ImageDiff d16 = compare_images(sixteen, render_on_cpu(scene, *scene.camera, settings));
  settings.colour = ColourDepth::Bits8;
  const ImageDiff d8 = compare_images(eight, render_on_cpu(scene, *scene.camera, settings, false));
  std::printf("[ colour ] %s: 16-bit against the CPU's 16-bit colours %.2f dB, 8-bit against unquantised "
              "%.2f dB; 8-bit within %.3f steps of 16-bit\n",
              api_name(GetParam()), d16.psnr, d8.psnr, worst);
  EXPECT_GE(d16.psnr, 80.0);
  EXPECT_LT(d8.psnr, 65.0);
}

// The shader counts steps exactly as the CPU traversal does: with a small loop cap, the GPU hands
// back as capped exactly the rays whose closest-hit walk or one of whose shadow walks needs more
// steps than the cap on the CPU. Odd stack depths too: the shader keeps entries two to a vec4 and
// must drop the one past an odd depth, as the CPU's stack does (a kept one would change the walk).
// On both backends: ES keeps a count of its stack entries and bounds its loops by the cap.
TEST_P(PerBackend, LoopCapStopsExactlyTheRaysWhoseCpuWalkIsLonger) {
  const Scene scene = test::random_soup_scene(3000, 7);
  ASSERT_FALSE(scene.lights.empty());
  for (const auto& [stack_depth, cap] : std::vector<std::pair<int, int>>{{2, 12}, {2, 40}, {1, 40}, {3, 40}}) {
    RenderSettings settings;
    settings.width = 96;
    settings.height = 64;
    settings.stack_depth = stack_depth;
    settings.max_steps = cap;
    settings.shadow_cells = 0;  // the shadow rays walk the tree, as the CPU's step counts assume
    Renderer renderer(*backend, settings);
    const FlatKdTree tree = build_kdtree(scene.mesh.positions, settings.kd);
    const RayBatch rays = primary_rays(*scene.camera, settings.width, settings.height);
    const TraceResult gpu = renderer.trace(scene, tree, rays);
    size_t capped = 0, mismatched = 0;
    for (uint32_t i = 0; i < rays.count(); ++i) {
      const Ray ray = rays.ray(i);
      TraversalStats stats;
      const Hit hit = traverse(tree, ray, stack_depth, stats);
      bool cpu_capped = stats.steps > uint64_t(cap);
      if (!cpu_capped && hit.valid()) {
        for (const std::optional<Ray>& shadow : shadow_rays(tree, scene.lights, hit.prim, ray, hit.t, ShadowSettings{})) {
          TraversalStats s;
          if (shadow) occluded(tree, *shadow, stack_depth, s);
          cpu_capped = cpu_capped || s.steps > uint64_t(cap);
        }
      }
      const bool gpu_capped = unpack_trace(gpu.packing, gpu.texels[i]).capped;
      capped += cpu_capped;
      mismatched += cpu_capped != gpu_capped;
    }
    EXPECT_GT(capped, 0u) << "cap " << cap << ", stack " << stack_depth;
    EXPECT_LT(capped, rays.count()) << "cap " << cap << ", stack " << stack_depth;
    EXPECT_EQ(mismatched, 0u) << "cap " << cap << ", stack " << stack_depth << ": " << capped
                              << " rays capped on the CPU";
  }
}

// A loop cap too small costs time, never pixels, on both backends.
TEST_P(PerBackend, CappedRaysAreTracedOnTheCpu) {
  test::expect_capped_rays_traced_on_the_cpu(*backend, 2000, 64, 48);
}

INSTANTIATE_TEST_SUITE_P(Backends, PerBackend, ::testing::Values(Api::Vulkan, Api::Gles),
                         [](const ::testing::TestParamInfo<Api>& p) { return std::string(api_name(p.param)); });

// ---- Vulkan against GLES -----------------------------------------------------------------------

struct ParityCase {
  const char* scene;  // file under scenes/
  int width, height;
  const char* level;  // "cast", "shadows", "bounces"
};

std::string case_name(const ParityCase& c) {
  std::string name = c.scene;
  name = name.substr(0, name.find('.'));
  return name + "_" + c.level;
}

RenderSettings case_settings(const ParityCase& c) {
  RenderSettings s;
  s.width = c.width;
  s.height = c.height;
  const std::string level = c.level;
  s.shadows = level != "cast";
  s.depth = level == "bounces" ? 2 : 0;
  return s;
}

class CrossBackend : public ::testing::TestWithParam<ParityCase> {
 protected:
  void SetUp() override {
    vulkan = make_backend(Api::Vulkan);
    gles = make_backend(Api::Gles);
  }
  void TearDown() override {
    if (vulkan) expect_no_messages(*vulkan, "vulkan");
    if (gles) expect_no_messages(*gles, "gles");
  }
  std::unique_ptr<Backend> vulkan, gles;
};

// The traversal passes: the same packed texel (hit index + 1 and shadow mask) for the same rays.
TEST_P(CrossBackend, SameHitsAndShadowMasks) {
  const ParityCase& c = GetParam();
  const Scene scene = load_scene(std::string(MOBIRT_SOURCE_DIR "/scenes/") + c.scene);
  const RenderSettings settings = case_settings(c);
  const FlatKdTree tree = build_kdtree(scene.mesh.positions, settings.kd);
  const RayBatch rays = primary_rays(scene_camera(scene, c.width, c.height), c.width, c.height);
  Renderer on_vulkan(*vulkan, settings);
  Renderer on_gles(*gles, settings);
  const TraceResult a = on_vulkan.trace(scene, tree, rays);
  const TraceResult b = on_gles.trace(scene, tree, rays);
  ASSERT_EQ(a.packing, b.packing);
  ASSERT_EQ(a.texels.size(), b.texels.size());
  size_t same_hit = 0, same_mask = 0, hits = 0;
  std::string first;
  for (size_t i = 0; i < a.texels.size(); ++i) {
    const TraceTexel ta = unpack_trace(a.packing, a.texels[i]);
    const TraceTexel tb = unpack_trace(b.packing, b.texels[i]);
    const bool hit_equal = ta.capped == tb.capped && ta.hit() == tb.hit() && (!ta.hit() || ta.prim() == tb.prim());
    if (hit_equal) ++same_hit;
    if (hit_equal && ta.hit()) {
      ++hits;
      if (ta.mask == tb.mask) ++same_mask;
    }
    if ((!hit_equal || ta.mask != tb.mask) && first.empty()) {
      std::ostringstream s;
      s << "ray " << i << ": vulkan texel " << std::hex << a.texels[i] << ", gles texel " << b.texels[i];
      first = s.str();
    }
  }
  const double n = double(a.texels.size());
  std::printf("[ parity ] %s: hits %zu/%zu (%.4f%%), masks %zu/%zu\n", case_name(c).c_str(), same_hit,
              a.texels.size(), 100.0 * double(same_hit) / n, same_mask, hits);
  EXPECT_GE(double(same_hit), 0.999 * n) << same_hit << " of " << a.texels.size() << " hits agree; first: " << first;
  EXPECT_GE(double(same_mask), 0.999 * double(hits)) << same_mask << " of " << hits << " masks agree; first: " << first;
}

// The final images: within 1/255 on >= 99.5% of pixels, PSNR >= 45 dB. With textures 2/255: Vulkan
// filters the atlas in hardware (one fetch, within 0.8/255 of the exact blend, atlas_test), GLES
// blends 4 texels exactly, and a pixel sums several lookups through mirrors and glass.
TEST_P(CrossBackend, SameImage) {
  const ParityCase& c = GetParam();
  const Scene scene = load_scene(std::string(MOBIRT_SOURCE_DIR "/scenes/") + c.scene);
  const Camera camera = scene_camera(scene, c.width, c.height);
  // Traced primaries (the paper's passes), then the default (--primary auto: rasterized here).
  for (PrimaryHits primary : {PrimaryHits::Trace, PrimaryHits::Auto}) {
  SCOPED_TRACE(primary_hits_name(primary));
  RenderSettings settings = case_settings(c);
  settings.primary = primary;
  Renderer on_vulkan(*vulkan, settings);
  Renderer on_gles(*gles, settings);
  const Image a = on_vulkan.render(scene, camera);
  const Image b = on_gles.render(scene, camera);
  // Accumulated float colours: one 8-bit step is 1/255, plus float rounding of the weights.
  const float steps = scene.textures.empty() ? 1.0f : 2.0f;
  const ImageDiff d = compare_images(a, b, steps / 255.0f + 1e-5f);
  std::printf("[ parity ] %s image: PSNR %.2f dB, max error %.4f (%.1f/255), %.4f%% of pixels beyond %.0f/255\n",
              case_name(c).c_str(), d.psnr, d.max_error, 255.0 * d.max_error, 100.0 * d.share_over, steps);
  if (d.psnr < 45.0 || d.share_over > 0.005) {
    const std::string diff = "parity-" + case_name(c) + "-diff.png";
    write_image(test::output_path(diff).string(), difference_image(a, b));
    write_image(test::output_path("parity-" + case_name(c) + "-vulkan.png").string(), a);
    write_image(test::output_path("parity-" + case_name(c) + "-gles.png").string(), b);
    ADD_FAILURE() << "Vulkan and GLES images differ: PSNR " << d.psnr << " dB, " << 100.0 * d.share_over
                  << "% of pixels beyond " << steps << "/255; see " << test::output_path(diff);
  }
  }
}

std::vector<ParityCase> parity_cases() {
  std::vector<ParityCase> cases;
  const ParityCase scenes[] = {{"default.gltf", 200, 120, ""},
                               {"toaster.gltf", 200, 120, ""},
                               {"marbles.gltf", 240, 400, ""},
                               {"fish.gltf", 200, 120, ""}};
  for (const ParityCase& s : scenes) {
    for (const char* level : {"cast", "shadows", "bounces"}) cases.push_back({s.scene, s.width, s.height, level});
  }
  return cases;
}

INSTANTIATE_TEST_SUITE_P(Scenes, CrossBackend, ::testing::ValuesIn(parity_cases()),
                         [](const ::testing::TestParamInfo<ParityCase>& p) { return case_name(p.param); });

// --colour 16: the textured scenes' 16-bit images agree across the backends to 16-bit precision.
// At 8 bits Vulkan filters its sRGB pages in one fetch; at 16 it reads RGBA8 pages texel by texel
// and decodes them as GLES does (atlas_page_format's exact pages): llvmpipe's own sRGB decode had
// held the Vulkan images at 65.6 dB from the reference and from GLES's (the marbles, 240x400).
TEST(CrossBackendColour, SixteenBitTexturesAgreeToSixteenBits) {
  const std::unique_ptr<Backend> vulkan = make_backend(Api::Vulkan), gles = make_backend(Api::Gles);
  for (const char* name : {"marbles", "fish"}) {
    SCOPED_TRACE(name);
    const Scene scene = load_scene(std::string(MOBIRT_SOURCE_DIR "/scenes/") + name + ".gltf");
    ASSERT_FALSE(scene.textures.empty());
    RenderSettings settings;
    settings.width = 120;
    settings.height = 80;
    settings.primary = PrimaryHits::Trace;
    settings.colour = ColourDepth::Bits16;
    const Camera camera = scene_camera(scene, settings.width, settings.height);
    const Image a = Renderer(*vulkan, settings).render(scene, camera);
    const Image b = Renderer(*gles, settings).render(scene, camera);
    const ImageDiff d = compare_images(a, b, 1.0f / 255.0f);
    std::printf("[ parity ] %s, 16-bit colour: PSNR %.2f dB, max error %.5f\n", name, d.psnr, d.max_error);
    EXPECT_GE(d.psnr, 80.0);
    EXPECT_EQ(d.share_over, 0.0);
  }
  expect_no_messages(*vulkan, "vulkan");
  expect_no_messages(*gles, "gles");
}

// ---- Vulkan: texel buffers against 2D images, storage buffers and device addresses -----------

// --data texel-buffers, images, storage-buffers and device-addresses run the same arithmetic on the
// same texels, so
// the traversal pass must give the same packed texel ray by ray, and the frame the same image.
class DataReadParity : public ::testing::TestWithParam<ParityCase> {
 protected:
  void SetUp() override { vulkan = make_backend(Api::Vulkan); }
  void TearDown() override {
    if (vulkan) expect_no_messages(*vulkan, "vulkan");
  }
  std::unique_ptr<Backend> vulkan;
};

RenderSettings with_data(RenderSettings s, DataReads reads) {
  s.data = reads;
  return s;
}

TEST_P(DataReadParity, SameHitsAndShadowMasks) {
  const ParityCase& c = GetParam();
  const Scene scene = load_scene(std::string(MOBIRT_SOURCE_DIR "/scenes/") + c.scene);
  const RenderSettings settings = case_settings(c);
  const FlatKdTree tree = build_kdtree(scene.mesh.positions, settings.kd);
  const RayBatch rays = primary_rays(scene_camera(scene, c.width, c.height), c.width, c.height);
  Renderer buffers(*vulkan, with_data(settings, DataReads::TexelBuffers));
  Renderer images(*vulkan, with_data(settings, DataReads::Images));
  Renderer storage(*vulkan, with_data(settings, DataReads::StorageBuffers));
  ASSERT_EQ(buffers.data_kind(), TextureKind::TexelBuffer);
  ASSERT_EQ(images.data_kind(), TextureKind::Image2D);
  ASSERT_EQ(storage.data_kind(), TextureKind::StorageBuffer);
  ASSERT_TRUE(vulkan->device_info().device_addresses) << "lavapipe has VK_KHR_buffer_device_address";
  const TraceResult a = buffers.trace(scene, tree, rays);
  const TraceResult b = images.trace(scene, tree, rays);
  const TraceResult s = storage.trace(scene, tree, rays);
  // Device addresses where this CPU runs them (refused with AVX-512: device_address_reads_fault);
  // there the storage buffers' texels stand in, and the refusal is checked instead.
  TraceResult r = s;
  if (device_address_reads_fault(vulkan->device_info())) {
    test::expect_bad_input([&] { Renderer refused(*vulkan, with_data(settings, DataReads::DeviceAddresses)); },
                           {"--data device-addresses", "AVX-512", "storage-buffers"});
  } else {
    Renderer addresses(*vulkan, with_data(settings, DataReads::DeviceAddresses));
    ASSERT_EQ(addresses.data_kind(), TextureKind::DeviceAddress);
    r = addresses.trace(scene, tree, rays);
  }
  ASSERT_EQ(a.packing, b.packing);
  ASSERT_EQ(a.packing, s.packing);
  ASSERT_EQ(a.packing, r.packing);
  ASSERT_EQ(a.texels.size(), b.texels.size());
  ASSERT_EQ(a.texels.size(), s.texels.size());
  ASSERT_EQ(a.texels.size(), r.texels.size());
  size_t hits = 0, masked = 0;
  for (size_t i = 0; i < a.texels.size(); ++i) {
    ASSERT_EQ(a.texels[i], b.texels[i]) << "ray " << i << ": texel buffers " << std::hex << a.texels[i]
                                        << ", images " << b.texels[i];
    ASSERT_EQ(a.texels[i], s.texels[i]) << "ray " << i << ": texel buffers " << std::hex << a.texels[i]
                                        << ", storage buffers " << s.texels[i];
    ASSERT_EQ(a.texels[i], r.texels[i]) << "ray " << i << ": texel buffers " << std::hex << a.texels[i]
                                        << ", device addresses " << r.texels[i];
    const TraceTexel t = unpack_trace(a.packing, a.texels[i]);
    if (t.hit()) ++hits;
    if (t.hit() && t.mask != 0) ++masked;
  }
  // The comparison means something only where rays hit and shadow rays ran.
  EXPECT_GT(hits, a.texels.size() / 10);
  if (settings.shadows) {
    EXPECT_GT(masked, 0u);
  }
}

TEST_P(DataReadParity, SameImage) {
  const ParityCase& c = GetParam();
  const Scene scene = load_scene(std::string(MOBIRT_SOURCE_DIR "/scenes/") + c.scene);
  const RenderSettings settings = case_settings(c);
  const Camera camera = scene_camera(scene, c.width, c.height);
  Renderer buffers(*vulkan, with_data(settings, DataReads::TexelBuffers));
  Renderer images(*vulkan, with_data(settings, DataReads::Images));
  Renderer storage(*vulkan, with_data(settings, DataReads::StorageBuffers));
  const Image a = buffers.render(scene, camera);
  const Image b = images.render(scene, camera);
  const Image s = storage.render(scene, camera);
  Image r = s;  // device addresses where this CPU runs them (SameHitsAndShadowMasks)
  if (!device_address_reads_fault(vulkan->device_info())) {
    Renderer addresses(*vulkan, with_data(settings, DataReads::DeviceAddresses));
    r = addresses.render(scene, camera);
  }
  const ImageDiff d = compare_images(a, b, 0.0f);
  EXPECT_EQ(d.max_error, 0.0) << "images: PSNR " << d.psnr << " dB, " << 100.0 * d.share_over << "% of pixels differ";
  const ImageDiff ds = compare_images(a, s, 0.0f);
  EXPECT_EQ(ds.max_error, 0.0) << "storage buffers: PSNR " << ds.psnr << " dB, " << 100.0 * ds.share_over
                               << "% of pixels differ";
  const ImageDiff dr = compare_images(a, r, 0.0f);
  EXPECT_EQ(dr.max_error, 0.0) << "device addresses: PSNR " << dr.psnr << " dB, " << 100.0 * dr.share_over
                               << "% of pixels differ";
}

INSTANTIATE_TEST_SUITE_P(Scenes, DataReadParity,
                         ::testing::Values(ParityCase{"toaster.gltf", 96, 64, "shadows"},
                                           ParityCase{"fish.gltf", 96, 64, "bounces"},
                                           ParityCase{"marbles.gltf", 64, 96, "bounces"}),
                         [](const ::testing::TestParamInfo<ParityCase>& p) { return case_name(p.param); });

}  // namespace
}  // namespace mobirt
