// Reliability (issue 8): fuzz findings replayed, synchronization validation on a real render, and a
// corrupted kd-tree that must end the traversal pass within its loop cap and be reported instead
// of hanging, on the GPU and in the CPU fallback.
#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "accel/kdtree.h"
#include "backend/backend.h"
#include "core/camera.h"
#include "layout.h"
#include "core/error.h"
#include "fuzz/scene_fuzz_one.h"
#include "raytree/hits.h"
#include "raytree/packing.h"
#include "raytree/rays.h"
#include "render/renderer.h"
#include "scene/loader.h"
#include "test_scenes.h"
#include "test_support.h"
#include "texels.h"
#include "vulkan_fixture.h"

namespace mobirt {
namespace {

namespace fs = std::filesystem;

std::vector<uint8_t> read_bytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::vector<uint8_t>(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

// Every file in tests/fuzz/regressions/ (inputs that once crashed, hung or leaked) and the seed
// corpus goes through the fuzz target's code path; each must end normally or in a mobirt::Error
// (run_one catches those), never in a crash; under MOBIRT_SANITIZE any sanitizer report fails.
TEST(FuzzRegressions, EveryFileLoadsOrIsRefused) {
  int files = 0;
  for (const char* folder : {"regressions", "corpus"}) {
    const fs::path dir = fs::path(MOBIRT_SOURCE_DIR) / "tests" / "fuzz" / folder;
    if (!fs::is_directory(dir)) continue;
    for (const auto& entry : fs::directory_iterator(dir)) {
      if (!entry.is_regular_file() || entry.path().filename() == "README.md") continue;
      SCOPED_TRACE(entry.path().string());
      const std::vector<uint8_t> bytes = read_bytes(entry.path());
      EXPECT_NO_THROW(fuzz::run_one(bytes.data(), bytes.size()));
      ++files;
    }
  }
  EXPECT_GE(files, 10);
}

// A required extension mobirt does not read is refused, naming the element and the extension
// (the seed tests/fuzz/corpus/gltf_required_ext, without its format byte, is such a file).
TEST(SceneValidation, UnsupportedRequiredExtensionIsRefused) {
  const std::vector<uint8_t> seed =
      read_bytes(fs::path(MOBIRT_SOURCE_DIR) / "tests" / "fuzz" / "corpus" / "gltf_required_ext");
  ASSERT_GT(seed.size(), 1u);
  const fs::path file = test::temp_dir() / "draco.gltf";
  std::ofstream(file, std::ios::binary).write(reinterpret_cast<const char*>(seed.data()) + 1,
                                              std::streamsize(seed.size() - 1));
  test::expect_bad_input([&] { (void)load_scene(file.string()); },
                         {"draco.gltf", "extensionsRequired[0]", "KHR_draco_mesh_compression", "not supported"});
}

// tinyobjloader reads a coordinate it cannot parse as 0; mobirt refuses it instead, naming the
// triangle ("nan", a decimal comma, garbage in a normal).
TEST(SceneValidation, UnparsableObjCoordinatesAreRefused) {
  const fs::path dir = test::temp_dir();
  const char* cases[][2] = {{"nan.obj", "v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n"},
                            {"comma.obj", "v 0 0 0 # origin\nv 1,5 0 0\nv 0 1 0\nf 1 2 3\n"},
                            {"normal.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 x\nf 1//1 2//1 3//1\n"}};
  for (const auto& c : cases) {
    std::ofstream(dir / c[0]) << c[1];
    test::expect_bad_input([&] { (void)load_scene((dir / c[0]).string()); }, {c[0], "triangle 0", "non-finite"});
  }
  std::ofstream(dir / "fine.obj") << "v 0 0 0 # a comment\nv 1e0 0 0\r\nv 0 1 -0.0\nf 1 2 3\n";
  EXPECT_EQ(load_scene((dir / "fine.obj").string()).mesh.triangle_count(), 1u);
}

// The Khronos layer with synchronization validation: a whole frame with shadows, a mirror bounce
// and a second frame reusing the textures and passes reports nothing.
TEST(SyncValidation, RenderReportsNothing) {
  VulkanOptions options;
  options.validation = true;
  options.sync_validation = true;
  auto backend = create_vulkan_backend(options);
  RenderSettings settings;
  settings.width = 48;
  settings.height = 32;
  settings.depth = 1;
  Renderer renderer(*backend, settings);
  const Scene scene = load_scene(MOBIRT_SOURCE_DIR "/scenes/default.gltf");
  ASSERT_TRUE(scene.camera.has_value());
  for (int frame = 0; frame < 2; ++frame) (void)renderer.render(scene, *scene.camera);
  const std::vector<std::string> messages = backend->take_debug_messages();
  EXPECT_TRUE(messages.empty()) << test::join(messages);
}

// A small scene with its tree, and the primary rays of a 32x24 image; `inside` marks the rays
// that enter the tree's box (the others miss before the walk starts).
struct Corruptible {
  Scene scene = test::box_grid_scene();
  FlatKdTree tree;
  RayBatch rays;
  std::vector<bool> inside;
  uint32_t entering = 0;
  uint32_t first_entering = 0;
  Corruptible() {
    tree = build_kdtree(scene.mesh.positions);
    rays = primary_rays(*scene.camera, 32, 24);
    for (uint32_t i = 0; i < rays.count(); ++i) {
      float t0 = 0.0f, t1 = 0.0f;
      inside.push_back(intersect_aabb(tree.bounds, rays.ray(i), t0, t1));
      if (inside.back() && entering++ == 0) first_entering = i;
    }
  }
};

// Trace `tree` on the GPU with a cap of `cap` steps: the pass must end, and quickly.
TraceResult trace_corrupt(Backend& backend, const Corruptible& c, const FlatKdTree& tree, int cap) {
  RenderSettings settings;
  settings.max_steps = cap;
  Renderer renderer(backend, settings);
  const auto start = std::chrono::steady_clock::now();
  TraceResult result = renderer.trace(c.scene, tree, c.rays);
  EXPECT_LT(elapsed_ms(start), 30000.0) << "the traversal pass did not end within its cap";
  return result;
}

// The Vulkan backend with a smaller texel-buffer limit, as a device with a smaller
// maxTexelBufferElements (or the 2^23 texels the shaders index) would have: refuses larger buffers
// with Error(BadInput), as the real one does, and counts the refusals.
class LimitedBackend final : public Backend {
 public:
  LimitedBackend(Backend& inner, uint32_t limit) : inner_(inner), limit_(limit) {}
  DeviceInfo device_info() const override { return inner_.device_info(); }
  TextureHandle create_texture(uint32_t width, uint32_t height, TexelFormat format) override {
    return inner_.create_texture(width, height, format);
  }
  TextureHandle create_texel_buffer(uint32_t texels, TexelFormat format) override {
    if (texels > limit_) {
      ++refused;
      throw Error(ErrorKind::BadInput, "a texel buffer of " + std::to_string(texels) + " texels exceeds the limit");
    }
    return inner_.create_texel_buffer(texels, format);
  }
  TextureHandle create_storage_buffer(uint32_t texels, TexelFormat format) override {
    return inner_.create_storage_buffer(texels, format);
  }
  void upload(TextureHandle texture, const void* data, size_t bytes) override { inner_.upload(texture, data, bytes); }
  void destroy(TextureHandle texture) override { inner_.destroy(texture); }
  PassHandle create_pass(const PassDesc& desc) override { return inner_.create_pass(desc); }
  void destroy(PassHandle pass) override { inner_.destroy(pass); }
  PassTiming run_pass(PassHandle pass, std::span<const TextureHandle> textures, std::span<const float> uniforms,
                      uint32_t width, uint32_t count, std::span<uint32_t> out) override {
    return inner_.run_pass(pass, textures, uniforms, width, count, out);
  }
  std::vector<std::string> take_debug_messages() override { return inner_.take_debug_messages(); }
  int refused = 0;

 private:
  Backend& inner_;
  uint32_t limit_;
};

// A tree of one leaf of `count` copies of a small triangle (entries and triangles: 3 texels each).
FlatKdTree one_leaf_tree(uint32_t count) {
  FlatKdTree tree;
  tree.bounds = Aabb{glm::vec3(-1.0f), glm::vec3(1.0f)};
  tree.nodes.push_back(node_texel::leaf(0.0f, float(count)));
  for (uint32_t i = 0; i < count; ++i) {
    const glm::vec4 v[3] = {glm::vec4(0.0f, 0.0f, 0.0f, 0.0f), glm::vec4(1e-3f, 0.0f, 0.0f, 0.0f),
                            glm::vec4(0.0f, 1e-3f, 0.0f, 0.0f)};
    for (const glm::vec4& t : v) tree.triangles.push_back(t);
    tree.leaf_prims.resize(tree.leaf_prims.size() + MOBIRT_TEXELS_PER_TRIANGLE);
    leaf_prim_texel::write(tree.leaf_prims.data() + tree.leaf_prims.size() - MOBIRT_TEXELS_PER_TRIANGLE, v,
                           int32_t(i));
  }
  return tree;
}

// The renderer grows its data textures with headroom (1.5x) so that an animation whose tree grows
// does not reallocate every frame. A frame whose tree fits under the backend's limit must not be
// refused because the headroom would not: the leaf entries of a 1M-triangle tree take about
// three quarters of the 2^23 texels a texel buffer holds. Here, with a limit of 5 rows of
// MOBIRT_DATA_WIDTH texels, a tree of 4 rows, then one of 5 (headroom: 6, refused), then one of 6.
TEST(DataTextures, GrowToTheExactSizeWhereTheHeadroomPassesTheLimit) {
  const std::unique_ptr<Backend> vulkan = create_vulkan_backend(test::validated_options());
  LimitedBackend backend(*vulkan, 5 * MOBIRT_DATA_WIDTH);
  const Scene scene = test::box_grid_scene();
  const RayBatch rays = primary_rays(*scene.camera, 8, 8);
  Renderer renderer(backend, RenderSettings{});
  const uint32_t per_row = MOBIRT_DATA_WIDTH / MOBIRT_TEXELS_PER_TRIANGLE;  // entries in a row of texels
  EXPECT_EQ(renderer.trace(scene, one_leaf_tree(4 * per_row - 10), rays).texels.size(), rays.count());
  EXPECT_EQ(backend.refused, 0);
  EXPECT_EQ(renderer.trace(scene, one_leaf_tree(5 * per_row - 10), rays).texels.size(), rays.count());
  EXPECT_GE(backend.refused, 1) << "the headroom was refused and the exact size taken";
  // More than the limit itself stays a clear error.
  try {
    (void)renderer.trace(scene, one_leaf_tree(6 * per_row - 10), rays);
    ADD_FAILURE() << "a tree over the backend's limit was accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::BadInput);
  }
  const std::vector<std::string> messages = vulkan->take_debug_messages();
  EXPECT_TRUE(messages.empty()) << test::join(messages);
}

// A tree whose one reachable leaf lies past 2^23 texels of the leaf-entry and triangle arrays (the
// size a scene of about 1M triangles at 3 references each fills): one_leaf_tree(far)'s entries and
// triangles, then the two triangles of a quad at z = 0, x in [0.1, 0.9], y in [-0.4, 0.4]
// (primitives far and far + 1). The root splits x at 0; its below leaf holds the `far` copies of
// the small triangle at the origin, outside the scene box (x from 0.05), so that no ray walks it;
// its above leaf, the arrays' last entries, the quad.
FlatKdTree far_leaf_tree(uint32_t far) {
  FlatKdTree tree = one_leaf_tree(far);
  tree.bounds = Aabb{glm::vec3(0.05f, -1.0f, -1.0f), glm::vec3(1.0f)};
  tree.nodes = {node_texel::interior(0.0f, 2.0f, 0.0f), node_texel::leaf(0.0f, float(far)),
                node_texel::leaf(float(far), 2.0f)};
  const glm::vec4 quad[2][3] = {
      {glm::vec4(0.1f, -0.4f, 0.0f, 0.0f), glm::vec4(0.9f, -0.4f, 0.0f, 0.0f), glm::vec4(0.9f, 0.4f, 0.0f, 0.0f)},
      {glm::vec4(0.1f, -0.4f, 0.0f, 0.0f), glm::vec4(0.9f, 0.4f, 0.0f, 0.0f), glm::vec4(0.1f, 0.4f, 0.0f, 0.0f)}};
  for (uint32_t q = 0; q < 2; ++q) {
    for (const glm::vec4& t : quad[q]) tree.triangles.push_back(t);
    tree.leaf_prims.resize(tree.leaf_prims.size() + MOBIRT_TEXELS_PER_TRIANGLE);
    leaf_prim_texel::write(tree.leaf_prims.data() + tree.leaf_prims.size() - MOBIRT_TEXELS_PER_TRIANGLE, quad[q],
                           int32_t(far + q));
  }
  return tree;
}

// Buffers of more than 2^23 texels: the texel-buffer passes are specialised to WIDE_INDICES and
// read the quad's entries and triangles (shadow rays) past 2^23 exactly, as the 2D images (indexed
// by coordinates) do. Until this, such a scene was refused on the default --data. About 0.8 GB of
// host memory at its peak (the arrays, the buffers, the images: lavapipe keeps all in host memory).
TEST(DataTextures, BuffersBeyond2To23TexelsAreIndexedExactly) {
  const std::unique_ptr<Backend> vulkan = create_vulkan_backend(test::validated_options());
  const uint32_t far = MOBIRT_NARROW_INDEX_TEXELS / MOBIRT_TEXELS_PER_TRIANGLE + 100;
  const FlatKdTree tree = far_leaf_tree(far);
  ASSERT_GT(tree.leaf_prims.size(), size_t(MOBIRT_NARROW_INDEX_TEXELS));
  ASSERT_GT(tree.triangles.size(), size_t(MOBIRT_NARROW_INDEX_TEXELS));
  Scene scene = test::box_grid_scene();  // its lights and primitive count only; the tree is the geometry
  Light light;
  light.position = {0.5f, 0.0f, 5.0f};
  light.intensity = 10.0f;
  scene.lights = {light};
  const RayBatch rays = primary_rays(Camera{{0.5f, 0.0f, 3.0f}, {0.5f, 0.0f, 0.0f}, {0.0f, 1.0f, 0.0f}, 0.3f, 0.0f}, 32, 24);
  RenderSettings settings;
  settings.data = DataReads::TexelBuffers;
  Renderer buffers(*vulkan, settings);
  settings.data = DataReads::Images;
  Renderer images(*vulkan, settings);
  const TraceResult got = buffers.trace(scene, tree, rays);
  const TraceResult want = images.trace(scene, tree, rays);
  ASSERT_EQ(got.texels.size(), rays.count());
  ASSERT_EQ(want.texels.size(), rays.count());
  uint32_t hits = 0;
  for (uint32_t i = 0; i < rays.count(); ++i) {
    EXPECT_EQ(got.texels[i], want.texels[i]) << "ray " << i;
    const TraceTexel t = unpack_trace(got.packing, got.texels[i]);
    EXPECT_FALSE(t.capped) << "ray " << i;
    if (!t.hit()) continue;
    ++hits;
    EXPECT_TRUE(t.prim() == int32_t(far) || t.prim() == int32_t(far) + 1) << "ray " << i << " hit " << t.prim();
    EXPECT_EQ(t.mask, 1u) << "ray " << i << ": the light faces the quad";
  }
  EXPECT_GT(hits, rays.count() / 4) << "the quad fills much of the view";
  EXPECT_LT(hits, rays.count()) << "and not all of it";
  const std::vector<std::string> messages = vulkan->take_debug_messages();
  EXPECT_TRUE(messages.empty()) << test::join(messages);
}

class CorruptTree : public test::VulkanTest {};

// An interior root whose "above" child is the root itself, split so that every ray goes there:
// a cycle. The GPU walk stops at the cap and flags every ray capped (index 0 with shadow bits);
// the CPU fallback then refuses the tree with "kd-tree corrupt" instead of looping forever.
TEST_F(CorruptTree, CycleEndsWithinTheCapAndIsReported) {
  Corruptible c;
  FlatKdTree cyclic = c.tree;
  cyclic.nodes[0] = glm::vec4(-1e30f, 0.0f, 0.0f, 0.0f);  // split x = -1e30, above child = node 0
  const TraceResult traced = trace_corrupt(*backend, c, cyclic, 256);
  ASSERT_EQ(traced.texels.size(), c.rays.count());
  ASSERT_GT(c.entering, 100u);
  uint32_t capped = 0;
  for (uint32_t i = 0; i < c.rays.count(); ++i) {
    const TraceTexel t = unpack_trace(traced.packing, traced.texels[i]);
    capped += t.capped ? 1 : 0;
    if (!c.inside[i]) {
      EXPECT_FALSE(t.hit() || t.capped) << "ray " << i << " misses the box";
    }
  }
  EXPECT_EQ(capped, c.entering) << "every ray that enters the box walks the cycle and must come back capped";
  try {
    (void)decode_hits(c.scene, cyclic, c.rays, traced.texels, traced.packing, c.scene.lights, ShadowSettings{});
    ADD_FAILURE() << "decode_hits accepted a cyclic tree";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::Internal);
    EXPECT_NE(std::string(e.what()).find("kd-tree corrupt"), std::string::npos) << e.what();
  }
  // The CPU traversal alone: bounded by its cap, flagged capped.
  TraversalStats stats;
  const Hit h = traverse(cyclic, c.rays.ray(c.first_entering), -1, stats, 1000);
  EXPECT_FALSE(h.valid());
  EXPECT_EQ(stats.capped, 1u);
}

// The root's "above" child far beyond the node array. The GPU pass must end within the cap (what
// an out-of-range texel fetch returns is the driver's business: every ray comes back capped, a
// miss or a real primitive, never garbage); the CPU traversal refuses the index.
TEST_F(CorruptTree, OutOfRangeChildEndsWithinTheCapAndIsReported) {
  Corruptible c;
  FlatKdTree broken = c.tree;
  const float outside = float(broken.nodes.size() + 100000);
  broken.nodes[0] = glm::vec4(-1e30f, outside, 0.0f, 0.0f);
  const TraceResult traced = trace_corrupt(*backend, c, broken, 256);
  ASSERT_EQ(traced.texels.size(), c.rays.count());
  uint32_t capped = 0;
  for (uint32_t texel : traced.texels) {
    const TraceTexel t = unpack_trace(traced.packing, texel);
    capped += t.capped ? 1 : 0;
    if (t.hit() && !t.capped) {
      EXPECT_LT(uint32_t(t.prim()), c.scene.mesh.triangle_count());
    }
  }
  std::printf("out-of-range child: %u of %u rays capped on the GPU\n", capped, c.rays.count());
  try {
    (void)traverse(broken, c.rays.ray(c.first_entering), -1);
    ADD_FAILURE() << "the CPU traversal followed an out-of-range child";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::Internal);
    EXPECT_NE(std::string(e.what()).find("kd-tree corrupt"), std::string::npos) << e.what();
  }
  if (capped > 0) {
    EXPECT_THROW(
        (void)decode_hits(c.scene, broken, c.rays, traced.texels, traced.packing, c.scene.lights, ShadowSettings{}),
        Error);
  }
}

}  // namespace
}  // namespace mobirt
