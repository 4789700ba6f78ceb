// The CPU ray-tree manager against known answers: a mirror shows a uniformly coloured wall times
// its reflectance, a glass slab shifts a ray without turning it, total internal reflection sets in
// beyond the critical angle; and the GPU frame with bounces matches the CPU expectation.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>


#include "accel/kdtree.h"
#include "core/parallel.h"
#include "backend/backend.h"
#include "raytree/hits.h"
#include "raytree/ray_order.h"
#include "raytree/secondary.h"
#include "render/cpu_render.h"
#include "render/renderer.h"
#include "scene/loader.h"
#include "test_scenes.h"
#include "test_support.h"
#include "vulkan_fixture.h"

namespace mobirt {
namespace {

// One ray, the hit it makes, and the next generation from it.
RayBatch one_bounce(const Scene& scene, const FlatKdTree& tree, const Ray& ray, SurfaceHit* hit_out = nullptr) {
  RayBatch rays;
  rays.width = 1;
  rays.push(ray, 0, glm::vec3(1.0f));
  const Hit h = traverse(tree, ray);
  EXPECT_TRUE(h.valid());
  std::vector<SurfaceHit> hits{surface_hit(scene, tree, ray, h.prim)};
  if (hit_out) *hit_out = hits[0];
  SecondarySettings settings;
  settings.min_weight = 0.0f;
  return next_generation(scene, tree.bounds, rays, SurfaceHits::copy_of(hits), settings);
}

Scene glass_slab(float thickness, float ior) {
  Scene s = test::base_scene("slab");
  Material glass;
  glass.diffuse = glm::vec3(0.0f);
  glass.transmittance = 1.0f;
  glass.ior = ior;
  glass.fresnel = false;  // fixed coefficients: all of the weight goes through
  s.materials.push_back(glass);
  test::add_box(s, {-50, -thickness, -50}, {50, 0, 50}, 2);
  return s;
}

// primary_rays() computes CameraBasis::ray four pixels to a register (SSE2) with a scalar tail: every ray must keep the very floats
// of camera_ray (the reference tracer and the tests' oracles make theirs with it), at odd sizes
// and for cameras looking along an axis, obliquely and from far away.
TEST(RayTree, PrimaryRaysAreCameraRaysBitForBit) {
  const Camera cameras[] = {
      Camera{},
      Camera{glm::vec3(1.5f, -2.0f, 7.25f), glm::vec3(-0.3f, 0.1f, 0.0f), glm::vec3(0.0f, 1.0f, 0.0f), 0.9f, 1e-3f},
      Camera{glm::vec3(1e4f, 3e3f, -2e4f), glm::vec3(0.0f), glm::vec3(0.2f, 1.0f, 0.1f), 0.2f, 0.5f},
  };
  const std::pair<int, int> sizes[] = {{1, 1}, {7, 3}, {400, 240}, {33, 65}};
  for (const Camera& camera : cameras) {
    for (const auto& [w, h] : sizes) {
      const RayBatch rays = primary_rays(camera, w, h);
      ASSERT_EQ(rays.count(), uint32_t(w * h));
      ASSERT_EQ(rays.width, uint32_t(w));
      for (int y = 0; y < h; ++y) {
        for (int x = 0; x < w; ++x) {
          const uint32_t i = uint32_t(y * w + x);
          const Ray expected = camera_ray(camera, w, h, float(x) + 0.5f, float(y) + 0.5f);
          const Ray got = rays.ray(i);
          ASSERT_EQ(std::memcmp(&got.origin, &expected.origin, sizeof(glm::vec3)), 0) << w << "x" << h << " pixel " << i;
          ASSERT_EQ(std::memcmp(&got.direction, &expected.direction, sizeof(glm::vec3)), 0)
              << w << "x" << h << " pixel " << i << ": " << got.direction.x << " " << expected.direction.x;
          ASSERT_EQ(got.tmin, expected.tmin);
          ASSERT_EQ(got.tmax, expected.tmax);
          ASSERT_EQ(rays.pixel[i], i);
          ASSERT_EQ(rays.weight[i], glm::vec3(1.0f));
        }
      }
    }
  }
}

// render_whitted adds a batch's colours on all cores only when the batch says no pixel has two
// rays in it: the primary rays say so, in any order; a secondary generation never does.
TEST(RayTree, OnlyPrimaryRaysAreMarkedOnePerPixel) {
  RayBatch rays = primary_rays(Camera{}, 8, 6);
  EXPECT_TRUE(rays.unique_pixels);
  order_in_simd_tiles(rays);
  EXPECT_TRUE(rays.unique_pixels);
  order_for_traversal(rays, Aabb{glm::vec3(-1.0f), glm::vec3(1.0f)}, 0.0f);  // sorted, then tiled
  EXPECT_TRUE(rays.unique_pixels);
  std::vector<int> seen(rays.count(), 0);
  for (uint32_t i = 0; i < rays.count(); ++i) ++seen.at(rays.pixel[i]);
  EXPECT_EQ(std::count(seen.begin(), seen.end(), 1), std::ptrdiff_t(seen.size()));
  // A glass hit with Fresnel's reflectance: a mirror and a refracted ray of the same pixel.
  Scene scene = glass_slab(2.0f, 1.5f);
  scene.materials.back().fresnel = true;
  const FlatKdTree tree = build_kdtree(scene.mesh.positions);
  const RayBatch next = one_bounce(scene, tree, Ray{glm::vec3(0.0f, 5.0f, 0.0f), glm::vec3(0.0f, -1.0f, 0.0f), 0.0f, kInfinity});
  ASSERT_EQ(next.count(), 2u);
  EXPECT_EQ(next.pixel[0], next.pixel[1]);
  EXPECT_FALSE(next.unique_pixels);
  // Rays pushed onto a batch may share pixels: a push takes the mark off.
  RayBatch more = primary_rays(Camera{}, 2, 1);
  more.push(more.ray(0), more.pixel[0], glm::vec3(1.0f));
  EXPECT_FALSE(more.unique_pixels);
  rays.clear();
  EXPECT_FALSE(rays.unique_pixels);
}

// next_generation() makes its rays on all cores, chunk by chunk: the batch must be the rays of one
// loop over the hits, in their order, whatever the chunk boundaries. The oracle is each ray's own
// next generation (a batch of one), concatenated: 5,000 rays (chunks of 2,048) onto Fresnel glass
// (a mirror and a refracted ray each), every seventh missing, every fifth too faint to go on.
TEST(RayTree, NextGenerationKeepsTheHitsOrderAcrossChunks) {
  Scene scene = glass_slab(2.0f, 1.5f);
  scene.materials.back().fresnel = true;
  const FlatKdTree tree = build_kdtree(scene.mesh.positions);
  SecondarySettings settings;
  settings.min_weight = 0.01f;
  RayBatch rays;
  rays.width = 64;
  std::vector<SurfaceHit> hits;
  for (uint32_t i = 0; i < 5000; ++i) {
    const float x = -40.0f + 80.0f * float(i % 97) / 97.0f, z = -40.0f + 80.0f * float(i % 89) / 89.0f;
    const glm::vec3 d = i % 7 == 3 ? glm::vec3(0.1f, 1.0f, 0.0f) : glm::normalize(glm::vec3(0.3f * float(i % 5) - 0.6f, -1.0f, 0.2f));
    const Ray ray{glm::vec3(x, 5.0f, z), d, 0.0f, kInfinity};
    rays.push(ray, 4999 - i, i % 5 == 1 ? glm::vec3(0.004f) : glm::vec3(1.0f, 0.5f, 0.25f));
    const Hit h = traverse(tree, ray);
    hits.push_back(h.valid() ? surface_hit(scene, tree, ray, h.prim) : SurfaceHit{});
  }
  SecondaryStats stats;
  const RayBatch next = next_generation(scene, tree.bounds, rays, SurfaceHits::copy_of(hits), settings, &stats);

  RayBatch want;
  SecondaryStats want_stats;
  for (uint32_t i = 0; i < rays.count(); ++i) {
    RayBatch one;
    one.width = 1;
    one.push(rays.ray(i), rays.pixel[i], rays.weight[i]);
    SecondaryStats s;
    const RayBatch part = next_generation(scene, tree.bounds, one, SurfaceHits::copy_of({&hits[i], 1}), settings, &s);
    for (uint32_t k = 0; k < part.count(); ++k) want.push(part.ray(k), part.pixel[k], part.weight[k]);
    want_stats.reflected += s.reflected;
    want_stats.refracted += s.refracted;
    want_stats.total_internal_reflections += s.total_internal_reflections;
    want_stats.culled += s.culled;
  }
  ASSERT_GT(rays.count(), 2u * 2048u);  // three of next_generation's chunks
  ASSERT_GT(want.count(), rays.count());  // most hits make a mirror and a refracted ray
  ASSERT_GT(want_stats.culled, 0u);
  ASSERT_EQ(next.count(), want.count());
  EXPECT_EQ(next.width, rays.width);
  EXPECT_FALSE(next.unique_pixels);
  for (uint32_t k = 0; k < next.count(); ++k) {
    ASSERT_EQ(std::memcmp(&next.origin[k], &want.origin[k], sizeof(glm::vec4)), 0) << "ray " << k;
    ASSERT_EQ(std::memcmp(&next.direction[k], &want.direction[k], sizeof(glm::vec4)), 0) << "ray " << k;
    ASSERT_EQ(next.pixel[k], want.pixel[k]) << "ray " << k;
    ASSERT_EQ(next.weight[k], want.weight[k]) << "ray " << k;
  }
  EXPECT_EQ(stats.reflected, want_stats.reflected);
  EXPECT_EQ(stats.refracted, want_stats.refracted);
  EXPECT_EQ(stats.total_internal_reflections, want_stats.total_internal_reflections);
  EXPECT_EQ(stats.culled, want_stats.culled);
}

// next_generation() makes eight hits' rays at a time where the CPU has AVX2 (make_rays_avx2 in
// src/raytree/secondary.cpp): each ray must be what the shading maths makes of its hit one at a
// time, bit for bit. The oracle here is those functions called per hit (split_weight(),
// mirror_direction(), offset_origin()): 3,001 made-up hits (batches of eight, and short ones at
// the ends of next_generation's chunks; the first 400 all on the mirror, batches without glass,
// the rest cycling through the materials) with unnormalised directions, shading normals bent off
// the geometric ones, points near the origin and far from it, entering and leaving, on a mirror, a
// mirror that also refracts, glass with and without Fresnel and a dense glass leaving which most
// rays reflect totally; every eleventh ray a miss, every sixth too faint to go on; under the fixed
// and the scaled offsets.
TEST(RayTree, NextGenerationIsEachHitsSplitBitForBit) {
  Scene scene = test::base_scene("materials");
  const auto material = [&](float reflectance, float transmittance, float ior, bool fresnel) {
    Material m;
    m.reflectance = reflectance;
    m.transmittance = transmittance;
    m.ior = ior;
    m.fresnel = fresnel;
    scene.materials.push_back(m);
    return uint32_t(scene.materials.size() - 1);
  };
  const uint32_t kinds[] = {material(0.6f, 0.0f, 1.5f, false), material(0.2f, 0.7f, 1.5f, true),
                            material(0.0f, 0.9f, 1.33f, false), material(0.0f, 1.0f, 2.4f, true),
                            material(0.0f, 0.0f, 1.5f, true)};
  const Aabb bounds{glm::vec3(-300.0f), glm::vec3(300.0f)};
  uint64_t state = 12345;
  const auto uniform = [&](float lo, float hi) {  // a fixed LCG: the same hits on every machine
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    return lo + (hi - lo) * float(state >> 40) / float(1ull << 24);
  };
  const auto unit = [&] {
    return glm::normalize(glm::vec3(uniform(-1.0f, 1.0f), uniform(-1.0f, 1.0f), uniform(-1.0f, 1.0f)) +
                          glm::vec3(0.0f, 0.01f, 0.0f));
  };
  RayBatch rays;
  rays.width = 64;
  std::vector<SurfaceHit> hits;
  for (uint32_t i = 0; i < 3001; ++i) {
    const glm::vec3 d = unit() * uniform(0.5f, 3.0f);
    glm::vec3 ng = unit();
    if (glm::dot(ng, d) > 0.0f) ng = -ng;  // normals face the ray
    glm::vec3 ns = glm::normalize(ng + 0.3f * unit());
    if (glm::dot(ns, ng) < 0.0f) ns = -ns;
    const float far = i % 3 == 0 ? 250.0f : 2.0f;
    const glm::vec3 p(uniform(-far, far), uniform(-far, far), uniform(-far, far));
    rays.push(Ray{p - d, d, 0.0f, kInfinity}, i, i % 6 == 1 ? glm::vec3(0.002f) : glm::vec3(1.0f, 0.5f, 0.25f));
    SurfaceHit h;
    if (i % 11 != 4) {
      h.prim = int32_t(i);
      h.t = 1.0f;
      h.position = p;
      h.normal = ns;
      h.geometric = ng;
      h.entering = i % 4 != 0;
      h.material = i < 400 ? kinds[0] : kinds[i % 5];
    }
    hits.push_back(h);
  }
  for (const OffsetMode mode : {OffsetMode::Scaled, OffsetMode::Fixed}) {
    SCOPED_TRACE(int(mode));
    SecondarySettings settings;
    settings.offset.mode = mode;
    settings.offset.epsilon = 1e-4f;
    settings.min_weight = 0.01f;
    const float absolute = absolute_offset(bounds, settings.offset);
    RayBatch want;
    SecondaryStats want_stats;
    const auto make = [&](const glm::vec3& p, const glm::vec3& n, const glm::vec3& dir, uint32_t pixel,
                          const glm::vec3& w, uint32_t& counter) {
      if (std::max(w.x, std::max(w.y, w.z)) < settings.min_weight) {
        ++want_stats.culled;
        return;
      }
      want.push(Ray{offset_origin(p, n, mode, absolute), dir, 0.0f, kInfinity}, pixel, w);
      ++counter;
    };
    for (uint32_t i = 0; i < rays.count(); ++i) {
      const SurfaceHit& h = hits[i];
      if (!h.valid()) continue;
      const Material& m = scene.materials[h.material];
      if (m.reflectance <= 0.0f && m.transmittance <= 0.0f) continue;
      const glm::vec3 d = glm::normalize(glm::vec3(rays.direction[i]));
      const WeightSplit<float> split = split_weight(m, d, h.normal, h.geometric, h.entering);
      if (split.total_internal_reflection) ++want_stats.total_internal_reflections;
      if (split.reflect > 0.0f) {
        make(h.position, h.geometric, mirror_direction(d, h.normal, h.geometric), rays.pixel[i],
             rays.weight[i] * split.reflect, want_stats.reflected);
      }
      if (split.refract > 0.0f) {
        make(h.position, -h.geometric, split.refracted, rays.pixel[i], rays.weight[i] * split.refract,
             want_stats.refracted);
      }
    }
    SecondaryStats stats;
    const RayBatch next = next_generation(scene, bounds, rays, SurfaceHits::copy_of(hits), settings, &stats);
    ASSERT_GT(want_stats.total_internal_reflections, 50u);
    ASSERT_GT(want_stats.refracted, 500u);
    ASSERT_GT(want_stats.culled, 100u);
    ASSERT_EQ(next.count(), want.count());
    for (uint32_t k = 0; k < next.count(); ++k) {
      ASSERT_EQ(std::memcmp(&next.origin[k], &want.origin[k], sizeof(glm::vec4)), 0) << "ray " << k;
      ASSERT_EQ(std::memcmp(&next.direction[k], &want.direction[k], sizeof(glm::vec4)), 0) << "ray " << k;
      ASSERT_EQ(next.pixel[k], want.pixel[k]) << "ray " << k;
      ASSERT_EQ(std::memcmp(&next.weight[k], &want.weight[k], sizeof(glm::vec3)), 0) << "ray " << k;
    }
    EXPECT_EQ(stats.reflected, want_stats.reflected);
    EXPECT_EQ(stats.refracted, want_stats.refracted);
    EXPECT_EQ(stats.total_internal_reflections, want_stats.total_internal_reflections);
    EXPECT_EQ(stats.culled, want_stats.culled);
  }
}

TEST(RayTree, GlassSlabShiftsTheRayWithoutTurningIt) {
  const float thickness = 2.0f, ior = 1.5f;
  const Scene scene = glass_slab(thickness, ior);
  const FlatKdTree tree = build_kdtree(scene.mesh.positions);
  for (float angle_deg : {0.0f, 20.0f, 45.0f, 70.0f}) {
    SCOPED_TRACE(angle_deg);
    const float a = angle_deg * 3.14159265f / 180.0f;
    const glm::vec3 d(std::sin(a), -std::cos(a), 0.0f);
    const Ray in{glm::vec3(0.0f, 5.0f, 0.0f), d, 0.0f, kInfinity};
    RayBatch inside = one_bounce(scene, tree, in);
    ASSERT_EQ(inside.count(), 1u);
    RayBatch out = one_bounce(scene, tree, inside.ray(0));
    ASSERT_EQ(out.count(), 1u);
    const Ray leaving = out.ray(0);
    test::expect_vec3(glm::normalize(leaving.direction), d, 1e-5f);
    EXPECT_NEAR(out.weight[0].x, 1.0f, 1e-6f);
    // Lateral shift of a slab: t sin(a - b) / cos(b), with sin(b) = sin(a) / ior.
    const float b = std::asin(std::sin(a) / ior);
    const float shift = thickness * std::sin(a - b) / std::cos(b);
    // Distance between the leaving ray's line and the incoming ray's line.
    const glm::vec3 w = leaving.origin - in.origin;
    const float distance = glm::length(w - glm::dot(w, d) * d);
    // The two origins are offset off the surfaces (offset_origin(): epsilon x the scene's size) each,
    // which moves the line sideways by up to that much over cos(a) per surface.
    const float offset = scene_offset(tree.bounds, SecondarySettings{}.offset.epsilon);
    EXPECT_NEAR(distance, shift, 1e-4f + 2.0f * offset / std::cos(a));
  }
}

TEST(RayTree, TotalInternalReflectionBeyondTheCriticalAngle) {
  const float ior = 1.5f;
  const float critical = std::asin(1.0f / ior);
  glm::vec3 out;
  const glm::vec3 n(0, 1, 0);  // facing the ray, which travels downwards out of the glass
  for (float delta : {-0.05f, 0.05f}) {
    const float a = critical + delta;
    const glm::vec3 d(std::sin(a), -std::cos(a), 0.0f);
    EXPECT_EQ(refract_direction(d, n, ior / 1.0f, out), delta < 0.0f) << "angle " << a;
  }
  // Through the ray tree: inside a slab, a steep ray is reflected whole.
  const Scene scene = glass_slab(2.0f, ior);
  const FlatKdTree tree = build_kdtree(scene.mesh.positions);
  const float a = critical + 0.1f;
  const Ray inside{glm::vec3(0.0f, -1.0f, 0.0f), glm::vec3(std::sin(a), -std::cos(a), 0.0f), 0.0f, kInfinity};
  SurfaceHit hit;
  const RayBatch next = one_bounce(scene, tree, inside, &hit);
  EXPECT_FALSE(hit.entering);
  ASSERT_EQ(next.count(), 1u);
  EXPECT_GT(next.direction[0].y, 0.0f);  // reflected back up into the glass
  EXPECT_NEAR(next.weight[0].x, 1.0f, 1e-6f);
}

TEST(RayTree, SchlickFresnelLimits) {
  EXPECT_NEAR(schlick_fresnel(1.0f, 1.0f, 1.5f), 0.04f, 1e-6f);   // normal incidence
  EXPECT_NEAR(schlick_fresnel(0.0f, 1.0f, 1.5f), 1.0f, 1e-6f);    // grazing
  EXPECT_EQ(schlick_fresnel(0.1f, 1.5f, 1.0f), 1.0f);             // beyond the critical angle
}

class VulkanRayTree : public test::VulkanTest {};

// A mirror at 45 degrees shows a wall of uniform colour c: the mirror's pixels are reflectance x c.
TEST_F(VulkanRayTree, MirrorShowsTheWallTimesItsReflectance) {
  Scene s = test::base_scene("mirror");
  s.materials.clear();
  Material wall;  // uniform: ambient only, no lights
  wall.diffuse = glm::vec3(0.8f, 0.4f, 0.2f);
  wall.ambient = 1.0f;
  Material mirror;
  mirror.diffuse = glm::vec3(0.0f);
  mirror.ambient = 0.0f;
  mirror.reflectance = 0.5f;
  s.materials = {wall, mirror};
  // The camera looks down -z at a mirror tilted 45 degrees about x (a plane through the origin
  // with normal (0, 1, 1)/sqrt(2)), which shows the wall above (+y).
  test::add_triangle(s, {-3, -3, 3}, {3, -3, 3}, {3, 3, -3}, 1);
  test::add_triangle(s, {-3, -3, 3}, {3, 3, -3}, {-3, 3, -3}, 1);
  // The wall: a big plane at y = 20 facing down.
  test::add_triangle(s, {-100, 20, -100}, {100, 20, -100}, {100, 20, 100}, 0);
  test::add_triangle(s, {-100, 20, -100}, {100, 20, 100}, {-100, 20, 100}, 0);
  const Camera camera{{0, 0, 10}, {0, 0, 0}, {0, 1, 0}, 0.3f, 0.0f};
  RenderSettings settings;
  settings.width = 32;
  settings.height = 32;
  settings.depth = 1;
  Renderer renderer(*backend, settings);
  const Image image = renderer.render(s, camera);
  const glm::vec3 expected = 0.5f * glm::round(wall.diffuse * 255.0f) / 255.0f;
  for (int y = 8; y < 24; ++y) {
    for (int x = 8; x < 24; ++x) {
      test::expect_vec3(image.at(x, y), expected, 1.0f / 255.0f);
    }
  }
  // Without bounces the mirror is black.
  settings.depth = 0;
  Renderer flat(*backend, settings);
  test::expect_vec3(flat.render(s, camera).at(16, 16), glm::vec3(0.0f), 1e-6f);
}

// Bounces on the GPU match the CPU expectation, and each generation holds only the rays made.
TEST_F(VulkanRayTree, BouncesMatchTheCpuExpectation) {
  Scene scene = test::box_grid_scene();
  scene.materials[1].reflectance = 0.4f;  // reflective boxes
  Material glass;
  glass.diffuse = glm::vec3(0.05f);
  glass.transmittance = 0.8f;
  glass.ior = 1.5f;
  scene.materials.push_back(glass);
  for (size_t i = 2; i < scene.mesh.material_ids.size(); i += 24) {
    for (size_t k = i; k < std::min(i + 12, scene.mesh.material_ids.size()); ++k) scene.mesh.material_ids[k] = 2;
  }
  RenderSettings settings;
  settings.width = 160;
  settings.height = 120;
  settings.depth = 3;
  // Traced primaries, as the CPU's: a box's face here is half glass, half mirror, and a pixel
  // centre on the diagonal between them may take either half when rasterized.
  settings.primary = PrimaryHits::Trace;
  Renderer renderer(*backend, settings);
  FrameTimings t;
  const Image gpu = renderer.render(scene, *scene.camera, &t);
  const Image cpu = render_on_cpu(scene, *scene.camera, settings);
  ASSERT_GE(t.generations.size(), 2u);
  for (size_t g = 1; g < t.generations.size(); ++g) {
    EXPECT_LT(t.generations[g].rays, t.generations[0].rays) << "generation " << g << " sized to the screen";
  }
  const ImageDiff d = compare_images(gpu, cpu);
  if (d.psnr < 40.0 || d.share_over > 0.005) {
    write_image(test::output_path("bounces-gpu.png").string(), gpu);
    write_image(test::output_path("bounces-cpu.png").string(), cpu);
    write_image(test::output_path("bounces-diff.png").string(), difference_image(gpu, cpu));
    ADD_FAILURE() << "PSNR " << d.psnr << " dB, " << 100 * d.share_over << "% over 2/255; see "
                  << test::output_path("bounces-diff.png");
  }
}

}  // namespace
// Every index exactly once, whatever the thread count and chunk.
TEST(ParallelFor, VisitsEveryIndexOnce) {
  for (unsigned threads : {1u, 2u, 3u, 0u}) {
    for (uint32_t chunk : {1u, 7u, 64u}) {
      std::vector<std::atomic<int>> seen(1000);
      parallel_for(uint32_t(seen.size()), threads, [&](uint32_t i) { seen[i].fetch_add(1); }, chunk);
      for (size_t i = 0; i < seen.size(); ++i) ASSERT_EQ(seen[i].load(), 1) << i << ", " << threads << " threads";
    }
  }
}

// An exception in one index reaches the caller, the other chunks stop, and the next loop on the
// same (persistent) threads runs in full.
TEST(ParallelFor, RethrowsAnExceptionAndRunsTheNextLoop) {
  // Each index does some work, so that the whole loop takes far longer (about 0.1 s) than
  // throwing and unwinding does, even when the scheduler preempts the thread that throws.
  constexpr uint32_t n = 1u << 20;
  for (unsigned threads : {1u, 2u, 0u}) {
    std::atomic<uint32_t> visited{0};
    std::string what;
    try {
      parallel_for(n, threads, [&](uint32_t i) {
        visited.fetch_add(1, std::memory_order_relaxed);
        if (i == 10) throw std::runtime_error("index 10");
        volatile uint32_t work = 0;
        for (uint32_t k = 0; k < 64; ++k) work = work + k;
      }, 4);
    } catch (const std::runtime_error& e) {
      what = e.what();
    }
    EXPECT_EQ(what, "index 10") << threads << " threads";
    if (threads == 1) {
      // One thread runs the indices in order and stops at the throw.
      EXPECT_EQ(visited.load(), 11u);
    } else {
      // Chunks already running finish; the others are dropped. How many ran before the throw
      // reached TBB depends on the scheduler (CI once saw 50,011 of 100,000 with a tighter
      // bound), so only the stop itself is asserted.
      EXPECT_LT(visited.load(), n) << "the loop went on after the exception, " << threads << " threads";
    }
    std::vector<std::atomic<int>> seen(5000);
    parallel_for(uint32_t(seen.size()), threads, [&](uint32_t i) { seen[i].fetch_add(1); }, 16);
    for (size_t i = 0; i < seen.size(); ++i) ASSERT_EQ(seen[i].load(), 1) << i << ", " << threads << " threads";
  }
}

// A loop inside a loop's index, and loops from two threads at once on the same persistent
// workers: every index of every loop runs exactly once, and none waits for another (a worker
// that waited for a loop it is meant to serve would hang here).
TEST(ParallelFor, NestedAndConcurrentLoopsVisitEveryIndexOnce) {
  constexpr uint32_t outer = 64, inner = 500;
  for (int round = 0; round < 20; ++round) {
    std::vector<std::atomic<int>> nested(outer * inner);
    std::vector<std::atomic<int>> other(100000);
    std::thread second([&] {
      for (int k = 0; k < 10; ++k) {
        parallel_for(uint32_t(other.size()), 0, [&](uint32_t i) { other[i].fetch_add(1); }, 16);
      }
    });
    parallel_for(outer, 0, [&](uint32_t o) {
      parallel_for(inner, 0, [&](uint32_t i) { nested[o * inner + i].fetch_add(1); }, 8);
    }, 1);
    second.join();
    for (size_t i = 0; i < nested.size(); ++i) ASSERT_EQ(nested[i].load(), 1) << "nested index " << i;
    for (size_t i = 0; i < other.size(); ++i) ASSERT_EQ(other[i].load(), 10) << "other thread's index " << i;
  }
}

// Many short loops back to back, as a frame's stages run them: no index of one loop runs in the
// next (each loop's counts are checked before the next starts), and an index thrown from
// whichever thread runs it stops only its own loop.
TEST(ParallelFor, BackToBackLoopsKeepTheirOwnIndices) {
  std::vector<std::atomic<int>> seen(3000);
  for (int loop = 0; loop < 2000; ++loop) {
    const uint32_t n = 100 + uint32_t(loop * 37 % 2900);
    for (uint32_t i = 0; i < n; ++i) seen[i].store(0, std::memory_order_relaxed);
    const bool throws = loop % 97 == 5;
    bool caught = false;
    try {
      parallel_for(n, 0, [&](uint32_t i) {
        seen[i].fetch_add(1, std::memory_order_relaxed);
        if (throws && i == n / 2) throw std::runtime_error("stop");
      }, 4);
    } catch (const std::runtime_error&) {
      caught = true;
    }
    ASSERT_EQ(caught, throws) << "loop " << loop;
    if (throws) continue;
    for (uint32_t i = 0; i < n; ++i) ASSERT_EQ(seen[i].load(), 1) << "loop " << loop << ", index " << i;
  }
}

// Worker threads do join loops, also after sleeping (every other loop 2 ms after the last), never
// more threads than a loop asks for, and the caller returns only once a worker's chunk has
// finished: the first index a worker runs says it joined, sleeps, then writes, and the write is
// there on return (the caller's chunks wait only for the join, not for the write). An exception
// thrown on a worker reaches the caller too. The caller's chunks wait (up to 2 s, so that a busy
// CI machine's scheduler is not what is tested) until a worker has joined.
TEST(ParallelFor, WorkersJoinWithinTheThreadCountAndFinishBeforeTheCallerReturns) {
  if (std::thread::hardware_concurrency() < 2) GTEST_SKIP() << "one core: every loop runs on the caller";
  const std::thread::id caller = std::this_thread::get_id();
  const auto wait_for = [](const std::atomic<bool>& flag) {
    const auto start = std::chrono::steady_clock::now();
    while (!flag.load() && std::chrono::steady_clock::now() - start < std::chrono::seconds(2)) std::this_thread::yield();
  };
  for (int loop = 0; loop < 20; ++loop) {
    // Every other loop after a pause, the workers asleep.
    if (loop % 2) std::this_thread::sleep_for(std::chrono::milliseconds(2));
    std::atomic<int> running{0}, most{0};
    std::atomic<bool> joined{false};
    int late_write = 0;
    parallel_for(64, 2, [&](uint32_t) {
      const int now = running.fetch_add(1) + 1;
      int seen = most.load();
      while (now > seen && !most.compare_exchange_weak(seen, now)) {
      }
      if (std::this_thread::get_id() != caller) {
        if (!joined.exchange(true)) {
          std::this_thread::sleep_for(std::chrono::milliseconds(1));
          late_write = 1;
        }
      } else {
        wait_for(joined);
      }
      running.fetch_sub(1);
    }, 1);
    EXPECT_LE(most.load(), 2) << "loop " << loop << ": more threads than asked for";
    ASSERT_TRUE(joined.load()) << "loop " << loop << ": no worker joined in 2 s";
    EXPECT_EQ(late_write, 1) << "loop " << loop << ": returned before a worker's chunk finished";
  }

  std::atomic<bool> thrown{false};
  std::string what;
  try {
    parallel_for(64, 2, [&](uint32_t) {
      if (std::this_thread::get_id() != caller) {
        thrown.store(true);
        throw std::runtime_error("worker");
      }
      wait_for(thrown);
    }, 1);
  } catch (const std::runtime_error& e) {
    what = e.what();
  }
  EXPECT_EQ(what, "worker") << "a worker's exception did not reach the caller";
}

// parallel_copy in pieces on all cores copies every byte, sizes at and around its piece size.
TEST(ParallelCopy, CopiesEveryByte) {
  for (size_t bytes : {size_t(0), size_t(1), 2 * kParallelCopyChunk - 1, 2 * kParallelCopyChunk,
                       5 * kParallelCopyChunk + 12345}) {
    std::vector<unsigned char> source(bytes), target(bytes, 0);
    for (size_t i = 0; i < bytes; ++i) source[i] = static_cast<unsigned char>(i * 2654435761u >> 24);
    parallel_copy(target.data(), source.data(), bytes);
    ASSERT_EQ(target, source) << bytes << " bytes";
  }
}

}  // namespace mobirt
