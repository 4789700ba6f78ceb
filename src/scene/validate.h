// Checks shared by the scene loaders: a loaded Scene is consistent before any later stage sees it.
#pragma once

#include <string>

#include "scene/scene.h"

namespace mobirt {

// Makes `scene` consistent or throws Error(BadInput) naming scene.source:
// - vertex arrays hold 3 entries per triangle (texcoords: that or none), one material id per
//   triangle, every material id in range (an Internal error otherwise: a loader bug);
// - positions, normals and texture coordinates finite ("triangle 12: vertex 1 has a non-finite
//   position");
// - at least one triangle ("no triangles");
// - at least one material (the default one is added when there is none);
// - normals unit length (renormalised; a zero normal becomes the geometric normal).
// Degenerate (zero-area) triangles are kept and counted in scene.degenerate_triangles.
void validate_scene(Scene& scene);

// validate_scene()'s checks of what posing changes (the arrays' sizes, positions, normals, the
// degenerate count): its material ids, materials, shapes and texture coordinates are the loaded
// scene's, which posing leaves as they are. Run by GltfRig::evaluate on every posed frame; the
// glTF loader follows the first pose with validate_scene.
void validate_posed(Scene& scene);

// Prints "mobirt: warning: FILE: MESSAGE" on stderr.
void scene_warning(const std::string& file, const std::string& message);

// A parser library's multi-line message as one line: distinct lines joined by "; ", repeats
// dropped, at most 6 lines kept ("... (N more)").
std::string library_message(const std::string& text);

// Unit normal of the triangle (a, b, c) in counter-clockwise order; (0, 0, 1) when it has no area.
glm::vec3 geometric_normal(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c);

}  // namespace mobirt
