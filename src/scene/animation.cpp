#include "scene/animation.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <system_error>
#include <utility>

#include "accel/closed_parts.h"
#include "core/error.h"
#include "scene/validate.h"

namespace mobirt {

namespace {

std::string lower_extension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

// A printf pattern with exactly one %d: the text before and after, the zero flag and the width.
struct FramePattern {
  std::string head;
  std::string tail;
  bool zero_pad = false;
  size_t width = 0;

  std::string format(size_t frame) const {
    std::string digits = std::to_string(frame);
    std::string out = head;
    if (digits.size() < width) out.append(width - digits.size(), zero_pad ? '0' : ' ');
    out.append(digits);
    out.append(tail);
    return out;
  }
};

FramePattern parse_pattern(const std::string& pattern) {
  FramePattern p;
  bool found = false;
  std::string* text = &p.head;
  for (size_t i = 0; i < pattern.size(); ++i) {
    if (pattern[i] != '%') {
      text->push_back(pattern[i]);
      continue;
    }
    if (i + 1 < pattern.size() && pattern[i + 1] == '%') {
      text->push_back('%');
      ++i;
      continue;
    }
    size_t j = i + 1;
    if (j < pattern.size() && pattern[j] == '0') {
      p.zero_pad = true;
      ++j;
    }
    size_t width = 0;
    while (j < pattern.size() && std::isdigit(static_cast<unsigned char>(pattern[j])) &&
           width < 100) {
      width = width * 10 + static_cast<size_t>(pattern[j] - '0');
      ++j;
    }
    if (j >= pattern.size() || (pattern[j] != 'd' && pattern[j] != 'i' && pattern[j] != 'u') ||
        found || width >= 100) {
      throw input_error(pattern,
                        "not a frame pattern: it needs exactly one %d conversion (like "
                        "wooddoll_%02d.obj; write %% for a literal %)");
    }
    found = true;
    p.width = width;
    text = &p.tail;
    i = j;
  }
  if (!found) {
    throw input_error(pattern, "not a frame pattern: it has no %d conversion (write %% for a "
                               "literal %)");
  }
  return p;
}

bool is_file(const std::string& path) {
  std::error_code ec;
  return std::filesystem::is_regular_file(path, ec);
}

}  // namespace

AnimatedScene::AnimatedScene(Scene rest, std::shared_ptr<const detail::Animator> animator,
                             double duration, double fps, size_t frames)
    : rest_(std::move(rest)),
      animator_(std::move(animator)),
      duration_(duration),
      fps_(fps),
      frames_(frames) {
  rest_.closed_parts = nullptr;  // found here, for this mesh, whatever the scene carried
  if (rest_.mesh.triangle_count() <= kClosedPartsMaxTriangles) {
    rest_.closed_parts = std::make_shared<const ClosedParts>(find_closed_parts(rest_.mesh.positions));
  }
}

void AnimatedScene::evaluate(double t, Scene& out) const {
  const TriangleMesh& rm = rest_.mesh;
  TriangleMesh& om = out.mesh;
  const bool initialised = out.source == rest_.source &&
                           out.materials.size() == rest_.materials.size() &&
                           out.textures.size() == rest_.textures.size() &&
                           om.material_ids.size() == rm.material_ids.size() &&
                           om.texcoords.size() == rm.texcoords.size();
  if (!initialised) {
    out.source = rest_.source;
    out.materials = rest_.materials;
    out.textures = rest_.textures;
    out.background = rest_.background;
    om.texcoords = rm.texcoords;
    om.material_ids = rm.material_ids;
  }
  out.closed_parts = rest_.closed_parts;
  if (std::isnan(t)) t = 0.0;  // infinities clamp like any time outside the animation
  if (!animator_) {
    om.positions.assign(rm.positions.begin(), rm.positions.end());
    om.normals.assign(rm.normals.begin(), rm.normals.end());
    out.lights = rest_.lights;
    out.camera = rest_.camera;
    out.degenerate_triangles = rest_.degenerate_triangles;
    return;
  }
  om.positions.resize(rm.positions.size());
  om.normals.resize(rm.normals.size());
  animator_->evaluate(t, out);
}

bool is_sequence_path(const std::string& path) {
  if (path.find('%') != std::string::npos && !is_file(path)) return true;
  std::error_code ec;
  return std::filesystem::is_directory(path, ec);
}

std::vector<std::string> sequence_files(const std::string& path) {
  std::vector<std::string> files;
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) {
    for (const auto& entry : std::filesystem::directory_iterator(path, ec)) {
      std::error_code fec;
      if (!entry.is_regular_file(fec)) continue;
      if (lower_extension(entry.path().string()) == ".obj") files.push_back(entry.path().string());
    }
    if (ec) throw input_error(path, "cannot list the folder: " + ec.message());
    // By file name; "frame_2" before "frame_10" only with zero padding, as `ls` sorts.
    std::sort(files.begin(), files.end(), [](const std::string& a, const std::string& b) {
      return std::filesystem::path(a).filename().string() <
             std::filesystem::path(b).filename().string();
    });
    if (files.empty()) throw input_error(path, "the folder holds no .obj files");
    return files;
  }
  const FramePattern pattern = parse_pattern(path);
  size_t first = 0;
  if (!is_file(pattern.format(0))) first = 1;
  for (size_t frame = first; is_file(pattern.format(frame)); ++frame) {
    files.push_back(pattern.format(frame));
  }
  if (files.empty()) {
    throw input_error(path, "no frame files: neither " + pattern.format(0) + " nor " +
                                pattern.format(1) + " exists");
  }
  return files;
}

AnimatedScene load_animated_scene(const std::string& path, const LoadOptions& options) {
  if (!(options.fps > 0.0) || !std::isfinite(options.fps)) {
    throw input_error(path, "frame rate " + std::to_string(options.fps) +
                                " must be a positive number of frames per second");
  }
  if (path.empty()) throw input_error("", "no scene file given");
  if (is_sequence_path(path)) {
    const std::vector<std::string> files = sequence_files(path);
    for (const std::string& f : files) {
      if (lower_extension(f) != ".obj") {
        throw input_error(f, "frame sequences are made of .obj files");
      }
    }
    return detail::load_obj_sequence(files, path, options);
  }
  check_scene_file(path);
  const std::string ext = lower_extension(path);
  if (ext == ".gltf" || ext == ".glb") return detail::load_gltf_animated(path, options);
  return AnimatedScene(load_scene(path, options), nullptr, 0.0, options.fps);
}

}  // namespace mobirt
