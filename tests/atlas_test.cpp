// The texture atlas: decoding (files and embedded bytes), downscaling, shelf packing, the limits,
// the wrap modes and the bilinear lookup inside a tile, on the CPU and, with the Khronos validation
// layer on, on the GPU (glsl/atlas.glsl through the test shader glsl/test/atlas_lookup.frag).
#include <gtest/gtest.h>

#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "backend/backend.h"
#include "core/error.h"
#include "layout.h"
#include "scene/animation.h"
#include "scene/atlas.h"
#include "scene/loader.h"
#include "scene/texture_images.h"
#include "test_support.h"
#include "vulkan_fixture.h"
#include "test_shader_ids.h"  // the test-only shaders (TestShader)

namespace mobirt {
namespace {

using test::expect_bad_input;

// ---- helpers -----------------------------------------------------------------------------------

TextureImage solid(int width, int height, uint32_t rgba) {
  TextureImage image;
  image.width = width;
  image.height = height;
  image.pixels.assign(size_t(width) * size_t(height), rgba);
  return image;
}

TextureImage random_image(int width, int height, std::mt19937& rng) {
  TextureImage image = solid(width, height, 0);
  std::uniform_int_distribution<uint32_t> byte(0, 255);
  for (uint32_t& p : image.pixels) p = pack_rgba8(byte(rng), byte(rng), byte(rng), 255);
  return image;
}

uint32_t channel(uint32_t rgba, int c) { return (rgba >> (8 * c)) & 0xffu; }

// Writes `image` with `channels` channels (1: red as grey, 3: RGB, 4: RGBA) through OIIO.
void write_test_image(const std::filesystem::path& path, const TextureImage& image, int channels) {
  std::vector<uint8_t> bytes;
  for (uint32_t p : image.pixels) {
    for (int c = 0; c < channels; ++c) bytes.push_back(uint8_t(channel(p, c)));
  }
  auto out = OIIO::ImageOutput::create(path.string());
  ASSERT_TRUE(out) << OIIO::geterror();
  OIIO::ImageSpec spec(image.width, image.height, channels, OIIO::TypeDesc::UINT8);
  if (channels == 4) spec.attribute("oiio:UnassociatedAlpha", 1);
  ASSERT_TRUE(out->open(path.string(), spec)) << out->geterror();
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, bytes.data())) << out->geterror();
  ASSERT_TRUE(out->close());
}

