// The texture atlas of the MobiRT paper: every base-colour texture of a scene packed into ONE
// 2048 x 2048 RGBA8 texture (OpenGL ES 2.0 guarantees only 8 texture units, so textures cannot each
// have their own), at most 16 textures of at most 512 x 512 texels, non-square allowed.
//
// - Decoding: scene/texture_images.h (OpenImageIO; embedded bytes through its in-memory IOProxy).
// - Textures over 512 on a side are scaled down (aspect ratio kept, filtered in linear light) with
//   one warning per texture and build_atlas() call on stderr:
//     "mobirt: warning: SCENE: texture 'name' 1024x1024 downscaled to 512x512 for the atlas"
// - More than 16 textures: Error(BadInput) naming the scene, the count and the fix. mobirt refuses
//   rather than dropping or shrinking textures silently (never a wrong image).
// - Packing: a shelf packer, tiles sorted by height (tallest first). It cannot fail within the
//   limits: every shelf holds at least 4 tiles (4 x 512 = 2048), so 16 tiles need at most 4
//   shelves, each at most 512 tall. 16 tiles of 512 x 512 fill the atlas exactly (4 x 4).
// - No gutter between tiles: the shader filters by hand (4 texel fetches, each texel index wrapped
//   or clamped inside its own tile), so a lookup never reads a neighbour's texel whatever the
//   wrap mode or coordinate. tests/atlas_test.cpp proves it on the CPU and on the GPU.
// - Lookup (glsl/atlas.glsl, mirrored by sample_atlas() below): p = uv * size - 0.5 in tile
//   texels; texels floor(p) and floor(p) + 1 on each axis, each wrapped by the glTF sampler's mode
//   exactly as OpenGL wraps the texels of a GL_LINEAR lookup (repeat, mirrored repeat,
//   clamp-to-edge), so a tile behaves like a texture of its own with a LINEAR sampler (no mipmaps).
// - Colour: the atlas stores the 8-bit values as the file has them (sRGB-encoded, as glTF base
//   colour textures are); the shader converts each of the 4 fetched texels from sRGB to linear
//   before the bilinear blend, as hardware sRGB textures do, and returns linear RGB. Alpha is kept
//   in the atlas but not used.
#pragma once

#include <glm/glm.hpp>

#include <cstdint>
#include <vector>

#include "layout.h"
#include "scene/scene.h"
#include "scene/texture_images.h"

namespace mobirt {

struct AtlasTile {
  int x, y, width, height;   // placement in atlas texels
  float wrap_s, wrap_t;      // MOBIRT_WRAP_* values
};

struct Atlas {
  int size = MOBIRT_ATLAS_SIZE;
  std::vector<uint32_t> pixels;  // size * size RGBA8 (r | g << 8 | b << 16 | a << 24), row-major,
                                 // y = 0 the top row; empty when the scene has no textures
  std::vector<AtlasTile> tiles;  // one per Scene::textures entry, same order

  bool empty() const { return tiles.empty(); }
  uint32_t at(int x, int y) const { return pixels[size_t(y) * size_t(size) + size_t(x)]; }
};

// Decodes, downscales and packs the scene's textures. Throws Error(BadInput) for more than
// MOBIRT_ATLAS_MAX_TEXTURES textures, a missing texture file or an undecodable image (messages in
// scene/texture_images.h). A scene without textures gets an empty atlas. Build it once per scene:
// textures do not change from frame to frame.
Atlas build_atlas(const Scene& scene);

// A texture already decoded and at most MOBIRT_ATLAS_MAX_TILE on a side, with its sampler.
struct AtlasTexture {
  TextureImage image;
  TextureWrap wrap_s = TextureWrap::Repeat;
  TextureWrap wrap_t = TextureWrap::Repeat;
};
// Packs decoded textures (build_atlas() without the decoding; for tests). Throws Error(BadInput)
// over the texture-count limit and Error(Internal) for a texture over the tile size.
Atlas assemble_atlas(const std::vector<AtlasTexture>& textures);

// Shelf packing of tiles of the given sizes (width, height) into a square of `atlas_size`, in input
// order; wrap fields are left 0. Throws Error(Internal) when they do not fit (impossible within
// the atlas limits, see above).
std::vector<AtlasTile> pack_tiles(const std::vector<glm::ivec2>& sizes, int atlas_size = MOBIRT_ATLAS_SIZE);

// MOBIRT_WRAP_* value of a glTF wrap mode.
float wrap_value(TextureWrap wrap);

// Writes the texture uniforms (MOBIRT_SP_VEC4S_PER_TEXTURE vec4 per tile, layout in glsl/layout.h)
// into a shading-pass uniform array of floats (4 per vec4) whose lights part is already there:
// from vec4 index MOBIRT_SP_TEXTURES(light_count) on, growing `uniforms` as needed.
void append_atlas_uniforms(const Atlas& atlas, int light_count, std::vector<float>& uniforms);

// The shader's lookup on the CPU (same arithmetic as glsl/atlas.glsl): linear RGB of `texture`
// at texture coordinate `uv` (glTF convention, (0, 0) the top-left corner). uv must be finite.
// An index outside the atlas reads as the shader reads it: atlas texel (0, 0).
glm::vec3 sample_atlas(const Atlas& atlas, int texture, glm::vec2 uv);

// The wrap of one texel index (an integer as a float) into [0, size) by mode (MOBIRT_WRAP_*),
// as atlas.glsl's atlas_wrap(): repeat = i mod size, mirrored repeat = GL's mirror of i mod
// 2 size, clamp = clamp(i, 0, size - 1). The result is clamped into the tile in every mode.
float atlas_wrap(float texel, float size, float mode);

}  // namespace mobirt
