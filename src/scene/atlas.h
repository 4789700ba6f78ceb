// The texture atlas of the MobiRT paper, repeated on pages: every base-colour texture of a scene
// packed into 2048 x 2048 RGBA8 pages of up to 16 tiles each (OpenGL ES 2.0 guarantees only 8
// texture units, so textures cannot each have their own), as many pages as the shading pass's
// other inputs leave units for (MOBIRT_ATLAS_MAX_PAGES = 8 - 5 = 3), so at most 48 textures.
//
// - Decoding: scene/texture_images.h (OpenImageIO; embedded bytes through its in-memory IOProxy).
// - Tile sizes: every texture keeps its own size up to one cap on the longest side, the largest cap
//   (at most a page less its gutter, 2046) at which the scene's textures pack into the pages (atlas_tile_limit).
//   Only textures over the cap are scaled down (aspect ratio kept, filtered in linear light), with
//   one warning per texture and build_atlas() call on stderr:
//     "mobirt: warning: SCENE: texture 'name' 4096x4096 downscaled to 2046x2046 for the atlas"
//   A cap of 510 always packs (any 16 tiles up to 512 fill at most one page), so no scene within
//   the count limit is refused for its sizes.
// - More than 48 textures: Error(BadInput) naming the scene, the count, the limit and the fix.
//   mobirt refuses rather than dropping textures silently (never a wrong image).
// - Packing: shelves, tiles sorted by height (tallest first), filling one page after another: a
//   tile that does not fit the page's next shelf, or a page that holds 16 tiles, opens the next.
// - Gutters: each tile is framed by MOBIRT_ATLAS_GUTTER (1) texel a side, copied by the tile's
//   wrap modes (atlas_wrap() of the texel indices -1 and size: the opposite edge for REPEAT, the
//   edge itself for MIRRORED_REPEAT and CLAMP_TO_EDGE; corners by both axes). A lookup wraps its
//   coordinate into [0, 1] once (atlas_wrap_coord()) and then a bilinear footprint reads texels
//   -1 .. size at most: the tile or its gutter, never a neighbour. Capacity: a tile's footprint is
//   its size + 2, so a tile is at most 2046 a side (a lone 2048 texture is downscaled to 2046) and
//   the size that always packs 16 a page is 510 (4 x 512 = 2048); a 1024x1024 texture stays whole.
// - Lookup (glsl/atlas.glsl): u' = wrap(uv) per axis; Vulkan: ONE hardware bilinear fetch of the
//   page, an R8G8B8A8_SRGB image behind a LINEAR sampler (no mipmaps), at (origin + u' * size) /
//   page size: the sampler decodes each texel from sRGB before it filters, as the texture's own
//   sampler would; the weights and the decode are the sampler's (on lavapipe within 0.79/255 of
//   the exact blend, tests/atlas_test.cpp).
//   OpenGL ES 2.0 has no sRGB texture without GL_EXT_sRGB, which Mesa does not offer to an ES 2.0
//   context, and filtering the encoded values would blend in the wrong space, so GLES keeps 4
//   NEAREST fetches at texels floor(p) and floor(p) + 1 (p = u' * size - 0.5, reading the gutter
//   at the edges instead of wrapping each index), each decoded before an exact bilinear blend.
//   sample_atlas() below is that exact lookup; it equals the texture's own GL_LINEAR lookup.
// - Colour: the pages store the 8-bit values as the file has them (sRGB-encoded, as glTF base
//   colour textures are); every lookup returns linear RGB. Alpha is kept but not used.
#pragma once

#include <glm/glm.hpp>

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "layout.h"
#include "scene/scene.h"
#include "scene/texture_images.h"

namespace mobirt {

struct AtlasTile {
  int page = 0;              // which page holds it
  int x = 0, y = 0;          // placement in the page's texels: the first texel, inside the gutter
  int width = 0, height = 0;
  float wrap_s = 0.0f, wrap_t = 0.0f;  // MOBIRT_WRAP_* values
};

struct Atlas {
  int size = MOBIRT_ATLAS_SIZE;
  // Each page size * size RGBA8 (r | g << 8 | b << 16 | a << 24), row-major, y = 0 the top row;
  // no page when the scene has no textures.
  std::vector<std::vector<uint32_t>> pages;
  std::vector<AtlasTile> tiles;  // one per Scene::textures entry, same order
  int tile_limit = 0;            // the cap on a tile's longest side that this atlas was packed with

