// The scene as every later stage sees it: world-space triangles with per-vertex attributes,
// materials for the Whitted/Phong model, punctual lights and a camera.
#pragma once

#include <glm/glm.hpp>

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/camera.h"
#include "core/geometry.h"
#include "core/shapes.h"

namespace mobirt {

struct ClosedParts;

// Whitted/Phong material. How glTF and OBJ materials map onto it is written down in README.md.
struct Material {
  std::string name;
  glm::vec3 diffuse{0.8f};       // Kd, or glTF baseColorFactor.rgb
  glm::vec3 specular{0.0f};      // Ks
  float shininess = 32.0f;       // Phong exponent
  float reflectance = 0.0f;      // weight of the mirror ray (fixed coefficient)
  float transmittance = 0.0f;    // weight of the refracted ray
  float ior = 1.5f;              // index of refraction
  // Schlick's Fresnel term moves weight from the refracted to the reflected ray at grazing angles
  // (dielectrics with transmittance > 0); false = the fixed coefficients above, as given.
  bool fresnel = true;
  float ambient = 0.1f;          // share of the diffuse colour lit by the ambient term
  int texture = -1;              // base-colour texture: index into Scene::textures, -1 = none
  // KHR_texture_transform of the base-colour texture: uv' = (M * (u, v, 1)).xy, applied where
  // hit decoding forms the texture coordinate (texture_transform_matrix(); identity without one).
  glm::mat3 texture_transform{1.0f};
};

// KHR_texture_transform's M = T * R * S: scale, then rotate by `rotation` radians
// counter-clockwise in uv space (v pointing down: u' = cos * u + sin * v, v' = -sin * u + cos * v,
// the extension's rotation matrix as printed, which its example (offset [0, 1], rotation pi/2,
// scale 0.5: "the lower left quadrant of the source image, rotated clockwise 90 degrees") and
// Khronos' sample viewer follow), then offset.
glm::mat3 texture_transform_matrix(glm::vec2 offset, float rotation, glm::vec2 scale);

inline glm::vec2 transform_texcoord(const glm::mat3& transform, glm::vec2 uv) {
  return glm::vec2(transform * glm::vec3(uv, 1.0f));
}

enum class TextureWrap { Repeat, ClampToEdge, MirroredRepeat };

// A base-colour texture as the file names it; decoding and atlas packing come later (issue 3).
// Exactly one of `path` and `data` is set.
struct TextureRef {
  std::string name;
  std::string path;                 // an external image file, resolved against the scene's folder
  std::vector<uint8_t> data;        // or the encoded image bytes (PNG, JPEG) embedded in the file
  std::string mime_type;            // "image/png", "image/jpeg", or empty when unknown
  TextureWrap wrap_s = TextureWrap::Repeat;
  TextureWrap wrap_t = TextureWrap::Repeat;
};

enum class LightType { Point, Spot, Directional };

// KHR_lights_punctual semantics: intensity in candela (point, spot) or lux (directional),
// falling off with the inverse square of the distance; range 0 = unlimited.
struct Light {
  LightType type = LightType::Point;
  glm::vec3 position{0.0f};
  glm::vec3 direction{0.0f, -1.0f, 0.0f};  // where the light points (spot, directional)
  glm::vec3 color{1.0f};
  float intensity = 1.0f;
  float range = 0.0f;
  float inner_cone = 0.0f;        // radians
  float outer_cone = 0.7853982f;  // radians
};

// Triangle soup in world space: triangle i uses entries 3i, 3i+1, 3i+2 of each vertex array.
struct TriangleMesh {
  std::vector<glm::vec3> positions;
  std::vector<glm::vec3> normals;     // per vertex; geometric normal where the file has none
  std::vector<glm::vec2> texcoords;   // empty when no primitive has texture coordinates; glTF
                                      // convention: (0, 0) is the top-left corner of the image
                                      // (OBJ's v is flipped on load)
  std::vector<uint32_t> material_ids; // one per triangle

  size_t triangle_count() const { return material_ids.size(); }
};

struct Scene {
  std::string source;                 // the file it came from, for messages
  TriangleMesh mesh;
  // Analytic spheres and cones (NFF s and c unless tessellated): primitive mesh.triangle_count() + k
  // in the kd-tree and in every hit record.
  std::vector<Shape> shapes;
  std::vector<Material> materials;    // at least one: the default material
  std::vector<TextureRef> textures;   // referenced by Material::texture
  std::vector<Light> lights;
  std::optional<Camera> camera;       // the file's first camera, if it has one
  glm::vec3 background{0.0f};
  // The image size the file asks for (NFF's resolution), used when the command line gives none.
  std::optional<glm::ivec2> image_size;
  // The file's up axis, for a camera that frames a scene without one (NFF's `v` up; glTF, OBJ and
  // PLY: +Y).
  glm::vec3 up{0.0f, 1.0f, 0.0f};
  size_t degenerate_triangles = 0;    // zero-area triangles, kept (the tracer skips them), counted
  // The mesh's closed parts (src/accel/closed_parts.h), found once per scene by AnimatedScene (for
  // meshes of up to kClosedPartsMaxTriangles) and shared by its poses: the shadow rays' light
  // buffers leave out their faces turned away from the light. Null: none known, every face listed.
  std::shared_ptr<const ClosedParts> closed_parts;

  size_t primitive_count() const { return mesh.triangle_count() + shapes.size(); }
  Aabb bounds() const;
};

}  // namespace mobirt
