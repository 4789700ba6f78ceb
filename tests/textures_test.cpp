// Textures end to end, from generated glTF files: 40 textures (three atlas pages) each show on
// their own quad on Vulkan and GLES; 49 are refused with the count; KHR_texture_transform maps
// texture coordinates as the extension specifies in the loader, on the CPU, on the GPU and in the
// reference; a lone 1024x1024 texture keeps its resolution (>= 45 dB against the reference, which
// samples the original image).
#include <gtest/gtest.h>

#include <OpenImageIO/imageio.h>
#include <glm/gtc/matrix_transform.hpp>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "backend/backend.h"
#include "reference/reference.h"
#include "render/cpu_render.h"
#include "render/renderer.h"
#include "scene/atlas.h"
#include "scene/loader.h"
#include "scene/texture_images.h"
#include "gltf_builder.h"
#include "test_support.h"
#include "vulkan_fixture.h"

namespace mobirt {
namespace {

using json = nlohmann::json;

// ---- helpers -----------------------------------------------------------------------------------

// An RGB PNG of width x height whose texel (x, y) is colour(x, y) (8-bit sRGB values).
void write_png(const std::filesystem::path& path, int width, int height,
               const std::function<glm::ivec3(int, int)>& colour) {
  std::vector<uint8_t> rgb;
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const glm::ivec3 c = colour(x, y);
      rgb.insert(rgb.end(), {uint8_t(c.x), uint8_t(c.y), uint8_t(c.z)});
    }
  }
  auto out = OIIO::ImageOutput::create(path.string());
  ASSERT_TRUE(out && out->open(path.string(), OIIO::ImageSpec(width, height, 3, OIIO::TypeDesc::UINT8)));
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, rgb.data()));
  out->close();
}

glm::vec3 linear(const glm::ivec3& c) {
  return glm::vec3(srgb_to_linear(float(c.x) / 255.0f), srgb_to_linear(float(c.y) / 255.0f),
                   srgb_to_linear(float(c.z) / 255.0f));
}

// A glTF of textured quads facing +z: quad k spans [x0, x1] x [y0, y1] at z = 0, texture
// coordinates (0, 0) at its top-left corner, and its own material and texture (an image file).
struct QuadScene {
  test::Gltf gltf;
  std::vector<int> nodes;
  glm::mat3 tilt{1.0f};  // turns the quads' plane z = 0 (and the backdrop) in the world

  // `texture_info` extends the material's baseColorTexture entry (extensions, texCoord);
  // `extra_texcoords` adds TEXCOORD_1 with these values (top-left, bottom-left, bottom-right, top-right).
  void quad(glm::vec2 lo, glm::vec2 hi, const std::string& image_uri, json texture_info = json::object(),
            const std::vector<glm::vec2>& texcoords0 = {{0, 0}, {0, 1}, {1, 1}, {1, 0}},
            const std::vector<glm::vec2>& texcoords1 = {}) {
    json attributes = {{"POSITION", corners(lo, hi, 0.0f)}, {"TEXCOORD_0", gltf.vec2s(texcoords0)}};
    if (!texcoords1.empty()) attributes["TEXCOORD_1"] = gltf.vec2s(texcoords1);
    const int indices = gltf.u16s({0, 1, 2, 0, 2, 3});
    const int k = int(gltf.doc["materials"].size());
    const int texture = int(gltf.doc["textures"].size());
    gltf.doc["images"].push_back({{"uri", image_uri}});
    gltf.doc["textures"].push_back({{"source", texture}});
    texture_info["index"] = texture;
    // Not metallic: the diffuse colour is the base colour, nothing reflects.
    gltf.doc["materials"].push_back(
        {{"pbrMetallicRoughness", {{"baseColorTexture", texture_info}, {"metallicFactor", 0.0}, {"roughnessFactor", 1.0}}}});
    const int mesh = gltf.mesh({{"attributes", attributes}, {"indices", indices}, {"material", k}});
    nodes.push_back(gltf.node({{"mesh", mesh}}));
  }
  // An untextured dark quad at depth z behind the others.
  void backdrop(glm::vec2 lo, glm::vec2 hi, float z) {
    const int positions = corners(lo, hi, z);
    const int indices = gltf.u16s({0, 1, 2, 0, 2, 3});
    const int k = int(gltf.doc["materials"].size());
    gltf.doc["materials"].push_back({{"pbrMetallicRoughness", {{"baseColorFactor", {0.02, 0.02, 0.02, 1.0}},
                                                               {"metallicFactor", 0.0}}}});
    const int mesh = gltf.mesh({{"attributes", {{"POSITION", positions}}}, {"indices", indices}, {"material", k}});
    nodes.push_back(gltf.node({{"mesh", mesh}}));
  }
  // Top-left, bottom-left, bottom-right, top-right at depth z, tilted.
  int corners(glm::vec2 lo, glm::vec2 hi, float z) {
    std::vector<glm::vec3> p = {{lo.x, hi.y, z}, {lo.x, lo.y, z}, {hi.x, lo.y, z}, {hi.x, hi.y, z}};
    for (glm::vec3& v : p) v = tilt * v;
    return gltf.vec3s(p);
  }
  std::string write(const std::filesystem::path& path) {
    gltf.scene(nodes);
    return gltf.write_gltf(path);
  }
};

