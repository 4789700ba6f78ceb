#include "textures.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>

#define STB_IMAGE_WRITE_IMPLEMENTATION
#define STB_IMAGE_WRITE_STATIC
#include <stb/stb_image_write.h>

namespace mobirt::scenes {

namespace {

uint8_t to_byte(float c) { return uint8_t(std::lround(std::clamp(c, 0.0f, 1.0f) * 255.0f)); }

uint32_t hash(uint32_t x, uint32_t y, uint32_t seed) {
  uint32_t h = x * 0x8da6b343u ^ y * 0xd8163841u ^ seed * 0xcb1ab31fu;
  h ^= h >> 16;
  h *= 0x7feb352du;
  h ^= h >> 15;
  h *= 0x846ca68bu;
  h ^= h >> 16;
  return h;
}

// 5x7 glyphs, one string of 7 rows of 5 columns per character ('#' = ink).
struct Glyph {
  char c;
  const char* rows[7];
};
const Glyph kFont[] = {
    {'M', {"#...#", "##.##", "#.#.#", "#.#.#", "#...#", "#...#", "#...#"}},
    {'O', {".###.", "#...#", "#...#", "#...#", "#...#", "#...#", ".###."}},
    {'B', {"####.", "#...#", "#...#", "####.", "#...#", "#...#", "####."}},
    {'I', {".###.", "..#..", "..#..", "..#..", "..#..", "..#..", ".###."}},
    {'R', {"####.", "#...#", "#...#", "####.", "#.#..", "#..#.", "#...#"}},
    {'T', {"#####", "..#..", "..#..", "..#..", "..#..", "..#..", "..#.."}},
    {'E', {"#####", "#....", "#....", "####.", "#....", "#....", "#####"}},
    {'S', {".####", "#....", "#....", ".###.", "....#", "....#", "####."}},
    {'A', {".###.", "#...#", "#...#", "#####", "#...#", "#...#", "#...#"}},
    {'N', {"#...#", "##..#", "#.#.#", "#..##", "#...#", "#...#", "#...#"}},
    {'F', {"#####", "#....", "#....", "####.", "#....", "#....", "#...."}},
    {'H', {"#...#", "#...#", "#...#", "#####", "#...#", "#...#", "#...#"}},
    {'1', {"..#..", ".##..", "..#..", "..#..", "..#..", "..#..", ".###."}},
    {'2', {".###.", "#...#", "....#", "...#.", "..#..", ".#...", "#####"}},
    {'3', {"####.", "....#", "....#", ".###.", "....#", "....#", "####."}},
    {'8', {".###.", "#...#", "#...#", ".###.", "#...#", "#...#", ".###."}},
    {'0', {".###.", "#...#", "#..##", "#.#.#", "##..#", "#...#", ".###."}},
};

}  // namespace

void Image::set(int x, int y, const glm::vec3& c) {
  if (x < 0 || y < 0 || x >= width || y >= height) return;
  uint8_t* p = &rgb[(size_t(y) * size_t(width) + size_t(x)) * 3];
  p[0] = to_byte(c.r);
  p[1] = to_byte(c.g);
  p[2] = to_byte(c.b);
}

glm::vec3 Image::get(int x, int y) const {
  const uint8_t* p = &rgb[(size_t(y) * size_t(width) + size_t(x)) * 3];
  return glm::vec3(p[0], p[1], p[2]) / 255.0f;
}

void Image::fill(const std::function<glm::vec3(float, float)>& f) {
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      set(x, y, f((float(x) + 0.5f) / float(width), (float(y) + 0.5f) / float(height)));
    }
  }
}

void Image::text(const std::string& s, int x, int y, int scale, const glm::vec3& color) {
  for (size_t i = 0; i < s.size(); ++i) {
    const Glyph* g = nullptr;
    for (const Glyph& candidate : kFont) {
      if (candidate.c == s[i]) g = &candidate;
    }
    if (g == nullptr) continue;  // a space, or a character the font lacks
    for (int row = 0; row < 7; ++row) {
      for (int col = 0; col < 5; ++col) {
        if (g->rows[row][col] != '#') continue;
        for (int dy = 0; dy < scale; ++dy) {
          for (int dx = 0; dx < scale; ++dx) {
            set(x + (int(i) * 6 + col) * scale + dx, y + row * scale + dy, color);
          }
        }
      }
    }
  }
}

void Image::write_png(const std::filesystem::path& path) const {
  std::error_code ec;
  std::filesystem::create_directories(path.parent_path(), ec);
  if (stbi_write_png(path.string().c_str(), width, height, 3, rgb.data(), width * 3) == 0) {
    std::fprintf(stderr, "make_scenes: cannot write %s\n", path.string().c_str());
    std::exit(1);
  }
}

float smoothstep(float e0, float e1, float x) {
  const float t = std::clamp((x - e0) / (e1 - e0), 0.0f, 1.0f);
  return t * t * (3.0f - 2.0f * t);
}

float value_noise(float x, float y, int period_x, int period_y, uint32_t seed) {
  const float fx = std::floor(x), fy = std::floor(y);
  const int ix = int(fx), iy = int(fy);
  const float tx = smoothstep(0.0f, 1.0f, x - fx), ty = smoothstep(0.0f, 1.0f, y - fy);
  auto at = [&](int cx, int cy) {
    const uint32_t px = uint32_t(((cx % period_x) + period_x) % period_x);
    const uint32_t py = uint32_t(((cy % period_y) + period_y) % period_y);
    return float(hash(px, py, seed) & 0xffffu) / 65535.0f;
  };
  const float a = at(ix, iy), b = at(ix + 1, iy), c = at(ix, iy + 1), d = at(ix + 1, iy + 1);
  return (a * (1 - tx) + b * tx) * (1 - ty) + (c * (1 - tx) + d * tx) * ty;
}

float fractal_noise(float x, float y, int period_x, int period_y, int octaves, uint32_t seed) {
  float sum = 0.0f, amplitude = 1.0f, total = 0.0f;
  for (int o = 0; o < octaves; ++o) {
    const int f = 1 << o;
    sum += amplitude * value_noise(x * float(f), y * float(f), period_x * f, period_y * f, seed + uint32_t(o));
    total += amplitude;
    amplitude *= 0.5f;
  }
  return sum / total;
}

}  // namespace mobirt::scenes
