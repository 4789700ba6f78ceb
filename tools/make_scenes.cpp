// Generates the project's own scenes in scenes/ as glTF 2.0 files with embedded buffers:
//   mobirt_make_scenes OUT_DIR
// The output is deterministic, so a test can regenerate the scenes and compare them with the
// committed files byte for byte.
#include <glm/glm.hpp>
#include <glm/gtc/quaternion.hpp>
#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace {

using nlohmann::json;
constexpr float kPi = 3.14159265358979f;

struct Mesh {
  std::vector<glm::vec3> positions;
  std::vector<glm::vec3> normals;
  std::vector<uint32_t> indices;

  uint32_t vertex(const glm::vec3& p, const glm::vec3& n) {
    positions.push_back(p);
    normals.push_back(n);
    return uint32_t(positions.size() - 1);
  }
  void quad(uint32_t a, uint32_t b, uint32_t c, uint32_t d) {
    indices.insert(indices.end(), {a, b, c, a, c, d});
  }
};

// An axis-aligned box centred on the origin, flat normals.
Mesh box(const glm::vec3& size) {
  Mesh m;
  const glm::vec3 h = 0.5f * size;
  for (int axis = 0; axis < 3; ++axis) {
    for (int sign = -1; sign <= 1; sign += 2) {
      glm::vec3 n(0.0f);
      n[axis] = float(sign);
      const int u = (axis + 1) % 3, v = (axis + 2) % 3;
      glm::vec3 corner[4];
      const float su[4] = {-1, 1, 1, -1}, sv[4] = {-1, -1, 1, 1};
      for (int k = 0; k < 4; ++k) {
        corner[k][axis] = float(sign) * h[axis];
        corner[k][u] = su[k] * h[u];
        corner[k][v] = sv[k] * h[v];
      }
      uint32_t i[4];
      for (int k = 0; k < 4; ++k) i[k] = m.vertex(corner[k], n);
      // Counter-clockwise seen from outside.
      if (sign > 0) m.quad(i[0], i[1], i[2], i[3]); else m.quad(i[0], i[3], i[2], i[1]);
    }
  }
  return m;
}

// A UV sphere centred on the origin, smooth normals.
Mesh sphere(float radius, int segments, int rings) {
  Mesh m;
  for (int r = 0; r <= rings; ++r) {
    const float theta = kPi * float(r) / float(rings);
    for (int s = 0; s <= segments; ++s) {
      const float phi = 2.0f * kPi * float(s) / float(segments);
      const glm::vec3 n(std::sin(theta) * std::cos(phi), std::cos(theta), -std::sin(theta) * std::sin(phi));
      m.vertex(radius * n, n);
    }
  }
  const uint32_t row = uint32_t(segments + 1);
  for (int r = 0; r < rings; ++r) {
    for (int s = 0; s < segments; ++s) {
      const uint32_t a = uint32_t(r) * row + uint32_t(s), b = a + row;
      if (r != 0) m.indices.insert(m.indices.end(), {a, b, a + 1});
      if (r != rings - 1) m.indices.insert(m.indices.end(), {a + 1, b, b + 1});
    }
  }
  return m;
}

// A closed cylinder standing on the origin, smooth sides, flat caps.
Mesh cylinder(float radius, float height, int segments) {
  Mesh m;
  for (int s = 0; s <= segments; ++s) {
    const float phi = 2.0f * kPi * float(s) / float(segments);
    const glm::vec3 n(std::cos(phi), 0.0f, -std::sin(phi));
    m.vertex(radius * n, n);
    m.vertex(radius * n + glm::vec3(0, height, 0), n);
  }
  for (int s = 0; s < segments; ++s) {
    const uint32_t a = uint32_t(2 * s);
    m.quad(a, a + 2, a + 3, a + 1);
  }
  for (int cap = 0; cap < 2; ++cap) {
    const float y = cap ? height : 0.0f;
    const glm::vec3 n(0, cap ? 1.0f : -1.0f, 0);
    const uint32_t center = m.vertex(glm::vec3(0, y, 0), n);
    for (int s = 0; s <= segments; ++s) {
      const float phi = 2.0f * kPi * float(s) / float(segments);
      m.vertex(glm::vec3(radius * std::cos(phi), y, -radius * std::sin(phi)), n);
    }
    for (int s = 0; s < segments; ++s) {
      const uint32_t a = center + 1 + uint32_t(s);
      if (cap) m.indices.insert(m.indices.end(), {center, a, a + 1});
      else m.indices.insert(m.indices.end(), {center, a + 1, a});
    }
  }
  return m;
}

