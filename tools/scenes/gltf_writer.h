// A minimal, deterministic glTF 2.0 writer for tools/make_scenes.cpp: one buffer (embedded as a
// data URI, or an external .bin beside the .gltf), nodes with children, materials with textures and
// the KHR_materials_transmission / KHR_materials_ior extensions, KHR_lights_punctual point lights,
// perspective cameras and node TRS animations.
#pragma once

#include "geometry.h"

#include <glm/glm.hpp>
#include <glm/gtc/quaternion.hpp>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <set>
#include <string>
#include <vector>

namespace mobirt::scenes {

constexpr int kRepeat = 10497, kMirroredRepeat = 33648, kClampToEdge = 33071;

struct MaterialDesc {
  std::string name;
  glm::vec3 color{1.0f};
  float metallic = 0.0f;
  float roughness = 1.0f;
  int texture = -1;              // Gltf::texture() index, or -1
  float transmission = -1.0f;    // KHR_materials_transmission.transmissionFactor; < 0: not written
  float ior = -1.0f;             // KHR_materials_ior.ior; < 0: not written
};

// One animated property of one node: values[i] at times[i] (seconds), LINEAR interpolation.
struct Channel {
  int node = -1;
  std::string path;                 // "translation", "rotation" or "scale"
  std::vector<float> times;
  std::vector<glm::vec4> values;    // xyz for translation/scale, quaternion xyzw for rotation
};

class Gltf {
 public:
  Gltf();

  int material(const std::string& name, const glm::vec3& color, float metallic, float roughness);
  int material(const MaterialDesc& desc);
  // An image file (uri relative to the .gltf) drawn through a sampler with these wrap modes.
  int texture(const std::string& name, const std::string& uri, int wrap_s, int wrap_t);

  // A node without a mesh, to group others; parent -1 = a root of the scene.
  int group(const std::string& name, const glm::vec3& translation, const glm::quat& rotation = glm::quat(1, 0, 0, 0),
            int parent = -1);
  // A mesh node; TEXCOORD_0 is written when the material has a texture.
  int object(const std::string& name, const Mesh& mesh, int material, const glm::vec3& translation,
             const glm::quat& rotation = glm::quat(1, 0, 0, 0), int parent = -1);

  void camera(const std::string& name, const glm::vec3& eye, const glm::vec3& target, float yfov_deg, float aspect);
  void point_light(const std::string& name, const glm::vec3& position, const glm::vec3& color, float intensity);
  void animation(const std::string& name, const std::vector<Channel>& channels);

  // Writes path; with external_buffer the buffer goes to path with the extension .bin.
  void write(const std::filesystem::path& path, bool external_buffer = false);

  size_t triangles() const { return triangles_; }

 private:
  static nlohmann::json look_rotation(const glm::vec3& eye, const glm::vec3& target);
  int add_node(const nlohmann::json& node, int parent);
  int accessor(const void* data, size_t bytes, size_t count, int component, const char* type, int target);

  nlohmann::json doc_;
  std::vector<uint8_t> buffer_;
  std::vector<int> parent_;
  std::vector<bool> textured_;
  std::set<std::string> extensions_;
  size_t triangles_ = 0;
};

}  // namespace mobirt::scenes