// Lit by its ambient term alone (no lights, ambient factor 1): each pixel is its texel, decoded.
Scene load_unlit(const std::string& path) {
  Scene scene = load_scene(path);
  for (Material& m : scene.materials) m.ambient = 1.0f;
  scene.lights.clear();
  return scene;
}

// A camera at (centre, distance) looking down -z whose view spans `half_height` above and below.
Camera camera_over(glm::vec2 centre, float half_height, float distance = 5.0f) {
  return Camera{{centre.x, centre.y, distance}, {centre.x, centre.y, 0}, {0, 1, 0},
                2.0f * std::atan(half_height / distance), 0.0f};
}

enum class Api { Vulkan, Gles };

std::unique_ptr<Backend> make_backend(Api api) {
  return api == Api::Vulkan ? create_vulkan_backend(test::validated_options())
                            : create_gles_backend(test::validated_options());
}

class TexturesPerBackend : public ::testing::TestWithParam<Api> {
 protected:
  void SetUp() override { backend = make_backend(GetParam()); }
  void TearDown() override {
    if (!backend) return;
    const std::vector<std::string> messages = backend->take_debug_messages();
    EXPECT_TRUE(messages.empty()) << test::join(messages);
  }
  std::unique_ptr<Backend> backend;
};

const char* api_name(const testing::TestParamInfo<Api>& p) { return p.param == Api::Vulkan ? "vulkan" : "gles"; }

// ---- 40 textures: three atlas pages ------------------------------------------------------------

// Texture i: 4x4 texels in 2x2 blocks, the top-left block colour_a(i), the bottom-right one
// colour_b(i), the other two grey; every texture's pair differs from every other's.
glm::ivec3 colour_a(int i) { return {10 + 6 * i, 250 - 5 * i, (37 * i) % 256}; }
glm::ivec3 colour_b(int i) { return {(91 * i + 40) % 256, 20 + 4 * i, 240 - 6 * i}; }

constexpr int kColumns = 8, kRows = 5, kQuads = kColumns * kRows;

// The grid's plane flat (z = 0, a split plane of the kd-tree, whose pixel centres fall on the
// quads' diagonals: Möller-Trumbore once let ~0.5 % of them through both triangles, and GLES's
// hits that the CPU's recomputation rejected took the centroid's texel) and turned a little about
// y and x.
const glm::mat3 kGridTilts[] = {glm::mat3(1.0f), glm::mat3(glm::rotate(glm::mat4(1.0f), 0.12f, glm::vec3(0, 1, 0)) *
                                                           glm::rotate(glm::mat4(1.0f), 0.08f, glm::vec3(1, 0, 0)))};

std::string forty_textures_gltf(const std::filesystem::path& dir, int count, const glm::mat3& tilt = kGridTilts[0]) {
  QuadScene s;
  s.tilt = tilt;
  for (int i = 0; i < count; ++i) {
    const std::string name = "t" + std::to_string(i) + ".png";
    write_png(dir / name, 4, 4, [&](int x, int y) {
      if (x < 2 && y < 2) return colour_a(i);
      if (x >= 2 && y >= 2) return colour_b(i);
      return glm::ivec3(128);
    });
    // Quads of 0.8 centred in the cells of a grid of 1: column c spans x in [c - 4, c - 3], row r
    // (0 at the top) y in [1.5 - r, 2.5 - r].
    const glm::vec2 lo(float(i % kColumns) - 3.9f, 1.6f - float(i / kColumns % kRows));
    s.quad(lo, lo + glm::vec2(0.8f), name);
  }
  s.backdrop({-5.0f, -3.0f}, {5.0f, 3.0f}, -1.0f);
  return s.write(dir / "forty.gltf");
}