// A square floor in the XZ plane, facing +Y, split into n x n quads.
Mesh floor_plane(float size, int n) {
  Mesh m;
  for (int j = 0; j <= n; ++j) {
    for (int i = 0; i <= n; ++i) {
      m.vertex(glm::vec3(size * (float(i) / float(n) - 0.5f), 0.0f, size * (float(j) / float(n) - 0.5f)),
               glm::vec3(0, 1, 0));
    }
  }
  const uint32_t row = uint32_t(n + 1);
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      const uint32_t a = uint32_t(j) * row + uint32_t(i);
      m.quad(a, a + row, a + row + 1, a + 1);
    }
  }
  return m;
}

std::string base64(const std::vector<uint8_t>& data) {
  static const char* table = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((data.size() + 2) / 3 * 4);
  for (size_t i = 0; i < data.size(); i += 3) {
    uint32_t v = uint32_t(data[i]) << 16;
    if (i + 1 < data.size()) v |= uint32_t(data[i + 1]) << 8;
    if (i + 2 < data.size()) v |= uint32_t(data[i + 2]);
    out += table[(v >> 18) & 63];
    out += table[(v >> 12) & 63];
    out += i + 1 < data.size() ? table[(v >> 6) & 63] : '=';
    out += i + 2 < data.size() ? table[v & 63] : '=';
  }
  return out;
}

// A minimal glTF 2.0 writer: one embedded buffer, one node per object.
class Gltf {
 public:
  Gltf() {
    doc_["asset"] = {{"version", "2.0"}, {"generator", "mobirt tools/make_scenes.cpp"}};
    for (const char* key : {"nodes", "meshes", "materials", "accessors", "bufferViews"}) {
      doc_[key] = json::array();
    }
  }

  int material(const std::string& name, const glm::vec3& color, float metallic, float roughness) {
    doc_["materials"].push_back({{"name", name},
                                 {"pbrMetallicRoughness",
                                  {{"baseColorFactor", {color.r, color.g, color.b, 1.0}},
                                   {"metallicFactor", metallic},
                                   {"roughnessFactor", roughness}}}});
    return int(doc_["materials"].size() - 1);
  }

  void object(const std::string& name, const Mesh& mesh, int material, const glm::vec3& translation,
              const glm::quat& rotation = glm::quat(1, 0, 0, 0)) {
    glm::vec3 lo(1e30f), hi(-1e30f);
    for (const glm::vec3& p : mesh.positions) {
      lo = glm::min(lo, p);
      hi = glm::max(hi, p);
    }
    const int pos = accessor(mesh.positions.data(), mesh.positions.size() * 12, mesh.positions.size(),
                             5126, "VEC3", 34962);
    doc_["accessors"][size_t(pos)]["min"] = {lo.x, lo.y, lo.z};
    doc_["accessors"][size_t(pos)]["max"] = {hi.x, hi.y, hi.z};
    const int nrm = accessor(mesh.normals.data(), mesh.normals.size() * 12, mesh.normals.size(), 5126,
                             "VEC3", 34962);
    int idx;
    if (mesh.positions.size() < 65536) {
      std::vector<uint16_t> small(mesh.indices.begin(), mesh.indices.end());
      idx = accessor(small.data(), small.size() * 2, small.size(), 5123, "SCALAR", 34963);
    } else {
      idx = accessor(mesh.indices.data(), mesh.indices.size() * 4, mesh.indices.size(), 5125, "SCALAR", 34963);
    }
    doc_["meshes"].push_back(
        {{"name", name},
         {"primitives", {{{"attributes", {{"POSITION", pos}, {"NORMAL", nrm}}}, {"indices", idx},
                          {"material", material}}}}});
    json node = {{"name", name}, {"mesh", int(doc_["meshes"].size() - 1)},
                 {"translation", {translation.x, translation.y, translation.z}}};
    if (rotation != glm::quat(1, 0, 0, 0)) node["rotation"] = {rotation.x, rotation.y, rotation.z, rotation.w};
    add_node(node);
  }

  void camera(const std::string& name, const glm::vec3& eye, const glm::vec3& target, float yfov_deg,
              float aspect) {
    doc_["cameras"].push_back({{"name", name}, {"type", "perspective"},
                               {"perspective", {{"yfov", yfov_deg * kPi / 180.0f}, {"aspectRatio", aspect},
                                                {"znear", 0.05}, {"zfar", 1000.0}}}});
    add_node({{"name", name}, {"camera", int(doc_["cameras"].size() - 1)},
              {"translation", {eye.x, eye.y, eye.z}}, {"rotation", look_rotation(eye, target)}});
  }