  bool empty() const { return tiles.empty(); }
  int page_count() const { return int(pages.size()); }
  uint32_t at(int page, int x, int y) const { return pages[size_t(page)][size_t(y) * size_t(size) + size_t(x)]; }
};

// Decodes, downscales where the pages require it and packs the scene's textures. Throws
// Error(BadInput) for more than MOBIRT_ATLAS_MAX_TEXTURES textures, a missing texture file or an
// undecodable image (messages in scene/texture_images.h). A scene without textures gets an empty
// atlas. Build it once per scene: textures do not change from frame to frame.
Atlas build_atlas(const Scene& scene);

// What build_atlas(scene) depends on, as a string: two scenes with the same key get the same
// atlas. Textures never change during an animation, so a renderer builds the atlas once and keeps
// it while the key stays the same (decoding and packing the textures every frame cost the CPU
// engines about 4 ms a frame on the toaster and the fish).
std::string atlas_key(const Scene& scene);

// A texture already decoded and sized for its tile, with its sampler.
struct AtlasTexture {
  TextureImage image;
  TextureWrap wrap_s = TextureWrap::Repeat;
  TextureWrap wrap_t = TextureWrap::Repeat;
};
// Packs decoded textures at their sizes (build_atlas() without the decoding and downscaling; for
// tests). Throws Error(BadInput) over the texture-count limit and Error(Internal) when they do not
// fit the pages.
Atlas assemble_atlas(const std::vector<AtlasTexture>& textures);

// Shelf packing of tiles of the given sizes (width, height), each with its gutter, onto at most
// `max_pages` square pages of `page_size`, MOBIRT_ATLAS_TILES_PER_PAGE tiles a page at most, in
// input order; x and y are the tiles' first texels, wrap fields are left 0. Empty when they do not
// fit.
std::optional<std::vector<AtlasTile>> try_pack_tiles(const std::vector<glm::ivec2>& sizes,
                                                     int max_pages = MOBIRT_ATLAS_MAX_PAGES,
                                                     int page_size = MOBIRT_ATLAS_SIZE);
// The same; throws Error(Internal) when they do not fit.
std::vector<AtlasTile> pack_tiles(const std::vector<glm::ivec2>& sizes, int max_pages = MOBIRT_ATLAS_MAX_PAGES,
                                  int page_size = MOBIRT_ATLAS_SIZE);

// The largest cap on the longest side (at most MOBIRT_ATLAS_SIZE less the gutters, at least
// MOBIRT_ATLAS_SURE_TILE)
// at which images of `sizes`, each fitted to the cap (fitted_size()), pack into the pages; the
// longest side among them when they all fit as they are. Throws Error(Internal) for more than
// MOBIRT_ATLAS_MAX_TEXTURES sizes.
int atlas_tile_limit(const std::vector<glm::ivec2>& sizes);

// MOBIRT_WRAP_* value of a glTF wrap mode.
float wrap_value(TextureWrap wrap);

// Writes the texture uniforms (MOBIRT_SP_VEC4S_PER_TEXTURE vec4 per tile, layout in glsl/layout.h)
// into a shading-pass uniform array of floats (4 per vec4) whose lights part is already there:
// from vec4 index MOBIRT_SP_TEXTURES(light_count) on, growing `uniforms` as needed.
void append_atlas_uniforms(const Atlas& atlas, int light_count, std::vector<float>& uniforms);

// The exact lookup on the CPU (the GLES shader's arithmetic in glsl/atlas.glsl; Vulkan's hardware
// filter differs from it by its 8-bit weights): linear RGB of `texture`
// at texture coordinate `uv` (glTF convention, (0, 0) the top-left corner). uv must be finite.
// An index outside the atlas reads as the shader reads it: texel (0, 0) of page 0.
glm::vec3 sample_atlas(const Atlas& atlas, int texture, glm::vec2 uv);

// The wrap of one texel index (an integer as a float) into [0, size) by mode (MOBIRT_WRAP_*),
// as atlas.glsl's atlas_wrap(): repeat = i mod size, mirrored repeat = GL's mirror of i mod
// 2 size, clamp = clamp(i, 0, size - 1). The result is clamped into the tile in every mode. The
// gutters are filled with it.
float atlas_wrap(float texel, float size, float mode);

// A texture coordinate wrapped into [0, 1] by mode, as atlas.glsl's atlas_wrap_coord(): repeat =
// fract(u), mirrored repeat = 1 - |1 - (u mod 2)|, clamp = clamp(u, 0, 1). With the gutters, the
// bilinear lookup of the wrapped coordinate equals the texture's GL_LINEAR lookup of u.
float atlas_wrap_coord(float u, float mode);

}  // namespace mobirt
