#include "scene/atlas.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <numeric>
#include <string>

#include "core/error.h"
#include "scene/validate.h"
#include "texels.h"

namespace mobirt {

namespace {

// A tile and its gutter fit a page.
constexpr int kLargestTile = MOBIRT_ATLAS_SIZE - 2 * MOBIRT_ATLAS_GUTTER;

std::string size_text(int width, int height) {
  std::string s = std::to_string(width);
  s.append("x").append(std::to_string(height));
  return s;
}

std::string texture_label(const Scene& scene, size_t index) {
  const TextureRef& ref = scene.textures[index];
  if (!ref.name.empty()) return ref.name;
  if (!ref.path.empty()) return std::filesystem::path(ref.path).filename().string();
  std::string label("textures[");
  label.append(std::to_string(index)).append("]");
  return label;
}

void check_texture_count(size_t count, const std::string& source) {
  if (count <= size_t(MOBIRT_ATLAS_MAX_TEXTURES)) return;
  std::string message(std::to_string(count));
  message.append(" textures, but the texture atlas holds at most ")
      .append(std::to_string(MOBIRT_ATLAS_MAX_TEXTURES))
      .append(" (")
      .append(std::to_string(MOBIRT_ATLAS_MAX_PAGES))
      .append(" pages of ")
      .append(size_text(MOBIRT_ATLAS_SIZE, MOBIRT_ATLAS_SIZE))
      .append(" RGBA8, ")
      .append(std::to_string(MOBIRT_ATLAS_TILES_PER_PAGE))
      .append(" textures each: the 8 texture units of OpenGL ES 2.0 less the shading pass's ")
      .append(std::to_string(MOBIRT_SHADE_DATA_TEXTURES))
      .append(" other inputs); merge textures into fewer images or remove some materials' base-colour textures");
  throw input_error(source, message);
}

// srgb_to_linear() of each 8-bit value v read as the UNORM v / 255, the linear value the shader
// computes from such a texel: the float srgb_to_linear() gives, looked up instead of computed.
// A bilinear lookup decodes 4 texels of 3 channels, up to twelve std::pow calls, which were more
// than half of the CPU engines' shading stage (the Embree and CPU kd-tree columns of `mobirt
// bench`: toaster ray casting 7.3-8.1 ms, 2.4-2.7 ms with the table).
const std::array<float, 256> kSrgbToLinear = [] {
  std::array<float, 256> table{};
  for (uint32_t v = 0; v < 256; ++v) table[v] = srgb_to_linear(float(v) / 255.0f);
  return table;
}();

// Linear value of an 8-bit channel, as the shader computes it from the UNORM texel.
float channel_linear(uint32_t texel, int channel) { return kSrgbToLinear[(texel >> (8 * channel)) & 0xffu]; }

glm::vec3 texel_linear(const Atlas& atlas, int page, float x, float y) {
  const uint32_t texel = atlas.at(page, int(x), int(y));
  return glm::vec3(channel_linear(texel, 0), channel_linear(texel, 1), channel_linear(texel, 2));
}

// GLSL mix(): x * (1 - a) + y * a.
glm::vec3 mix3(const glm::vec3& x, const glm::vec3& y, float a) { return x * (1.0f - a) + y * a; }

// The tile's texels and its gutter: gutter texel i (i = -1 or size on an axis) holds the texel
// that the tile's wrap mode maps i to (atlas_wrap: the last column left of a REPEAT tile, the edge
// itself for MIRRORED_REPEAT and CLAMP_TO_EDGE), so that a bilinear fetch of a coordinate wrapped
// into [0, 1] reads, at the tile's edges, the neighbours the texture's own sampler would read.
void copy_tile(const TextureImage& image, const AtlasTile& tile, int page_size, std::vector<uint32_t>& page) {
  const float w = float(image.width), h = float(image.height);
  constexpr int g = MOBIRT_ATLAS_GUTTER;
  for (int row = -g; row < image.height + g; ++row) {
    const int src_row = row < 0 || row >= image.height ? int(atlas_wrap(float(row), h, tile.wrap_t)) : row;
    const uint32_t* src = &image.pixels[size_t(src_row) * size_t(image.width)];
    uint32_t* dst = &page[size_t(tile.y + row) * size_t(page_size) + size_t(tile.x)];
    std::copy_n(src, size_t(image.width), dst);
    for (int k = 1; k <= g; ++k) {
      dst[-k] = src[size_t(atlas_wrap(float(-k), w, tile.wrap_s))];
      dst[image.width - 1 + k] = src[size_t(atlas_wrap(float(image.width - 1 + k), w, tile.wrap_s))];
    }
  }
}

}  // namespace

float wrap_value(TextureWrap wrap) {
  switch (wrap) {
    case TextureWrap::Repeat: return float(MOBIRT_WRAP_REPEAT);
    case TextureWrap::MirroredRepeat: return float(MOBIRT_WRAP_MIRRORED_REPEAT);
    case TextureWrap::ClampToEdge: return float(MOBIRT_WRAP_CLAMP);
  }
  return float(MOBIRT_WRAP_REPEAT);
}

std::optional<std::vector<AtlasTile>> try_pack_tiles(const std::vector<glm::ivec2>& sizes, int max_pages,
                                                     int page_size) {
  std::vector<size_t> order(sizes.size());
  std::iota(order.begin(), order.end(), size_t(0));
  // Tallest first (then widest, then input order): each shelf's first tile sets its height.
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) {
    if (sizes[a].y != sizes[b].y) return sizes[a].y > sizes[b].y;
    return sizes[a].x > sizes[b].x;
  });
  std::vector<AtlasTile> tiles(sizes.size());
  constexpr int frame = 2 * MOBIRT_ATLAS_GUTTER;  // each tile's footprint is its size plus a gutter a side
  int page = 0, on_page = 0, x = 0, y = 0, shelf_height = 0;
  for (size_t i : order) {
    const int w = sizes[i].x + frame, h = sizes[i].y + frame;
    if (sizes[i].x <= 0 || sizes[i].y <= 0 || w > page_size || h > page_size) return std::nullopt;
    if (x + w > page_size) {  // next shelf
      y += shelf_height;
      x = 0;
      shelf_height = 0;
    }
    if (y + h > page_size || on_page == MOBIRT_ATLAS_TILES_PER_PAGE) {  // next page
      ++page;
      on_page = x = y = shelf_height = 0;
    }
    if (page >= max_pages) return std::nullopt;
    tiles[i] = AtlasTile{page, x + MOBIRT_ATLAS_GUTTER, y + MOBIRT_ATLAS_GUTTER, sizes[i].x, sizes[i].y, 0.0f, 0.0f};
    x += w;
    shelf_height = std::max(shelf_height, h);
    ++on_page;
  }
  return tiles;
}