TEST_P(TexturesPerBackend, FortyTexturesEachShowOnTheirOwnQuad) {
  for (const glm::mat3& tilt : kGridTilts) {
    SCOPED_TRACE(tilt == glm::mat3(1.0f) ? "flat grid" : "tilted grid");
    const auto dir = test::temp_dir();
    const Scene scene = load_unlit(forty_textures_gltf(dir, kQuads, tilt));
    ASSERT_EQ(scene.textures.size(), size_t(kQuads));
    EXPECT_EQ(build_atlas(scene).page_count(), 3) << "40 textures: 16 + 16 + 8 tiles";
    // About 33 x 33 pixels per grid cell.
    const int width = 320, height = 200;
    RenderSettings settings;
    settings.width = width;
    settings.height = height;
    Renderer renderer(*backend, settings);
    const Camera camera = camera_over({0.0f, 0.0f}, 3.0f);
    const Image image = renderer.render(scene, camera);
    const glm::vec3 normal = tilt * glm::vec3(0, 0, 1);
    size_t checked = 0, wrong = 0;
    std::vector<int> per_quad(kQuads, 0);
    for (int py = 0; py < height; ++py) {
      for (int px = 0; px < width; ++px) {
        // Where the pixel's ray meets the grid's plane, in the grid's own coordinates.
        const Ray ray = camera_ray(camera, width, height, float(px) + 0.5f, float(py) + 0.5f);
        const float t = -glm::dot(normal, ray.origin) / glm::dot(normal, ray.direction);
        const glm::vec3 local = glm::transpose(tilt) * (ray.origin + t * ray.direction);
        const float x = local.x, y = local.y;
        const int column = int(std::floor(x + 4.0f)), row = int(std::floor(2.5f - y));
        if (column < 0 || column >= kColumns || row < 0 || row >= kRows) continue;
        // Texture coordinates on the quad of that cell; blocks are pure where the 4 texels of the
        // bilinear lookup lie in one block (uv within [1/8, 3/8] of it), here with a margin.
        const float u = (x - (float(column) - 3.9f)) / 0.8f;
        const float v = ((2.4f - float(row)) - y) / 0.8f;
        const int i = row * kColumns + column;
        glm::vec3 want;
        if (u > 0.14f && u < 0.36f && v > 0.14f && v < 0.36f) {
          want = linear(colour_a(i));
        } else if (u > 0.64f && u < 0.86f && v > 0.64f && v < 0.86f) {
          want = linear(colour_b(i));
        } else {
          continue;
        }
        ++checked;
        ++per_quad[size_t(i)];
        const glm::vec3 got = image.at(px, py);
        const float error = glm::max(glm::max(std::abs(got.x - want.x), std::abs(got.y - want.y)), std::abs(got.z - want.z));
        if (error > 1.5f / 255.0f && ++wrong <= 5) {
          ADD_FAILURE() << "quad " << i << " pixel " << px << ", " << py << ": got " << got.x << " " << got.y << " "
                        << got.z << ", want " << want.x << " " << want.y << " " << want.z;
        }
      }
    }
    EXPECT_EQ(wrong, 0u) << "of " << checked << " pixels";
    for (int i = 0; i < kQuads; ++i) EXPECT_GE(per_quad[size_t(i)], 30) << "quad " << i << " is in view";
  }
}

TEST(Textures, FortyNineTexturesAreRefusedWithTheCount) {
  const auto dir = test::temp_dir();
  const std::string path = forty_textures_gltf(dir, 49);
  const Scene scene = load_scene(path);
  const std::unique_ptr<Backend> backend = make_backend(Api::Vulkan);
  Renderer renderer(*backend, RenderSettings{});
  test::expect_bad_input([&] { renderer.render(scene, camera_over({0.0f, 0.0f}, 2.5f)); },
                         {path, "49 textures", "at most 48", "3 pages", "merge textures"});
  // The command line: one line, exit code 2, no image.
  const std::filesystem::path out = dir / "out.png";
  const test::CommandResult r = test::run_mobirt("render " + path + " --size 32x20 -o " + out.string());
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("49 textures, but the texture atlas holds at most 48"), std::string::npos) << r.output;
  EXPECT_FALSE(std::filesystem::exists(out));
}

