#include "gltf_writer.h"

#include <cstdio>
#include <cstdlib>
#include <fstream>

namespace mobirt::scenes {

using nlohmann::json;

namespace {

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

}  // namespace

Gltf::Gltf() {
  doc_["asset"] = {{"version", "2.0"}, {"generator", "mobirt tools/make_scenes.cpp"}};
  for (const char* key : {"nodes", "meshes", "materials", "accessors", "bufferViews"}) {
    doc_[key] = json::array();
  }
}

int Gltf::material(const std::string& name, const glm::vec3& color, float metallic, float roughness) {
  MaterialDesc d;
  d.name = name;
  d.color = color;
  d.metallic = metallic;
  d.roughness = roughness;
  return material(d);
}

int Gltf::material(const MaterialDesc& d) {
  json pbr = {{"baseColorFactor", {d.color.r, d.color.g, d.color.b, 1.0}},
              {"metallicFactor", d.metallic},
              {"roughnessFactor", d.roughness}};
  if (d.texture >= 0) pbr["baseColorTexture"] = {{"index", d.texture}, {"texCoord", 0}};
  json m = {{"name", d.name}, {"pbrMetallicRoughness", pbr}};
  if (d.transmission >= 0.0f) {
    m["extensions"]["KHR_materials_transmission"] = {{"transmissionFactor", d.transmission}};
    extensions_.insert("KHR_materials_transmission");
  }
  if (d.ior >= 0.0f) {
    m["extensions"]["KHR_materials_ior"] = {{"ior", d.ior}};
    extensions_.insert("KHR_materials_ior");
  }
  doc_["materials"].push_back(m);
  textured_.push_back(d.texture >= 0);
  return int(doc_["materials"].size() - 1);
}

int Gltf::texture(const std::string& name, const std::string& uri, int wrap_s, int wrap_t) {
  doc_["images"].push_back({{"name", name}, {"uri", uri}, {"mimeType", "image/png"}});
  doc_["samplers"].push_back({{"magFilter", 9729}, {"minFilter", 9729}, {"wrapS", wrap_s}, {"wrapT", wrap_t}});
  doc_["textures"].push_back({{"name", name}, {"source", int(doc_["images"].size() - 1)},
                              {"sampler", int(doc_["samplers"].size() - 1)}});
  return int(doc_["textures"].size() - 1);
}

int Gltf::group(const std::string& name, const glm::vec3& translation, const glm::quat& rotation, int parent) {
  json node = {{"name", name}, {"translation", {translation.x, translation.y, translation.z}}};
  if (rotation != glm::quat(1, 0, 0, 0)) node["rotation"] = {rotation.x, rotation.y, rotation.z, rotation.w};
  return add_node(node, parent);
}

int Gltf::object(const std::string& name, const Mesh& mesh, int material, const glm::vec3& translation,
                 const glm::quat& rotation, int parent) {
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
  json attributes = {{"POSITION", pos}, {"NORMAL", nrm}};
  if (textured_.at(size_t(material))) {
    attributes["TEXCOORD_0"] =
        accessor(mesh.uvs.data(), mesh.uvs.size() * 8, mesh.uvs.size(), 5126, "VEC2", 34962);
  }
  int idx;
  if (mesh.positions.size() < 65536) {
    std::vector<uint16_t> small(mesh.indices.begin(), mesh.indices.end());
    idx = accessor(small.data(), small.size() * 2, small.size(), 5123, "SCALAR", 34963);
  } else {
    idx = accessor(mesh.indices.data(), mesh.indices.size() * 4, mesh.indices.size(), 5125, "SCALAR", 34963);
  }
  doc_["meshes"].push_back(
      {{"name", name},
       {"primitives", {{{"attributes", attributes}, {"indices", idx}, {"material", material}}}}});
  json node = {{"name", name}, {"mesh", int(doc_["meshes"].size() - 1)},
               {"translation", {translation.x, translation.y, translation.z}}};
  if (rotation != glm::quat(1, 0, 0, 0)) node["rotation"] = {rotation.x, rotation.y, rotation.z, rotation.w};
  triangles_ += mesh.triangles();
  return add_node(node, parent);
}

void Gltf::camera(const std::string& name, const glm::vec3& eye, const glm::vec3& target, float yfov_deg,
                  float aspect) {
  doc_["cameras"].push_back({{"name", name}, {"type", "perspective"},
                             {"perspective", {{"yfov", yfov_deg * kPi / 180.0f}, {"aspectRatio", aspect},
                                              {"znear", 0.05}, {"zfar", 1000.0}}}});
  add_node({{"name", name}, {"camera", int(doc_["cameras"].size() - 1)},
            {"translation", {eye.x, eye.y, eye.z}}, {"rotation", look_rotation(eye, target)}},
           -1);
}

void Gltf::point_light(const std::string& name, const glm::vec3& position, const glm::vec3& color, float intensity) {
  json& lights = doc_["extensions"]["KHR_lights_punctual"]["lights"];
  lights.push_back({{"name", name}, {"type", "point"}, {"color", {color.r, color.g, color.b}},
                    {"intensity", intensity}});
  add_node({{"name", name}, {"translation", {position.x, position.y, position.z}},
            {"extensions", {{"KHR_lights_punctual", {{"light", int(lights.size() - 1)}}}}}},
           -1);
  extensions_.insert("KHR_lights_punctual");
}

void Gltf::animation(const std::string& name, const std::vector<Channel>& channels) {
  json samplers = json::array(), targets = json::array();
  for (const Channel& c : channels) {
    const int input = accessor(c.times.data(), c.times.size() * 4, c.times.size(), 5126, "SCALAR", 0);
    doc_["accessors"][size_t(input)]["min"] = {c.times.front()};
    doc_["accessors"][size_t(input)]["max"] = {c.times.back()};
    const bool rot = c.path == "rotation";
    std::vector<float> flat;
    for (const glm::vec4& v : c.values) {
      flat.insert(flat.end(), {v.x, v.y, v.z});
      if (rot) flat.push_back(v.w);
    }
    const int output = accessor(flat.data(), flat.size() * 4, c.values.size(), 5126, rot ? "VEC4" : "VEC3", 0);
    samplers.push_back({{"input", input}, {"output", output}, {"interpolation", "LINEAR"}});
    targets.push_back({{"sampler", int(samplers.size() - 1)}, {"target", {{"node", c.node}, {"path", c.path}}}});
  }
  doc_["animations"].push_back({{"name", name}, {"samplers", samplers}, {"channels", targets}});
}

void Gltf::write(const std::filesystem::path& path, bool external_buffer) {
  if (external_buffer) {
    std::filesystem::path bin = path;
    bin.replace_extension(".bin");
    std::ofstream out(bin, std::ios::binary);
    out.write(reinterpret_cast<const char*>(buffer_.data()), std::streamsize(buffer_.size()));
    if (!out) {
      std::fprintf(stderr, "make_scenes: cannot write %s\n", bin.string().c_str());
      std::exit(1);
    }
    doc_["buffers"] = {{{"byteLength", buffer_.size()}, {"uri", bin.filename().string()}}};
  } else {
    doc_["buffers"] = {{{"byteLength", buffer_.size()},
                        {"uri", "data:application/octet-stream;base64," + base64(buffer_)}}};
  }
  json scene_nodes = json::array();
  for (size_t i = 0; i < doc_["nodes"].size(); ++i) {
    if (parent_[i] < 0) scene_nodes.push_back(i);
  }
  doc_["scenes"] = {{{"nodes", scene_nodes}}};
  doc_["scene"] = 0;
  if (!extensions_.empty()) doc_["extensionsUsed"] = extensions_;
  std::ofstream out(path, std::ios::binary);
  out << doc_.dump(1) << "\n";
  if (!out) {
    std::fprintf(stderr, "make_scenes: cannot write %s\n", path.string().c_str());
    std::exit(1);
  }
}

json Gltf::look_rotation(const glm::vec3& eye, const glm::vec3& target) {
  // glTF cameras look down their local -Z with +Y up.
  const glm::vec3 f = glm::normalize(target - eye);
  const glm::vec3 r = glm::normalize(glm::cross(f, glm::vec3(0, 1, 0)));
  const glm::vec3 u = glm::cross(r, f);
  const glm::quat q = glm::quat_cast(glm::mat3(r, u, -f));
  return {q.x, q.y, q.z, q.w};
}

int Gltf::add_node(const json& node, int parent) {
  doc_["nodes"].push_back(node);
  parent_.push_back(parent);
  const int index = int(doc_["nodes"].size() - 1);
  if (parent >= 0) doc_["nodes"][size_t(parent)]["children"].push_back(index);
  return index;
}

int Gltf::accessor(const void* data, size_t bytes, size_t count, int component, const char* type, int target) {
  while (buffer_.size() % 4) buffer_.push_back(0);
  const size_t offset = buffer_.size();
  const auto* p = static_cast<const uint8_t*>(data);
  buffer_.insert(buffer_.end(), p, p + bytes);
  json view = {{"buffer", 0}, {"byteOffset", offset}, {"byteLength", bytes}};
  if (target != 0) view["target"] = target;
  doc_["bufferViews"].push_back(view);
  doc_["accessors"].push_back({{"bufferView", int(doc_["bufferViews"].size() - 1)},
                               {"componentType", component}, {"count", count}, {"type", type}});
  return int(doc_["accessors"].size() - 1);
}

}  // namespace mobirt::scenes
