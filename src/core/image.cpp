#include "core/image.h"

#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <unistd.h>

#include "core/error.h"

namespace mobirt {

namespace {

bool is_float_format(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return ext == ".exr" || ext == ".hdr" || ext == ".pfm";
}

}  // namespace

void check_image_output(const std::string& path) {
  auto out = OIIO::ImageOutput::create(path);
  if (!out) {
    throw input_error(path, "cannot write this image format; use .png, .jpg, .exr or .hdr");
  }
  const std::filesystem::path folder = std::filesystem::path(path).parent_path();
  if (!folder.empty() && !std::filesystem::is_directory(folder)) {
    throw input_error(path, "the folder '" + folder.string() + "' does not exist; create it first");
  }
}

void write_image(const std::string& path, const Image& image) {
  auto out = OIIO::ImageOutput::create(path);
  if (!out) {
    throw input_error(path, "cannot write this image format (" + OIIO::geterror() +
                                "); use .png or .exr");
  }
  const std::filesystem::path target(path);
  // Temporary name in the same folder keeps the rename atomic; the extension stays so that the
  // writer picks the right format.
  std::string temp_name(".");  // built by appends: GCC 12 warns falsely (-Wrestrict) on "." + s
  temp_name.append(target.stem().string()).append(".tmp").append(std::to_string(::getpid()));
  temp_name.append(target.extension().string());
  const std::filesystem::path temp = target.parent_path() / temp_name;
  const bool is_float = is_float_format(path);
  OIIO::ImageSpec spec(image.width, image.height, 3, is_float ? OIIO::TypeDesc::FLOAT : OIIO::TypeDesc::UINT8);
  bool ok = out->open(temp.string(), spec);
  if (ok) {
    if (is_float) {
      ok = out->write_image(OIIO::TypeDesc::FLOAT, image.pixels.data());
    } else {
      std::vector<unsigned char> bytes(image.pixels.size() * 3);
      for (size_t i = 0; i < image.pixels.size(); ++i) {
        for (int c = 0; c < 3; ++c) {
          const float v = image.pixels[i][c];
          const float clamped = std::isnan(v) ? 0.0f : std::clamp(v, 0.0f, 1.0f);
          bytes[3 * i + size_t(c)] = static_cast<unsigned char>(std::lround(clamped * 255.0f));
        }
      }
      ok = out->write_image(OIIO::TypeDesc::UINT8, bytes.data());
    }
    ok = out->close() && ok;
  }
  if (!ok) {
    const std::string why = out->geterror();
    std::error_code ignored;
    std::filesystem::remove(temp, ignored);
    throw input_error(path, "cannot write the image: " + why + " (is the folder there and writable?)");
  }
  std::error_code ec;
  std::filesystem::rename(temp, target, ec);
  if (ec) {
    std::filesystem::remove(temp, ec);
    throw input_error(path, "cannot move the finished image into place: " + ec.message());
  }
}

Image read_image(const std::string& path) {
  auto in = OIIO::ImageInput::open(path);
  if (!in) throw input_error(path, "cannot read the image: " + OIIO::geterror());
  const OIIO::ImageSpec& spec = in->spec();
  const int channels = spec.nchannels;
  std::vector<float> data(size_t(spec.width) * size_t(spec.height) * size_t(channels));
  if (!in->read_image(0, 0, 0, channels, OIIO::TypeDesc::FLOAT, data.data())) {
    throw input_error(path, "cannot decode the image: " + in->geterror());
  }
  Image image(spec.width, spec.height);
  for (size_t i = 0; i < image.pixels.size(); ++i) {
    for (int c = 0; c < 3; ++c) {
      image.pixels[i][c] = data[i * size_t(channels) + size_t(std::min(c, channels - 1))];
    }
  }
  return image;
}

ImageDiff compare_images(const Image& a, const Image& b, float threshold) {
  ImageDiff diff;
  if (a.width != b.width || a.height != b.height) {
    diff.psnr = 0.0;
    diff.max_error = 1.0;
    diff.share_over = 1.0;
    return diff;
  }
  double squared = 0.0;
  size_t over = 0;
  for (size_t i = 0; i < a.pixels.size(); ++i) {
    float worst = 0.0f;
    for (int c = 0; c < 3; ++c) {
      const float d = std::fabs(a.pixels[i][c] - b.pixels[i][c]);
      worst = std::max(worst, d);
      squared += double(d) * double(d);
    }
    diff.max_error = std::max(diff.max_error, double(worst));
    if (worst > threshold) ++over;
  }
  const double mse = squared / double(std::max<size_t>(1, a.pixels.size() * 3));
  diff.psnr = mse == 0.0 ? std::numeric_limits<double>::infinity() : 10.0 * std::log10(1.0 / mse);
  diff.share_over = double(over) / double(std::max<size_t>(1, a.pixels.size()));
  return diff;
}

Image difference_image(const Image& a, const Image& b, float scale) {
  Image out(a.width, a.height);
  if (a.width != b.width || a.height != b.height) return out;
  for (size_t i = 0; i < a.pixels.size(); ++i) {
    out.pixels[i] = glm::min(glm::abs(a.pixels[i] - b.pixels[i]) * scale, glm::vec3(1.0f));
  }
  return out;
}

}  // namespace mobirt
