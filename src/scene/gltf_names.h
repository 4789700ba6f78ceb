// Names of glTF elements in messages, as JSON paths of the file ("meshes[2].primitives[0]"), so
// that an error points at the place to fix.
#pragma once

#include <cstddef>
#include <string>

namespace mobirt::gltf {

inline std::string str(size_t v) { return std::to_string(v); }
inline std::string str(int v) { return std::to_string(v); }

inline std::string element(const char* array, size_t index) {
  return std::string(array) + "[" + str(index) + "]";
}

}  // namespace mobirt::gltf
