// decode_hits() (the per-chunk counting, the shadow-ray count that trusts the mask) against the
// per-ray composition it replaces: surface_hit() + the pass's mask, shadow_ray_count() (and
// shadow_rays() for the lights the mask calls visible), and retrace_capped() for capped rays. Every SurfaceHit must match bit for bit, on triangle scenes
// with textures and glass and on analytic shapes, primary and secondary rays, under each ray test
// and offset mode: where the CPU has AVX2 this compares its eight-lane path (Möller-Trumbore,
// and its shadow-ray count: single precision, offset fixed or scaled, no spot light) with the
// scalar one.
#include <gtest/gtest.h>

#include <bit>
#include <string>
#include <vector>

#include "accel/kdtree.h"
#include "core/camera.h"
#include "raytree/hits.h"
#include "raytree/packing.h"
#include "raytree/rays.h"
#include "raytree/secondary.h"
#include "scene/loader.h"
#include "test_scenes.h"

namespace mobirt {
namespace {

bool same(float a, float b) { return std::bit_cast<uint32_t>(a) == std::bit_cast<uint32_t>(b); }
bool same(const glm::vec3& a, const glm::vec3& b) { return same(a.x, b.x) && same(a.y, b.y) && same(a.z, b.z); }

bool same(const SurfaceHit& a, const SurfaceHit& b) {
  return a.prim == b.prim && same(a.t, b.t) && same(a.u, b.u) && same(a.v, b.v) && same(a.position, b.position) &&
         same(a.normal, b.normal) && same(a.geometric, b.geometric) && a.entering == b.entering &&
         same(a.texcoord.x, b.texcoord.x) && same(a.texcoord.y, b.texcoord.y) && a.material == b.material &&
         a.mask == b.mask;
}

struct Case {
  std::string name;
  Scene scene;
};

std::vector<Case> cases() {
  std::vector<Case> c;
  c.push_back({"toaster", load_scene(std::string(MOBIRT_SOURCE_DIR) + "/scenes/toaster.gltf")});
  c.push_back({"fish", load_scene(std::string(MOBIRT_SOURCE_DIR) + "/scenes/fish.gltf")});
  // A texture transform of its own per material (KHR_texture_transform), so that the eight lanes'
  // texture coordinates read each lane's material's matrix.
  Scene transformed = load_scene(std::string(MOBIRT_SOURCE_DIR) + "/scenes/toaster.gltf");
  for (size_t m = 0; m < transformed.materials.size(); ++m) {
    transformed.materials[m].texture_transform =
        texture_transform_matrix({0.25f - 0.1f * float(m), -0.5f}, 0.7f + 0.3f * float(m), {2.0f, 0.5f + float(m)});
  }
  c.push_back({"toaster-uv-transform", std::move(transformed)});
  c.push_back({"shapes", test::shapes_scene()});
  c.push_back({"box-grid", test::box_grid_scene()});  // a directional light beside a point light
  c.push_back({"soup-spot", test::random_soup_scene(2000)});  // a spot light: the scalar shadow count
  return c;
}

// The texels the traversal pass would return for `rays` (the CPU walk, full stack), every 61st
// ray marked capped so that the CPU retrace is part of the comparison.
std::vector<uint32_t> pass_texels(const Scene& scene, const FlatKdTree& tree, const RayBatch& rays, Packing packing,
                                  const ShadowSettings& shadows) {
  std::vector<uint32_t> texels(rays.count());
  for (uint32_t i = 0; i < rays.count(); ++i) {
    if (i % 61 == 7) {
      texels[i] = pack_capped(packing);
      continue;
    }
    const Ray ray = rays.ray(i);
    const Hit h = traverse(tree, ray, -1, shadows.ray_test);
    const uint32_t mask = h.valid() ? shadow_mask(tree, scene.lights, h.prim, ray, h.t, shadows, -1) : 0u;
    texels[i] = pack_trace(packing, uint32_t(h.prim + 1), mask);
  }
  return texels;
}

void expect_decode_matches_reference(const Case& c, const ShadowSettings& shadows) {
  const Scene& scene = c.scene;
  const FlatKdTree tree = build_kdtree(scene.mesh.positions, scene.shapes);
  const Packing packing = choose_packing(scene.primitive_count(), int(scene.lights.size()), scene.source);
  const int w = 120, h = 72;
  const Camera camera = scene.camera ? *scene.camera : frame_box(scene.bounds(), 0.7854f, float(w) / float(h));
  RayBatch rays = primary_rays(camera, w, h);
  for (int generation = 0; generation < 2 && rays.count() > 0; ++generation) {
    SCOPED_TRACE(c.name + " generation " + std::to_string(generation));
    std::vector<uint32_t> texels = pass_texels(scene, tree, rays, packing, shadows);
    DecodeStats stats;
    const SurfaceHits hits = decode_hits(scene, tree, rays, texels, packing, scene.lights, shadows, &stats);
    ASSERT_EQ(hits.size(), rays.count());
    uint32_t ref_hits = 0, ref_capped = 0, mismatches = 0;
    uint64_t ref_shadow = 0;  // shadow_ray_count(): the CPU's facing test for every light
    uint64_t ref_cast = 0;    // lights the mask calls visible, or that test passes
    for (uint32_t i = 0; i < rays.count(); ++i) {
      const TraceTexel texel = unpack_trace(packing, texels[i]);
      const Ray ray = rays.ray(i);
      SurfaceHit ref;
      if (texel.capped) {
        ++ref_capped;
        ref = retrace_capped(scene, tree, ray, scene.lights, shadows);
      } else if (texel.hit()) {
        ref = surface_hit(scene, tree, ray, texel.prim(), shadows.ray_test.test);
        ref.mask = texel.mask;
        ref_shadow += shadow_ray_count(tree, scene.lights, texel.prim(), ray, ref.t, shadows);
        const auto cast = shadow_rays(tree, scene.lights, texel.prim(), ray, ref.t, shadows);
        for (size_t l = 0; l < cast.size(); ++l) ref_cast += ((texel.mask >> l) & 1u) || cast[l].has_value();
      }
      if (ref.valid()) ++ref_hits;
      if (!same(hits[i], ref) && ++mismatches <= 3) {
        ADD_FAILURE() << "ray " << i << " decoded differently";
      }
    }
    EXPECT_EQ(mismatches, 0u);
    EXPECT_GT(ref_hits, 0u);
    EXPECT_EQ(stats.hits, ref_hits);
    EXPECT_EQ(stats.capped, ref_capped);
    EXPECT_EQ(stats.shadow_rays, ref_cast);
    // The pass and the decoding test the same t unless the pass runs in mediump: then a grazing
    // light may be cast to by the pass and not by the CPU's test.
    if (shadows.ray_test.precision == Precision::High) {
      EXPECT_EQ(ref_cast, ref_shadow);
    }

    // With every shadow bit cleared the count falls back to the facing test for every light and
    // must still give the reference count (it never sees a set bit to trust).
    for (uint32_t& t : texels) {
      const TraceTexel texel = unpack_trace(packing, t);
      if (!texel.capped) {
        t = pack_trace(packing, texel.prim_plus_one, 0);
      }
    }
    DecodeStats dark;
    (void)decode_hits(scene, tree, rays, texels, packing, scene.lights, shadows, &dark);
    EXPECT_EQ(dark.shadow_rays, ref_shadow);
    if (!scene.lights.empty()) {
      EXPECT_GT(ref_shadow, 0u);
    }

    rays = next_generation(scene, tree.bounds, rays, hits, SecondarySettings{shadows.offset});
  }
}

// SurfaceHits keeps a record for each hit and a byte per ray: a miss, however it is marked (set()
// with a miss record, set_miss()), reads as SurfaceHit{} and its record is not touched; copy_of()
// and the range-for see the same records as operator[].
TEST(SurfaceHits, MissesReadAsEmptyRecordsHitsAsWritten) {
  SurfaceHit hit;
  hit.prim = 7;
  hit.t = 2.5f;
  hit.mask = 0b11u;
  SurfaceHit miss_with_data = hit;
  miss_with_data.prim = -1;  // a miss, whatever else it holds
  SurfaceHits hits(4);
  hits.set(0, hit);
  hits.set(1, miss_with_data);
  hits.set_miss(2);
  hits.record(3) = hit;
  hits.record(3).prim = 9;
  hits.set_hit(3);
  EXPECT_TRUE(hits.hit(0));
  EXPECT_FALSE(hits.hit(1));
  EXPECT_FALSE(hits.hit(2));
  EXPECT_TRUE(hits.hit(3));
  EXPECT_TRUE(same(hits[0], hit));
  EXPECT_TRUE(same(hits[1], SurfaceHit{}));
  EXPECT_TRUE(same(hits[2], SurfaceHit{}));
  EXPECT_EQ(hits[3].prim, 9);
  EXPECT_EQ(hits.hit_flags()[0] + hits.hit_flags()[1] + hits.hit_flags()[2] + hits.hit_flags()[3], 2);
  // A hit marked a miss later reads as a miss.
  hits.set(0, miss_with_data);
  EXPECT_TRUE(same(hits[0], SurfaceHit{}));
  const std::vector<SurfaceHit> records = {hit, SurfaceHit{}, miss_with_data};
  const SurfaceHits copy = SurfaceHits::copy_of(records);
  ASSERT_EQ(copy.size(), 3u);
  uint32_t i = 0;
  for (const SurfaceHit& r : copy) {
    EXPECT_TRUE(same(r, copy[i]));
    EXPECT_EQ(copy.hit(i), records[i].valid());
    ++i;
  }
  EXPECT_EQ(i, 3u);
  EXPECT_TRUE(same(copy[0], hit));
  EXPECT_TRUE(same(copy[2], SurfaceHit{}));
}

// decode_hits() makes its records and hit bytes in memory it does not clear first (SurfaceHits):
// every ray must be marked, and a miss reads as SurfaceHit{}. Decoding a batch of hits and then the
// same batch as misses hands the second call the first one's freed blocks (the same sizes, just
// freed): a miss left unmarked would still read as a hit.
TEST(DecodeHits, EveryMissIsWrittenAsAMiss) {
  const Scene scene = load_scene(std::string(MOBIRT_SOURCE_DIR) + "/scenes/toaster.gltf");
  const FlatKdTree tree = build_kdtree(scene.mesh.positions, scene.shapes);
  const Packing packing = choose_packing(scene.primitive_count(), int(scene.lights.size()), scene.source);
  const int w = 120, h = 72;
  const Camera camera = scene.camera ? *scene.camera : frame_box(scene.bounds(), 0.7854f, float(w) / float(h));
  const RayBatch rays = primary_rays(camera, w, h);
  const ShadowSettings shadows;
  std::vector<uint32_t> texels = pass_texels(scene, tree, rays, packing, shadows);
  size_t hit_count = 0;
  {
    const SurfaceHits hits = decode_hits(scene, tree, rays, texels, packing, scene.lights, shadows);
    for (const SurfaceHit& hit : hits) hit_count += hit.valid();
  }
  ASSERT_GT(hit_count, rays.count() / 4) << "the camera must see the toaster";
  for (uint32_t& t : texels) t = pack_trace(packing, 0, 0);
  const SurfaceHits misses = decode_hits(scene, tree, rays, texels, packing, scene.lights, shadows);
  ASSERT_EQ(misses.size(), rays.count());
  size_t wrong = 0;
  for (const SurfaceHit& miss : misses) wrong += !same(miss, SurfaceHit{});
  EXPECT_EQ(wrong, 0u);
}

// Without shadows (no lights passed, every mask 0) mask_or makes the given lights visible on every
// hit, capped ones included, and leaves misses alone: what the frame loop once did in a pass of
// its own.
TEST(DecodeHits, MaskOrLightsEveryHit) {
  const Scene scene = load_scene(std::string(MOBIRT_SOURCE_DIR) + "/scenes/toaster.gltf");
  const FlatKdTree tree = build_kdtree(scene.mesh.positions, scene.shapes);
  const Packing packing = choose_packing(scene.primitive_count(), int(scene.lights.size()), scene.source);
  const Camera camera = scene.camera ? *scene.camera : frame_box(scene.bounds(), 0.7854f, 120.0f / 72.0f);
  const RayBatch rays = primary_rays(camera, 120, 72);
  ShadowSettings shadows;
  std::vector<uint32_t> texels(rays.count());
  for (uint32_t i = 0; i < rays.count(); ++i) {
    const Hit h = traverse(tree, rays.ray(i), -1, shadows.ray_test);
    texels[i] = i % 61 == 7 ? pack_capped(packing) : pack_trace(packing, uint32_t(h.prim + 1), 0u);
  }
  DecodeStats stats;
  const SurfaceHits hits = decode_hits(scene, tree, rays, texels, packing, {}, shadows, &stats, 0b101u);
  ASSERT_GT(stats.hits, 0u);
  ASSERT_GT(stats.capped, 0u);
  EXPECT_EQ(stats.shadow_rays, 0u);
  uint32_t lit = 0;
  for (uint32_t i = 0; i < rays.count(); ++i) {
    if (!hits[i].valid()) {
      EXPECT_EQ(hits[i].mask, 0u) << "ray " << i;
      continue;
    }
    EXPECT_EQ(hits[i].mask, 0b101u) << "ray " << i;
    ++lit;
  }
  EXPECT_EQ(lit, stats.hits);
}

TEST(DecodeHits, MatchesPerRayReferenceBitForBit) {
  for (const Case& c : cases()) expect_decode_matches_reference(c, ShadowSettings{});
}

TEST(DecodeHits, MatchesUnderWatertightAndNormalUlp) {
  ShadowSettings s;
  s.ray_test.test = IntersectTest::Watertight;
  s.offset.mode = OffsetMode::NormalUlp;
  for (const Case& c : cases()) expect_decode_matches_reference(c, s);
}

// The vectorised decoding's shadow-ray count under both offsets it handles (scaled is the default).
TEST(DecodeHits, MatchesUnderFixedOffset) {
  ShadowSettings s;
  s.offset.mode = OffsetMode::Fixed;
  s.offset.epsilon = 1e-3f;
  for (const Case& c : cases()) expect_decode_matches_reference(c, s);
}

TEST(DecodeHits, MatchesUnderMediumpAndFixedOffset) {
  ShadowSettings s;
  s.ray_test.precision = Precision::Medium;
  s.offset.mode = OffsetMode::Fixed;
  s.offset.epsilon = 1e-4f;
  for (const Case& c : cases()) expect_decode_matches_reference(c, s);
}

}  // namespace
}  // namespace mobirt
