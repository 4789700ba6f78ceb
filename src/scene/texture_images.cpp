#include "scene/texture_images.h"

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <memory>

#include "core/error.h"

namespace mobirt {

namespace {

// Reads colour unassociated: OIIO premultiplies RGB by alpha on read unless told not to, and a glTF
// base colour is not premultiplied.
OIIO::ImageSpec read_config() {
  OIIO::ImageSpec config;
  config.attribute("oiio:UnassociatedAlpha", 1);
  return config;
}

// The whole first subimage as RGBA8.
TextureImage read_rgba8(OIIO::ImageInput& in, const std::string& what) {
  const OIIO::ImageSpec& spec = in.spec();
  const int width = spec.width;
  const int height = spec.height;
  const int channels = spec.nchannels;
  if (width <= 0 || height <= 0 || channels <= 0 || spec.depth > 1) {
    throw Error(ErrorKind::BadInput, what + ": not a 2D image (" + std::to_string(width) + "x" +
                                         std::to_string(height) + ", " + std::to_string(channels) +
                                         " channels)");
  }
  // 16384 x 16384 is far more than the atlas keeps (2048 x 2048): refuse absurd sizes before
  // allocating for them.
  if (width > 16384 || height > 16384) {
    throw Error(ErrorKind::BadInput, what + ": " + std::to_string(width) + "x" + std::to_string(height) +
                                         " is too large (at most 16384 on a side)");
  }
  std::vector<uint8_t> bytes(size_t(width) * size_t(height) * size_t(channels));
  if (!in.read_image(0, 0, 0, channels, OIIO::TypeDesc::UINT8, bytes.data())) {
    throw Error(ErrorKind::BadInput, what + ": cannot be decoded: " + in.geterror());
  }
  TextureImage image;
  image.width = width;
  image.height = height;
  image.pixels.resize(size_t(width) * size_t(height));
  for (size_t i = 0; i < image.pixels.size(); ++i) {
    const uint8_t* p = &bytes[i * size_t(channels)];
    uint32_t r = p[0], g = p[0], b = p[0], a = 255;
    if (channels == 2) {
      a = p[1];
    } else if (channels >= 3) {
      g = p[1];
      b = p[2];
      if (channels >= 4) a = p[3];
    }
    image.pixels[i] = pack_rgba8(r, g, b, a);
  }
  return image;
}

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return s;
}

// File extension that makes OIIO pick its reader for these bytes: sniffed from the signature,
// else from the MIME type.
std::string extension_for(const std::vector<uint8_t>& bytes, const std::string& mime_type) {
  static const uint8_t png[] = {0x89, 'P', 'N', 'G', 0x0d, 0x0a, 0x1a, 0x0a};
  if (bytes.size() >= sizeof(png) && std::equal(png, png + sizeof(png), bytes.begin())) return "png";
  if (bytes.size() >= 3 && bytes[0] == 0xff && bytes[1] == 0xd8 && bytes[2] == 0xff) return "jpg";
  const std::string mime = lower(mime_type);
  if (mime == "image/png") return "png";
  if (mime == "image/jpeg" || mime == "image/jpg") return "jpg";
  if (mime.rfind("image/", 0) == 0 && mime.size() > 6) return mime.substr(6);
  return "";
}

}  // namespace

float srgb_to_linear(float encoded) {
  return encoded <= 0.04045f ? encoded / 12.92f : std::pow((encoded + 0.055f) / 1.055f, 2.4f);
}

float linear_to_srgb(float linear) {
  return linear <= 0.0031308f ? linear * 12.92f : 1.055f * std::pow(linear, 1.0f / 2.4f) - 0.055f;
}

TextureImage decode_image_bytes(const std::vector<uint8_t>& bytes, const std::string& mime_type,
                                const std::string& what) {
  const std::string ext = extension_for(bytes, mime_type);
  if (bytes.empty() || ext.empty()) {
    std::string message(what);
    message.append(bytes.empty() ? ": the embedded image is empty" : ": unknown image format");
    if (!mime_type.empty()) message.append(" (").append(mime_type).append(")");
    message.append("; mobirt reads PNG and JPEG textures");
    throw Error(ErrorKind::BadInput, message);
  }
  // The proxy goes in through the configuration: OIIO 2.4's readers take it from there when they
  // are opened with a configuration (ImageInput::open's ioproxy argument is then dropped).
  OIIO::Filesystem::IOMemReader proxy(bytes.data(), bytes.size());
  OIIO::ImageSpec config = read_config();
  void* proxy_pointer = &proxy;
  config.attribute("oiio:ioproxy", OIIO::TypeDesc::PTR, &proxy_pointer);
  std::string name("embedded.");
  name.append(ext);
  auto in = OIIO::ImageInput::open(name, &config, &proxy);
  if (!in) {
    std::string message(what);
    message.append(" (embedded ").append(mime_type.empty() ? ext : mime_type).append(") cannot be decoded: ");
    message.append(OIIO::geterror()).append("; mobirt reads PNG and JPEG textures");
    throw Error(ErrorKind::BadInput, message);
  }
  TextureImage image = read_rgba8(*in, what);
  in->close();
  return image;
}

