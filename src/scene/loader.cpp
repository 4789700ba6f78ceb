#include "scene/loader.h"

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <system_error>

#include "core/error.h"

namespace mobirt {

void check_scene_file(const std::string& path) {
  std::error_code ec;
  const std::filesystem::file_status st = std::filesystem::status(path, ec);
  if (path.empty()) throw input_error("", "no scene file given");
  if (ec || !std::filesystem::exists(st)) {
    throw input_error(path, "file not found");
  }
  if (std::filesystem::is_directory(st)) {
    throw input_error(path, "is a folder, not a scene file");
  }
}

Scene load_scene(const std::string& path) { return load_scene(path, LoadOptions{}); }

Scene load_scene(const std::string& path, const LoadOptions& options) {
  check_scene_file(path);
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (ext == ".gltf" || ext == ".glb") return load_gltf(path, options);
  if (ext == ".obj") return load_obj(path, options);
  if (ext == ".nff") return load_nff(path, options);
  if (ext == ".ply") return load_ply(path);
  throw input_error(path, "unsupported scene format '" + (ext.empty() ? std::string("") : ext) +
                              "': mobirt reads .gltf, .glb, .obj, .nff and .ply");
}

}  // namespace mobirt
