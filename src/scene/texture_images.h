// Decoding of the scene's base-colour textures (Scene::textures) into RGBA8 images for the atlas.
//
// Images decode through OpenImageIO: files by path, embedded bytes (glTF bufferViews and data
// URIs) through OIIO's in-memory IOProxy (Filesystem::IOMemReader), which the PNG and JPEG readers
// of OIIO 2.4 support. Pixel values stay as the file stores them (sRGB-encoded for glTF base
// colour): atlas.glsl converts sRGB to linear per texel, before filtering. Colour is read
// unassociated (never premultiplied by alpha).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "scene/scene.h"

namespace mobirt {

// 8-bit RGBA, row-major, y = 0 the top row (the glTF texture-coordinate convention: v = 0 at the
// top). Texel (x, y) is pixels[y * width + x] = r | g << 8 | b << 16 | a << 24 (the byte order of
// an RGBA8 texture in memory on a little-endian machine).
struct TextureImage {
  int width = 0;
  int height = 0;
  std::vector<uint32_t> pixels;

  uint32_t at(int x, int y) const { return pixels[size_t(y) * size_t(width) + size_t(x)]; }
};

inline uint32_t pack_rgba8(uint32_t r, uint32_t g, uint32_t b, uint32_t a) {
  return r | (g << 8) | (b << 16) | (a << 24);
}

// Decodes one texture of `scene` (index into scene.textures). Grey, grey+alpha and RGB images gain
// the missing channels (alpha = 255); 16-bit and float images are converted to 8 bits by OIIO.
// Errors are Error(BadInput) naming scene.source, the texture and the materials that use it:
//   "SCENE: texture 'PATH' not found (referenced by materials[2] 'wood'); put it beside the scene
//    or fix the path"
//   "SCENE: texture 'NAME' (embedded image/webp) cannot be decoded: ...; mobirt reads PNG and JPEG"
TextureImage decode_texture(const Scene& scene, int texture);

// Decodes an image from encoded bytes (PNG, JPEG, anything OIIO sniffs or `mime_type` names).
// `what` names the image in the error message. Throws Error(BadInput).
TextureImage decode_image_bytes(const std::vector<uint8_t>& bytes, const std::string& mime_type,
                                const std::string& what);

// Decodes an image file. Throws Error(BadInput) naming `what` when it cannot be read.
TextureImage decode_image_file(const std::string& path, const std::string& what);

// The image scaled down so that neither side exceeds `max_side`, keeping the aspect ratio (each
// side rounded, at least 1 texel); unchanged when it already fits. Filtering happens in linear
// light (sRGB decoded, OIIO ImageBufAlgo::resize with its default filter, re-encoded); alpha is
// filtered as it is.
TextureImage downscale_to_fit(const TextureImage& image, int max_side);

// Size that downscale_to_fit() gives an image of width x height.
void fitted_size(int width, int height, int max_side, int& out_width, int& out_height);

// "materials[2] 'wood'" (and ", materials[5] 'oak'", up to three, then "and N more") for the
// materials of `scene` that use `texture`; "no material" when none does.
std::string texture_users(const Scene& scene, int texture);

// sRGB transfer function, as atlas.glsl computes it (float arithmetic, same formula).
float srgb_to_linear(float encoded);
float linear_to_srgb(float linear);

}  // namespace mobirt