// ---- KHR_texture_transform ---------------------------------------------------------------------

// The extension's own formula, written out: scale, rotate (u' = cos u + sin v, v' = -sin u + cos
// v), offset.
glm::vec2 spec_transform(glm::vec2 uv, glm::vec2 offset, float rotation, glm::vec2 scale) {
  const glm::vec2 s = uv * scale;
  const float c = std::cos(rotation), n = std::sin(rotation);
  return offset + glm::vec2(c * s.x + n * s.y, -n * s.x + c * s.y);
}

json transform_json(glm::vec2 offset, float rotation, glm::vec2 scale) {
  return {{"extensions",
           {{"KHR_texture_transform", {{"offset", {offset.x, offset.y}}, {"rotation", rotation}, {"scale", {scale.x, scale.y}}}}}}};
}

void expect_uv(glm::vec2 got, glm::vec2 want) {
  EXPECT_NEAR(got.x, want.x, 1e-6f);
  EXPECT_NEAR(got.y, want.y, 1e-6f);
}

TEST(TextureTransform, TheExtensionsExamplesMapAsItSays) {
  const auto dir = test::temp_dir();
  write_png(dir / "t.png", 2, 2, [](int, int) { return glm::ivec3(200); });
  QuadScene s;
  // "This example utilizes only the lower left quadrant of the source image, rotated clockwise 90°."
  s.quad({0, 0}, {1, 1}, "t.png", transform_json({0, 1}, 1.57079632679f, {0.5f, 0.5f}));
  // "This example inverts the T axis, effectively defining a bottom-left origin."
  s.quad({2, 0}, {3, 1}, "t.png", transform_json({0, 1}, 0.0f, {1, -1}));
  s.quad({4, 0}, {5, 1}, "t.png");
  s.gltf.doc["extensionsUsed"] = {"KHR_texture_transform"};
  s.gltf.doc["extensionsRequired"] = {"KHR_texture_transform"};
  const Scene scene = load_scene(s.write(dir / "examples.gltf"));
  ASSERT_EQ(scene.materials.size(), 3u);
  const glm::mat3& quadrant = scene.materials[0].texture_transform;
  // The unit square onto [0, 0.5] x [0.5, 1] (v down: the lower left), turned: the image's
  // bottom-left corner at the quad's top-left, so the image appears turned clockwise.
  expect_uv(transform_texcoord(quadrant, {0, 0}), {0.0f, 1.0f});
  expect_uv(transform_texcoord(quadrant, {1, 0}), {0.0f, 0.5f});
  expect_uv(transform_texcoord(quadrant, {0, 1}), {0.5f, 1.0f});
  expect_uv(transform_texcoord(quadrant, {1, 1}), {0.5f, 0.5f});
  const glm::mat3& flip = scene.materials[1].texture_transform;
  expect_uv(transform_texcoord(flip, {0.25f, 0.0f}), {0.25f, 1.0f});
  expect_uv(transform_texcoord(flip, {0.75f, 0.25f}), {0.75f, 0.75f});
  EXPECT_EQ(scene.materials[2].texture_transform, glm::mat3(1.0f)) << "no extension: identity";
  // Any offset, rotation and scale: the extension's formula.
  const glm::vec2 offset(0.3f, -0.2f), scale(1.5f, 0.7f);
  const float rotation = 0.4f;
  const glm::mat3 m = texture_transform_matrix(offset, rotation, scale);
  for (const glm::vec2 uv : {glm::vec2(0, 0), glm::vec2(1, 0), glm::vec2(0.3f, 0.9f), glm::vec2(-2, 3.5f)}) {
    expect_uv(transform_texcoord(m, uv), spec_transform(uv, offset, rotation, scale));
  }
}

