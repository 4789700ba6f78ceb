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
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "core/error.h"
#include "scene/animation.h"
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

// ---- The rig: what the file animates, in a form evaluate() walks without the tinygltf model ----

enum class ChannelPath { Translation, Rotation, Scale, Weights };
enum class Interpolation { Linear, Step, CubicSpline };

struct AnimSampler {
  std::vector<double> times;   // key times, non-decreasing
  std::vector<double> values;  // per key `width` numbers (CUBICSPLINE: in-tangent, value, out-tangent)
  Interpolation interpolation = Interpolation::Linear;
  size_t width = 0;
};

struct AnimChannel {
  size_t node = 0;
  ChannelPath path = ChannelPath::Translation;
  size_t sampler = 0;
};

// One triangle primitive in its mesh's space, ready to be posed.
struct PrimData {
  std::vector<glm::vec3> positions;                 // per vertex
  std::vector<glm::vec3> normals;                   // per vertex; empty: flat normals
  std::vector<std::vector<glm::vec3>> target_positions;  // per morph target (empty: none)
  std::vector<std::vector<glm::vec3>> target_normals;    // per morph target (empty: none)
  std::vector<glm::uvec4> joints;                   // JOINTS_0; empty: not skinnable
  std::vector<glm::vec4> weights;                   // WEIGHTS_0, renormalised to sum 1
  uint32_t max_joint = 0;
  std::vector<uint32_t> triangles;                  // vertex indices, the file's winding
  std::vector<glm::vec2> uvs;                       // per vertex; empty: none
  uint32_t material = 0;
};

struct MeshData {
  bool prepared = false;
  std::vector<PrimData> prims;
};

struct SkinData {
  std::vector<size_t> joints;         // node indices
  std::vector<glm::dmat4> inverse_bind;
};

// A node as visited by the traversal of the scene (a node reached twice is two instances).
struct Instance {
  size_t node = 0;
  int parent = -1;  // instance index
};

struct Draw {
  size_t instance = 0;
  size_t mesh = 0;
  int skin = -1;
  size_t first_corner = 0;  // where its triangles start in the scene's vertex arrays
  bool flip = false;        // the rest pose mirrors (negative determinant): winding reversed
};

struct LightInstance {
  size_t instance = 0;
  Light light;  // everything but position and direction
};

struct CameraInstance {
  size_t instance = 0;
  size_t camera = 0;
  double yfov = 0.0;
  float znear = 0.0f;
};

class GltfRig : public detail::Animator {
 public:
  void evaluate(double t, Scene& out) const override;

  std::string file;
  // Nodes.
  std::vector<glm::dmat4> rest_local;         // the file's local transforms
  std::vector<glm::dvec3> rest_translation;   // TRS (a matrix node that is animated: decomposed)
  std::vector<glm::dquat> rest_rotation;
  std::vector<glm::dvec3> rest_scale;
  std::vector<uint8_t> animated_node;         // 1: its local transform comes from TRS at t
  std::vector<size_t> weight_offset;          // into rest_weights; npos: no morph weights
  std::vector<size_t> weight_count;
  std::vector<double> rest_weights;
  std::vector<int> node_parent;               // first parent, -1: root
  std::vector<size_t> node_order;             // parents before children (for joint worlds)
  // Scene traversal.
  std::vector<Instance> instances;
  std::vector<MeshData> meshes;
  std::vector<SkinData> skins;
  std::vector<Draw> draws;
  std::vector<LightInstance> lights;
  std::optional<CameraInstance> camera;
  size_t corners = 0;
  // Animation.
  std::vector<AnimSampler> samplers;
  std::vector<AnimChannel> channels;
  double duration = 0.0;

 private:
  [[noreturn]] void fail_at(double t, const std::string& message) const;
};

class GltfReader {
 public:
  GltfReader(const std::string& file, const tinygltf::Model& model) : file_(file), model_(model) {
    const auto& used = model.extensionsUsed;
    quantized_ = std::find(used.begin(), used.end(), "KHR_mesh_quantization") != used.end();
  }

  // The static parts of the scene (materials, textures, texture coordinates, material ids) and
  // the rig that poses it.
  std::shared_ptr<GltfRig> read(const LoadOptions& options, bool animated, Scene& scene);

 private:
  [[noreturn]] void fail(const std::string& message) const { throw input_error(file_, message); }

  const uint8_t* view_bytes(int view_index, size_t offset, size_t count, size_t elem,
                            size_t stride, const std::string& who) const;
  std::vector<double> read_accessor(int index, const std::string& user,
                                    bool matrix4 = false) const;
  const tinygltf::Accessor& accessor(int index, const std::string& user) const;
  std::vector<glm::vec3> read_vec3(int index, const std::string& user, const char* attribute) const;
  std::vector<glm::vec2> read_texcoords(int index, const std::string& user) const;
  std::vector<uint32_t> read_indices(int index, const std::string& user) const;

  glm::dmat4 local_transform(size_t node_index) const;
  void traverse(const std::vector<int>& roots, const std::string& roots_name);
  void prepare_mesh(size_t mesh_index);
  bool prepare_primitive(size_t mesh_index, size_t prim_index, PrimData& out);
  void add_draw(size_t instance, size_t mesh_index, int skin);
  int prepare_skin(size_t node_index);
  void add_camera(size_t instance);
  void add_light(size_t instance);
  void prepare_nodes();
  void prepare_animations(int only, bool warn_overrides);
  size_t mesh_targets(size_t mesh_index) const;
  void convert_materials();
  int texture_for(int gltf_texture, const std::string& user);
  uint32_t default_material();

