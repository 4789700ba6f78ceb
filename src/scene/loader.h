// Scene files in: glTF 2.0 (.gltf, .glb) through tinygltf, Wavefront OBJ (+ .mtl) through
// tinyobjloader. Every problem with the file ends in a mobirt::Error of kind BadInput whose message
// names the file, the element and the problem.
#pragma once

#include <string>

#include "scene/scene.h"

namespace mobirt {

// Picks the loader by extension (case-insensitive). The result is validated: finite positions,
// in-range indices, at least one material, unit normals.
Scene load_scene(const std::string& path);

Scene load_gltf(const std::string& path);
Scene load_obj(const std::string& path);

}  // namespace mobirt