TEST(TextureTransform, TexCoordSelectsTheSet) {
  const auto dir = test::temp_dir();
  write_png(dir / "t.png", 2, 2, [](int, int) { return glm::ivec3(200); });
  const std::vector<glm::vec2> junk = {{9, 9}, {9, 9}, {9, 9}, {9, 9}};
  const std::vector<glm::vec2> set1 = {{0.1f, 0.2f}, {0.3f, 0.4f}, {0.5f, 0.6f}, {0.7f, 0.8f}};
  QuadScene s;
  json by_extension = transform_json({0, 0}, 0.0f, {1, 1});
  by_extension["extensions"]["KHR_texture_transform"]["texCoord"] = 1;  // overrides texCoord 0
  s.quad({0, 0}, {1, 1}, "t.png", by_extension, junk, set1);
  s.quad({2, 0}, {3, 1}, "t.png", json{{"texCoord", 1}}, junk, set1);
  s.quad({4, 0}, {5, 1}, "t.png", json::object(), set1, junk);
  const Scene scene = load_scene(s.write(dir / "sets.gltf"));
  ASSERT_EQ(scene.mesh.texcoords.size(), 18u);
  // Each quad is two triangles (0, 1, 2) and (0, 2, 3) of its four corners.
  const int corners[6] = {0, 1, 2, 0, 2, 3};
  for (size_t k = 0; k < 18; ++k) {
    SCOPED_TRACE("corner " + std::to_string(k));
    expect_uv(scene.mesh.texcoords[k], set1[size_t(corners[k % 6])]);
  }
}

TEST(TextureTransform, BadValuesNameTheMaterial) {
  const auto dir = test::temp_dir();
  write_png(dir / "t.png", 2, 2, [](int, int) { return glm::ivec3(200); });
  const json cases[] = {
      {{"offset", {1.0}}},
      {{"scale", {"a", 1.0}}},
      {{"rotation", "half"}},
      {{"scale", {1e39, 1.0}}},
      {{"texCoord", -1}},
      {{"texCoord", 0.5}},
  };
  const char* names[] = {"offset", "scale", "rotation", "scale", "texCoord", "texCoord"};
  for (size_t i = 0; i < std::size(cases); ++i) {
    QuadScene s;
    s.quad({0, 0}, {1, 1}, "t.png", json{{"extensions", {{"KHR_texture_transform", cases[i]}}}});
    const std::string path = s.write(dir / ("bad" + std::to_string(i) + ".gltf"));
    test::expect_bad_input([&] { load_scene(path); },
                           {path, "materials[0].pbrMetallicRoughness.baseColorTexture.extensions.KHR_texture_transform." +
                                      std::string(names[i])});
  }
}

// An 8x8 texture of 4x4 blocks of 2x2 texels, each block its own colour.
glm::ivec3 block_colour(int bx, int by) { return {30 + 60 * bx, 30 + 60 * by, 220 - 25 * (bx + 4 * by) % 200}; }

// Pixels of a 64x64 image of the unit quad [-1, 1]^2 whose transformed texture coordinate lies
// inside a block (all 4 texels of its bilinear lookup in that block, with a margin) show that
// block's colour. Returns the number of pixels checked.
size_t expect_transformed_blocks(const Image& image, glm::vec2 offset, float rotation, glm::vec2 scale,
                                 const char* what) {
  size_t checked = 0, wrong = 0;
  for (int py = 0; py < image.height; ++py) {
    for (int px = 0; px < image.width; ++px) {
      const glm::vec2 uv((float(px) + 0.5f) / float(image.width), (float(py) + 0.5f) / float(image.height));
      const glm::vec2 t = spec_transform(uv, offset, rotation, scale) * 4.0f;  // in blocks
      const glm::vec2 inside = t - glm::floor(t);
      if (glm::any(glm::lessThan(inside, glm::vec2(0.28f))) || glm::any(glm::greaterThan(inside, glm::vec2(0.72f)))) continue;
      const glm::ivec2 block = (glm::ivec2(glm::floor(t)) % 4 + 4) % 4;  // repeat wrap
      const glm::vec3 want = linear(block_colour(block.x, block.y));
      const glm::vec3 got = image.at(px, py);
      ++checked;
      const float error = glm::max(glm::max(std::abs(got.x - want.x), std::abs(got.y - want.y)), std::abs(got.z - want.z));
      if (error > 1.5f / 255.0f && ++wrong <= 5) {
        ADD_FAILURE() << what << ": pixel " << px << ", " << py << " (block " << block.x << ", " << block.y
                      << "): got " << got.x << " " << got.y << " " << got.z << ", want " << want.x << " " << want.y
                      << " " << want.z;
      }
    }
  }
  EXPECT_EQ(wrong, 0u) << what << ": of " << checked << " pixels";
  return checked;
}

