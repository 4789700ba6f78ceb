// One fuzz input through the scene pipeline; shared by the libFuzzer target (scene_fuzzer.cpp)
// and the regression replay test (tests/reliability_test.cpp). See scene_fuzzer.cpp for the
// input layout. Returns normally for accepted inputs and for mobirt::Error; anything else escapes
// (an exception other than mobirt::Error is re-thrown; libFuzzer reports it as a crash).
#pragma once

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>

#include "accel/kdtree.h"
#include "core/error.h"
#include "scene/animation.h"
#include "scene/tessellate.h"
#include "scene/texture_images.h"

namespace mobirt::fuzz {

// A private folder for this process's files, made once, removed at exit.
inline const std::filesystem::path& work_dir() {
  static const std::filesystem::path dir = [] {
    std::string pattern = (std::filesystem::temp_directory_path() / "mobirt-fuzz-XXXXXX").string();
    if (!::mkdtemp(pattern.data())) std::abort();
    static std::string keep;
    keep = pattern;
    std::atexit([] {
      std::error_code ignored;
      std::filesystem::remove_all(keep, ignored);
    });
    return std::filesystem::path(pattern);
  }();
  return dir;
}

inline void write_file(const std::filesystem::path& path, const uint8_t* data, size_t size) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(data), std::streamsize(size));
}

inline void run_one(const uint8_t* data, size_t size) {
  if (size < 1) return;
  const std::filesystem::path& dir = work_dir();
  std::error_code ignored;
  for (const char* name : {"scene.gltf", "scene.glb", "scene.obj", "scene.nff", "scene.ply", "b.bin", "m.mtl"}) {
    std::filesystem::remove(dir / name, ignored);
  }
  const int kind = data[0] % 6;
  const uint8_t* body = data + 1;
  const size_t body_size = size - 1;
  const bool whole = kind == 1 || kind >= 4;  // formats without a companion file
  const uint8_t* nul = whole ? nullptr : static_cast<const uint8_t*>(std::memchr(body, 0, body_size));
  const size_t main_size = nul ? size_t(nul - body) : body_size;
  static const char* const names[] = {"scene.gltf", "scene.glb", "scene.obj", "scene.obj", "scene.nff", "scene.ply"};
  const std::filesystem::path scene = dir / names[kind];
  write_file(scene, body, main_size);
  LoadOptions options;
  options.tessellation.segments = 8;  // the same code as 32 segments, at a quarter of the triangles
  if (nul) {
    const std::filesystem::path companion = dir / (kind == 0 ? "b.bin" : "m.mtl");
    write_file(companion, nul + 1, body_size - main_size - 1);
    if (kind == 3) options.mtl = companion.string();
  }
  try {
    const AnimatedScene animation = load_animated_scene(scene.string(), options);
    Scene frame;
    const double d = animation.duration();
    for (double t : {0.37, std::isfinite(d) ? d * 0.71 + 0.01 : 1.0}) {
      animation.evaluate(t, frame);
      (void)build_kdtree(frame.mesh.positions, frame.shapes, KdBuildOptions{});
    }
    // NFF spheres and cones arrive analytic: their tessellation (--primitives tessellated) too.
    if (!frame.shapes.empty()) {
      tessellate_shapes(frame, options.tessellation);
      (void)build_kdtree(frame.mesh.positions, KdBuildOptions{});
    }
    // Embedded textures only: decoding exercises the image checks on the fuzzed bytes.
    for (size_t i = 0; i < frame.textures.size(); ++i) {
      if (frame.textures[i].path.empty()) {
        try {
          (void)decode_texture(frame, int(i));
        } catch (const Error&) {
        }
      }
    }
  } catch (const Error&) {
    // expected: the file was refused with a message
  }
}

}  // namespace mobirt::fuzz