std::vector<AtlasTile> pack_tiles(const std::vector<glm::ivec2>& sizes, int max_pages, int page_size) {
  std::optional<std::vector<AtlasTile>> tiles = try_pack_tiles(sizes, max_pages, page_size);
  if (!tiles) {
    std::string message(std::to_string(sizes.size()));
    message.append(" atlas tiles do not fit into ").append(std::to_string(max_pages)).append(" pages of ");
    message.append(size_text(page_size, page_size));
    throw Error(ErrorKind::Internal, message);
  }
  return *std::move(tiles);
}

int atlas_tile_limit(const std::vector<glm::ivec2>& sizes) {
  if (sizes.size() > size_t(MOBIRT_ATLAS_MAX_TEXTURES)) {
    throw Error(ErrorKind::Internal, "atlas_tile_limit: " + std::to_string(sizes.size()) + " textures");
  }
  int longest = 1;
  for (const glm::ivec2& s : sizes) longest = std::max({longest, s.x, s.y});
  // Downward from the longest side (or a page): the first cap that packs is the largest. At most
  // 1,537 packings of at most 48 tiles, once per scene; MOBIRT_ATLAS_SURE_TILE always packs.
  std::vector<glm::ivec2> fitted(sizes.size());
  for (int limit = std::min(longest, kLargestTile); limit > MOBIRT_ATLAS_SURE_TILE; --limit) {
    for (size_t i = 0; i < sizes.size(); ++i) fitted_size(sizes[i].x, sizes[i].y, limit, fitted[i].x, fitted[i].y);
    if (try_pack_tiles(fitted)) return limit;
  }
  return std::min(longest, MOBIRT_ATLAS_SURE_TILE);
}

Atlas assemble_atlas(const std::vector<AtlasTexture>& textures) {
  check_texture_count(textures.size(), "");
  Atlas atlas;
  if (textures.empty()) return atlas;
  std::vector<glm::ivec2> sizes;
  for (size_t i = 0; i < textures.size(); ++i) {
    const TextureImage& image = textures[i].image;
    if (image.pixels.size() != size_t(image.width) * size_t(image.height)) {
      std::string message("atlas texture ");
      message.append(std::to_string(i)).append(" is ").append(size_text(image.width, image.height));
      message.append(" but holds ").append(std::to_string(image.pixels.size())).append(" texels");
      throw Error(ErrorKind::Internal, message);
    }
    sizes.emplace_back(image.width, image.height);
    atlas.tile_limit = std::max({atlas.tile_limit, image.width, image.height});
  }
  atlas.tiles = pack_tiles(sizes);
  int pages = 0;
  for (const AtlasTile& tile : atlas.tiles) pages = std::max(pages, tile.page + 1);
  atlas.pages.resize(size_t(pages));
  for (std::vector<uint32_t>& page : atlas.pages) page.assign(size_t(atlas.size) * size_t(atlas.size), 0u);
  for (size_t i = 0; i < textures.size(); ++i) {
    AtlasTile& tile = atlas.tiles[i];
    tile.wrap_s = wrap_value(textures[i].wrap_s);
    tile.wrap_t = wrap_value(textures[i].wrap_t);
    copy_tile(textures[i].image, tile, atlas.size, atlas.pages[size_t(tile.page)]);
  }
  return atlas;
}