struct TransformCase {
  glm::vec2 offset;
  float rotation;
  glm::vec2 scale;
};
const TransformCase kTransformCases[] = {
    {{0.0f, 1.0f}, 1.57079632679f, {0.5f, 0.5f}},  // the extension's lower-left-quadrant example
    {{0.1f, 0.2f}, 0.3f, {1.5f, 0.8f}},            // and one that wraps (REPEAT)
};

Scene transformed_quad(const std::filesystem::path& dir, const TransformCase& c) {
  write_png(dir / "blocks.png", 8, 8, [](int x, int y) { return block_colour(x / 2, y / 2); });
  QuadScene s;
  s.quad({-1, -1}, {1, 1}, "blocks.png", transform_json(c.offset, c.rotation, c.scale));
  return load_unlit(s.write(dir / "transformed.gltf"));
}

// The GPU path and the CPU engine (hit decoding forms the transformed uv for both).
TEST_P(TexturesPerBackend, TransformedTextureRendersAsTheExtensionMapsIt) {
  for (const TransformCase& c : kTransformCases) {
    const Scene scene = transformed_quad(test::temp_dir(), c);
    RenderSettings settings;
    settings.width = settings.height = 64;
    Renderer renderer(*backend, settings);
    const Camera camera = camera_over({0.0f, 0.0f}, 1.0f);
    const size_t gpu = expect_transformed_blocks(renderer.render(scene, camera), c.offset, c.rotation, c.scale, "GPU");
    EXPECT_GT(gpu, 64u * 64u / 8u);
    expect_transformed_blocks(render_on_cpu(scene, camera, settings), c.offset, c.rotation, c.scale, "CPU");
  }
}

TEST(TextureTransform, TheReferenceMapsItTheSameWay) {
  for (const TransformCase& c : kTransformCases) {
    const Scene scene = transformed_quad(test::temp_dir(), c);
    RenderSettings settings;
    settings.width = settings.height = 64;
    const ReferenceResult ref = render_reference(scene, camera_over({0.0f, 0.0f}, 1.0f), reference_settings(settings));
    EXPECT_GT(expect_transformed_blocks(ref.image, c.offset, c.rotation, c.scale, "reference"), 64u * 64u / 8u);
  }
}

// ---- tile edges: the gutters and the one filtered fetch against the reference ------------------

// A quad filling the view whose texture coordinates run from -1.3 to 2.4 (s) and -1.2 to 2.1 (t),
// so the image crosses every edge of a 5x3 texture of high-contrast random texels several times,
// in one wrap mode on both axes. The reference samples the original image in double with the
// sampler's wrap (exact bilinear, sRGB decoded per texel). Vulkan filters in hardware (one fetch,
// the sampler's weights and decode), GLES blends 4 decoded texels exactly; both must stay within
// 1/255 of the reference in every channel of every pixel and above 45 dB (measured on lavapipe:
// Vulkan 0.80/255 and 57.9-59.3 dB, GLES 0.56/255 and 58.9-59.7 dB).
TEST_P(TexturesPerBackend, TileEdgesInEveryWrapModeMatchTheReference) {
  const std::pair<int, const char*> modes[] = {{10497, "REPEAT"}, {33648, "MIRRORED_REPEAT"}, {33071, "CLAMP_TO_EDGE"}};
  uint32_t seed = 12345;
  const auto next = [&seed] { return int((seed = seed * 1664525u + 1013904223u) >> 24); };
  for (const auto& [gl_mode, name] : modes) {
    SCOPED_TRACE(name);
    const auto dir = test::temp_dir();
    std::vector<glm::ivec3> texels;
    for (int i = 0; i < 15; ++i) texels.emplace_back(next(), next(), next());
    write_png(dir / "edges.png", 5, 3, [&](int x, int y) { return texels[size_t(y * 5 + x)]; });
    QuadScene q;
    q.quad({-1, -1}, {1, 1}, "edges.png", json::object(), {{-1.3f, -1.2f}, {-1.3f, 2.1f}, {2.4f, 2.1f}, {2.4f, -1.2f}});
    q.gltf.doc["samplers"] = json::array({{{"wrapS", gl_mode}, {"wrapT", gl_mode}}});
    q.gltf.doc["textures"][0]["sampler"] = 0;
    const Scene scene = load_unlit(q.write(dir / "edges.gltf"));
    ASSERT_EQ(scene.textures.size(), 1u);
    RenderSettings settings;
    settings.width = settings.height = 96;
    const Camera camera = camera_over({0.0f, 0.0f}, 0.95f);  // inside the quad: every ray hits it
    Renderer renderer(*backend, settings);
    const Image gpu = renderer.render(scene, camera);
    const ReferenceResult ref = render_reference(scene, camera, reference_settings(settings));
    const ImageDiff d = compare_images(gpu, ref.image);
    std::printf("%s %s: %.1f dB, largest difference %.2f / 255\n", GetParam() == Api::Vulkan ? "vulkan" : "gles", name,
                d.psnr, d.max_error * 255.0);
    EXPECT_LE(d.max_error, 1.0 / 255.0);
    EXPECT_GE(d.psnr, 45.0);
  }
}

