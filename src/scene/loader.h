// Scene files in: glTF 2.0 (.gltf, .glb) through tinygltf, Wavefront OBJ (+ .mtl) through
// tinyobjloader. Every problem with the file ends in a mobirt::Error of kind BadInput whose message
// names the file, the element and the problem.
#pragma once

#include <string>

#include "scene/scene.h"

namespace mobirt {

// Options of load_scene and load_animated_scene (scene/animation.h).
struct LoadOptions {
  double fps = 24.0;  // OBJ sequences: frames per second; glTF: the frame rate fps() reports
  std::string mtl;    // OBJ: a .mtl file used instead of the one(s) the OBJ names (mtllib);
                      // its map_Kd paths are relative to its own folder. Empty: the OBJ's own.
  int animation = -1; // glTF: -1 plays all animations together; k plays animations[k] only
};

// Picks the loader by extension (case-insensitive): .gltf and .glb -> load_gltf, .obj -> load_obj;
// anything else: "unsupported scene format '.xyz': mobirt reads .gltf, .glb and .obj". A missing
// file: "FILE: file not found". The result is validated (scene/validate.h): finite positions and
// normals, at least one triangle, in-range indices, at least one material, unit normals;
// degenerate triangles are kept and counted in Scene::degenerate_triangles.
Scene load_scene(const std::string& path);
// The same with options (LoadOptions::mtl for OBJ files; fps and animation do not change the
// scene at t = 0 except for the animation chosen). For a glTF file with animations the result is
// the scene at t = 0 with every animation played applied (scene/animation.h).
Scene load_scene(const std::string& path, const LoadOptions& options);

// glTF 2.0, text (.gltf, external or data-URI buffers) or binary (.glb).
// - Geometry: the default scene (else scene 0, else every root node), node matrices or TRS
//   applied; primitives of mode TRIANGLES, TRIANGLE_STRIP or TRIANGLE_FAN (others are an error
//   naming "meshes[m].primitives[p]"); indexed or not; sparse accessors supported; every accessor
//   read is bounds-checked. Normals by the inverse transpose; a primitive without normals gets
//   flat (geometric) normals; a mirroring transform (negative determinant) flips the winding.
//   Skins, morph targets and animations are evaluated at t = 0 (scene/animation.h).
// - Camera: the first perspective camera of the node traversal (looks down -Z, up +Y of its node;
//   znear kept). Orthographic cameras are skipped with a warning (no orthographic projection).
// - Lights: KHR_lights_punctual point, spot and directional lights in world space.
// - Materials: pbrMetallicRoughness (+ KHR_materials_transmission, KHR_materials_ior) mapped to
//   the Phong material as docs/materials.md tells; baseColorTexture -> Scene::textures.
Scene load_gltf(const std::string& path);
Scene load_gltf(const std::string& path, const LoadOptions& options);

// Wavefront OBJ + MTL (searched in the OBJ's folder). Polygons are triangulated; a missing .mtl
// is a warning (default material). Normals from the file, flat where a face has none; texture
// coordinates with v flipped to the glTF convention. MTL mapping: docs/materials.md.
Scene load_obj(const std::string& path);
// With LoadOptions::mtl: that .mtl replaces the OBJ's own (a missing one is an error).
Scene load_obj(const std::string& path, const LoadOptions& options);

// Throws Error(BadInput) "FILE: file not found" unless `path` names an existing file.
void check_scene_file(const std::string& path);

}  // namespace mobirt