std::string atlas_key(const Scene& scene) {
  std::string key = scene.source;
  for (const TextureRef& t : scene.textures) {
    key.append("|").append(t.name).append(":").append(t.path).append(":").append(std::to_string(t.data.size()));
    key.append(":").append(std::to_string(int(t.wrap_s))).append(std::to_string(int(t.wrap_t)));
  }
  return key;
}

Atlas build_atlas(const Scene& scene) {
  check_texture_count(scene.textures.size(), scene.source);
  std::vector<AtlasTexture> textures(scene.textures.size());
  std::vector<glm::ivec2> sizes;
  for (size_t i = 0; i < scene.textures.size(); ++i) {
    textures[i].image = decode_texture(scene, int(i));
    textures[i].wrap_s = scene.textures[i].wrap_s;
    textures[i].wrap_t = scene.textures[i].wrap_t;
    sizes.emplace_back(textures[i].image.width, textures[i].image.height);
  }
  const int limit = atlas_tile_limit(sizes);
  for (size_t i = 0; i < textures.size(); ++i) {
    TextureImage& image = textures[i].image;
    if (image.width <= limit && image.height <= limit) continue;
    TextureImage smaller = downscale_to_fit(image, limit);
    std::string message("texture '");
    message.append(texture_label(scene, i)).append("' ").append(size_text(image.width, image.height));
    message.append(" downscaled to ").append(size_text(smaller.width, smaller.height)).append(" for the atlas");
    scene_warning(scene.source, message);
    image = std::move(smaller);
  }
  return assemble_atlas(textures);
}

void append_atlas_uniforms(const Atlas& atlas, int light_count, std::vector<float>& uniforms) {
  const size_t base = size_t(MOBIRT_SP_TEXTURES(light_count));
  const size_t end = base + size_t(MOBIRT_SP_VEC4S_PER_TEXTURE) * atlas.tiles.size();
  if (uniforms.size() < end * 4) uniforms.resize(end * 4, 0.0f);
  for (size_t t = 0; t < atlas.tiles.size(); ++t) {
    const AtlasTile& tile = atlas.tiles[t];
    const AtlasTileParams params{glm::vec2(float(tile.x), float(tile.y)), glm::vec2(float(tile.width), float(tile.height)),
                                 tile.wrap_s, tile.wrap_t, float(tile.page), 0.0f};
    std::memcpy(&uniforms[(base + size_t(MOBIRT_SP_VEC4S_PER_TEXTURE) * t) * 4], &params, sizeof(params));
  }
}

float atlas_wrap(float texel, float size, float mode) {
  float r = texel;
  if (mode == float(MOBIRT_WRAP_MIRRORED_REPEAT)) {
    const float period = 2.0f * size;
    r = texel - period * std::floor((texel + 0.5f) / period);
    if (r >= size) r = period - 1.0f - r;
  } else if (mode != float(MOBIRT_WRAP_CLAMP)) {
    r = texel - size * std::floor((texel + 0.5f) / size);
  }
  return std::clamp(r, 0.0f, size - 1.0f);
}

float atlas_wrap_coord(float u, float mode) {
  float r = u - std::floor(u);  // repeat
  if (mode == float(MOBIRT_WRAP_MIRRORED_REPEAT)) {
    r = 1.0f - std::fabs(1.0f - (u - 2.0f * std::floor(0.5f * u)));
  } else if (mode == float(MOBIRT_WRAP_CLAMP)) {
    r = u;
  }
  return std::clamp(r, 0.0f, 1.0f);
}

glm::vec3 sample_atlas(const Atlas& atlas, int texture, glm::vec2 uv) {
  glm::vec4 tile(0.0f, 0.0f, 1.0f, 1.0f);
  glm::vec2 wrap(0.0f);
  int page = 0;
  if (texture >= 0 && size_t(texture) < atlas.tiles.size()) {
    const AtlasTile& t = atlas.tiles[size_t(texture)];
    tile = glm::vec4(float(t.x), float(t.y), float(t.width), float(t.height));
    wrap = glm::vec2(t.wrap_s, t.wrap_t);
    page = t.page;
  }
  if (atlas.pages.empty()) return glm::vec3(0.0f);
  const glm::vec2 w(atlas_wrap_coord(uv.x, wrap.x), atlas_wrap_coord(uv.y, wrap.y));
  const glm::vec2 p = w * glm::vec2(tile.z, tile.w) - 0.5f;
  const glm::vec2 p0 = glm::floor(p);
  const glm::vec2 f = p - p0;
  // p0 is in [-1, size - 1]: texels -1 and size are the gutter (at most one texel out on each side).
  const float x0 = tile.x + p0.x, x1 = x0 + 1.0f;
  const float y0 = tile.y + p0.y, y1 = y0 + 1.0f;
  const glm::vec3 top = mix3(texel_linear(atlas, page, x0, y0), texel_linear(atlas, page, x1, y0), f.x);
  const glm::vec3 bottom = mix3(texel_linear(atlas, page, x0, y1), texel_linear(atlas, page, x1, y1), f.x);
  return mix3(top, bottom, f.y);
}

}  // namespace mobirt