  void point_light(const std::string& name, const glm::vec3& position, const glm::vec3& color, float intensity) {
    json& lights = doc_["extensions"]["KHR_lights_punctual"]["lights"];
    lights.push_back({{"name", name}, {"type", "point"}, {"color", {color.r, color.g, color.b}},
                      {"intensity", intensity}});
    add_node({{"name", name}, {"translation", {position.x, position.y, position.z}},
              {"extensions", {{"KHR_lights_punctual", {{"light", int(lights.size() - 1)}}}}}});
    doc_["extensionsUsed"] = {"KHR_lights_punctual"};
  }

  void write(const std::filesystem::path& path) {
    doc_["buffers"] = {{{"byteLength", buffer_.size()},
                        {"uri", "data:application/octet-stream;base64," + base64(buffer_)}}};
    json scene_nodes = json::array();
    for (size_t i = 0; i < doc_["nodes"].size(); ++i) scene_nodes.push_back(i);
    doc_["scenes"] = {{{"nodes", scene_nodes}}};
    doc_["scene"] = 0;
    std::ofstream out(path, std::ios::binary);
    out << doc_.dump(1) << "\n";
    if (!out) {
      std::fprintf(stderr, "make_scenes: cannot write %s\n", path.string().c_str());
      std::exit(1);
    }
  }

 private:
  static json look_rotation(const glm::vec3& eye, const glm::vec3& target) {
    // glTF cameras look down their local -Z with +Y up.
    const glm::vec3 f = glm::normalize(target - eye);
    const glm::vec3 r = glm::normalize(glm::cross(f, glm::vec3(0, 1, 0)));
    const glm::vec3 u = glm::cross(r, f);
    const glm::quat q = glm::quat_cast(glm::mat3(r, u, -f));
    return {q.x, q.y, q.z, q.w};
  }

  void add_node(const json& node) { doc_["nodes"].push_back(node); }

  int accessor(const void* data, size_t bytes, size_t count, int component, const char* type, int target) {
    while (buffer_.size() % 4) buffer_.push_back(0);
    const size_t offset = buffer_.size();
    const auto* p = static_cast<const uint8_t*>(data);
    buffer_.insert(buffer_.end(), p, p + bytes);
    doc_["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", offset}, {"byteLength", bytes}, {"target", target}});
    doc_["accessors"].push_back({{"bufferView", int(doc_["bufferViews"].size() - 1)},
                                 {"componentType", component}, {"count", count}, {"type", type}});
    return int(doc_["accessors"].size() - 1);
  }

  json doc_;
  std::vector<uint8_t> buffer_;
};

// The default scene: three objects on a floor under one point light, with clear shadows.
void make_default(const std::filesystem::path& dir) {
  Gltf g;
  const int floor_mat = g.material("floor", glm::vec3(0.75f, 0.75f, 0.72f), 0.0f, 0.8f);
  const int red = g.material("red plastic", glm::vec3(0.8f, 0.12f, 0.1f), 0.0f, 0.3f);
  const int blue = g.material("blue matte", glm::vec3(0.15f, 0.3f, 0.85f), 0.0f, 0.9f);
  const int gold = g.material("gold", glm::vec3(0.9f, 0.7f, 0.25f), 1.0f, 0.4f);
  g.object("floor", floor_plane(14.0f, 8), floor_mat, glm::vec3(0.0f));
  g.object("sphere", sphere(1.0f, 48, 24), red, glm::vec3(-1.6f, 1.0f, 0.2f));
  g.object("box", box(glm::vec3(1.4f)), blue, glm::vec3(1.5f, 0.7f, -0.6f),
           glm::angleAxis(0.5f, glm::vec3(0, 1, 0)));
  g.object("column", cylinder(0.45f, 2.2f, 40), gold, glm::vec3(0.4f, 0.0f, 1.9f));
  g.point_light("key light", glm::vec3(-3.0f, 6.5f, 4.0f), glm::vec3(1.0f, 0.97f, 0.9f), 70.0f);
  g.camera("camera", glm::vec3(0.5f, 3.6f, 8.5f), glm::vec3(0.0f, 0.8f, 0.0f), 40.0f, 400.0f / 240.0f);
  g.write(dir / "default.gltf");
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2 || std::strcmp(argv[1], "--help") == 0) {
    std::fprintf(stderr, "usage: mobirt_make_scenes OUT_DIR   (writes default.gltf)\n");
    return argc == 2 ? 0 : 2;
  }
  const std::filesystem::path dir(argv[1]);
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  make_default(dir);
  return 0;
}
