// glTF 2.0 through tinygltf. tinygltf parses the JSON and the buffers; everything read from a
// buffer is bounds-checked here, so that a broken file ends in a BadInput error, never a crash.
// Images are not decoded: their encoded bytes or paths go into Scene::textures.

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wshadow"
#pragma GCC diagnostic ignored "-Wunused-parameter"
#pragma GCC diagnostic ignored "-Wunused-function"
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"
#define TINYGLTF_IMPLEMENTATION
#define TINYGLTF_NO_STB_IMAGE
#define TINYGLTF_NO_STB_IMAGE_WRITE
#define TINYGLTF_NO_EXTERNAL_IMAGE
#include <tiny_gltf.h>
#pragma GCC diagnostic pop

#include <glm/gtc/constants.hpp>
#include <glm/gtc/matrix_inverse.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/quaternion.hpp>
#include <glm/gtc/type_ptr.hpp>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <map>
#include <string>
#include <vector>

#include "core/error.h"
#include "scene/loader.h"
#include "scene/validate.h"

namespace mobirt {

namespace {

constexpr size_t kMaxUnbackedCount = size_t(1) << 26;  // accessors without a bufferView
constexpr size_t kMaxNodeVisits = size_t(1) << 22;

std::string str(size_t v) { return std::to_string(v); }
std::string str(int v) { return std::to_string(v); }

std::string element(const char* array, size_t index) {
  return std::string(array) + "[" + str(index) + "]";
}

const char* mode_name(int mode) {
  switch (mode) {
    case TINYGLTF_MODE_POINTS: return "POINTS";
    case TINYGLTF_MODE_LINE: return "LINES";
    case TINYGLTF_MODE_LINE_LOOP: return "LINE_LOOP";
    case TINYGLTF_MODE_LINE_STRIP: return "LINE_STRIP";
    case TINYGLTF_MODE_TRIANGLES: return "TRIANGLES";
    case TINYGLTF_MODE_TRIANGLE_STRIP: return "TRIANGLE_STRIP";
    case TINYGLTF_MODE_TRIANGLE_FAN: return "TRIANGLE_FAN";
    default: return "unknown";
  }
}

std::string component_name(int ct) {
  const char* name = "unknown";
  switch (ct) {
    case TINYGLTF_COMPONENT_TYPE_BYTE: name = "BYTE"; break;
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: name = "UNSIGNED_BYTE"; break;
    case TINYGLTF_COMPONENT_TYPE_SHORT: name = "SHORT"; break;
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: name = "UNSIGNED_SHORT"; break;
    case TINYGLTF_COMPONENT_TYPE_INT: name = "INT"; break;
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: name = "UNSIGNED_INT"; break;
    case TINYGLTF_COMPONENT_TYPE_FLOAT: name = "FLOAT"; break;
    case TINYGLTF_COMPONENT_TYPE_DOUBLE: name = "DOUBLE"; break;
    default: break;
  }
  return std::string(name) + " (" + str(ct) + ")";
}

std::string type_name(int type) {
  switch (type) {
    case TINYGLTF_TYPE_SCALAR: return "SCALAR";
    case TINYGLTF_TYPE_VEC2: return "VEC2";
    case TINYGLTF_TYPE_VEC3: return "VEC3";
    case TINYGLTF_TYPE_VEC4: return "VEC4";
    case TINYGLTF_TYPE_MAT2: return "MAT2";
    case TINYGLTF_TYPE_MAT3: return "MAT3";
    case TINYGLTF_TYPE_MAT4: return "MAT4";
    default: return "unknown type " + str(type);
  }
}


std::string url_decode(const std::string& s) {
  std::string out;
  for (size_t i = 0; i < s.size(); ++i) {
    if (s[i] == '%' && i + 2 < s.size() && std::isxdigit(static_cast<unsigned char>(s[i + 1])) &&
        std::isxdigit(static_cast<unsigned char>(s[i + 2]))) {
      out += static_cast<char>(std::stoi(s.substr(i + 1, 2), nullptr, 16));
      i += 2;
    } else {
      out += s[i];
    }
  }
  return out;
}

// Keeps the encoded image bytes (data URIs); images in buffer views are read later, bounds-checked.
bool keep_encoded_image(tinygltf::Image* image, const int, std::string*, std::string*, int, int,
                        const unsigned char* bytes, int size, void*) {
  image->as_is = true;
  if (image->bufferView >= 0) return true;
  if (bytes != nullptr && size > 0) image->image.assign(bytes, bytes + size);
  return true;
}

double number_or(const tinygltf::Value& object, const char* key, double fallback) {
  if (!object.IsObject() || !object.Has(key)) return fallback;
  const tinygltf::Value& v = object.Get(key);
  return v.IsNumber() ? v.GetNumberAsDouble() : fallback;
}

class GltfReader {
 public:
  GltfReader(const std::string& file, const tinygltf::Model& model) : file_(file), model_(model) {
    const auto& used = model.extensionsUsed;
    quantized_ = std::find(used.begin(), used.end(), "KHR_mesh_quantization") != used.end();
  }

  Scene read();

 private:
  [[noreturn]] void fail(const std::string& message) const { throw input_error(file_, message); }