std::vector<uint8_t> read_bytes(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::vector<uint8_t>(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

// A scene whose material i uses texture i.
Scene scene_with_textures(std::vector<TextureRef> textures, const std::string& source) {
  Scene scene;
  scene.source = source;
  for (size_t i = 0; i < textures.size(); ++i) {
    Material m;
    m.name = "mat" + std::to_string(i);
    m.texture = int(i);
    scene.materials.push_back(m);
  }
  if (scene.materials.empty()) scene.materials.emplace_back();
  scene.textures = std::move(textures);
  return scene;
}

// Tiles with their gutters overlap.
bool overlap(const AtlasTile& a, const AtlasTile& b) {
  constexpr int g = MOBIRT_ATLAS_GUTTER;
  return a.x - g < b.x + b.width + g && b.x - g < a.x + a.width + g && a.y - g < b.y + b.height + g &&
         b.y - g < a.y + a.height + g;
}

// Every tile at its size, inside a page with its gutter, no two overlapping on a page (gutters
// included), at most 16 a page.
void expect_valid_packing(const std::vector<glm::ivec2>& sizes, const std::vector<AtlasTile>& tiles) {
  ASSERT_EQ(tiles.size(), sizes.size());
  std::vector<int> per_page(MOBIRT_ATLAS_MAX_PAGES, 0);
  for (size_t i = 0; i < tiles.size(); ++i) {
    SCOPED_TRACE("tile " + std::to_string(i));
    EXPECT_EQ(tiles[i].width, sizes[i].x);
    EXPECT_EQ(tiles[i].height, sizes[i].y);
    ASSERT_GE(tiles[i].page, 0);
    ASSERT_LT(tiles[i].page, MOBIRT_ATLAS_MAX_PAGES);
    ++per_page[size_t(tiles[i].page)];
    EXPECT_GE(tiles[i].x, MOBIRT_ATLAS_GUTTER);
    EXPECT_GE(tiles[i].y, MOBIRT_ATLAS_GUTTER);
    EXPECT_LE(tiles[i].x + tiles[i].width + MOBIRT_ATLAS_GUTTER, MOBIRT_ATLAS_SIZE);
    EXPECT_LE(tiles[i].y + tiles[i].height + MOBIRT_ATLAS_GUTTER, MOBIRT_ATLAS_SIZE);
    for (size_t j = 0; j < i; ++j) {
      EXPECT_FALSE(tiles[i].page == tiles[j].page && overlap(tiles[i], tiles[j])) << "overlaps tile " << j;
    }
  }
  for (int n : per_page) EXPECT_LE(n, MOBIRT_ATLAS_TILES_PER_PAGE);
}

int pages_used(const std::vector<AtlasTile>& tiles) {
  int pages = 0;
  for (const AtlasTile& t : tiles) pages = std::max(pages, t.page + 1);
  return pages;
}

float lin(uint32_t byte) { return srgb_to_linear(float(byte) / 255.0f); }

// ---- packing -----------------------------------------------------------------------------------

// The atlas is kept from frame to frame while atlas_key stays the same: the key of an animated
// scene must not change as it plays, and must change with its textures.
TEST(AtlasKey, SameWhileTheAnimationPlaysOtherForOtherTextures) {
  const AnimatedScene animation = load_animated_scene(std::string(MOBIRT_SOURCE_DIR) + "/scenes/toaster.gltf");
  ASSERT_TRUE(animation.animated());
  Scene a, b;
  animation.evaluate(0.0, a);
  animation.evaluate(1.5, b);
  ASSERT_FALSE(a.textures.empty());
  EXPECT_NE(a.mesh.positions, b.mesh.positions) << "the frames must differ for the test to mean anything";
  EXPECT_EQ(atlas_key(a), atlas_key(b));
  Scene c = a;
  c.textures.pop_back();
  EXPECT_NE(atlas_key(a), atlas_key(c));
  Scene d = a;
  d.textures[0].wrap_s = d.textures[0].wrap_s == TextureWrap::Repeat ? TextureWrap::ClampToEdge : TextureWrap::Repeat;
  EXPECT_NE(atlas_key(a), atlas_key(d));
}

TEST(AtlasPacking, OneTile) {
  const std::vector<glm::ivec2> sizes = {{300, 200}};
  const auto tiles = pack_tiles(sizes);
  expect_valid_packing(sizes, tiles);
  EXPECT_EQ(tiles[0].x, MOBIRT_ATLAS_GUTTER);
  EXPECT_EQ(tiles[0].y, MOBIRT_ATLAS_GUTTER);
}

TEST(AtlasPacking, FiveNonSquare) {
  const std::vector<glm::ivec2> sizes = {{512, 128}, {37, 300}, {512, 512}, {1, 1}, {200, 37}};
  expect_valid_packing(sizes, pack_tiles(sizes));
}

TEST(AtlasPacking, SixteenFullTilesFillTheAtlasExactly) {
  const std::vector<glm::ivec2> sizes(16, glm::ivec2(MOBIRT_ATLAS_SURE_TILE, MOBIRT_ATLAS_SURE_TILE));
  const auto tiles = pack_tiles(sizes);
  expect_valid_packing(sizes, tiles);
  // 16 x (510 + 2)^2 = 2048^2: no overlap and inside means the 4 x 4 grid.
  std::vector<int> seen(16, 0);
  for (const AtlasTile& t : tiles) {
    EXPECT_EQ(t.page, 0);
    EXPECT_EQ(t.x % 512, 1);
    EXPECT_EQ(t.y % 512, 1);
    ++seen[size_t(t.y / 512 * 4 + t.x / 512)];
  }
  for (int s : seen) EXPECT_EQ(s, 1);
  // The gutters cost the paper's 512: sixteen 512s do not share a page.
  EXPECT_EQ(pages_used(pack_tiles(std::vector<glm::ivec2>(16, glm::ivec2(512, 512)))), 2);
}

TEST(AtlasPacking, AnySixteenTilesUpTo510Fit) {
  std::mt19937 rng(7);
  constexpr int sure = MOBIRT_ATLAS_SURE_TILE;
  std::uniform_int_distribution<int> side(1, sure);
  std::uniform_int_distribution<int> count(1, 16);
  for (int round = 0; round < 500; ++round) {
    std::vector<glm::ivec2> sizes(size_t(count(rng)));
    for (auto& s : sizes) s = glm::ivec2(side(rng), side(rng));
    if (round % 5 == 0) {  // worst cases: full height or full width
      for (auto& s : sizes) s = round % 10 == 0 ? glm::ivec2(side(rng), sure) : glm::ivec2(sure, side(rng));
    }
    SCOPED_TRACE("round " + std::to_string(round));
    const auto tiles = pack_tiles(sizes);
    expect_valid_packing(sizes, tiles);
    EXPECT_EQ(pages_used(tiles), 1) << "16 tiles up to 510 fit one page";
    if (HasFailure()) return;
  }
}

TEST(AtlasPacking, SeventeenTilesOpenASecondPage) {
  const std::vector<glm::ivec2> sizes(17, glm::ivec2(510, 510));
  const auto tiles = pack_tiles(sizes);
  expect_valid_packing(sizes, tiles);
  EXPECT_EQ(pages_used(tiles), 2);
  // A page holds the paper's 16 tiles at most, even small ones that would fit its area.
  const std::vector<glm::ivec2> small(17, glm::ivec2(8, 8));
  const auto small_tiles = pack_tiles(small);
  expect_valid_packing(small, small_tiles);
  EXPECT_EQ(pages_used(small_tiles), 2);
  EXPECT_EQ(small_tiles[16].page, 1);
  EXPECT_EQ(small_tiles[16].x, MOBIRT_ATLAS_GUTTER);
  EXPECT_EQ(small_tiles[16].y, MOBIRT_ATLAS_GUTTER);
}

TEST(AtlasPacking, FortyEightFullTilesFillThreePagesAndNoMore) {
  const std::vector<glm::ivec2> sizes(MOBIRT_ATLAS_MAX_TEXTURES, glm::ivec2(510, 510));
  const auto tiles = pack_tiles(sizes);
  expect_valid_packing(sizes, tiles);
  EXPECT_EQ(pages_used(tiles), MOBIRT_ATLAS_MAX_PAGES);
  std::vector<glm::ivec2> one_more = sizes;
  one_more.emplace_back(1, 1);
  EXPECT_FALSE(try_pack_tiles(one_more).has_value());
  EXPECT_THROW(pack_tiles(one_more), Error);
}

TEST(AtlasPacking, PageSizedTilesTakeAPageEach) {
  // A page less its gutters: 2046.
  const std::vector<glm::ivec2> sizes = {{2046, 2046}, {5, 7}, {2046, 1024}, {2046, 2046}};
  const auto tiles = pack_tiles(sizes);
  expect_valid_packing(sizes, tiles);
  EXPECT_EQ(pages_used(tiles), 3);
  EXPECT_NE(tiles[0].page, tiles[3].page);
  EXPECT_EQ(tiles[1].page, tiles[2].page) << "the small tile goes beside the half-page one";
  EXPECT_FALSE(try_pack_tiles({{2046, 2046}, {2046, 2046}, {2046, 2046}, {1, 1}}).has_value());
  EXPECT_FALSE(try_pack_tiles({{2047, 16}}).has_value()) << "wider than a page with its gutters";
  EXPECT_FALSE(try_pack_tiles({{2048, 2048}}).has_value()) << "a page-sized texture needs its gutter too";
  EXPECT_FALSE(try_pack_tiles({{7, 7}}, 1, 8).has_value()) << "larger than a smaller page with gutters";
  EXPECT_TRUE(try_pack_tiles({{6, 6}}, 1, 8).has_value());
}

TEST(AtlasPacking, AnyFortyEightTilesUpTo510Fit) {
  std::mt19937 rng(17);
  std::uniform_int_distribution<int> side(1, MOBIRT_ATLAS_SURE_TILE);
  std::uniform_int_distribution<int> count(17, MOBIRT_ATLAS_MAX_TEXTURES);
  for (int round = 0; round < 200; ++round) {
    std::vector<glm::ivec2> sizes(size_t(count(rng)));
    for (auto& s : sizes) s = round % 4 == 0 ? glm::ivec2(MOBIRT_ATLAS_SURE_TILE, side(rng)) : glm::ivec2(side(rng), side(rng));
    SCOPED_TRACE("round " + std::to_string(round));
    expect_valid_packing(sizes, pack_tiles(sizes));
    if (HasFailure()) return;
  }
}

// ---- tile sizes: the largest cap at which the scene's textures pack ----------------------------

TEST(AtlasTileLimit, TexturesKeepTheirSizeWhenThePagesHoldThem) {
  EXPECT_EQ(atlas_tile_limit({{1024, 1024}}), 1024) << "one 1024 texture stays whole";
  EXPECT_EQ(atlas_tile_limit(std::vector<glm::ivec2>(3, {1024, 1024})), 1024) << "one a page, gutter beside it";
  EXPECT_EQ(atlas_tile_limit({{2046, 2046}}), 2046);
  EXPECT_EQ(atlas_tile_limit({{2048, 2048}}), 2046) << "a tile and its gutters are at most a page";
  EXPECT_EQ(atlas_tile_limit({{4096, 4096}}), 2046);
  EXPECT_EQ(atlas_tile_limit({{3000, 100}}), 2046);
  EXPECT_EQ(atlas_tile_limit({{2048, 2048}, {2048, 2048}, {1000, 700}}), 2046) << "one page each";
  EXPECT_EQ(atlas_tile_limit({{64, 32}, {300, 200}}), 300) << "the longest side, when nothing needs scaling";
  EXPECT_EQ(atlas_tile_limit(std::vector<glm::ivec2>(12, {1022, 1022})), 1022) << "4 a page, 3 pages";
  EXPECT_EQ(atlas_tile_limit(std::vector<glm::ivec2>(40, {64, 64})), 64);
}

TEST(AtlasTileLimit, DownscaleOnlyAsFarAsThePagesRequire) {
  // Four page-sized textures: three pages hold three; at 1022 (2 x (1022 + 2) = 2048) all four
  // share one page.
  EXPECT_EQ(atlas_tile_limit(std::vector<glm::ivec2>(4, {2048, 2048})), 1022);
  // Twelve 1024s: one a page at 1024 (1026 + 1026 > 2048), four a page at 1022.
  EXPECT_EQ(atlas_tile_limit(std::vector<glm::ivec2>(12, {1024, 1024})), 1022);
  // Thirteen 1024s: 12 fit at 1022; at 680 (3 x (680 + 2) = 2046) nine share a page.
  EXPECT_EQ(atlas_tile_limit(std::vector<glm::ivec2>(13, {1024, 1024})), 680);
  // Forty-eight of anything: 16 a page, so 510.
  EXPECT_EQ(atlas_tile_limit(std::vector<glm::ivec2>(48, {2048, 2048})), 510);
  EXPECT_EQ(atlas_tile_limit(std::vector<glm::ivec2>(48, {600, 600})), 510);
  // Each answer is the largest cap that packs: one texel more does not.
  for (const auto& sizes : {std::vector<glm::ivec2>(4, {2048, 2048}), std::vector<glm::ivec2>(13, {1024, 1024}),
                            std::vector<glm::ivec2>{{2048, 2048}, {2048, 2048}, {2048, 2048}, {100, 100}}}) {
    const int limit = atlas_tile_limit(sizes);
    auto fitted = [&](int cap) {
      std::vector<glm::ivec2> f(sizes.size());
      for (size_t i = 0; i < sizes.size(); ++i) fitted_size(sizes[i].x, sizes[i].y, cap, f[i].x, f[i].y);
      return f;
    };
    EXPECT_TRUE(try_pack_tiles(fitted(limit)).has_value()) << limit;
    EXPECT_FALSE(try_pack_tiles(fitted(limit + 1)).has_value()) << limit;
  }
  EXPECT_THROW(atlas_tile_limit(std::vector<glm::ivec2>(49, {1, 1})), Error);
}

TEST(AtlasPacking, TilesAreCopiedWithGuttersByTheirWrapModes) {
  std::mt19937 rng(3);
  std::vector<AtlasTexture> textures = {{random_image(37, 300, rng), TextureWrap::Repeat, TextureWrap::MirroredRepeat},
                                        {random_image(512, 128, rng), TextureWrap::ClampToEdge, TextureWrap::Repeat},
                                        {random_image(5, 5, rng), TextureWrap::MirroredRepeat, TextureWrap::ClampToEdge}};
  const Atlas atlas = assemble_atlas(textures);
  ASSERT_EQ(atlas.page_count(), 1);
  ASSERT_EQ(atlas.pages[0].size(), size_t(MOBIRT_ATLAS_SIZE) * MOBIRT_ATLAS_SIZE);
  ASSERT_EQ(atlas.tiles.size(), 3u);
  for (size_t i = 0; i < textures.size(); ++i) {
    const AtlasTile& t = atlas.tiles[i];
    for (int y = 0; y < t.height; ++y) {
      for (int x = 0; x < t.width; ++x) ASSERT_EQ(atlas.at(t.page, t.x + x, t.y + y), textures[i].image.at(x, y));
    }
  }
  // The tallest tile comes first; the next one starts after the two gutters between them.
  EXPECT_EQ(atlas.tiles[0].x, 1);
  EXPECT_EQ(atlas.tiles[1].x, 1 + 37 + 2);
  EXPECT_EQ(atlas.tiles[2].x, 1 + 37 + 2 + 512 + 2);
  // Gutter texels, corners included: texel -1 / size of a REPEAT axis is the opposite edge, of a
  // MIRRORED_REPEAT or CLAMP_TO_EDGE axis the edge itself.
  for (size_t i = 0; i < textures.size(); ++i) {
    const AtlasTile& t = atlas.tiles[i];
    const TextureImage& im = textures[i].image;
    auto source = [](int k, int size, TextureWrap mode) {
      if (k >= 0 && k < size) return k;
      if (mode == TextureWrap::Repeat) return k < 0 ? size - 1 : 0;
      return k < 0 ? 0 : size - 1;
    };
    for (int y = -1; y <= t.height; ++y) {
      for (int x = -1; x <= t.width; ++x) {
        if (x >= 0 && x < t.width && y >= 0 && y < t.height) continue;
        ASSERT_EQ(atlas.at(t.page, t.x + x, t.y + y),
                  im.at(source(x, im.width, textures[i].wrap_s), source(y, im.height, textures[i].wrap_t)))
            << "tile " << i << " gutter texel " << x << ", " << y;
      }
    }
  }
}

TEST(AtlasPacking, NoTexturesNoAtlas) {
  Scene scene = scene_with_textures({}, "empty.gltf");
  const Atlas atlas = build_atlas(scene);
  EXPECT_TRUE(atlas.empty());
  EXPECT_TRUE(atlas.pages.empty());
  std::vector<float> uniforms(4 * 5, 1.0f);
  append_atlas_uniforms(atlas, 1, uniforms);
  EXPECT_EQ(uniforms.size(), 4u * 5u);
}

// ---- limits and errors -------------------------------------------------------------------------

TEST(AtlasLimits, FortyNineTexturesAreRefused) {
  // Refused on the count, before any file is opened.
  std::vector<TextureRef> refs(49);
  for (size_t i = 0; i < refs.size(); ++i) refs[i].path = "/nonexistent/t" + std::to_string(i) + ".png";
  const Scene scene = scene_with_textures(refs, "big.gltf");
  expect_bad_input([&] { build_atlas(scene); },
                   {"big.gltf", "49 textures", "at most 48", "3 pages of 2048x2048", "8 texture units",
                    "merge textures"});
  std::vector<AtlasTexture> textures(49, AtlasTexture{solid(2, 2, 0)});
  expect_bad_input([&] { assemble_atlas(textures); }, {"49 textures", "at most 48"});
  textures.pop_back();
  EXPECT_EQ(assemble_atlas(textures).page_count(), 3);
}

TEST(AtlasLimits, MissingTextureFileNamesFileSceneAndMaterial) {
  const auto dir = test::temp_dir();
  TextureRef ref;
  ref.name = "foo";
  ref.path = (dir / "foo.png").string();
  Scene scene = scene_with_textures({ref}, (dir / "scene.gltf").string());
  scene.materials.insert(scene.materials.begin(), 2, Material{});  // the user becomes materials[2]
  expect_bad_input([&] { build_atlas(scene); },
                   {(dir / "scene.gltf").string(), "texture '", "foo.png' not found",
                    "referenced by materials[2] 'mat0'", "put it beside the scene or fix the path"});
}

TEST(AtlasLimits, UndecodableTexturesAreBadInput) {
  const auto dir = test::temp_dir();
  {
    std::ofstream(dir / "broken.png") << "not a png at all";
  }
  TextureRef file;
  file.path = (dir / "broken.png").string();
  expect_bad_input([&] { build_atlas(scene_with_textures({file}, "s.gltf")); }, {"s.gltf", "broken.png"});
  TextureRef embedded;
  embedded.name = "weird";
  embedded.data = {1, 2, 3, 4, 5};
  embedded.mime_type = "image/ktx2";
  expect_bad_input([&] { build_atlas(scene_with_textures({embedded}, "s.glb")); },
                   {"s.glb", "'weird'", "PNG and JPEG"});
  TextureRef empty;
  empty.name = "nothing";
  expect_bad_input([&] { build_atlas(scene_with_textures({empty}, "s.glb")); }, {"s.glb", "'nothing'"});
}

// ---- decoding ----------------------------------------------------------------------------------

TEST(AtlasDecode, PngFromFileAndFromEmbeddedBytes) {
  const auto dir = test::temp_dir();
  std::mt19937 rng(11);
  TextureImage image = random_image(29, 13, rng);
  image.pixels[0] = pack_rgba8(255, 0, 0, 0);    // transparent red stays red (never premultiplied)
  image.pixels[1] = pack_rgba8(10, 200, 30, 77);
  write_test_image(dir / "rgba.png", image, 4);
  ASSERT_FALSE(HasFailure());
  const TextureImage from_file = decode_image_file((dir / "rgba.png").string(), "rgba.png");
  EXPECT_EQ(from_file.width, 29);
  EXPECT_EQ(from_file.height, 13);
  EXPECT_EQ(from_file.pixels, image.pixels);
  const TextureImage from_bytes = decode_image_bytes(read_bytes(dir / "rgba.png"), "image/png", "embedded");
  EXPECT_EQ(from_bytes.pixels, image.pixels);
  // Without a MIME type, the signature decides.
  EXPECT_EQ(decode_image_bytes(read_bytes(dir / "rgba.png"), "", "embedded").pixels, image.pixels);

  // Grey and RGB gain the missing channels.
  write_test_image(dir / "grey.png", image, 1);
  write_test_image(dir / "rgb.png", image, 3);
  ASSERT_FALSE(HasFailure());
  const TextureImage grey = decode_image_file((dir / "grey.png").string(), "grey.png");
  const TextureImage rgb = decode_image_file((dir / "rgb.png").string(), "rgb.png");
  for (size_t i = 0; i < image.pixels.size(); ++i) {
    const uint32_t r = channel(image.pixels[i], 0);
    ASSERT_EQ(grey.pixels[i], pack_rgba8(r, r, r, 255));
    ASSERT_EQ(rgb.pixels[i], image.pixels[i] | 0xff000000u);
  }
}

TEST(AtlasDecode, JpegFromEmbeddedBytes) {
  const auto dir = test::temp_dir();
  const TextureImage image = solid(40, 24, pack_rgba8(200, 120, 40, 255));
  write_test_image(dir / "t.jpg", image, 3);
  ASSERT_FALSE(HasFailure());
  const TextureImage decoded = decode_image_bytes(read_bytes(dir / "t.jpg"), "image/jpeg", "embedded");
  ASSERT_EQ(decoded.width, 40);
  ASSERT_EQ(decoded.height, 24);
  for (uint32_t p : decoded.pixels) {
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(double(channel(p, c)), double(channel(image.pixels[0], c)), 3.0);
    EXPECT_EQ(channel(p, 3), 255u);
  }
}

TEST(AtlasDecode, TexturesAreDownscaledOnlyWhereThePagesRequireWithAWarning) {
  const auto dir = test::temp_dir();
  const uint32_t colour = pack_rgba8(200, 100, 50, 255);
  write_test_image(dir / "big.png", solid(1024, 768, colour), 4);
  write_test_image(dir / "small.png", solid(64, 32, pack_rgba8(1, 2, 3, 255)), 4);
  write_test_image(dir / "wide.png", solid(4096, 8, colour), 4);
  ASSERT_FALSE(HasFailure());
  TextureRef big;
  big.name = "bigtex";
  big.path = (dir / "big.png").string();
  TextureRef small;
  small.path = (dir / "small.png").string();
  TextureRef wide;
  wide.path = (dir / "wide.png").string();
  {
    // The pages hold 1024x768 and 64x32 as they are: no warning, no scaling.
    testing::internal::CaptureStderr();
    const Atlas atlas = build_atlas(scene_with_textures({big, small}, "scene.gltf"));
    EXPECT_EQ(testing::internal::GetCapturedStderr(), "");
    ASSERT_EQ(atlas.tiles.size(), 2u);
    EXPECT_EQ(atlas.tiles[0].width, 1024);
    EXPECT_EQ(atlas.tiles[0].height, 768);
    EXPECT_EQ(atlas.tiles[1].width, 64);
    EXPECT_EQ(atlas.tiles[1].height, 32);
    EXPECT_EQ(atlas.tile_limit, 1024);
  }
  // Wider than a page: 2046 (a page less its gutters) on its long side, the others untouched.
  testing::internal::CaptureStderr();
  const Atlas atlas = build_atlas(scene_with_textures({wide, small}, "scene.gltf"));
  EXPECT_EQ(testing::internal::GetCapturedStderr(),
            "mobirt: warning: scene.gltf: texture 'wide.png' 4096x8 downscaled to 2046x4 for the atlas\n");
  EXPECT_EQ(atlas.tiles[0].width, 2046);
  EXPECT_EQ(atlas.tiles[0].height, 4);
  EXPECT_EQ(atlas.tiles[1].width, 64);
  // (Which cap the pages need is atlas_tile_limit()'s, tested above on sizes alone: scaling real
  // images of that area costs seconds.)
  EXPECT_EQ(atlas.tile_limit, 2046);
  // A constant image stays that constant (filtering in linear light, re-encoded).
  for (int y : {0, 3}) {
    for (int x : {0, 1000, 2045}) {
      const uint32_t p = atlas.at(atlas.tiles[0].page, atlas.tiles[0].x + x, atlas.tiles[0].y + y);
      for (int c = 0; c < 4; ++c) EXPECT_NEAR(double(channel(p, c)), double(channel(colour, c)), 1.0);
    }
  }
  // Aspect ratio kept, each side rounded, at least 1.
  int w = 0, h = 0;
  fitted_size(2000, 3, 512, w, h);
  EXPECT_EQ(w, 512);
  EXPECT_EQ(h, 1);
  fitted_size(600, 1000, 512, w, h);
  EXPECT_EQ(w, 307);
  EXPECT_EQ(h, 512);
  fitted_size(512, 100, 512, w, h);
  EXPECT_EQ(w, 512);
  EXPECT_EQ(h, 100);
}

// ---- wrap modes and filtering on the CPU -------------------------------------------------------

// uv -> the two texels blended (in a 4-texel-wide tile) and the weight of the second, per mode.
struct WrapCase {
  float uv;
  int repeat[2];
  int mirrored[2];
  int clamp[2];
  float weight;
};
const WrapCase kWrapCases[] = {
    {-1.25f, {2, 3}, {2, 3}, {0, 0}, 0.5f},  {-0.5f, {1, 2}, {2, 1}, {0, 0}, 0.5f},
    {0.0f, {3, 0}, {0, 0}, {0, 0}, 0.5f},    {0.5f, {1, 2}, {1, 2}, {1, 2}, 0.5f},
    {0.999f, {3, 0}, {3, 3}, {3, 3}, 0.496f}, {1.0f, {3, 0}, {3, 3}, {3, 3}, 0.5f},
    {1.5f, {1, 2}, {2, 1}, {3, 3}, 0.5f},    {2.75f, {2, 3}, {2, 3}, {3, 3}, 0.5f},
};

TEST(AtlasWrap, TexelIndicesHaveKnownAnswers) {
  for (const WrapCase& c : kWrapCases) {
    SCOPED_TRACE("uv " + std::to_string(c.uv));
    const float p = c.uv * 4.0f - 0.5f;
    const float p0 = std::floor(p);
    EXPECT_NEAR(p - p0, c.weight, 1e-5f);
    for (int k = 0; k < 2; ++k) {
      EXPECT_EQ(atlas_wrap(p0 + float(k), 4.0f, float(MOBIRT_WRAP_REPEAT)), float(c.repeat[k]));
      EXPECT_EQ(atlas_wrap(p0 + float(k), 4.0f, float(MOBIRT_WRAP_MIRRORED_REPEAT)), float(c.mirrored[k]));
      EXPECT_EQ(atlas_wrap(p0 + float(k), 4.0f, float(MOBIRT_WRAP_CLAMP)), float(c.clamp[k]));
    }
  }
  // Every index lands in the tile, whatever its size and mode, even far away.
  for (float size : {1.0f, 2.0f, 3.0f, 37.0f, 512.0f}) {
    for (float mode : {0.0f, 1.0f, 2.0f}) {
      for (float i : {-1e7f, -1025.0f, -513.0f, -1.0f, 0.0f, 511.0f, 512.0f, 1024.0f, 3e6f}) {
        const float r = atlas_wrap(i, size, mode);
        EXPECT_GE(r, 0.0f);
        EXPECT_LE(r, size - 1.0f);
        EXPECT_EQ(r, std::floor(r));
      }
    }
  }
}

TEST(AtlasWrap, SampledValuesHaveKnownAnswers) {
  // A 4 x 2 texture: column k has red 60k + 20, green = row * 255; placed after a 7-wide tile so
  // that its origin is not 0.
  TextureImage image = solid(4, 2, 0);
  for (int y = 0; y < 2; ++y) {
    for (int x = 0; x < 4; ++x) image.pixels[size_t(y * 4 + x)] = pack_rgba8(uint32_t(60 * x + 20), uint32_t(255 * y), 0, 255);
  }
  const TextureWrap modes[] = {TextureWrap::Repeat, TextureWrap::MirroredRepeat, TextureWrap::ClampToEdge};
  for (TextureWrap mode : modes) {
    const Atlas atlas = assemble_atlas({{solid(7, 2, pack_rgba8(0, 0, 255, 255))}, {image, mode, TextureWrap::ClampToEdge}});
    ASSERT_EQ(atlas.tiles[1].x, 1 + 7 + 2);
    for (const WrapCase& c : kWrapCases) {
      SCOPED_TRACE("mode " + std::to_string(int(mode)) + ", uv " + std::to_string(c.uv));
      const int* texels = mode == TextureWrap::Repeat ? c.repeat : mode == TextureWrap::MirroredRepeat ? c.mirrored : c.clamp;
      const float want = lin(uint32_t(60 * texels[0] + 20)) * (1.0f - c.weight) + lin(uint32_t(60 * texels[1] + 20)) * c.weight;
      // v = 0.25 is the centre of row 0: no green; v = 0.5 blends rows 0 and 1 half and half.
      const glm::vec3 top = sample_atlas(atlas, 1, glm::vec2(c.uv, 0.25f));
      EXPECT_NEAR(top.x, want, 1e-5f);
      EXPECT_EQ(top.y, 0.0f);
      EXPECT_EQ(top.z, 0.0f);
      const glm::vec3 middle = sample_atlas(atlas, 1, glm::vec2(c.uv, 0.5f));
      EXPECT_NEAR(middle.x, want, 1e-5f);
      EXPECT_NEAR(middle.y, 0.5f, 1e-6f);
    }
  }
}

// One red tile of 5 x 3 at (8, 8), with its red gutter (what the copy gives a solid tile in every
// mode), in an atlas that is green everywhere else.
Atlas red_tile_in_green(TextureWrap wrap_s, TextureWrap wrap_t) {
  Atlas atlas;
  atlas.pages.assign(1, std::vector<uint32_t>(size_t(atlas.size) * size_t(atlas.size), pack_rgba8(0, 255, 0, 255)));
  atlas.tiles.push_back(AtlasTile{0, 8, 8, 5, 3, wrap_value(wrap_s), wrap_value(wrap_t)});
  for (int y = 7; y < 12; ++y) {
    for (int x = 7; x < 14; ++x) atlas.pages[0][size_t(y) * size_t(atlas.size) + size_t(x)] = pack_rgba8(255, 0, 0, 255);
  }
  return atlas;
}

// uv on and around the tile's borders plus random ones, in [-3, 3]^2.
std::vector<glm::vec2> border_and_random_uvs(size_t random_count, std::mt19937& rng) {
  std::vector<glm::vec2> uvs;
  const float special[] = {-1.25f, -0.5f, -1e-4f, 0.0f, 1e-4f, 0.1f, 0.5f, 0.9f, 0.999f, 1.0f, 1.0001f, 1.5f, 2.75f};
  for (float u : special) {
    for (float v : special) uvs.emplace_back(u, v);
  }
  std::uniform_real_distribution<float> coord(-3.0f, 3.0f);
  while (uvs.size() < random_count) uvs.emplace_back(coord(rng), coord(rng));
  return uvs;
}

const TextureWrap kModes[] = {TextureWrap::Repeat, TextureWrap::MirroredRepeat, TextureWrap::ClampToEdge};

// At a texel's centre the bilinear weights are 0 and 1, so the lookup is the texel's own linear
// value: for each of the 256 bytes, in every channel, the float srgb_to_linear() gives, bit for
// bit, whatever way sample_atlas() decodes it (a table since the CPU engines stopped calling
// std::pow per texel).
TEST(AtlasFilter, TexelCentresDecodeEverySrgbByteAsSrgbToLinear) {
  TextureImage image = solid(16, 16, 0);
  for (uint32_t i = 0; i < 256; ++i) image.pixels[i] = pack_rgba8(i, 255 - i, (i * 7) & 0xffu, 255);
  const Atlas atlas = assemble_atlas({{solid(3, 2, pack_rgba8(9, 9, 9, 255))}, {image}});
  for (int y = 0; y < 16; ++y) {
    for (int x = 0; x < 16; ++x) {
      const glm::vec2 uv((float(x) + 0.5f) / 16.0f, (float(y) + 0.5f) / 16.0f);
      const uint32_t p = image.at(x, y);
      const glm::vec3 got = sample_atlas(atlas, 1, uv);
      for (int c = 0; c < 3; ++c) {
        ASSERT_EQ(std::bit_cast<uint32_t>(got[c]), std::bit_cast<uint32_t>(lin(channel(p, c))))
            << "texel " << x << ", " << y << " channel " << c << " byte " << channel(p, c);
      }
    }
  }
}

TEST(AtlasFilter, BilinearNeverReadsANeighbourTile) {
  std::mt19937 rng(5);
  const auto uvs = border_and_random_uvs(5000, rng);
  for (TextureWrap s : kModes) {
    for (TextureWrap t : kModes) {
      const Atlas atlas = red_tile_in_green(s, t);
      for (const glm::vec2& uv : uvs) {
        const glm::vec3 c = sample_atlas(atlas, 0, uv);
        ASSERT_EQ(c.y, 0.0f) << "green leaked in at uv " << uv.x << ", " << uv.y;
        ASSERT_EQ(c.z, 0.0f);
        ASSERT_NEAR(c.x, 1.0f, 1e-6f);
      }
    }
  }
  // And between packed tiles: a red tile beside green and blue ones.
  const Atlas packed = assemble_atlas({{solid(6, 4, pack_rgba8(0, 255, 0, 255))},
                                       {solid(5, 4, pack_rgba8(255, 0, 0, 255)), TextureWrap::ClampToEdge, TextureWrap::Repeat},
                                       {solid(3, 4, pack_rgba8(0, 0, 255, 255))}});
  // Green, red, blue side by side, their gutters touching.
  ASSERT_EQ(packed.tiles[1].x, packed.tiles[0].x + 6 + 2);
  ASSERT_EQ(packed.tiles[2].x, packed.tiles[1].x + 5 + 2);
  for (const glm::vec2& uv : uvs) {
    const glm::vec3 c = sample_atlas(packed, 1, uv);
    ASSERT_EQ(c.y, 0.0f);
    ASSERT_EQ(c.z, 0.0f);
  }
}

// The lookup through the gutters (the coordinate wrapped once, texels -1 and size read from the
// gutter) equals the texture's own GL_LINEAR lookup: each of the 4 texel indices wrapped by the
// sampler's mode into the original image, as the reference and the old gutterless atlas did.
TEST(AtlasFilter, GutterLookupEqualsWrappingEachTexel) {
  std::mt19937 rng(11);
  const auto uvs = border_and_random_uvs(4000, rng);
  for (TextureWrap s : kModes) {
    for (TextureWrap t : kModes) {
      SCOPED_TRACE("wrap " + std::to_string(int(s)) + ", " + std::to_string(int(t)));
      const std::vector<AtlasTexture> textures = {{random_image(6, 4, rng)}, {random_image(5, 3, rng), s, t},
                                                  {random_image(1, 2, rng), s, t}};
      const Atlas atlas = assemble_atlas(textures);
      for (int k : {1, 2}) {
        const TextureImage& im = textures[size_t(k)].image;
        const float w = float(im.width), h = float(im.height);
        const auto texel = [&](float x, float y) {
          const uint32_t p = im.at(int(atlas_wrap(x, w, wrap_value(s))), int(atlas_wrap(y, h, wrap_value(t))));
          return glm::vec3(lin(channel(p, 0)), lin(channel(p, 1)), lin(channel(p, 2)));
        };
        for (const glm::vec2& uv : uvs) {
          const glm::vec2 p = uv * glm::vec2(w, h) - 0.5f;
          const glm::vec2 p0 = glm::floor(p), f = p - p0;
          const glm::vec3 want = glm::mix(glm::mix(texel(p0.x, p0.y), texel(p0.x + 1, p0.y), f.x),
                                          glm::mix(texel(p0.x, p0.y + 1), texel(p0.x + 1, p0.y + 1), f.x), f.y);
          const glm::vec3 got = sample_atlas(atlas, k, uv);
          // Equal up to the float rounding of the wrapped coordinate (u - floor(u) for u in [-3, 3]).
          for (int c = 0; c < 3; ++c) ASSERT_NEAR(got[c], want[c], 2e-5f) << "uv " << uv.x << ", " << uv.y;
        }
      }
    }
  }
}

TEST(AtlasFilter, UniformsFollowTheLights) {
  std::mt19937 rng(1);
  const Atlas atlas = assemble_atlas({{random_image(37, 300, rng), TextureWrap::MirroredRepeat, TextureWrap::ClampToEdge},
                                      {random_image(512, 128, rng)}});
  const int lights = 3;
  std::vector<float> uniforms(size_t(MOBIRT_SP_TEXTURES(lights)) * 4, 99.0f);
  append_atlas_uniforms(atlas, lights, uniforms);
  ASSERT_EQ(uniforms.size(), size_t(MOBIRT_SP_TEXTURES(lights) + 2 * MOBIRT_SP_VEC4S_PER_TEXTURE) * 4);
  const float* t0 = &uniforms[size_t(MOBIRT_SP_TEXTURES(lights)) * 4];
  EXPECT_EQ(uniforms[size_t(MOBIRT_SP_TEXTURES(lights)) * 4 - 1], 99.0f);  // lights untouched
  const AtlasTile& a = atlas.tiles[0];
  const std::vector<float> want0 = {float(a.x), float(a.y), 37.0f, 300.0f, float(MOBIRT_WRAP_MIRRORED_REPEAT),
                                    float(MOBIRT_WRAP_CLAMP), float(a.page), 0.0f};
  EXPECT_EQ(std::vector<float>(t0, t0 + 8), want0);
  const AtlasTile& b = atlas.tiles[1];
  const std::vector<float> want1 = {float(b.x), float(b.y), 512.0f, 128.0f, float(MOBIRT_WRAP_REPEAT),
                                    float(MOBIRT_WRAP_REPEAT), float(b.page), 0.0f};
  EXPECT_EQ(std::vector<float>(t0 + 8, t0 + 16), want1);
  // On a later page, the page number is the tile's third wrap component.
  std::vector<AtlasTexture> seventeen(17, AtlasTexture{solid(512, 512, 0)});
  const Atlas two_pages = assemble_atlas(seventeen);
  ASSERT_EQ(two_pages.page_count(), 2);
  std::vector<float> u;
  append_atlas_uniforms(two_pages, 0, u);
  for (size_t t = 0; t < 17; ++t) {
    EXPECT_EQ(u[(size_t(MOBIRT_SP_TEXTURES(0)) + 2 * t + 1) * 4 + 2], float(two_pages.tiles[t].page));
  }
}

// ---- the GPU lookup (glsl/atlas.glsl) against sample_atlas() -----------------------------------

// Runs the test shader for lookups (uv, texture) with `lights` light slots before the textures;
// returns the RGBA8 texels.
std::vector<uint32_t> run_gpu_lookups(Backend& backend, const Atlas& atlas, const std::vector<glm::vec3>& lookups,
                                  int lights) {
  const uint32_t width = 256;
  const uint32_t count = uint32_t(lookups.size());
  const uint32_t height = (count + width - 1) / width;
  std::vector<float> texels(size_t(width) * height * 4, 0.0f);
  for (size_t i = 0; i < lookups.size(); ++i) {
    texels[i * 4 + 0] = lookups[i].x;
    texels[i * 4 + 1] = lookups[i].y;
    texels[i * 4 + 2] = lookups[i].z;
  }
  const TextureHandle input = backend.create_texture(width, height, TexelFormat::RGBA32F);
  backend.upload(input, texels.data(), texels.size() * sizeof(float));
  std::vector<TextureHandle> pages;
  const DeviceInfo info = backend.device_info();
  for (const std::vector<uint32_t>& page : atlas.pages) {
    pages.push_back(backend.create_texture(uint32_t(atlas.size), uint32_t(atlas.size), atlas_page_format(info)));
    backend.upload(pages.back(), page.data(), page.size() * sizeof(uint32_t));
  }

  std::vector<float> uniforms(size_t(MOBIRT_SP_TEXTURES(lights)) * 4, 123.0f);  // junk lights
  append_atlas_uniforms(atlas, lights, uniforms);
  PassDesc desc;
  desc.shader = test_shader(TestShader::AtlasLookup);
  desc.specialization = {{MOBIRT_SPEC_LIGHT_COUNT, lights},
                         {MOBIRT_SPEC_TEXTURE_COUNT, int32_t(atlas.tiles.size())},
                         {MOBIRT_SPEC_ATLAS_PAGES, atlas.page_count()}};
  desc.uniform_vec4s = uint32_t(uniforms.size() / 4);
  desc.texture_bindings = {MOBIRT_BIND_HIT_TEXCOORD, MOBIRT_BIND_ATLAS_PAGE_0, MOBIRT_BIND_ATLAS_PAGE_1,
                           MOBIRT_BIND_ATLAS_PAGE_2};
  desc.linear_bindings = atlas_linear_bindings(info);
  const PassHandle pass = backend.create_pass(desc);
  // Every page slot is bound; one the atlas lacks gets its last page (never read).
  const TextureHandle textures[4] = {input, pages[0], pages[std::min<size_t>(1, pages.size() - 1)],
                                     pages[std::min<size_t>(2, pages.size() - 1)]};
  std::vector<uint32_t> out(count);
  backend.run_pass(pass, textures, uniforms, width, count, out);
  backend.destroy(pass);
  backend.destroy(input);
  for (TextureHandle page : pages) backend.destroy(page);
  return out;
}

// Each GPU lookup against sample_atlas() within 1/255; returns the largest difference in 1/255.
// GLES blends 4 decoded texels as sample_atlas() does: only the output's rounding differs (0.5).
// Vulkan's one hardware fetch has the sampler's own weights and sRGB decode: 0.79 on lavapipe.
double expect_lookups_match_cpu(const Atlas& atlas, const std::vector<glm::vec3>& lookups,
                                const std::vector<uint32_t>& out) {
  size_t bad = 0;
  double worst = 0.0;
  for (size_t i = 0; i < lookups.size(); ++i) {
    const glm::vec3 want = sample_atlas(atlas, int(lookups[i].z), glm::vec2(lookups[i]));
    for (int c = 0; c < 3; ++c) {
      const double diff = std::abs(double(channel(out[i], c)) - double(want[c]) * 255.0);
      worst = std::max(worst, diff);
      if (diff > 1.0 && ++bad <= 5) {
        ADD_FAILURE() << "texture " << lookups[i].z << " uv " << lookups[i].x << ", " << lookups[i].y << " channel "
                      << c << ": GPU " << channel(out[i], c) << ", CPU " << want[c] * 255.0f;
      }
    }
    EXPECT_EQ(channel(out[i], 3), 255u);
  }
  EXPECT_EQ(bad, 0u) << "of " << lookups.size() << " lookups";
  return worst;
}

class AtlasGpuTest : public test::VulkanTest {
 protected:
  std::vector<uint32_t> gpu_lookups(const Atlas& atlas, const std::vector<glm::vec3>& lookups, int lights) {
    return run_gpu_lookups(*backend, atlas, lookups, lights);
  }
};

TEST_F(AtlasGpuTest, LookupMatchesTheCpuInEveryWrapMode) {
  std::mt19937 rng(2024);
  // Every combination of wrap modes, on tiles of odd, non-square and full sizes.
  std::vector<AtlasTexture> textures;
  const glm::ivec2 sizes[] = {{37, 300}, {512, 128}, {5, 3}, {1, 1}, {64, 64}, {512, 512}, {2, 7}, {300, 37}, {3, 3}};
  size_t k = 0;
  for (TextureWrap s : kModes) {
    for (TextureWrap t : kModes) {
      textures.push_back({random_image(sizes[k].x, sizes[k].y, rng), s, t});
      ++k;
    }
  }
  const Atlas atlas = assemble_atlas(textures);
  const auto uvs = border_and_random_uvs(2000, rng);
  std::vector<glm::vec3> lookups;
  for (size_t t = 0; t < textures.size(); ++t) {
    for (const glm::vec2& uv : uvs) lookups.emplace_back(uv, float(t));
  }
  const std::vector<uint32_t> out = gpu_lookups(atlas, lookups, 2);
  const double worst = expect_lookups_match_cpu(atlas, lookups, out);
  std::printf("atlas lookups: %zu, largest GPU-CPU difference %.3f / 255\n", lookups.size(), worst);
}

// Three pages on both backends: 40 textures of 320x320 (a cap of 512 packs 16 a page), each a
// random image of its own; lookups in every texture match the CPU, so each reads its own page.
class AtlasPagesTest : public ::testing::TestWithParam<bool> {};

TEST_P(AtlasPagesTest, LookupsOnEveryPageMatchTheCpu) {
  const bool gles = GetParam();
  std::unique_ptr<Backend> backend = gles ? create_gles_backend(test::validated_options())
                                          : create_vulkan_backend(test::validated_options());
  std::mt19937 rng(41);
  std::vector<AtlasTexture> textures;
  for (int t = 0; t < 40; ++t) {
    const TextureWrap s = kModes[t % 3], w = kModes[(t / 3) % 3];
    textures.push_back({random_image(t % 2 ? 320 : 301, t % 5 ? 320 : 97, rng), s, w});
  }
  const Atlas atlas = assemble_atlas(textures);
  ASSERT_EQ(atlas.page_count(), 3);
  std::vector<glm::vec3> lookups;
  std::uniform_real_distribution<float> coord(-1.5f, 2.5f);
  for (int t = 0; t < 40; ++t) {
    for (int k = 0; k < 200; ++k) lookups.emplace_back(coord(rng), coord(rng), float(t));
  }
  const std::vector<uint32_t> out = run_gpu_lookups(*backend, atlas, lookups, 1);
  const double worst = expect_lookups_match_cpu(atlas, lookups, out);
  std::printf("%s: 3-page atlas lookups: %zu, largest GPU-CPU difference %.3f / 255\n", gles ? "gles" : "vulkan",
              lookups.size(), worst);
  const std::vector<std::string> messages = backend->take_debug_messages();
  EXPECT_TRUE(messages.empty()) << test::join(messages);
}

INSTANTIATE_TEST_SUITE_P(Backends, AtlasPagesTest, ::testing::Values(false, true),
                         [](const testing::TestParamInfo<bool>& p) { return p.param ? "gles" : "vulkan"; });

TEST_F(AtlasGpuTest, BilinearNeverReadsANeighbourTile) {
  std::mt19937 rng(9);
  const auto uvs = border_and_random_uvs(3000, rng);
  for (TextureWrap s : kModes) {
    for (TextureWrap t : kModes) {
      SCOPED_TRACE("wrap " + std::to_string(int(s)) + ", " + std::to_string(int(t)));
      const Atlas atlas = red_tile_in_green(s, t);
      std::vector<glm::vec3> lookups;
      for (const glm::vec2& uv : uvs) lookups.emplace_back(uv, 0.0f);
      const std::vector<uint32_t> out = gpu_lookups(atlas, lookups, 0);
      size_t leaks = 0;
      for (uint32_t texel : out) leaks += texel != pack_rgba8(255, 0, 0, 255);
      EXPECT_EQ(leaks, 0u);
    }
  }
}

// ---- real data ---------------------------------------------------------------------------------

TEST(AtlasRealData, BoxTexturedExternalPng) {
  MOBIRT_REQUIRE_SHARED(path, "gltf/assimp-testmodels/BoxTextured-glTF/BoxTextured.gltf");
  const Scene scene = load_scene(path.string());
  ASSERT_EQ(scene.textures.size(), 1u);
  const Atlas atlas = build_atlas(scene);
  ASSERT_EQ(atlas.tiles.size(), 1u);
  const AtlasTile& t = atlas.tiles[0];
  // A single texture keeps its size up to a page.
  const TextureImage original = decode_texture(scene, 0);
  EXPECT_EQ(t.width, std::min(original.width, MOBIRT_ATLAS_SIZE));
  EXPECT_LE(t.height, MOBIRT_ATLAS_SIZE);
  // Not blank: the logo has more than one colour.
  const uint32_t first = atlas.at(t.page, t.x, t.y);
  bool varied = false;
  for (int y = 0; y < t.height && !varied; ++y) {
    for (int x = 0; x < t.width && !varied; ++x) varied = atlas.at(t.page, t.x + x, t.y + y) != first;
  }
  EXPECT_TRUE(varied);
}

TEST(AtlasRealData, FoxEmbeddedTexture) {
  MOBIRT_REQUIRE_SHARED(path, "gltf/Fox/Fox.glb");
  const Scene scene = load_scene(path.string());
  ASSERT_GE(scene.textures.size(), 1u);
  ASSERT_FALSE(scene.textures[0].data.empty()) << "Fox.glb embeds its texture";
  testing::internal::CaptureStderr();
  const Atlas atlas = build_atlas(scene);
  const std::string err = testing::internal::GetCapturedStderr();
  ASSERT_EQ(atlas.tiles.size(), scene.textures.size());
  const TextureImage original = decode_texture(scene, 0);
  int w = 0, h = 0;
  fitted_size(original.width, original.height, MOBIRT_ATLAS_SIZE, w, h);
  EXPECT_EQ(atlas.tiles[0].width, w);
  EXPECT_EQ(atlas.tiles[0].height, h);
  const bool downscaled = original.width > MOBIRT_ATLAS_SIZE || original.height > MOBIRT_ATLAS_SIZE;
  EXPECT_EQ(err.find("downscaled to") != std::string::npos, downscaled) << err;
  std::printf("Fox texture %dx%d -> tile %dx%d\n", original.width, original.height, w, h);
}

}  // namespace
}  // namespace mobirt