  const std::string& file_;
  const tinygltf::Model& model_;
  bool quantized_ = false;
  bool warned_orthographic_ = false;
  Scene scene_;
  std::shared_ptr<GltfRig> rig_;
  std::map<int, int> texture_map_;  // glTF texture -> Scene::textures
  std::map<int, int> skin_map_;     // glTF skin -> GltfRig::skins
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
std::vector<double> GltfReader::read_accessor(int index, const std::string& user,
                                              bool matrix4) const {
  const tinygltf::Accessor& a = accessor(index, user);
  const std::string name = element("accessors", static_cast<size_t>(index)) + " (" + user + ")";
  const int ncomp = tinygltf::GetNumComponentsInType(static_cast<uint32_t>(a.type));
  const int csize = tinygltf::GetComponentSizeInBytes(static_cast<uint32_t>(a.componentType));
  if (ncomp <= 0 || csize <= 0 || a.componentType == TINYGLTF_COMPONENT_TYPE_DOUBLE) {
    fail(name + ": unsupported type " + type_name(a.type) + " of " +
         component_name(a.componentType));
  }
  if (matrix4) {
    if (a.type != TINYGLTF_TYPE_MAT4 || a.componentType != TINYGLTF_COMPONENT_TYPE_FLOAT) {
      fail(name + ": type " + type_name(a.type) + " of " + component_name(a.componentType) +
           ", expected MAT4 of FLOAT");
    }
  } else if (a.type != TINYGLTF_TYPE_SCALAR && a.type != TINYGLTF_TYPE_VEC2 &&
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

// Reads primitive `prim_index` of mesh `mesh_index` into `out`; false when it is skipped (no
// POSITION, or no whole triangle).
bool GltfReader::prepare_primitive(size_t mesh_index, size_t prim_index, PrimData& out) {
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

  auto attr = [&](const std::map<std::string, int>& attributes, const char* key) {
    auto it = attributes.find(key);
    return it == attributes.end() ? -1 : it->second;
  };
  const int pos_acc = attr(prim.attributes, "POSITION");
  if (pos_acc < 0) {
    scene_warning(file_, path + " has no POSITION attribute: skipped");
    return false;
  }
  out.positions = read_vec3(pos_acc, path, "POSITION");
  const size_t nverts = out.positions.size();
  auto check_count = [&](int acc, size_t count, const std::string& what) {
    if (count != nverts) {
      fail(element("accessors", static_cast<size_t>(acc)) + " (" + path + " " + what + "): " +
           str(count) + " elements, but POSITION has " + str(nverts));
    }
  };
  if (const int acc = attr(prim.attributes, "NORMAL"); acc >= 0) {
    out.normals = read_vec3(acc, path, "NORMAL");
    check_count(acc, out.normals.size(), "NORMAL");
  }
  if (const int acc = attr(prim.attributes, "TEXCOORD_0"); acc >= 0) {
    out.uvs = read_texcoords(acc, path);
    check_count(acc, out.uvs.size(), "TEXCOORD_0");
  }

  // Morph targets.
  out.target_positions.resize(prim.targets.size());
  out.target_normals.resize(prim.targets.size());
  for (size_t k = 0; k < prim.targets.size(); ++k) {
    const std::string tname = element("targets", k);
    if (const int acc = attr(prim.targets[k], "POSITION"); acc >= 0) {
      out.target_positions[k] = read_vec3(acc, path, (tname + ".POSITION").c_str());
      check_count(acc, out.target_positions[k].size(), tname + ".POSITION");
    }
    if (const int acc = attr(prim.targets[k], "NORMAL"); acc >= 0 && !out.normals.empty()) {
      out.target_normals[k] = read_vec3(acc, path, (tname + ".NORMAL").c_str());
      check_count(acc, out.target_normals[k].size(), tname + ".NORMAL");
    }
  }

  // Skinning attributes (set 0; further sets are ignored with a warning).
  const int joints_acc = attr(prim.attributes, "JOINTS_0");
  const int weights_acc = attr(prim.attributes, "WEIGHTS_0");
  if (joints_acc >= 0 && weights_acc >= 0) {
    const tinygltf::Accessor& ja = accessor(joints_acc, path);
    if (ja.type != TINYGLTF_TYPE_VEC4 ||
        (ja.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE &&
         ja.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT) ||
        ja.normalized) {
      fail(element("accessors", static_cast<size_t>(joints_acc)) + " (" + path +
           " JOINTS_0): " + type_name(ja.type) + " of " + component_name(ja.componentType) +
           ", expected VEC4 of UNSIGNED_BYTE or UNSIGNED_SHORT");
    }
    const tinygltf::Accessor& wa = accessor(weights_acc, path);
    const int wct = wa.componentType;
    if (wa.type != TINYGLTF_TYPE_VEC4 ||
        !(wct == TINYGLTF_COMPONENT_TYPE_FLOAT ||
          ((wct == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE ||
            wct == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT) &&
           wa.normalized))) {
      fail(element("accessors", static_cast<size_t>(weights_acc)) + " (" + path +
           " WEIGHTS_0): " + type_name(wa.type) + " of " + component_name(wct) +
           ", expected VEC4 of FLOAT or normalized UNSIGNED_BYTE / UNSIGNED_SHORT");
    }
    const std::vector<double> j = read_accessor(joints_acc, path + " JOINTS_0");
    const std::vector<double> w = read_accessor(weights_acc, path + " WEIGHTS_0");
    check_count(joints_acc, ja.count, "JOINTS_0");
    check_count(weights_acc, wa.count, "WEIGHTS_0");
    out.joints.resize(nverts);
    out.weights.resize(nverts);
    for (size_t v = 0; v < nverts; ++v) {
      glm::dvec4 wv(w[4 * v], w[4 * v + 1], w[4 * v + 2], w[4 * v + 3]);
      for (int c = 0; c < 4; ++c) {
        const double jc = j[4 * v + static_cast<size_t>(c)];
        out.joints[v][c] = static_cast<uint32_t>(jc);
        if (!std::isfinite(wv[c]) || wv[c] < 0.0) {
          fail(element("accessors", static_cast<size_t>(weights_acc)) + " (" + path +
               " WEIGHTS_0): vertex " + str(v) + " has a negative or non-finite weight");
        }
        if (wv[c] > 0.0) {
          out.max_joint = std::max(out.max_joint, out.joints[v][c]);
        } else {
          out.joints[v][c] = 0;  // weight 0: unchecked against the skin, so never indexed with
        }
      }
      const double sum = wv.x + wv.y + wv.z + wv.w;
      out.weights[v] = sum > 0.0 ? glm::vec4(wv / sum) : glm::vec4(0.0f);
    }
    if (prim.attributes.count("JOINTS_1") != 0) {
      scene_warning(file_, path + ": JOINTS_1 / WEIGHTS_1 are ignored (mobirt skins with the "
                                  "first four influences)");
    }
  } else if (joints_acc >= 0 || weights_acc >= 0) {
    scene_warning(file_, path + ": JOINTS_0 without WEIGHTS_0 (or the reverse): not skinned");
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
  std::vector<uint32_t>& tri = out.triangles;
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
  if (tri.empty()) return false;

  if (prim.material < 0) {
    out.material = default_material();
  } else if (static_cast<size_t>(prim.material) >= model_.materials.size()) {
    fail(path + ": material " + str(prim.material) + " does not exist (the file has " +
         str(model_.materials.size()) + " materials)");
  } else {
    out.material = static_cast<uint32_t>(prim.material);
  }
  return true;
}

size_t GltfReader::mesh_targets(size_t mesh_index) const {
  size_t targets = 0;
  for (const tinygltf::Primitive& prim : model_.meshes[mesh_index].primitives) {
    targets = std::max(targets, prim.targets.size());
  }
  return targets;
}

void GltfReader::prepare_mesh(size_t mesh_index) {
  MeshData& mesh = rig_->meshes[mesh_index];
  if (mesh.prepared) return;
  mesh.prepared = true;
  const tinygltf::Mesh& src = model_.meshes[mesh_index];
  for (size_t p = 0; p < src.primitives.size(); ++p) {
    PrimData prim;
    if (prepare_primitive(mesh_index, p, prim)) mesh.prims.push_back(std::move(prim));
  }
}

// The skin of node `node_index` as an index into rig_->skins, or -1 for none.
int GltfReader::prepare_skin(size_t node_index) {
  const tinygltf::Node& node = model_.nodes[node_index];
  if (node.skin < 0) return -1;
  const std::string name = element("nodes", node_index);
  if (static_cast<size_t>(node.skin) >= model_.skins.size()) {
    fail(name + ": skin " + str(node.skin) + " does not exist (the file has " +
         str(model_.skins.size()) + " skins)");
  }
  if (auto it = skin_map_.find(node.skin); it != skin_map_.end()) return it->second;
  const tinygltf::Skin& src = model_.skins[static_cast<size_t>(node.skin)];
  const std::string sname = element("skins", static_cast<size_t>(node.skin));
  SkinData skin;
  for (int j : src.joints) {
    if (j < 0 || static_cast<size_t>(j) >= model_.nodes.size()) {
      fail(sname + ".joints: node " + str(j) + " does not exist (the file has " +
           str(model_.nodes.size()) + " nodes)");
    }
    skin.joints.push_back(static_cast<size_t>(j));
  }
  if (skin.joints.empty()) fail(sname + ": no joints");
  skin.inverse_bind.assign(skin.joints.size(), glm::dmat4(1.0));
  if (src.inverseBindMatrices >= 0) {
    const std::vector<double> m =
        read_accessor(src.inverseBindMatrices, sname + ".inverseBindMatrices", true);
    if (m.size() < 16 * skin.joints.size()) {
      fail(sname + ".inverseBindMatrices: " + str(m.size() / 16) + " matrices for " +
           str(skin.joints.size()) + " joints");
    }
    for (size_t k = 0; k < skin.joints.size(); ++k) {
      for (size_t c = 0; c < 16; ++c) {
        if (!std::isfinite(m[16 * k + c])) {
          fail(sname + ".inverseBindMatrices: matrix " + str(k) + " is not finite");
        }
      }
      skin.inverse_bind[k] = glm::make_mat4(m.data() + 16 * k);
    }
  }
  const int index = static_cast<int>(rig_->skins.size());
  rig_->skins.push_back(std::move(skin));
  skin_map_[node.skin] = index;
  return index;
}

void GltfReader::add_draw(size_t instance, size_t mesh_index, int skin) {
  prepare_mesh(mesh_index);
  const MeshData& mesh = rig_->meshes[mesh_index];
  const size_t node = rig_->instances[instance].node;
  if (skin >= 0) {
    const SkinData& s = rig_->skins[static_cast<size_t>(skin)];
    for (size_t p = 0; p < mesh.prims.size(); ++p) {
      if (!mesh.prims[p].joints.empty() && mesh.prims[p].max_joint >= s.joints.size()) {
        fail(element("meshes", mesh_index) + ".primitives: JOINTS_0 uses joint " +
             str(static_cast<size_t>(mesh.prims[p].max_joint)) + ", but the skin of " +
             element("nodes", node) + " has " + str(s.joints.size()) + " joints");
      }
    }
  }
  Draw draw;
  draw.instance = instance;
  draw.mesh = mesh_index;
  draw.skin = skin;
  draw.first_corner = rig_->corners;
  for (const PrimData& prim : mesh.prims) rig_->corners += prim.triangles.size();
  rig_->draws.push_back(draw);
}

void GltfReader::add_camera(size_t instance) {
  const size_t node_index = rig_->instances[instance].node;
  const tinygltf::Node& node = model_.nodes[node_index];
  const std::string name = element("nodes", node_index);
  if (static_cast<size_t>(node.camera) >= model_.cameras.size()) {
    fail(name + ": camera " + str(node.camera) + " does not exist (the file has " +
         str(model_.cameras.size()) + " cameras)");
  }
  if (rig_->camera) return;
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
  CameraInstance c;
  c.instance = instance;
  c.camera = static_cast<size_t>(node.camera);
  c.yfov = yfov;
  c.znear = cam.perspective.znear > 0.0 ? static_cast<float>(cam.perspective.znear) : 0.0f;
  rig_->camera = c;
}

void GltfReader::add_light(size_t instance) {
  const size_t node_index = rig_->instances[instance].node;
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
  if (light.type == LightType::Spot) {
    light.inner_cone = static_cast<float>(src.spot.innerConeAngle);
    light.outer_cone = static_cast<float>(src.spot.outerConeAngle);
    if (!(light.inner_cone >= 0.0f) || !(light.inner_cone < light.outer_cone) ||
        !(light.outer_cone <= 1.5707964f)) {
      fail(lname + ": spot cone angles must satisfy 0 <= innerConeAngle < outerConeAngle <= pi/2");
    }
  }
  rig_->lights.push_back({instance, light});
}

void GltfReader::traverse(const std::vector<int>& roots, const std::string& roots_name) {
  struct Item {
    size_t node;
    int parent;  // instance
    size_t depth;
  };
  std::vector<Item> stack;
  const size_t nnodes = model_.nodes.size();
  for (auto it = roots.rbegin(); it != roots.rend(); ++it) {
    if (*it < 0 || static_cast<size_t>(*it) >= nnodes) {
      fail(roots_name + ": node " + str(*it) + " does not exist (the file has " + str(nnodes) +
           " nodes)");
    }
    stack.push_back({static_cast<size_t>(*it), -1, 0});
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
    const size_t instance = rig_->instances.size();
    rig_->instances.push_back({item.node, item.parent});
    if (node.mesh >= 0) {
      if (static_cast<size_t>(node.mesh) >= model_.meshes.size()) {
        fail(name + ": mesh " + str(node.mesh) + " does not exist (the file has " +
             str(model_.meshes.size()) + " meshes)");
      }
      add_draw(instance, static_cast<size_t>(node.mesh), prepare_skin(item.node));
    }
    if (node.camera >= 0) add_camera(instance);
    add_light(instance);
    for (auto it = node.children.rbegin(); it != node.children.rend(); ++it) {
      if (*it < 0 || static_cast<size_t>(*it) >= nnodes) {
        fail(name + ".children: node " + str(*it) + " does not exist (the file has " +
             str(nnodes) + " nodes)");
      }
      stack.push_back({static_cast<size_t>(*it), static_cast<int>(instance), item.depth + 1});
    }
  }
}

// Rest transforms, morph weights and the parent-first order of every node of the file.
void GltfReader::prepare_nodes() {
  const size_t nnodes = model_.nodes.size();
  GltfRig& rig = *rig_;
  rig.rest_local.resize(nnodes);
  rig.rest_translation.assign(nnodes, glm::dvec3(0.0));
  rig.rest_rotation.assign(nnodes, glm::dquat(1.0, 0.0, 0.0, 0.0));
  rig.rest_scale.assign(nnodes, glm::dvec3(1.0));
  rig.animated_node.assign(nnodes, 0);
  rig.weight_offset.assign(nnodes, std::numeric_limits<size_t>::max());
  rig.weight_count.assign(nnodes, 0);
  rig.node_parent.assign(nnodes, -1);
  for (size_t i = 0; i < nnodes; ++i) {
    const tinygltf::Node& node = model_.nodes[i];
    rig.rest_local[i] = local_transform(i);
    if (!node.matrix.empty()) {
      // Only used when the node is animated (which glTF forbids for matrix nodes): T * R * S
      // read back from the matrix.
      const glm::dmat4& m = rig.rest_local[i];
      glm::dvec3 s(glm::length(glm::dvec3(m[0])), glm::length(glm::dvec3(m[1])),
                   glm::length(glm::dvec3(m[2])));
      if (glm::determinant(glm::dmat3(m)) < 0.0) s.x = -s.x;
      rig.rest_translation[i] = glm::dvec3(m[3]);
      rig.rest_scale[i] = s;
      if (s.x != 0.0 && s.y != 0.0 && s.z != 0.0) {
        rig.rest_rotation[i] = glm::normalize(glm::quat_cast(
            glm::dmat3(glm::dvec3(m[0]) / s.x, glm::dvec3(m[1]) / s.y, glm::dvec3(m[2]) / s.z)));
      }
    } else {
      if (!node.translation.empty()) {
        rig.rest_translation[i] =
            glm::dvec3(node.translation[0], node.translation[1], node.translation[2]);
      }
      if (!node.rotation.empty()) {
        const glm::dquat q(node.rotation[3], node.rotation[0], node.rotation[1], node.rotation[2]);
        rig.rest_rotation[i] = q / glm::length(q);  // local_transform refused a zero quaternion
      }
      if (!node.scale.empty()) {
        rig.rest_scale[i] = glm::dvec3(node.scale[0], node.scale[1], node.scale[2]);
      }
    }
    if (node.mesh >= 0 && static_cast<size_t>(node.mesh) < model_.meshes.size()) {
      const size_t targets = mesh_targets(static_cast<size_t>(node.mesh));
      if (targets > 0) {
        const tinygltf::Mesh& mesh = model_.meshes[static_cast<size_t>(node.mesh)];
        const std::vector<double>* w = nullptr;
        if (node.weights.size() == targets) {
          w = &node.weights;
        } else if (mesh.weights.size() == targets) {
          w = &mesh.weights;
        }
        if (!node.weights.empty() && node.weights.size() != targets) {
          scene_warning(file_, element("nodes", i) + ": " + str(node.weights.size()) +
                                   " morph weights for " + str(targets) + " targets: ignored");
        }
        rig.weight_offset[i] = rig.rest_weights.size();
        rig.weight_count[i] = targets;
        for (size_t k = 0; k < targets; ++k) {
          const double v = w != nullptr ? (*w)[k] : 0.0;
          if (!std::isfinite(v)) fail(element("nodes", i) + ": a morph weight is not finite");
          rig.rest_weights.push_back(v);
        }
      }
    }
    for (int c : node.children) {
      if (c >= 0 && static_cast<size_t>(c) < nnodes && rig.node_parent[static_cast<size_t>(c)] < 0 &&
          static_cast<size_t>(c) != i) {
        rig.node_parent[static_cast<size_t>(c)] = static_cast<int>(i);
      }
    }
  }
  // Parents before children: breadth-first from the roots (nodes in a parent cycle never come
  // up; their world transform stays the identity).
  std::vector<std::vector<size_t>> children(nnodes);
  for (size_t i = 0; i < nnodes; ++i) {
    if (rig.node_parent[i] >= 0) children[static_cast<size_t>(rig.node_parent[i])].push_back(i);
  }
  for (size_t i = 0; i < nnodes; ++i) {
    if (rig.node_parent[i] < 0) rig.node_order.push_back(i);
  }
  for (size_t k = 0; k < rig.node_order.size(); ++k) {
    for (size_t c : children[rig.node_order[k]]) rig.node_order.push_back(c);
  }
}

// Channels and samplers of the animations played: all (only < 0) or animations[only].
void GltfReader::prepare_animations(int only, bool warn_overrides) {
  GltfRig& rig = *rig_;
  const size_t nanim = model_.animations.size();
  if (only >= 0 && static_cast<size_t>(only) >= nanim) {
    fail("animation " + str(only) + " does not exist (the file has " + str(nanim) +
         " animations)");
  }
  std::set<size_t> claimed;        // node * 4 + path
  std::vector<size_t> overridden;  // animations with channels dropped
  for (size_t a = 0; a < nanim; ++a) {
    if (only >= 0 && a != static_cast<size_t>(only)) continue;
    const tinygltf::Animation& anim = model_.animations[a];
    const std::string aname = element("animations", a);
    std::map<int, size_t> sampler_map;  // the animation's sampler -> rig.samplers
    for (size_t c = 0; c < anim.channels.size(); ++c) {
      const tinygltf::AnimationChannel& ch = anim.channels[c];
      const std::string cname = aname + "." + element("channels", c);
      if (ch.target_node < 0) continue;  // no target node: the channel is ignored (glTF 2.0)
      if (static_cast<size_t>(ch.target_node) >= model_.nodes.size()) {
        fail(cname + ": target node " + str(ch.target_node) + " does not exist (the file has " +
             str(model_.nodes.size()) + " nodes)");
      }
      const size_t node = static_cast<size_t>(ch.target_node);
      ChannelPath path;
      size_t width;
      int want_type;
      if (ch.target_path == "translation") {
        path = ChannelPath::Translation, width = 3, want_type = TINYGLTF_TYPE_VEC3;
      } else if (ch.target_path == "rotation") {
        path = ChannelPath::Rotation, width = 4, want_type = TINYGLTF_TYPE_VEC4;
      } else if (ch.target_path == "scale") {
        path = ChannelPath::Scale, width = 3, want_type = TINYGLTF_TYPE_VEC3;
      } else if (ch.target_path == "weights") {
        path = ChannelPath::Weights, width = rig.weight_count[node],
        want_type = TINYGLTF_TYPE_SCALAR;
        if (width == 0) {
          scene_warning(file_, cname + ": animates the morph weights of " +
                                   element("nodes", node) +
                                   ", which has no mesh with morph targets: ignored");
          continue;
        }
      } else {
        scene_warning(file_, cname + ": target path '" + ch.target_path + "' is not supported: "
                                 "ignored");
        continue;
      }
      // Played together, the first channel that drives a property of a node wins.
      const size_t claim = node * 4 + static_cast<size_t>(path);
      if (!claimed.insert(claim).second) {
        if (overridden.empty() || overridden.back() != a) overridden.push_back(a);
        continue;
      }
      if (ch.sampler < 0 || static_cast<size_t>(ch.sampler) >= anim.samplers.size()) {
        fail(cname + ": sampler " + str(ch.sampler) + " does not exist (the animation has " +
             str(anim.samplers.size()) + " samplers)");
      }
      size_t sampler_index;
      if (auto it = sampler_map.find(ch.sampler); it != sampler_map.end()) {
        sampler_index = it->second;
        if (rig.samplers[sampler_index].width != width) {
          fail(cname + ": sampler " + str(ch.sampler) + " is shared by targets of different sizes");
        }
      } else {
        const tinygltf::AnimationSampler& src = anim.samplers[static_cast<size_t>(ch.sampler)];
        const std::string sname = aname + "." + element("samplers", static_cast<size_t>(ch.sampler));
        AnimSampler s;
        s.width = width;
        if (src.interpolation.empty() || src.interpolation == "LINEAR") {
          s.interpolation = Interpolation::Linear;
        } else if (src.interpolation == "STEP") {
          s.interpolation = Interpolation::Step;
        } else if (src.interpolation == "CUBICSPLINE") {
          s.interpolation = Interpolation::CubicSpline;
        } else {
          fail(sname + ": interpolation '" + src.interpolation +
               "' must be LINEAR, STEP or CUBICSPLINE");
        }
        const tinygltf::Accessor& in = accessor(src.input, sname + ".input");
        if (in.type != TINYGLTF_TYPE_SCALAR || in.componentType != TINYGLTF_COMPONENT_TYPE_FLOAT) {
          fail(element("accessors", static_cast<size_t>(src.input)) + " (" + sname +
               ".input): " + type_name(in.type) + " of " + component_name(in.componentType) +
               ", expected SCALAR of FLOAT (key times in seconds)");
        }
        s.times = read_accessor(src.input, sname + ".input");
        if (s.times.empty()) fail(sname + ".input: no key times");
        for (size_t k = 0; k < s.times.size(); ++k) {
          if (!std::isfinite(s.times[k]) || s.times[k] < 0.0 ||
              (k > 0 && s.times[k] < s.times[k - 1])) {
            fail(sname + ".input: key time " + str(k) + " (" + std::to_string(s.times[k]) +
                 ") is negative, not finite or smaller than the one before");
          }
        }
        const tinygltf::Accessor& out = accessor(src.output, sname + ".output");
        if (out.type != want_type) {
          fail(element("accessors", static_cast<size_t>(src.output)) + " (" + sname +
               ".output): type " + type_name(out.type) + ", expected " + type_name(want_type) +
               " for " + ch.target_path);
        }
        const bool float_or_normalized =
            out.componentType == TINYGLTF_COMPONENT_TYPE_FLOAT ||
            (out.normalized && path != ChannelPath::Translation && path != ChannelPath::Scale);
        if (!float_or_normalized) {
          fail(element("accessors", static_cast<size_t>(src.output)) + " (" + sname +
               ".output): component type " + component_name(out.componentType) +
               ", expected FLOAT (or normalized integers for rotation and weights)");
        }
        s.values = read_accessor(src.output, sname + ".output");
        const size_t per_key = s.interpolation == Interpolation::CubicSpline ? 3 : 1;
        const size_t want = s.times.size() * per_key * (path == ChannelPath::Weights ? width : 1);
        if (out.count != want) {
          fail(element("accessors", static_cast<size_t>(src.output)) + " (" + sname +
               ".output): " + str(out.count) + " elements, expected " + str(want) + " (" +
               str(s.times.size()) + " key times" + (per_key == 3 ? " x 3 for CUBICSPLINE" : "") +
               (path == ChannelPath::Weights ? " x " + str(width) + " morph targets" : "") + ")");
        }
        for (double v : s.values) {
          if (!std::isfinite(v)) fail(sname + ".output: a value is not finite");
        }
        if (path == ChannelPath::Rotation) {
          for (size_t k = 0; k < s.times.size(); ++k) {
            const double* q = &s.values[(k * per_key + (per_key == 3 ? 1 : 0)) * 4];
            if (q[0] == 0.0 && q[1] == 0.0 && q[2] == 0.0 && q[3] == 0.0) {
              fail(sname + ".output: key " + str(k) + " is a zero quaternion");
            }
          }
        }
        rig.duration = std::max(rig.duration, s.times.back());
        sampler_index = rig.samplers.size();
        rig.samplers.push_back(std::move(s));
        sampler_map[ch.sampler] = sampler_index;
      }
      if (path != ChannelPath::Weights) {
        if (!model_.nodes[node].matrix.empty() && !rig.animated_node[node]) {
          scene_warning(file_, cname + ": " + element("nodes", node) +
                                   " has a matrix, which glTF forbids for animated nodes; it is "
                                   "split into translation, rotation and scale");
        }
        rig.animated_node[node] = 1;
      }
      rig.channels.push_back({node, path, sampler_index});
    }
  }
  if (!overridden.empty() && warn_overrides) {
    std::string list;
    for (size_t a : overridden) {
      if (!list.empty()) list.append(", ");
      list.append(element("animations", a));
    }
    scene_warning(file_, list + (overridden.size() == 1 ? " drives" : " drive") +
                             " node properties that an earlier animation drives already; all "
                             "animations play together and the earlier wins (choose one "
                             "animation to see it alone)");
  }
}

// ---- Evaluation -------------------------------------------------------------------------------

glm::dquat slerp_shortest(glm::dquat a, glm::dquat b, double u) {
  double d = glm::dot(a, b);
  if (d < 0.0) {
    b = -b;
    d = -d;
  }
  if (d > 0.9995) return glm::normalize(a * (1.0 - u) + b * u);
  const double theta = std::acos(std::min(d, 1.0));
  const double s = std::sin(theta);
  return a * (std::sin((1.0 - u) * theta) / s) + b * (std::sin(u * theta) / s);
}

// The sampler's value at time t into out[0 .. width).
void sample(const AnimSampler& s, double t, bool quaternion, double* out) {
  const size_t w = s.width;
  const size_t n = s.times.size();
  const bool cubic = s.interpolation == Interpolation::CubicSpline;
  const size_t stride = cubic ? 3 * w : w;
  const size_t value = cubic ? w : 0;  // offset of the value inside a key
  auto key = [&](size_t k) { return &s.values[k * stride + value]; };
  if (n == 1 || t <= s.times[0]) {
    std::copy(key(0), key(0) + w, out);
    return;
  }
  if (t >= s.times[n - 1]) {
    std::copy(key(n - 1), key(n - 1) + w, out);
    return;
  }
  const size_t k =
      static_cast<size_t>(std::upper_bound(s.times.begin(), s.times.end(), t) - s.times.begin()) -
      1;  // times[k] <= t < times[k + 1]
  const double t0 = s.times[k];
  const double td = s.times[k + 1] - t0;
  const double u = td > 0.0 ? (t - t0) / td : 1.0;
  const double* a = key(k);
  const double* b = key(k + 1);
  switch (s.interpolation) {
    case Interpolation::Step:
      std::copy(a, a + w, out);
      return;
    case Interpolation::Linear:
      if (quaternion) {
        const glm::dquat q = slerp_shortest(glm::dquat(a[3], a[0], a[1], a[2]),
                                            glm::dquat(b[3], b[0], b[1], b[2]), u);
        out[0] = q.x, out[1] = q.y, out[2] = q.z, out[3] = q.w;
      } else {
        for (size_t c = 0; c < w; ++c) out[c] = a[c] + (b[c] - a[c]) * u;
      }
      return;
    case Interpolation::CubicSpline: {
      // glTF 2.0 Appendix C: p(u) = (2u^3 - 3u^2 + 1) v_k + (u^3 - 2u^2 + u) td b_k
      //                             + (-2u^3 + 3u^2) v_k+1 + (u^3 - u^2) td a_k+1
      const double u2 = u * u;
      const double u3 = u2 * u;
      const double h00 = 2.0 * u3 - 3.0 * u2 + 1.0;
      const double h10 = (u3 - 2.0 * u2 + u) * td;
      const double h01 = -2.0 * u3 + 3.0 * u2;
      const double h11 = (u3 - u2) * td;
      const double* out_tangent = a + w;  // b_k
      const double* in_tangent = b - w;   // a_k+1
      for (size_t c = 0; c < w; ++c) {
        out[c] = h00 * a[c] + h10 * out_tangent[c] + h01 * b[c] + h11 * in_tangent[c];
      }
      if (quaternion) {
        const double len = std::sqrt(out[0] * out[0] + out[1] * out[1] + out[2] * out[2] +
                                     out[3] * out[3]);
        if (len > 0.0) {
          for (size_t c = 0; c < 4; ++c) out[c] /= len;
        } else {
          out[0] = out[1] = out[2] = 0.0, out[3] = 1.0;
        }
      }
      return;
    }
  }
}

glm::dmat4 trs_matrix(const glm::dvec3& t, const glm::dquat& r, const glm::dvec3& s) {
  glm::dmat4 m(1.0);
  m[3] = glm::dvec4(t, 1.0);
  m = m * glm::mat4_cast(r);
  return m * glm::scale(glm::dmat4(1.0), s);
}

// Inverse transpose of the upper 3x3 of m, up to the determinant's magnitude (normals are
// normalised afterwards): the cofactor matrix, times the determinant's sign.
glm::dmat3 normal_matrix_of(const glm::dmat3& m, double det) {
  const glm::dmat3 cof(glm::cross(m[1], m[2]), glm::cross(m[2], m[0]), glm::cross(m[0], m[1]));
  return det < 0.0 ? -cof : cof;
}

void GltfRig::fail_at(double t, const std::string& message) const {
  throw input_error(file, message + (channels.empty() ? std::string()
                                                      : " (at t = " + std::to_string(t) + " s)"));
}

struct Pose {
  std::vector<glm::dvec3> translation;
  std::vector<glm::dquat> rotation;
  std::vector<glm::dvec3> scale;
  std::vector<double> weights;
  std::vector<glm::dmat4> instance_world;
  std::vector<glm::dmat4> node_world;
  std::vector<std::vector<glm::dmat4>> joint_matrices;  // per skin
};

void pose(const GltfRig& rig, double t, Pose& p) {
  const size_t nnodes = rig.rest_local.size();
  p.translation = rig.rest_translation;
  p.rotation = rig.rest_rotation;
  p.scale = rig.rest_scale;
  p.weights = rig.rest_weights;
  double v[4];
  for (const AnimChannel& ch : rig.channels) {
    const AnimSampler& s = rig.samplers[ch.sampler];
    switch (ch.path) {
      case ChannelPath::Translation:
        sample(s, t, false, v);
        p.translation[ch.node] = glm::dvec3(v[0], v[1], v[2]);
        break;
      case ChannelPath::Rotation: {
        sample(s, t, true, v);
        const glm::dquat q(v[3], v[0], v[1], v[2]);
        const double len = glm::length(q);
        p.rotation[ch.node] = len > 0.0 ? q / len : glm::dquat(1.0, 0.0, 0.0, 0.0);
        break;
      }
      case ChannelPath::Scale:
        sample(s, t, false, v);
        p.scale[ch.node] = glm::dvec3(v[0], v[1], v[2]);
        break;
      case ChannelPath::Weights:
        sample(s, t, false, &p.weights[rig.weight_offset[ch.node]]);
        break;
    }
  }
  auto local = [&](size_t node) {
    return rig.animated_node[node]
               ? trs_matrix(p.translation[node], p.rotation[node], p.scale[node])
               : rig.rest_local[node];
  };
  p.instance_world.resize(rig.instances.size());
  for (size_t i = 0; i < rig.instances.size(); ++i) {
    const Instance& inst = rig.instances[i];
    p.instance_world[i] =
        inst.parent < 0 ? local(inst.node)
                        : p.instance_world[static_cast<size_t>(inst.parent)] * local(inst.node);
  }
  p.joint_matrices.resize(rig.skins.size());
  if (rig.skins.empty()) return;
  p.node_world.assign(nnodes, glm::dmat4(1.0));
  for (size_t node : rig.node_order) {
    const int parent = rig.node_parent[node];
    p.node_world[node] =
        parent < 0 ? local(node) : p.node_world[static_cast<size_t>(parent)] * local(node);
  }
  for (size_t s = 0; s < rig.skins.size(); ++s) {
    const SkinData& skin = rig.skins[s];
    p.joint_matrices[s].resize(skin.joints.size());
    for (size_t j = 0; j < skin.joints.size(); ++j) {
      p.joint_matrices[s][j] = p.node_world[skin.joints[j]] * skin.inverse_bind[j];
    }
  }
}

void GltfRig::evaluate(double t, Scene& out) const {
  Pose p;
  pose(*this, t, p);
  TriangleMesh& mesh = out.mesh;
  mesh.positions.resize(corners);
  mesh.normals.resize(corners);
  // Per vertex of one primitive: posed position, and normal (zero: use the flat normal).
  std::vector<glm::vec3> pos;
  std::vector<glm::vec3> nrm;
  for (const Draw& draw : draws) {
    const MeshData& md = meshes[draw.mesh];
    const size_t node = instances[draw.instance].node;
    const double* weights =
        weight_count[node] > 0 ? &p.weights[weight_offset[node]] : nullptr;
    const glm::dmat4& world = p.instance_world[draw.instance];
    const glm::dmat3 linear(world);
    const double det = glm::determinant(linear);
    const bool invertible = std::abs(det) > 1e-300 && std::isfinite(det);
    const glm::dmat3 normal_matrix =
        invertible ? glm::inverseTranspose(linear) : glm::dmat3(1.0);
    size_t corner = draw.first_corner;
    for (const PrimData& prim : md.prims) {
      const size_t nv = prim.positions.size();
      pos.resize(nv);
      nrm.resize(nv);
      const bool has_normals = !prim.normals.empty();
      const bool skinned = draw.skin >= 0 && !prim.joints.empty();
      const std::vector<glm::dmat4>* joints =
          skinned ? &p.joint_matrices[static_cast<size_t>(draw.skin)] : nullptr;
      for (size_t v = 0; v < nv; ++v) {
        glm::vec3 lp = prim.positions[v];
        glm::vec3 ln = has_normals ? prim.normals[v] : glm::vec3(0.0f);
        if (weights != nullptr) {
          for (size_t k = 0; k < prim.target_positions.size(); ++k) {
            const float wk = static_cast<float>(weights[k]);
            if (wk == 0.0f) continue;
            if (!prim.target_positions[k].empty()) lp += wk * prim.target_positions[k][v];
            if (has_normals && !prim.target_normals[k].empty()) {
              ln += wk * prim.target_normals[k][v];
            }
          }
        }
        glm::dmat4 m;
        glm::dmat3 nm;
        bool ok;
        if (skinned) {
          const glm::vec4& w = prim.weights[v];
          const glm::uvec4& j = prim.joints[v];
          if (w.x + w.y + w.z + w.w > 0.0f) {
            m = double(w.x) * (*joints)[j.x] + double(w.y) * (*joints)[j.y] +
                double(w.z) * (*joints)[j.z] + double(w.w) * (*joints)[j.w];
          } else {
            m = glm::dmat4(1.0);
          }
          const glm::dmat3 l(m);
          const double d = glm::determinant(l);
          ok = std::abs(d) > 1e-300 && std::isfinite(d);
          nm = normal_matrix_of(l, d);
        } else {
          m = world;
          nm = normal_matrix;
          ok = invertible;
        }
        pos[v] = glm::vec3(m * glm::dvec4(glm::dvec3(lp), 1.0));
        glm::vec3 n(0.0f);
        if (has_normals && ok) {
          const glm::dvec3 wn = nm * glm::dvec3(ln);
          const double len = glm::length(wn);
          if (!std::isfinite(len)) {
            n = glm::vec3(wn);  // NaN or infinite in the file: validation names the triangle
          } else if (len > 0.0) {
            n = glm::vec3(wn / len);
          }
        }
        nrm[v] = n;
      }
      const size_t ntri = prim.triangles.size() / 3;
      for (size_t tr = 0; tr < ntri; ++tr) {
        uint32_t vi[3] = {prim.triangles[3 * tr], prim.triangles[3 * tr + 1],
                          prim.triangles[3 * tr + 2]};
        if (draw.flip && !skinned) std::swap(vi[1], vi[2]);
        const glm::vec3 flat = geometric_normal(pos[vi[0]], pos[vi[1]], pos[vi[2]]);
        for (int k = 0; k < 3; ++k) {
          mesh.positions[corner] = pos[vi[k]];
          const glm::vec3& n = nrm[vi[k]];
          mesh.normals[corner] = (n.x == 0.0f && n.y == 0.0f && n.z == 0.0f) ? flat : n;
          ++corner;
        }
      }
    }
  }

  out.lights.resize(lights.size());
  for (size_t i = 0; i < lights.size(); ++i) {
    const glm::dmat4& world = p.instance_world[lights[i].instance];
    Light light = lights[i].light;
    light.position = glm::vec3(world[3]);
    const glm::dvec3 dir = glm::dmat3(world) * glm::dvec3(0.0, 0.0, -1.0);
    const double len = glm::length(dir);
    if (light.type != LightType::Point && (!(len > 0.0) || !std::isfinite(len))) {
      fail_at(t, element("nodes", instances[lights[i].instance].node) +
                     ".extensions.KHR_lights_punctual: the node transform is singular: the "
                     "light has no direction");
    }
    if (len > 0.0 && std::isfinite(len)) light.direction = glm::vec3(dir / len);
    out.lights[i] = light;
  }

  out.camera.reset();
  if (camera) {
    const glm::dmat4& world = p.instance_world[camera->instance];
    const glm::dmat3 linear(world);
    const glm::dvec3 eye = glm::dvec3(world[3]);
    const glm::dvec3 forward = linear * glm::dvec3(0.0, 0.0, -1.0);
    const glm::dvec3 up = linear * glm::dvec3(0.0, 1.0, 0.0);
    const double fl = glm::length(forward);
    const double ul = glm::length(up);
    if (!(fl > 0.0) || !(ul > 0.0) || !std::isfinite(fl) || !std::isfinite(ul) ||
        glm::length(glm::cross(forward / fl, up / ul)) < 1e-9) {
      fail_at(t, element("nodes", instances[camera->instance].node) + ": the transform of camera " +
                     str(camera->camera) + " is singular (zero scale): no view direction");
    }
    Camera c;
    c.eye = glm::vec3(eye);
    c.target = glm::vec3(eye + forward / fl);
    c.up = glm::vec3(up / ul);
    c.yfov = static_cast<float>(camera->yfov);
    c.znear = camera->znear;
    out.camera = c;
  }
  validate_scene(out);
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
    std::error_code ec;  // the non-throwing form: a name too long is just "not found"
    if (!std::filesystem::exists(ref.path, ec)) {
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

std::shared_ptr<GltfRig> GltfReader::read(const LoadOptions& options, bool animated,
                                          Scene& scene) {
  scene_ = Scene();
  scene_.source = file_;
  if (!options.mtl.empty()) {
    scene_warning(file_, "a replacement .mtl (" + options.mtl + ") applies to OBJ files only: "
                         "ignored for glTF");
  }
  rig_ = std::make_shared<GltfRig>();
  rig_->file = file_;
  rig_->meshes.resize(model_.meshes.size());
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
  prepare_nodes();
  prepare_animations(options.animation, animated);

  // The winding is fixed at t = 0: a draw whose node mirrors at t = 0 has its triangles reversed
  // (and its texture coordinates with them) in every frame. Skinned primitives keep the file's.
  Pose rest;
  pose(*rig_, 0.0, rest);
  bool any_uvs = false;
  for (Draw& draw : rig_->draws) {
    draw.flip = glm::determinant(glm::dmat3(rest.instance_world[draw.instance])) < 0.0;
    for (const PrimData& prim : rig_->meshes[draw.mesh].prims) any_uvs |= !prim.uvs.empty();
  }
  TriangleMesh& mesh = scene_.mesh;
  mesh.material_ids.reserve(rig_->corners / 3);
  if (any_uvs) mesh.texcoords.reserve(rig_->corners);
  for (const Draw& draw : rig_->draws) {
    for (const PrimData& prim : rig_->meshes[draw.mesh].prims) {
      const bool flip = draw.flip && !(draw.skin >= 0 && !prim.joints.empty());
      for (size_t t = 0; t + 2 < prim.triangles.size(); t += 3) {
        mesh.material_ids.push_back(prim.material);
        if (!any_uvs) continue;
        uint32_t v[3] = {prim.triangles[t], prim.triangles[t + 1], prim.triangles[t + 2]};
        if (flip) std::swap(v[1], v[2]);
        for (int k = 0; k < 3; ++k) {
          mesh.texcoords.push_back(prim.uvs.empty() ? glm::vec2(0.0f) : prim.uvs[v[k]]);
        }
      }
    }
  }
  rig_->evaluate(0.0, scene_);
  scene = std::move(scene_);
  return std::move(rig_);
}

tinygltf::Model parse_gltf(const std::string& path) {
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
  // A required extension changes what the file means: one mobirt does not read is an error.
  static const char* const kSupported[] = {"KHR_lights_punctual", "KHR_materials_transmission",
                                           "KHR_materials_ior", "KHR_mesh_quantization"};
  for (size_t i = 0; i < model.extensionsRequired.size(); ++i) {
    const std::string& name = model.extensionsRequired[i];
    if (std::find(std::begin(kSupported), std::end(kSupported), name) == std::end(kSupported)) {
      throw input_error(path, "extensionsRequired[" + std::to_string(i) + "]: extension '" + name +
                                  "' is not supported (mobirt reads KHR_lights_punctual, "
                                  "KHR_materials_transmission, KHR_materials_ior, KHR_mesh_quantization)");
    }
  }
  return model;
}

}  // namespace

Scene load_gltf(const std::string& path) { return load_gltf(path, LoadOptions{}); }

Scene load_gltf(const std::string& path, const LoadOptions& options) {
  const tinygltf::Model model = parse_gltf(path);
  GltfReader reader(path, model);
  Scene scene;
  reader.read(options, false, scene);
  return scene;
}

namespace detail {

AnimatedScene load_gltf_animated(const std::string& path, const LoadOptions& options) {
  const tinygltf::Model model = parse_gltf(path);
  GltfReader reader(path, model);
  Scene scene;
  std::shared_ptr<GltfRig> rig = reader.read(options, true, scene);
  const double duration = rig->duration;
  std::shared_ptr<const Animator> animator;
  if (!rig->channels.empty()) animator = std::move(rig);
  return AnimatedScene(std::move(scene), std::move(animator), duration, options.fps);
}

}  // namespace detail

}  // namespace mobirt
