// Builds glTF documents in the tests: one binary buffer, written as .gltf (the buffer embedded as a
// base64 data URI) or .glb, with helpers for accessors, meshes, nodes, scenes and animations.
#pragma once

#include <glm/glm.hpp>
#include <nlohmann/json.hpp>

#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace mobirt::test {

// glTF accessor component types.
inline constexpr int kFloat = 5126;
inline constexpr int kU8 = 5121;
inline constexpr int kU16 = 5123;
inline constexpr int kU32 = 5125;

inline std::string base64(const std::vector<uint8_t>& data) {
  static const char* table = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  size_t i = 0;
  for (; i + 2 < data.size(); i += 3) {
    const uint32_t v = (uint32_t(data[i]) << 16) | (uint32_t(data[i + 1]) << 8) | data[i + 2];
    out += table[(v >> 18) & 63];
    out += table[(v >> 12) & 63];
    out += table[(v >> 6) & 63];
    out += table[v & 63];
  }
  if (i + 1 == data.size()) {
    const uint32_t v = uint32_t(data[i]) << 16;
    out += table[(v >> 18) & 63];
    out += table[(v >> 12) & 63];
    out += "==";
  } else if (i + 2 == data.size()) {
    const uint32_t v = (uint32_t(data[i]) << 16) | (uint32_t(data[i + 1]) << 8);
    out += table[(v >> 18) & 63];
    out += table[(v >> 12) & 63];
    out += table[(v >> 6) & 63];
    out += '=';
  }
  return out;
}

// A glTF document with one binary buffer. Each helper returns the index of what it added.
struct Gltf {
  using json = nlohmann::json;

  json doc = {{"asset", {{"version", "2.0"}}}};
  std::vector<uint8_t> bin;

  int view(const void* data, size_t bytes, int stride = 0) {
    while (bin.size() % 4 != 0) bin.push_back(0);
    json v = {{"buffer", 0}, {"byteOffset", bin.size()}, {"byteLength", bytes}};
    if (stride != 0) v["byteStride"] = stride;
    const auto* p = static_cast<const uint8_t*>(data);
    bin.insert(bin.end(), p, p + bytes);
    doc["bufferViews"].push_back(v);
    return static_cast<int>(doc["bufferViews"].size()) - 1;
  }
  int accessor(int view_index, int component, size_t count, const char* type,
               size_t offset = 0, bool normalized = false) {
    json a = {{"bufferView", view_index}, {"componentType", component}, {"count", count},
              {"type", type}};
    if (offset != 0) a["byteOffset"] = offset;
    if (normalized) a["normalized"] = true;
    doc["accessors"].push_back(a);
    return static_cast<int>(doc["accessors"].size()) - 1;
  }
  // Floats grouped `per` to an element of `type`.
  int floats(const std::vector<float>& v, const char* type, size_t per) {
    return accessor(view(v.data(), v.size() * 4), kFloat, v.size() / per, type);
  }
  int vec3s(const std::vector<glm::vec3>& v) {
    return accessor(view(v.data(), v.size() * sizeof(glm::vec3)), kFloat, v.size(), "VEC3");
  }
  int vec2s(const std::vector<glm::vec2>& v) {
    return accessor(view(v.data(), v.size() * sizeof(glm::vec2)), kFloat, v.size(), "VEC2");
  }
  // Indices of 1, 2 or 4 bytes.
  template <class T>
  int indices(const std::vector<T>& v) {
    const int ct = sizeof(T) == 1 ? kU8 : sizeof(T) == 2 ? kU16 : kU32;
    return accessor(view(v.data(), v.size() * sizeof(T)), ct, v.size(), "SCALAR");
  }
  int u16s(const std::vector<uint16_t>& v) { return indices(v); }
  // A mesh with one primitive and the other members of `extra` (weights, ...).
  int mesh(json primitive, json extra = json::object()) {
    extra["primitives"] = json::array({primitive});
    doc["meshes"].push_back(extra);
    return static_cast<int>(doc["meshes"].size()) - 1;
  }
  int node(json n) {
    doc["nodes"].push_back(n);
    return static_cast<int>(doc["nodes"].size()) - 1;
  }
  void scene(std::vector<int> roots) {
    doc["scenes"] = json::array({{{"nodes", roots}}});
    doc["scene"] = 0;
  }
  // Adds a channel (with its own sampler) to animations[anim]; values as the accessor holds them.
  void channel(size_t anim, int node_index, const char* path, const std::vector<float>& times,
               const std::vector<float>& values, const char* interpolation = "LINEAR") {
    while (doc["animations"].size() <= anim) {
      doc["animations"].push_back({{"channels", json::array()}, {"samplers", json::array()}});
    }
    const char* type = std::strcmp(path, "rotation") == 0   ? "VEC4"
                       : std::strcmp(path, "weights") == 0 ? "SCALAR"
                                                           : "VEC3";
    const size_t per = std::strcmp(path, "rotation") == 0 ? 4 : std::strcmp(path, "weights") == 0 ? 1 : 3;
    const int in = floats(times, "SCALAR", 1);
    const int out = floats(values, type, per);
    json& a = doc["animations"][anim];
    a["samplers"].push_back({{"input", in}, {"output", out}, {"interpolation", interpolation}});
    a["channels"].push_back({{"sampler", a["samplers"].size() - 1},
                             {"target", {{"node", node_index}, {"path", path}}}});
  }

  // The document with its buffer (none while `bin` is empty), embedded as a data URI or not.
  json finished(bool embed) const {
    json d = doc;
    if (bin.empty()) return d;
    json buffer = {{"byteLength", bin.size()}};
    if (embed) buffer["uri"] = "data:application/octet-stream;base64," + base64(bin);
    d["buffers"] = json::array({buffer});
    return d;
  }
  std::string write_gltf(const std::filesystem::path& path) const {
    std::ofstream(path) << finished(true).dump(1);
    return path.string();
  }
  std::string write_glb(const std::filesystem::path& path) const {
    std::string text = finished(false).dump();
    while (text.size() % 4 != 0) text += ' ';
    std::vector<uint8_t> chunk = bin;
    while (chunk.size() % 4 != 0) chunk.push_back(0);
    const uint32_t total = 12 + 8 + static_cast<uint32_t>(text.size()) + 8 +
                           static_cast<uint32_t>(chunk.size());
    std::ofstream out(path, std::ios::binary);
    auto u32 = [&](uint32_t v) { out.write(reinterpret_cast<const char*>(&v), 4); };
    out.write("glTF", 4);
    u32(2);
    u32(total);
    u32(static_cast<uint32_t>(text.size()));
    out.write("JSON", 4);
    out.write(text.data(), static_cast<std::streamsize>(text.size()));
    u32(static_cast<uint32_t>(chunk.size()));
    out.write("BIN\0", 4);
    out.write(reinterpret_cast<const char*>(chunk.data()), static_cast<std::streamsize>(chunk.size()));
    return path.string();
  }
};

}  // namespace mobirt::test