INSTANTIATE_TEST_SUITE_P(Backends, TexturesPerBackend, ::testing::Values(Api::Vulkan, Api::Gles), api_name);

// ---- tile sizes --------------------------------------------------------------------------------

// One 1024x1024 texture of fine detail (periods of 5 to 9 texels) on a quad filling a 256x256
// image: the atlas keeps it whole, and the image is within 45 dB of the reference, which samples
// the original. At the old 512 tile limit the same detail is lost: the reference of the halved
// image is far below 45 dB of the original's.
TEST(Textures, LoneLargeTextureKeepsItsResolution) {
  const auto dir = test::temp_dir();
  const auto detail = [](int x, int y) {
    const double pi2 = 6.283185307179586;
    return glm::ivec3(int(127.5 + 127.0 * std::sin(pi2 * x / 5.3)), int(127.5 + 127.0 * std::sin(pi2 * y / 7.1)),
                      int(127.5 + 127.0 * std::sin(pi2 * (x + y) / 9.2)));
  };
  write_png(dir / "detail.png", 1024, 1024, detail);
  QuadScene s;
  s.quad({-1, -1}, {1, 1}, "detail.png");
  const Scene scene = load_unlit(s.write(dir / "large.gltf"));
  const Atlas atlas = build_atlas(scene);
  ASSERT_EQ(atlas.tiles.size(), 1u);
  EXPECT_EQ(atlas.tiles[0].width, 1024);
  EXPECT_EQ(atlas.tiles[0].height, 1024);

  RenderSettings settings;
  settings.width = settings.height = 256;
  const Camera camera = camera_over({0.0f, 0.0f}, 1.0f);
  const std::unique_ptr<Backend> backend = make_backend(Api::Vulkan);
  Renderer renderer(*backend, settings);
  const Image gpu = renderer.render(scene, camera);
  const ReferenceResult ref = render_reference(scene, camera, reference_settings(settings));
  const ImageDiff d = compare_images(gpu, ref.image);
  std::printf("lone 1024x1024 texture: %.1f dB against the reference\n", d.psnr);
  EXPECT_GE(d.psnr, 45.0);

  // The same scene with the texture halved, as the 512 tile limit did.
  const TextureImage halved = downscale_to_fit(decode_texture(scene, 0), 512);
  write_png(dir / "halved.png", halved.width, halved.height, [&](int x, int y) {
    const uint32_t p = halved.at(x, y);
    return glm::ivec3(int(p & 0xffu), int((p >> 8) & 0xffu), int((p >> 16) & 0xffu));
  });
  QuadScene h;
  h.quad({-1, -1}, {1, 1}, "halved.png");
  const ReferenceResult halved_ref =
      render_reference(load_unlit(h.write(dir / "halved.gltf")), camera, reference_settings(settings));
  const ImageDiff lost = compare_images(halved_ref.image, ref.image);
  std::printf("the same texture halved to 512x512: %.1f dB\n", lost.psnr);
  EXPECT_LT(lost.psnr, 45.0);
}

}  // namespace
}  // namespace mobirt
