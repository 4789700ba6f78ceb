// Coherent secondary rays (src/raytree/ray_order.h): the reorder is a permutation that carries
// every ray's pixel and weight with it, sorts by octant then origin, and leaves the traversal
// pass's answer for every ray, and so the image, unchanged.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <map>
#include <random>
#include <tuple>

#include "accel/kdtree.h"
#include "backend/backend.h"
#include "raytree/hits.h"
#include "raytree/ray_order.h"
#include "raytree/secondary.h"
#include "render/renderer.h"
#include "scene/loader.h"
#include "test_support.h"
#include "vulkan_fixture.h"

namespace mobirt {
namespace {

RayBatch random_batch(uint32_t count, uint32_t width, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-10.0f, 10.0f);
  RayBatch batch;
  batch.width = width;
  for (uint32_t i = 0; i < count; ++i) {
    batch.push(Ray{{u(rng), u(rng), u(rng)}, test::random_direction(rng), 0.0f, kInfinity}, i,
               glm::vec3(float(i), 0.5f, 0.25f));
  }
  return batch;
}

// Every ray of `before` exactly once in `after`, with its own origin, direction and weight
// (before's pixels are 0..count-1).
void expect_same_rays(const RayBatch& before, const RayBatch& after) {
  ASSERT_EQ(after.count(), before.count());
  ASSERT_EQ(after.width, before.width);
  std::vector<int> seen(before.count(), 0);
  for (uint32_t i = 0; i < after.count(); ++i) {
    const uint32_t p = after.pixel[i];
    ASSERT_LT(p, before.count());
    ++seen[p];
    EXPECT_EQ(after.origin[i], before.origin[p]);
    EXPECT_EQ(after.direction[i], before.direction[p]);
    EXPECT_EQ(after.weight[i], before.weight[p]);
  }
  EXPECT_EQ(std::count(seen.begin(), seen.end(), 1), ptrdiff_t(before.count())) << "not a permutation";
}

TEST(RayOrder, IsAPermutationThatCarriesEveryRay) {
  const Aabb box{glm::vec3(-10.0f), glm::vec3(10.0f)};
  // Full pairs of rows and a remainder; a width that is no multiple of 4 (no tiling); tiny batches.
  for (const auto& [count, width] : std::vector<std::pair<uint32_t, uint32_t>>{
           {1000, 40}, {960, 40}, {999, 30}, {7, 40}, {1, 4}, {0, 8}}) {
    const RayBatch before = random_batch(count, width, count + width);
    RayBatch after = before;
    order_for_traversal(after, box, 0.0f);
    SCOPED_TRACE(testing::Message() << count << " rays, width " << width);
    expect_same_rays(before, after);
  }
}

TEST(RayOrder, ACoherentBatchIsOnlyTiled) {
  const Aabb box{glm::vec3(-10.0f), glm::vec3(10.0f)};
  RayBatch batch = random_batch(1000, 40, 5);
  for (glm::vec4& d : batch.direction) d = glm::vec4(glm::abs(glm::vec3(d)), d.w);  // one octant
  EXPECT_EQ(octant_change_rate(batch), 0.0f);
  RayBatch tiled = batch, ordered = batch;
  order_in_simd_tiles(tiled);
  order_for_traversal(ordered, box);
  EXPECT_EQ(ordered.pixel, tiled.pixel) << "a batch with one octant keeps its order, in tiles";
  // Random directions change octant 7 times in 8.
  EXPECT_NEAR(octant_change_rate(random_batch(1000, 40, 6)), 0.875f, 0.05f);
}

TEST(RayOrder, SortsByOctantThenOriginStably) {
  const Aabb box{glm::vec3(-10.0f), glm::vec3(10.0f)};
  // 5,100 rays sort in one part; 70,100 in five, counted and scattered on all cores.
  for (const uint32_t count : {5000u, 70000u}) {
    SCOPED_TRACE(testing::Message() << count << " rays");
    RayBatch batch = random_batch(count, 40, 3);
    // Duplicates: the same ray twice must keep its order (stable); in the large batch they lie in
    // other parts than their twins.
    for (uint32_t i = 0; i < 100; ++i) batch.push(batch.ray(i * (count / 100)), count + i, glm::vec3(1.0f));
    const std::vector<uint32_t> order = coherent_ray_order(batch, box);
    ASSERT_EQ(order.size(), batch.count());
    auto key = [&](uint32_t i) {
      return ray_order_key(glm::vec3(batch.origin[i]), glm::vec3(batch.direction[i]), box);
    };
    for (size_t k = 1; k < order.size(); ++k) {
      ASSERT_LE(key(order[k - 1]), key(order[k])) << "at " << k;
      if (key(order[k - 1]) == key(order[k])) {
        ASSERT_LT(order[k - 1], order[k]) << "not stable at " << k;
      }
    }
    // The order a serial stable sort gives, exactly.
    std::vector<uint32_t> expected(batch.count());
    for (uint32_t i = 0; i < batch.count(); ++i) expected[i] = i;
    std::stable_sort(expected.begin(), expected.end(), [&](uint32_t a, uint32_t b) { return key(a) < key(b); });
    EXPECT_EQ(order, expected);
    // The octant is the top of the key: all rays going -x, -y, -z come last.
    EXPECT_EQ(key(order.back()) >> 21, 7u);
  }
  EXPECT_TRUE(coherent_ray_order(random_batch(0, 8, 1), box).empty());
  EXPECT_EQ(coherent_ray_order(random_batch(1, 8, 1), box), std::vector<uint32_t>{0});
  EXPECT_EQ(ray_order_key(glm::vec3(-10.0f), glm::vec3(1.0f), box), 0u);
  EXPECT_EQ(ray_order_key(glm::vec3(10.0f), glm::vec3(-1.0f), box), (7u << 21) | ((1u << 21) - 1));
  // Origins outside the box (or NaN) clamp to it instead of wrapping.
  EXPECT_EQ(ray_order_key(glm::vec3(-1e9f), glm::vec3(1.0f), box), 0u);
  EXPECT_EQ(ray_order_key(glm::vec3(NAN), glm::vec3(1.0f), box), 0u);
}

// The fish's first secondary generation (mirror and refracted rays side by side), traced by the
// Vulkan traversal pass in the old order (tiles only) and in the coherent order: every ray gets the
// same texel, and the image made from them is the same.
class VulkanRayOrder : public test::VulkanTest {};

TEST_F(VulkanRayOrder, TraversalAnswersAndImageUnchanged) {
  const Scene scene = load_scene(MOBIRT_SOURCE_DIR "/scenes/fish.gltf");
  ASSERT_TRUE(scene.camera.has_value());
  const FlatKdTree tree = build_kdtree(scene.mesh.positions);
  RenderSettings settings;
  settings.width = 160;
  settings.height = 96;
  RayBatch primary = primary_rays(*scene.camera, settings.width, settings.height);
  std::vector<SurfaceHit> hits(primary.count());
  for (uint32_t i = 0; i < primary.count(); ++i) {
    const Hit h = traverse(tree, primary.ray(i));
    if (h.valid()) hits[i] = surface_hit(scene, tree, primary.ray(i), h.prim);
  }
  RayBatch tiles = next_generation(scene, tree.bounds, primary, SurfaceHits::copy_of(hits), settings.secondary);
  ASSERT_GT(tiles.count(), 2 * tiles.width) << "the fish's glass makes a secondary generation";
  ASSERT_GE(octant_change_rate(tiles), kSortAboveOctantChanges) << "mirror and refracted rays mixed: sorted";
  RayBatch coherent = tiles;
  order_in_simd_tiles(tiles);
  order_for_traversal(coherent, tree.bounds);

  Renderer renderer(*backend, settings);
  const TraceResult a = renderer.trace(scene, tree, tiles);
  const TraceResult b = renderer.trace(scene, tree, coherent);
  // A ray is its pixel and direction (a pixel's two rays go different ways).
  using RayId = std::tuple<uint32_t, uint32_t, uint32_t, uint32_t>;
  auto id = [](const RayBatch& r, uint32_t i) {
    return RayId{r.pixel[i], std::bit_cast<uint32_t>(r.direction[i].x), std::bit_cast<uint32_t>(r.direction[i].y),
                 std::bit_cast<uint32_t>(r.direction[i].z)};
  };
  std::map<RayId, uint32_t> texel_of;
  for (uint32_t i = 0; i < tiles.count(); ++i) texel_of[id(tiles, i)] = a.texels[i];
  ASSERT_EQ(texel_of.size(), tiles.count());
  uint32_t differ = 0;
  for (uint32_t i = 0; i < coherent.count(); ++i) {
    const auto it = texel_of.find(id(coherent, i));
    ASSERT_NE(it, texel_of.end()) << "ray " << i << " is not in the old order";
    if (it->second != b.texels[i]) ++differ;
  }
  EXPECT_EQ(differ, 0u) << "rays whose traversal texel changed with the order";

  // The image: each ray adds its weight times a colour of what it hit, in batch order, as the
  // renderer accumulates; only the order of float additions differs.
  auto image = [&](const RayBatch& r, const TraceResult& t) {
    std::vector<glm::vec3> pixels(size_t(settings.width) * settings.height, glm::vec3(0.0f));
    for (uint32_t i = 0; i < r.count(); ++i) {
      const TraceTexel texel = unpack_trace(t.packing, t.texels[i]);
      const float c = texel.hit() ? float(texel.prim() % 97) / 97.0f : 0.1f;
      pixels[r.pixel[i]] += r.weight[i] * glm::vec3(c, 1.0f - c, float(texel.mask));
    }
    return pixels;
  };
  const std::vector<glm::vec3> ia = image(tiles, a), ib = image(coherent, b);
  for (size_t p = 0; p < ia.size(); ++p) test::expect_vec3(ib[p], ia[p], 1e-6f);
}

}  // namespace
}  // namespace mobirt