  const uint8_t* view_bytes(int view_index, size_t offset, size_t count, size_t elem,
                            size_t stride, const std::string& who) const;
  std::vector<double> read_accessor(int index, const std::string& user) const;
  const tinygltf::Accessor& accessor(int index, const std::string& user) const;
  std::vector<glm::vec3> read_vec3(int index, const std::string& user, const char* attribute) const;
  std::vector<glm::vec2> read_texcoords(int index, const std::string& user) const;
  std::vector<uint32_t> read_indices(int index, const std::string& user) const;

  glm::dmat4 local_transform(size_t node_index) const;
  void traverse(const std::vector<int>& roots, const std::string& roots_name);
  void add_mesh(size_t mesh_index, const glm::dmat4& world);
  void add_primitive(size_t mesh_index, size_t prim_index, const glm::dmat4& world);
  void add_camera(size_t node_index, const glm::dmat4& world);
  void add_light(size_t node_index, const glm::dmat4& world);
  void convert_materials();
  int texture_for(int gltf_texture, const std::string& user);
  uint32_t default_material();

  const std::string& file_;
  const tinygltf::Model& model_;
  bool quantized_ = false;
  bool warned_orthographic_ = false;
  Scene scene_;
  std::map<int, int> texture_map_;  // glTF texture -> Scene::textures
  int default_material_ = -1;
};

const tinygltf::Accessor& GltfReader::accessor(int index, const std::string& user) const {
  if (index < 0 || static_cast<size_t>(index) >= model_.accessors.size()) {
    fail(user + ": accessor " + str(index) + " does not exist (the file has " +
         str(model_.accessors.size()) + " accessors)");
  }
  return model_.accessors[static_cast<size_t>(index)];
}

// Bytes of `count` elements of `elem` bytes, `stride` apart, starting `offset` bytes into buffer
// view `view_index`: every range checked against the view and the view against its buffer.
const uint8_t* GltfReader::view_bytes(int view_index, size_t offset, size_t count, size_t elem,
                                      size_t stride, const std::string& who) const {
  if (view_index < 0 || static_cast<size_t>(view_index) >= model_.bufferViews.size()) {
    fail(who + ": bufferView " + str(view_index) + " does not exist (the file has " +
         str(model_.bufferViews.size()) + " buffer views)");
  }
  const tinygltf::BufferView& view = model_.bufferViews[static_cast<size_t>(view_index)];
  const std::string view_name = element("bufferViews", static_cast<size_t>(view_index));
  if (view.buffer < 0 || static_cast<size_t>(view.buffer) >= model_.buffers.size()) {
    fail(view_name + ": buffer " + str(view.buffer) + " does not exist (the file has " +
         str(model_.buffers.size()) + " buffers)");
  }
  const tinygltf::Buffer& buffer = model_.buffers[static_cast<size_t>(view.buffer)];
  const size_t size = buffer.data.size();
  if (view.byteOffset > size || view.byteLength > size - view.byteOffset) {
    fail(view_name + ": bytes " + str(view.byteOffset) + ".." +
         str(view.byteOffset + view.byteLength) + " lie outside buffers[" + str(view.buffer) +
         "], which holds " + str(size) + " bytes (truncated buffer?)");
  }
  if (count == 0) return buffer.data.data() + view.byteOffset;
  if (elem == 0 || stride == 0) fail(who + ": zero-sized elements");
  const size_t length = view.byteLength;
  if (offset > length || elem > length - offset ||
      (count - 1) > (length - offset - elem) / stride) {
    fail(who + ": " + str(count) + " elements of " + str(elem) + " bytes, " + str(stride) +
         " bytes apart from byte " + str(offset) + ", do not fit in " + view_name + " (" +
         str(length) + " bytes)");
  }
  return buffer.data.data() + view.byteOffset + offset;
}

double read_component(const uint8_t* p, int ct, bool normalized) {
  switch (ct) {
    case TINYGLTF_COMPONENT_TYPE_BYTE: {
      int8_t v;
      std::memcpy(&v, p, 1);
      return normalized ? std::max(v / 127.0, -1.0) : v;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: {
      uint8_t v;
      std::memcpy(&v, p, 1);
      return normalized ? v / 255.0 : v;
    }
    case TINYGLTF_COMPONENT_TYPE_SHORT: {
      int16_t v;
      std::memcpy(&v, p, 2);
      return normalized ? std::max(v / 32767.0, -1.0) : v;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
      uint16_t v;
      std::memcpy(&v, p, 2);
      return normalized ? v / 65535.0 : v;
    }
    case TINYGLTF_COMPONENT_TYPE_INT: {
      int32_t v;
      std::memcpy(&v, p, 4);
      return normalized ? std::max(v / 2147483647.0, -1.0) : v;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: {
      uint32_t v;
      std::memcpy(&v, p, 4);
      return normalized ? v / 4294967295.0 : v;
    }
    case TINYGLTF_COMPONENT_TYPE_FLOAT: {
      float v;
      std::memcpy(&v, p, 4);
      return v;
    }
    default: return 0.0;
  }
}

// All components of an accessor as doubles (normalised integers mapped to [0, 1] or [-1, 1]),
// sparse substitution applied.
std::vector<double> GltfReader::read_accessor(int index, const std::string& user) const {
  const tinygltf::Accessor& a = accessor(index, user);
  const std::string name = element("accessors", static_cast<size_t>(index)) + " (" + user + ")";
  const int ncomp = tinygltf::GetNumComponentsInType(static_cast<uint32_t>(a.type));
  const int csize = tinygltf::GetComponentSizeInBytes(static_cast<uint32_t>(a.componentType));
  if (ncomp <= 0 || csize <= 0 || a.componentType == TINYGLTF_COMPONENT_TYPE_DOUBLE) {
    fail(name + ": unsupported type " + type_name(a.type) + " of " +
         component_name(a.componentType));
  }
  if (a.type != TINYGLTF_TYPE_SCALAR && a.type != TINYGLTF_TYPE_VEC2 &&
      a.type != TINYGLTF_TYPE_VEC3 && a.type != TINYGLTF_TYPE_VEC4) {
    fail(name + ": matrix accessors are not vertex data (type " + type_name(a.type) + ")");
  }
  const size_t n = static_cast<size_t>(ncomp);
  const size_t elem = n * static_cast<size_t>(csize);
  std::vector<double> out;

  if (a.bufferView >= 0) {
    const tinygltf::BufferView* view =
        static_cast<size_t>(a.bufferView) < model_.bufferViews.size()
            ? &model_.bufferViews[static_cast<size_t>(a.bufferView)]
            : nullptr;
    size_t stride = elem;
    if (view != nullptr && view->byteStride != 0) {
      stride = view->byteStride;
      if (stride < elem || stride % static_cast<size_t>(csize) != 0) {
        fail(name + ": byteStride " + str(stride) + " of " +
             element("bufferViews", static_cast<size_t>(a.bufferView)) +
             " is smaller than an element (" + str(elem) +
             " bytes) or not a multiple of the component size");
      }
    }
    const uint8_t* base = view_bytes(a.bufferView, a.byteOffset, a.count, elem, stride, name);
    out.resize(a.count * n);
    for (size_t i = 0; i < a.count; ++i) {
      const uint8_t* p = base + i * stride;
      for (size_t c = 0; c < n; ++c) {
        out[i * n + c] = read_component(p + c * static_cast<size_t>(csize), a.componentType,
                                        a.normalized);
      }
    }
  } else {
    if (!a.sparse.isSparse) {
      scene_warning(file_, name + " has no bufferView: all its values are zero");
    }
    if (a.count > kMaxUnbackedCount) {
      fail(name + ": count " + str(a.count) + " without a bufferView is too large");
    }
    out.assign(a.count * n, 0.0);
  }

  if (a.sparse.isSparse) {
    const auto& sp = a.sparse;
    const std::string sname = name + ".sparse";
    if (sp.count <= 0 || static_cast<size_t>(sp.count) > a.count) {
      fail(sname + ": count " + str(sp.count) + " must be in 1.." + str(a.count));
    }
    if (sp.indices.byteOffset < 0 || sp.values.byteOffset < 0) {
      fail(sname + ": negative byteOffset");
    }
    const int ict = sp.indices.componentType;
    if (ict != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE &&
        ict != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT &&
        ict != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT) {
      fail(sname + ".indices: componentType " + component_name(ict) +
           " must be UNSIGNED_BYTE, UNSIGNED_SHORT or UNSIGNED_INT");
    }
    const size_t isize =
        static_cast<size_t>(tinygltf::GetComponentSizeInBytes(static_cast<uint32_t>(ict)));
    const size_t count = static_cast<size_t>(sp.count);
    const uint8_t* ip = view_bytes(sp.indices.bufferView,
                                   static_cast<size_t>(sp.indices.byteOffset), count, isize,
                                   isize, sname + ".indices");
    const uint8_t* vp = view_bytes(sp.values.bufferView, static_cast<size_t>(sp.values.byteOffset),
                                   count, elem, elem, sname + ".values");
    for (size_t i = 0; i < count; ++i) {
      const double target = read_component(ip + i * isize, ict, false);
      if (target >= static_cast<double>(a.count)) {
        fail(sname + ".indices: index " + str(static_cast<size_t>(target)) + " at position " +
             str(i) + " is out of range: the accessor has " + str(a.count) + " elements");
      }
      const size_t t = static_cast<size_t>(target);
      for (size_t c = 0; c < n; ++c) {
        out[t * n + c] = read_component(vp + i * elem + c * static_cast<size_t>(csize),
                                        a.componentType, a.normalized);
      }
    }
  }
  return out;
}

std::vector<glm::vec3> GltfReader::read_vec3(int index, const std::string& user,
                                             const char* attribute) const {
  const tinygltf::Accessor& a = accessor(index, user);
  const std::string name = element("accessors", static_cast<size_t>(index));
  if (a.type != TINYGLTF_TYPE_VEC3) {
    fail(name + " (" + user + " " + attribute + "): type " + type_name(a.type) +
         ", expected VEC3");
  }
  if (!quantized_ && a.componentType != TINYGLTF_COMPONENT_TYPE_FLOAT) {
    fail(name + " (" + user + " " + attribute + "): component type " +
         component_name(a.componentType) +
         ", expected FLOAT (integer attributes need KHR_mesh_quantization)");
  }
  const std::vector<double> v = read_accessor(index, user + " " + attribute);
  std::vector<glm::vec3> out(a.count);
  for (size_t i = 0; i < a.count; ++i) {
    out[i] = glm::vec3(static_cast<float>(v[3 * i]), static_cast<float>(v[3 * i + 1]),
                       static_cast<float>(v[3 * i + 2]));
  }
  return out;
}

std::vector<glm::vec2> GltfReader::read_texcoords(int index, const std::string& user) const {
  const tinygltf::Accessor& a = accessor(index, user);
  const std::string name = element("accessors", static_cast<size_t>(index));
  if (a.type != TINYGLTF_TYPE_VEC2) {
    fail(name + " (" + user + " TEXCOORD_0): type " + type_name(a.type) + ", expected VEC2");
  }
  const int ct = a.componentType;
  const bool ok = ct == TINYGLTF_COMPONENT_TYPE_FLOAT ||
                  ((ct == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE ||
                    ct == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT) &&
                   (a.normalized || quantized_)) ||
                  ((ct == TINYGLTF_COMPONENT_TYPE_BYTE || ct == TINYGLTF_COMPONENT_TYPE_SHORT) &&
                   quantized_);
  if (!ok) {
    fail(name + " (" + user + " TEXCOORD_0): component type " + component_name(ct) +
         (a.normalized ? "" : " (not normalized)") +
         ", expected FLOAT or normalized UNSIGNED_BYTE / UNSIGNED_SHORT");
  }
  const std::vector<double> v = read_accessor(index, user + " TEXCOORD_0");
  std::vector<glm::vec2> out(a.count);
  for (size_t i = 0; i < a.count; ++i) {
    out[i] = glm::vec2(static_cast<float>(v[2 * i]), static_cast<float>(v[2 * i + 1]));
  }
  return out;
}

std::vector<uint32_t> GltfReader::read_indices(int index, const std::string& user) const {
  const tinygltf::Accessor& a = accessor(index, user);
  const std::string name = element("accessors", static_cast<size_t>(index));
  const int ct = a.componentType;
  if (a.type != TINYGLTF_TYPE_SCALAR) {
    fail(name + " (" + user + " indices): type " + type_name(a.type) + ", expected SCALAR");
  }
  if (ct != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE && ct != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT &&
      ct != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT) {
    fail(name + " (" + user + " indices): component type " + component_name(ct) +
         ", expected UNSIGNED_BYTE, UNSIGNED_SHORT or UNSIGNED_INT");
  }
  if (a.normalized) fail(name + " (" + user + " indices): indices must not be normalized");
  const std::vector<double> v = read_accessor(index, user + " indices");
  std::vector<uint32_t> out(v.size());
  for (size_t i = 0; i < v.size(); ++i) out[i] = static_cast<uint32_t>(v[i]);
  return out;
}

glm::dmat4 GltfReader::local_transform(size_t node_index) const {
  const tinygltf::Node& node = model_.nodes[node_index];
  const std::string name = element("nodes", node_index);
  auto check = [&](const std::vector<double>& v, size_t n, const char* what) {
    if (!v.empty() && v.size() != n) {
      fail(name + ": " + what + " needs " + str(n) + " numbers, has " + str(v.size()));
    }
    for (double x : v) {
      if (!std::isfinite(x)) fail(name + ": " + what + " is not finite");
    }
  };
  check(node.matrix, 16, "matrix");
  check(node.translation, 3, "translation");
  check(node.rotation, 4, "rotation");
  check(node.scale, 3, "scale");
  if (!node.matrix.empty()) return glm::make_mat4(node.matrix.data());  // column-major, as glTF
  glm::dmat4 m(1.0);
  if (!node.translation.empty()) {
    m[3] = glm::dvec4(node.translation[0], node.translation[1], node.translation[2], 1.0);
  }
  if (!node.rotation.empty()) {
    glm::dquat q(node.rotation[3], node.rotation[0], node.rotation[1], node.rotation[2]);
    const double len = glm::length(q);
    if (!(len > 0.0)) fail(name + ": rotation is a zero quaternion");
    m = m * glm::mat4_cast(q / len);
  }
  if (!node.scale.empty()) {
    m = m * glm::scale(glm::dmat4(1.0), glm::dvec3(node.scale[0], node.scale[1], node.scale[2]));
  }
  return m;
}

uint32_t GltfReader::default_material() {
  if (default_material_ < 0) {
    Material m;
    m.name = "default";
    default_material_ = static_cast<int>(scene_.materials.size());
    scene_.materials.push_back(m);
  }
  return static_cast<uint32_t>(default_material_);
}

void GltfReader::add_primitive(size_t mesh_index, size_t prim_index, const glm::dmat4& world) {
  const tinygltf::Primitive& prim = model_.meshes[mesh_index].primitives[prim_index];
  const std::string path =
      element("meshes", mesh_index) + "." + element("primitives", prim_index);
  const int mode = prim.mode < 0 ? TINYGLTF_MODE_TRIANGLES : prim.mode;
  if (mode == TINYGLTF_MODE_POINTS || mode == TINYGLTF_MODE_LINE ||
      mode == TINYGLTF_MODE_LINE_LOOP || mode == TINYGLTF_MODE_LINE_STRIP) {
    fail(path + ": mode " + mode_name(mode) + " (" + str(mode) +
         ") is not supported: mobirt renders triangles only; export the mesh as triangles");
  }
  if (mode != TINYGLTF_MODE_TRIANGLES && mode != TINYGLTF_MODE_TRIANGLE_STRIP &&
      mode != TINYGLTF_MODE_TRIANGLE_FAN) {
    fail(path + ": unknown primitive mode " + str(mode));
  }

  auto attr = [&](const char* key) {
    auto it = prim.attributes.find(key);
    return it == prim.attributes.end() ? -1 : it->second;
  };
  const int pos_acc = attr("POSITION");
  if (pos_acc < 0) {
    scene_warning(file_, path + " has no POSITION attribute: skipped");
    return;
  }
  const std::vector<glm::vec3> positions = read_vec3(pos_acc, path, "POSITION");
  const size_t nverts = positions.size();
  std::vector<glm::vec3> normals;
  std::vector<glm::vec2> uvs;
  auto check_count = [&](int acc, size_t count, const char* what) {
    if (count != nverts) {
      fail(element("accessors", static_cast<size_t>(acc)) + " (" + path + " " + what + "): " +
           str(count) + " elements, but POSITION has " + str(nverts));
    }
  };
  if (const int acc = attr("NORMAL"); acc >= 0) {
    normals = read_vec3(acc, path, "NORMAL");
    check_count(acc, normals.size(), "NORMAL");
  }
  if (const int acc = attr("TEXCOORD_0"); acc >= 0) {
    uvs = read_texcoords(acc, path);
    check_count(acc, uvs.size(), "TEXCOORD_0");
  }

  std::vector<uint32_t> indices;
  if (prim.indices >= 0) {
    indices = read_indices(prim.indices, path);
    for (size_t i = 0; i < indices.size(); ++i) {
      if (indices[i] >= nverts) {
        fail(element("accessors", static_cast<size_t>(prim.indices)) + " (" + path +
             " indices): index " + str(static_cast<size_t>(indices[i])) + " at position " +
             str(i) + " is out of range: POSITION has " + str(nverts) + " vertices");
      }
    }
  } else {
    indices.resize(nverts);
    for (size_t i = 0; i < nverts; ++i) indices[i] = static_cast<uint32_t>(i);
  }

  // Triangle list in the file's winding.
  std::vector<uint32_t> tri;
  const size_t n = indices.size();
  if (mode == TINYGLTF_MODE_TRIANGLES) {
    if (n % 3 != 0) {
      scene_warning(file_, path + ": " + str(n) +
                               " TRIANGLES indices are not a multiple of 3; the last " +
                               str(n % 3) + " are ignored");
    }
    tri.assign(indices.begin(), indices.begin() + static_cast<std::ptrdiff_t>(n - n % 3));
  } else if (mode == TINYGLTF_MODE_TRIANGLE_STRIP) {
    for (size_t i = 0; i + 2 < n; ++i) {
      const bool odd = (i % 2) != 0;
      tri.push_back(indices[i]);
      tri.push_back(indices[odd ? i + 2 : i + 1]);
      tri.push_back(indices[odd ? i + 1 : i + 2]);
    }
  } else {  // fan
    for (size_t i = 1; i + 1 < n; ++i) {
      tri.push_back(indices[0]);
      tri.push_back(indices[i]);
      tri.push_back(indices[i + 1]);
    }
  }
  if (tri.empty()) return;

  uint32_t material_id;
  if (prim.material < 0) {
    material_id = default_material();
  } else if (static_cast<size_t>(prim.material) >= model_.materials.size()) {
    fail(path + ": material " + str(prim.material) + " does not exist (the file has " +
         str(model_.materials.size()) + " materials)");
  } else {
    material_id = static_cast<uint32_t>(prim.material);
  }

  const glm::dmat3 linear(world);
  const double det = glm::determinant(linear);
  const bool flip = det < 0.0;
  const bool invertible = std::abs(det) > 1e-300 && std::isfinite(det);
  const glm::dmat3 normal_matrix = invertible ? glm::inverseTranspose(linear) : glm::dmat3(1.0);

  TriangleMesh& mesh = scene_.mesh;
  if (!uvs.empty() && mesh.texcoords.empty() && !mesh.positions.empty()) {
    mesh.texcoords.assign(mesh.positions.size(), glm::vec2(0.0f));
  }
  for (size_t t = 0; t + 2 < tri.size(); t += 3) {
    uint32_t v[3] = {tri[t], tri[t + 1], tri[t + 2]};
    if (flip) std::swap(v[1], v[2]);
    glm::vec3 p[3];
    for (int k = 0; k < 3; ++k) {
      p[k] = glm::vec3(world * glm::dvec4(glm::dvec3(positions[v[k]]), 1.0));
    }
    const glm::vec3 flat = geometric_normal(p[0], p[1], p[2]);
    for (int k = 0; k < 3; ++k) {
      mesh.positions.push_back(p[k]);
      glm::vec3 nrm = flat;
      if (!normals.empty() && invertible) {
        const glm::dvec3 wn = normal_matrix * glm::dvec3(normals[v[k]]);
        const double len = glm::length(wn);
        if (!std::isfinite(len)) {
          nrm = glm::vec3(wn);  // NaN or infinite in the file: validation names the triangle
        } else if (len > 0.0) {
          nrm = glm::vec3(wn / len);
        }
      }
      mesh.normals.push_back(nrm);
      if (!uvs.empty()) {
        mesh.texcoords.push_back(uvs[v[k]]);
      } else if (!mesh.texcoords.empty()) {
        mesh.texcoords.push_back(glm::vec2(0.0f));
      }
    }
    mesh.material_ids.push_back(material_id);
  }
}

void GltfReader::add_mesh(size_t mesh_index, const glm::dmat4& world) {
  const tinygltf::Mesh& mesh = model_.meshes[mesh_index];
  for (size_t p = 0; p < mesh.primitives.size(); ++p) add_primitive(mesh_index, p, world);
}

void GltfReader::add_camera(size_t node_index, const glm::dmat4& world) {
  const tinygltf::Node& node = model_.nodes[node_index];
  const std::string name = element("nodes", node_index);
  if (static_cast<size_t>(node.camera) >= model_.cameras.size()) {
    fail(name + ": camera " + str(node.camera) + " does not exist (the file has " +
         str(model_.cameras.size()) + " cameras)");
  }
  if (scene_.camera) return;
  const tinygltf::Camera& cam = model_.cameras[static_cast<size_t>(node.camera)];
  const std::string cname = element("cameras", static_cast<size_t>(node.camera));
  if (cam.type != "perspective") {
    if (!warned_orthographic_) {
      scene_warning(file_, cname + " is " + (cam.type.empty() ? "untyped" : cam.type) +
                               ": mobirt has perspective cameras only; it is skipped");
      warned_orthographic_ = true;
    }
    return;
  }
  const double yfov = cam.perspective.yfov;
  if (!(yfov > 0.0) || !(yfov < glm::pi<double>())) {
    fail(cname + ": yfov " + std::to_string(yfov) + " must lie in (0, pi) radians");
  }
  const glm::dmat3 linear(world);
  const glm::dvec3 eye = glm::dvec3(world[3]);
  const glm::dvec3 forward = linear * glm::dvec3(0.0, 0.0, -1.0);
  const glm::dvec3 up = linear * glm::dvec3(0.0, 1.0, 0.0);
  const double fl = glm::length(forward);
  const double ul = glm::length(up);
  if (!(fl > 0.0) || !(ul > 0.0) || !std::isfinite(fl) || !std::isfinite(ul) ||
      glm::length(glm::cross(forward / fl, up / ul)) < 1e-9) {
    fail(name + ": the transform of camera " + str(node.camera) +
         " is singular (zero scale): no view direction");
  }
  Camera c;
  c.eye = glm::vec3(eye);
  c.target = glm::vec3(eye + forward / fl);
  c.up = glm::vec3(up / ul);
  c.yfov = static_cast<float>(yfov);
  c.znear = cam.perspective.znear > 0.0 ? static_cast<float>(cam.perspective.znear) : 0.0f;
  scene_.camera = c;
}

void GltfReader::add_light(size_t node_index, const glm::dmat4& world) {
  const tinygltf::Node& node = model_.nodes[node_index];
  auto ext = node.extensions.find("KHR_lights_punctual");
  if (ext == node.extensions.end()) return;
  const std::string name = element("nodes", node_index) + ".extensions.KHR_lights_punctual";
  const double index = number_or(ext->second, "light", -1.0);
  if (!(index >= 0.0) || index >= static_cast<double>(model_.lights.size())) {
    fail(name + ": light " + std::to_string(static_cast<long long>(index)) +
         " does not exist (the file has " + str(model_.lights.size()) + " lights)");
  }
  const size_t li = static_cast<size_t>(index);
  const tinygltf::Light& src = model_.lights[li];
  const std::string lname = "extensions.KHR_lights_punctual.lights[" + str(li) + "]";
  Light light;
  if (src.type == "point") {
    light.type = LightType::Point;
  } else if (src.type == "spot") {
    light.type = LightType::Spot;
  } else if (src.type == "directional") {
    light.type = LightType::Directional;
  } else {
    scene_warning(file_, lname + ": unknown light type '" + src.type + "': skipped");
    return;
  }
  if (src.color.size() >= 3) {
    light.color = glm::vec3(static_cast<float>(src.color[0]), static_cast<float>(src.color[1]),
                            static_cast<float>(src.color[2]));
  }
  light.intensity = static_cast<float>(src.intensity);
  light.range = static_cast<float>(src.range);
  if (!std::isfinite(light.intensity) || light.intensity < 0.0f || !std::isfinite(light.range) ||
      light.range < 0.0f || !std::isfinite(light.color.x) || !std::isfinite(light.color.y) ||
      !std::isfinite(light.color.z)) {
    fail(lname + ": colour, intensity and range must be finite and non-negative");
  }
  light.position = glm::vec3(world[3]);
  const glm::dvec3 dir = glm::dmat3(world) * glm::dvec3(0.0, 0.0, -1.0);
  const double len = glm::length(dir);
  if (light.type != LightType::Point && (!(len > 0.0) || !std::isfinite(len))) {
    fail(name + ": the node transform is singular: the light has no direction");
  }
  if (len > 0.0 && std::isfinite(len)) light.direction = glm::vec3(dir / len);
  if (light.type == LightType::Spot) {
    light.inner_cone = static_cast<float>(src.spot.innerConeAngle);
    light.outer_cone = static_cast<float>(src.spot.outerConeAngle);
    if (!(light.inner_cone >= 0.0f) || !(light.inner_cone < light.outer_cone) ||
        !(light.outer_cone <= 1.5707964f)) {
      fail(lname + ": spot cone angles must satisfy 0 <= innerConeAngle < outerConeAngle <= pi/2");
    }
  }
  scene_.lights.push_back(light);
}

void GltfReader::traverse(const std::vector<int>& roots, const std::string& roots_name) {
  struct Item {
    size_t node;
    glm::dmat4 parent;
    size_t depth;
  };
  std::vector<Item> stack;
  const size_t nnodes = model_.nodes.size();
  for (auto it = roots.rbegin(); it != roots.rend(); ++it) {
    if (*it < 0 || static_cast<size_t>(*it) >= nnodes) {
      fail(roots_name + ": node " + str(*it) + " does not exist (the file has " + str(nnodes) +
           " nodes)");
    }
    stack.push_back({static_cast<size_t>(*it), glm::dmat4(1.0), 0});
  }
  size_t visits = 0;
  while (!stack.empty()) {
    const Item item = stack.back();
    stack.pop_back();
    const std::string name = element("nodes", item.node);
    if (item.depth > nnodes || ++visits > kMaxNodeVisits) {
      fail(name + ": the node hierarchy has a cycle (or shares nodes too often)");
    }
    const tinygltf::Node& node = model_.nodes[item.node];
    const glm::dmat4 world = item.parent * local_transform(item.node);
    if (node.mesh >= 0) {
      if (static_cast<size_t>(node.mesh) >= model_.meshes.size()) {
        fail(name + ": mesh " + str(node.mesh) + " does not exist (the file has " +
             str(model_.meshes.size()) + " meshes)");
      }
      add_mesh(static_cast<size_t>(node.mesh), world);
    }
    if (node.camera >= 0) add_camera(item.node, world);
    add_light(item.node, world);
    for (auto it = node.children.rbegin(); it != node.children.rend(); ++it) {
      if (*it < 0 || static_cast<size_t>(*it) >= nnodes) {
        fail(name + ".children: node " + str(*it) + " does not exist (the file has " +
             str(nnodes) + " nodes)");
      }
      stack.push_back({static_cast<size_t>(*it), world, item.depth + 1});
    }
  }
}

TextureWrap wrap_mode(int mode) {
  switch (mode) {
    case TINYGLTF_TEXTURE_WRAP_CLAMP_TO_EDGE: return TextureWrap::ClampToEdge;
    case TINYGLTF_TEXTURE_WRAP_MIRRORED_REPEAT: return TextureWrap::MirroredRepeat;
    default: return TextureWrap::Repeat;
  }
}

int GltfReader::texture_for(int gltf_texture, const std::string& user) {
  if (gltf_texture < 0) return -1;
  if (auto it = texture_map_.find(gltf_texture); it != texture_map_.end()) return it->second;
  if (static_cast<size_t>(gltf_texture) >= model_.textures.size()) {
    fail(user + ": texture " + str(gltf_texture) + " does not exist (the file has " +
         str(model_.textures.size()) + " textures)");
  }
  const tinygltf::Texture& tex = model_.textures[static_cast<size_t>(gltf_texture)];
  const std::string tname = element("textures", static_cast<size_t>(gltf_texture));
  if (tex.source < 0) {
    scene_warning(file_, tname + " has no image source: the material is untextured");
    texture_map_[gltf_texture] = -1;
    return -1;
  }
  if (static_cast<size_t>(tex.source) >= model_.images.size()) {
    fail(tname + ": image " + str(tex.source) + " does not exist (the file has " +
         str(model_.images.size()) + " images)");
  }
  const tinygltf::Image& image = model_.images[static_cast<size_t>(tex.source)];
  const std::string iname = element("images", static_cast<size_t>(tex.source));
  TextureRef ref;
  ref.name = image.name.empty() ? tex.name : image.name;
  ref.mime_type = image.mimeType;
  if (image.bufferView >= 0) {
    if (static_cast<size_t>(image.bufferView) >= model_.bufferViews.size()) {
      fail(iname + ": bufferView " + str(image.bufferView) + " does not exist");
    }
    const size_t length = model_.bufferViews[static_cast<size_t>(image.bufferView)].byteLength;
    const uint8_t* bytes = view_bytes(image.bufferView, 0, 1, length, length, iname);
    ref.data.assign(bytes, bytes + length);
  } else if (!image.image.empty()) {
    ref.data = image.image;  // a data URI, kept encoded by keep_encoded_image
  } else if (!image.uri.empty()) {
    const std::filesystem::path folder = std::filesystem::path(file_).parent_path();
    ref.path = (folder / url_decode(image.uri)).lexically_normal().string();
    if (!std::filesystem::exists(ref.path)) {
      scene_warning(file_, iname + ": image file " + ref.path + " not found");
    }
  } else {
    fail(iname + ": has neither data nor a uri");
  }
  if (tex.sampler >= 0) {
    if (static_cast<size_t>(tex.sampler) >= model_.samplers.size()) {
      fail(tname + ": sampler " + str(tex.sampler) + " does not exist (the file has " +
           str(model_.samplers.size()) + " samplers)");
    }
    const tinygltf::Sampler& s = model_.samplers[static_cast<size_t>(tex.sampler)];
    ref.wrap_s = wrap_mode(s.wrapS);
    ref.wrap_t = wrap_mode(s.wrapT);
  }
  const int index = static_cast<int>(scene_.textures.size());
  scene_.textures.push_back(std::move(ref));
  texture_map_[gltf_texture] = index;
  return index;
}

void GltfReader::convert_materials() {
  for (size_t i = 0; i < model_.materials.size(); ++i) {
    const tinygltf::Material& src = model_.materials[i];
    const std::string name = element("materials", i);
    const auto& pbr = src.pbrMetallicRoughness;
    glm::vec3 base(1.0f);
    float alpha = 1.0f;
    if (pbr.baseColorFactor.size() == 4) {
      base = glm::vec3(static_cast<float>(pbr.baseColorFactor[0]),
                       static_cast<float>(pbr.baseColorFactor[1]),
                       static_cast<float>(pbr.baseColorFactor[2]));
      alpha = static_cast<float>(pbr.baseColorFactor[3]);
    }
    const float metallic = std::clamp(static_cast<float>(pbr.metallicFactor), 0.0f, 1.0f);
    const float roughness = std::clamp(static_cast<float>(pbr.roughnessFactor), 0.0f, 1.0f);
    if (!std::isfinite(base.x) || !std::isfinite(base.y) || !std::isfinite(base.z) ||
        !std::isfinite(alpha) || !std::isfinite(pbr.metallicFactor) ||
        !std::isfinite(pbr.roughnessFactor)) {
      fail(name + ": non-finite pbrMetallicRoughness factors");
    }
    base = glm::clamp(base, 0.0f, 1.0f);

    Material m;
    m.name = src.name.empty() ? name : src.name;
    m.reflectance = metallic * (1.0f - roughness);
    float transmittance = 0.0f;
    float ior = 1.5f;
    if (auto it = src.extensions.find("KHR_materials_transmission"); it != src.extensions.end()) {
      transmittance = static_cast<float>(number_or(it->second, "transmissionFactor", 0.0));
    } else if (src.alphaMode == "BLEND" && alpha < 1.0f) {
      transmittance = 1.0f - alpha;  // alpha blending as a straight (unbent) transmission
      ior = 1.0f;
    }
    if (auto it = src.extensions.find("KHR_materials_ior"); it != src.extensions.end()) {
      const double v = number_or(it->second, "ior", 1.5);
      ior = v >= 1.0 && std::isfinite(v) ? static_cast<float>(v) : ior;
    }
    m.transmittance = std::isfinite(transmittance) ? std::clamp(transmittance, 0.0f, 1.0f) : 0.0f;
    m.ior = ior;
    m.diffuse = base * (1.0f - m.reflectance) * (1.0f - m.transmittance);
    m.specular = glm::mix(glm::vec3(0.04f), base, metallic);
    const float r4 = std::max(roughness * roughness * roughness * roughness, 1e-6f);
    m.shininess = std::clamp(2.0f / r4 - 2.0f, 1.0f, 1024.0f);
    if (pbr.baseColorTexture.index >= 0) {
      if (pbr.baseColorTexture.texCoord != 0) {
        scene_warning(file_, name + ": baseColorTexture uses TEXCOORD_" +
                                 str(pbr.baseColorTexture.texCoord) +
                                 "; mobirt reads TEXCOORD_0 only");
      }
      m.texture = texture_for(pbr.baseColorTexture.index, name + ".baseColorTexture");
    }
    scene_.materials.push_back(m);
  }
}

Scene GltfReader::read() {
  scene_.source = file_;
  convert_materials();
  std::vector<int> roots;
  std::string roots_name;
  if (!model_.scenes.empty()) {
    size_t s = 0;
    if (model_.defaultScene >= 0 && static_cast<size_t>(model_.defaultScene) < model_.scenes.size()) {
      s = static_cast<size_t>(model_.defaultScene);
    }
    roots = model_.scenes[s].nodes;
    roots_name = element("scenes", s) + ".nodes";
  } else {
    std::vector<bool> is_child(model_.nodes.size(), false);
    for (const tinygltf::Node& node : model_.nodes) {
      for (int c : node.children) {
        if (c >= 0 && static_cast<size_t>(c) < is_child.size()) is_child[static_cast<size_t>(c)] = true;
      }
    }
    for (size_t i = 0; i < model_.nodes.size(); ++i) {
      if (!is_child[i]) roots.push_back(static_cast<int>(i));
    }
    roots_name = "root nodes";
  }
  traverse(roots, roots_name);
  return std::move(scene_);
}

}  // namespace

Scene load_gltf(const std::string& path) {
  check_scene_file(path);
  std::ifstream in(path, std::ios::binary);
  if (!in) throw input_error(path, "cannot be opened for reading");
  std::vector<unsigned char> bytes((std::istreambuf_iterator<char>(in)),
                                   std::istreambuf_iterator<char>());
  if (bytes.size() >= std::numeric_limits<unsigned int>::max()) {
    throw input_error(path, "is larger than 4 GiB; glTF files that large are not supported");
  }
  if (bytes.empty()) throw input_error(path, "is empty: not a glTF file");

  tinygltf::TinyGLTF gltf;
  gltf.SetImageLoader(keep_encoded_image, nullptr);
  tinygltf::Model model;
  std::string err;
  std::string warn;
  const std::string base_dir = std::filesystem::path(path).parent_path().string();
  const bool binary = bytes.size() >= 4 && std::memcmp(bytes.data(), "glTF", 4) == 0;
  bool ok;
  if (binary) {
    ok = gltf.LoadBinaryFromMemory(&model, &err, &warn, bytes.data(),
                                   static_cast<unsigned int>(bytes.size()), base_dir);
  } else {
    ok = gltf.LoadASCIIFromString(&model, &err, &warn, reinterpret_cast<const char*>(bytes.data()),
                                  static_cast<unsigned int>(bytes.size()), base_dir);
  }
  if (!ok) {
    const std::string why = library_message(err.empty() ? warn : err);
    throw input_error(path, std::string("not a valid glTF ") + (binary ? "binary (.glb)" : "file") +
                                ": " + (why.empty() ? "tinygltf could not parse it" : why));
  }
  if (!warn.empty()) scene_warning(path, library_message(warn));

  GltfReader reader(path, model);
  Scene scene = reader.read();
  validate_scene(scene);
  return scene;
}

}  // namespace mobirt
