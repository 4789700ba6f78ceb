// Scene files in: glTF 2.0 (.gltf, .glb) through tinygltf, Wavefront OBJ (+ .mtl) through
// tinyobjloader. Every problem with the file ends in a mobirt::Error of kind BadInput whose message
// names the file, the element and the problem.
#pragma once

#include <string>

#include "scene/scene.h"
#include "scene/tessellate.h"

namespace mobirt {

// Options of load_scene and load_animated_scene (scene/animation.h).
struct LoadOptions {
  double fps = 24.0;  // OBJ sequences: frames per second; glTF: the frame rate fps() reports
  std::string mtl;    // OBJ: a .mtl file used instead of the one(s) the OBJ names (mtllib);
                      // its map_Kd paths are relative to its own folder. Empty: the OBJ's own.
  int animation = -1; // glTF: -1 plays all animations together; k plays animations[k] only
  // NFF spheres, cylinders and cones: analytic kd-tree primitives (Scene::shapes), or triangles
  // (--primitives tessellated) cut as `tessellation` says (scene/tessellate.h).
  bool analytic = true;
  Tessellation tessellation;
};

// Picks the loader by extension (case-insensitive): .gltf and .glb -> load_gltf, .obj -> load_obj,
// .nff -> load_nff, .ply -> load_ply; anything else: "unsupported scene format '.xyz': mobirt reads
// .gltf, .glb, .obj, .nff and .ply". A missing
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

// Eric Haines' Neutral File Format (NFF.TXT 3.9, the SPD's format), every entity:
// - v: the camera (from, at, up; angle is the field of view between the centres of the outer pixel
//   rows, hither -> znear) and Scene::image_size (resolution); Scene::up = the view's up;
// - b: the background; l X Y Z [R G B]: point lights, intensity as README's NFF section tells
//   (NFF lights have no falloff: each gets sqrt(n) / (2 n) times its squared distance to the
//   look-at point, the SPD's suggested brightness where the view looks);
// - f R G B Kd Ks Shine T ior: a material (README's materials table), used by what follows;
// - p and pp: polygons (flat normal) and patches (normals given), triangulated by ear clipping,
//   concave ones included;
// - s and c: spheres, cylinders and cones as analytic primitives (Scene::shapes), or tessellated
//   with LoadOptions::analytic false (LoadOptions::tessellation); cones without end caps, as the
//   spec says; negative radii: inside visible.
// Errors are "FILE:LINE: problem" (BadInput). Limits: 16,384 vertices a polygon, 2^24 - 1 primitives.
Scene load_nff(const std::string& path, const LoadOptions& options = {});

// PLY (Stanford polygon file), ASCII and binary of either byte order: vertex x, y, z; nx, ny, nz;
// texture coordinates (u, v / s, t / texture_u, texture_v / texture_s, texture_t; v flipped to
// the glTF convention); vertex colours red, green, blue (integers scaled by their type's maximum,
// floats as given), and face colours; faces from the list vertex_indices (or vertex_index),
// triangulated by ear clipping (at most 16,384 vertices a face). mobirt has no per-vertex colour:
// faces are grouped by their colour (the face's own, else the mean of its vertices') quantised to
// 6 bits per channel, and each group is one material whose diffuse is the group's mean colour.
// Other elements and properties are read past. Errors name the file, the header line or the
// element and record (BadInput).
Scene load_ply(const std::string& path);

// Throws Error(BadInput) "FILE: file not found" unless `path` names an existing file.
void check_scene_file(const std::string& path);

}  // namespace mobirt