TextureImage decode_image_file(const std::string& path, const std::string& what) {
  const OIIO::ImageSpec config = read_config();
  auto in = OIIO::ImageInput::open(path, &config);
  if (!in) {
    std::string message(what);
    message.append(" cannot be decoded: ").append(OIIO::geterror()).append("; mobirt reads PNG and JPEG textures");
    throw Error(ErrorKind::BadInput, message);
  }
  TextureImage image = read_rgba8(*in, what);
  in->close();
  return image;
}

std::string texture_users(const Scene& scene, int texture) {
  std::string result;
  size_t count = 0;
  for (size_t m = 0; m < scene.materials.size(); ++m) {
    if (scene.materials[m].texture != texture) continue;
    if (++count > 3) continue;
    if (!result.empty()) result.append(", ");
    result.append("materials[").append(std::to_string(m)).append("]");
    if (!scene.materials[m].name.empty()) result.append(" '").append(scene.materials[m].name).append("'");
  }
  if (count == 0) return "no material";
  if (count > 3) result.append(" and ").append(std::to_string(count - 3)).append(" more");
  return result;
}

TextureImage decode_texture(const Scene& scene, int texture) {
  const TextureRef& ref = scene.textures.at(size_t(texture));
  const std::string prefix = scene.source.empty() ? std::string() : scene.source + ": ";
  std::string label = ref.name;
  if (label.empty()) label.append("textures[").append(std::to_string(texture)).append("]");
  if (!ref.path.empty()) {
    std::error_code ec;
    if (!std::filesystem::is_regular_file(ref.path, ec)) {
      std::string message(prefix);
      message.append("texture '").append(ref.path).append("' not found (referenced by ");
      message.append(texture_users(scene, texture)).append("); put it beside the scene or fix the path");
      throw Error(ErrorKind::BadInput, message);
    }
    std::string what(prefix);
    what.append("texture '").append(ref.path).append("' (referenced by ").append(texture_users(scene, texture));
    what.append(")");
    return decode_image_file(ref.path, what);
  }
  std::string what(prefix);
  what.append("texture '").append(label).append("' (referenced by ").append(texture_users(scene, texture));
  what.append(")");
  return decode_image_bytes(ref.data, ref.mime_type, what);
}

void fitted_size(int width, int height, int max_side, int& out_width, int& out_height) {
  out_width = width;
  out_height = height;
  if (width <= max_side && height <= max_side) return;
  const int64_t longer = std::max(width, height);
  auto scaled = [&](int64_t side) {
    return int(std::max<int64_t>(1, (side * max_side + longer / 2) / longer));
  };
  out_width = scaled(width);
  out_height = scaled(height);
}

TextureImage downscale_to_fit(const TextureImage& image, int max_side) {
  int width = 0, height = 0;
  fitted_size(image.width, image.height, max_side, width, height);
  if (width == image.width && height == image.height) return image;

  // Filter in linear light: decode sRGB, resize, re-encode.
  std::vector<float> linear(image.pixels.size() * 4);
  for (size_t i = 0; i < image.pixels.size(); ++i) {
    const uint32_t p = image.pixels[i];
    for (int c = 0; c < 4; ++c) {
      const float v = float((p >> (8 * c)) & 0xffu) / 255.0f;
      linear[i * 4 + size_t(c)] = c < 3 ? srgb_to_linear(v) : v;
    }
  }
  const OIIO::ImageSpec src_spec(image.width, image.height, 4, OIIO::TypeDesc::FLOAT);
  const OIIO::ImageBuf src(src_spec, linear.data());
  OIIO::ImageBuf dst(OIIO::ImageSpec(width, height, 4, OIIO::TypeDesc::FLOAT));
  if (!OIIO::ImageBufAlgo::resize(dst, src)) {
    throw Error(ErrorKind::Internal, std::string("texture downscale failed: ").append(dst.geterror()));
  }
  std::vector<float> out(size_t(width) * size_t(height) * 4);
  if (!dst.get_pixels(OIIO::ROI::All(), OIIO::TypeDesc::FLOAT, out.data())) {
    throw Error(ErrorKind::Internal, std::string("texture downscale failed: ").append(dst.geterror()));
  }
  TextureImage result;
  result.width = width;
  result.height = height;
  result.pixels.resize(size_t(width) * size_t(height));
  for (size_t i = 0; i < result.pixels.size(); ++i) {
    uint32_t channel[4];
    for (int c = 0; c < 4; ++c) {
      float v = out[i * 4 + size_t(c)];
      v = std::isnan(v) ? 0.0f : std::clamp(v, 0.0f, 1.0f);  // the filter's lobes can overshoot
      if (c < 3) v = linear_to_srgb(v);
      channel[c] = uint32_t(std::lround(v * 255.0f));
    }
    result.pixels[i] = pack_rgba8(channel[0], channel[1], channel[2], channel[3]);
  }
  return result;
}

}  // namespace mobirt
