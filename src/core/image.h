// Linear float RGB images and their output through OpenImageIO.
#pragma once

#include <glm/glm.hpp>

#include <string>
#include <vector>

namespace mobirt {

struct Image {
  int width = 0;
  int height = 0;
  std::vector<glm::vec3> pixels;  // row-major, y = 0 is the top row

  Image() = default;
  Image(int w, int h) : width(w), height(h), pixels(size_t(w) * size_t(h), glm::vec3(0.0f)) {}
  glm::vec3& at(int x, int y) { return pixels[size_t(y) * size_t(width) + size_t(x)]; }
  const glm::vec3& at(int x, int y) const { return pixels[size_t(y) * size_t(width) + size_t(x)]; }
};

// Writes PNG, JPEG, EXR, ... chosen by the extension. 8-bit formats get the values clamped to
// [0, 1] and rounded; float formats get them unchanged. The file appears whole or not at all: it is
// written to a temporary name beside the target and renamed. Throws mobirt::Error on failure.
void write_image(const std::string& path, const Image& image);

// Fails early, before any rendering, when `path` cannot be written: an extension OpenImageIO
// cannot write, or a folder that does not exist. Throws Error(BadInput) naming the path.
void check_image_output(const std::string& path);

// Reads any format OpenImageIO knows into linear float RGB (8-bit values divided by 255).
Image read_image(const std::string& path);

// Per-pixel comparison of two images of the same size.
struct ImageDiff {
  double psnr = 0.0;             // dB, over RGB in [0, 1]; +inf when identical
  double max_error = 0.0;        // largest channel difference
  double share_over = 0.0;       // share of pixels with a channel off by more than the threshold
};
ImageDiff compare_images(const Image& a, const Image& b, float threshold = 2.0f / 255.0f);

// |a - b| scaled so that `scale` maps to white: a picture of where two images differ.
Image difference_image(const Image& a, const Image& b, float scale = 8.0f);

}  // namespace mobirt
