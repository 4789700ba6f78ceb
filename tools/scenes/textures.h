// Procedural RGB textures for tools/make_scenes.cpp, written as PNG with stb_image_write (which,
// unlike OpenImageIO's writer, adds no software-version or history text chunks, so the bytes only
// depend on the pixels). All randomness is an integer hash: the images are the same on every run.
#pragma once

#include <glm/glm.hpp>

#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace mobirt::scenes {

struct Image {
  int width = 0, height = 0;
  std::vector<uint8_t> rgb;

  Image(int w, int h) : width(w), height(h), rgb(size_t(w) * size_t(h) * 3, 0) {}
  void set(int x, int y, const glm::vec3& c);
  glm::vec3 get(int x, int y) const;
  // Fills every texel with f(u, v), u and v in [0, 1) at texel centres (v = 0 at the top row).
  void fill(const std::function<glm::vec3(float, float)>& f);
  // Draws text in a 5x7 pixel font, each font pixel scale x scale texels, top-left corner at (x, y).
  void text(const std::string& s, int x, int y, int scale, const glm::vec3& color);
  static int text_width(const std::string& s, int scale) { return int(s.size()) * 6 * scale - scale; }
  void write_png(const std::filesystem::path& path) const;
};

// Value noise in [0, 1], periodic with period `period` cells in x and y, `seed` picks the pattern.
float value_noise(float x, float y, int period_x, int period_y, uint32_t seed);
// Sum of octaves of value_noise, in [0, 1].
float fractal_noise(float x, float y, int period_x, int period_y, int octaves, uint32_t seed);
float smoothstep(float e0, float e1, float x);

}  // namespace mobirt::scenes
