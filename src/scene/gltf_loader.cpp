// glTF 2.0 through tinygltf: the scene graph (node traversal, meshes and their primitives, skins,
// materials, textures, lights and camera) read into the static Scene and the rig that poses it.
// tinygltf parses the JSON and the buffers; buffer data is read only through the bounds-checked
// AccessorReader (gltf_accessors.h), animations by gltf_animation.cpp, poses by gltf_pose.cpp.
// Images are not decoded: their encoded bytes or paths go into Scene::textures.

#define TINYGLTF_IMPLEMENTATION
#include "scene/gltf_accessors.h"

#include <glm/gtc/constants.hpp>
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
#include <string>
#include <vector>

#include "core/error.h"
#include "scene/animation.h"
#include "scene/gltf_animation.h"
#include "scene/gltf_rig.h"
#include "scene/loader.h"
#include "scene/validate.h"

namespace mobirt {

namespace {

using namespace gltf;

constexpr size_t kMaxNodeVisits = size_t(1) << 22;

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
  GltfReader(const std::string& file, const tinygltf::Model& model)
      : file_(file), model_(model), accessors_(file, model) {}

  // The static parts of the scene (materials, textures, texture coordinates, material ids) and
  // the rig that poses it.
  std::shared_ptr<GltfRig> read(const LoadOptions& options, bool animated, Scene& scene);

 private:
  [[noreturn]] void fail(const std::string& message) const { throw input_error(file_, message); }

  glm::dmat4 local_transform(size_t node_index) const;
  void traverse(const std::vector<int>& roots, const std::string& roots_name);
  void prepare_mesh(size_t mesh_index);
  bool prepare_primitive(size_t mesh_index, size_t prim_index, PrimData& out);
  void add_draw(size_t instance, size_t mesh_index, int skin);
  int prepare_skin(size_t node_index);
  void add_camera(size_t instance);
  void add_light(size_t instance);
  void prepare_nodes();
  size_t mesh_targets(size_t mesh_index) const;
  void convert_materials();
  glm::mat3 texture_transform(const tinygltf::TextureInfo& info, const std::string& name, int& texcoord_set) const;
  int texture_for(int gltf_texture, const std::string& user);
  uint32_t default_material();

  const std::string& file_;
  const tinygltf::Model& model_;
  const AccessorReader accessors_;
  bool warned_orthographic_ = false;
  Scene scene_;
  std::shared_ptr<GltfRig> rig_;
  std::map<int, int> texture_map_;  // glTF texture -> Scene::textures
  std::map<int, int> skin_map_;     // glTF skin -> GltfRig::skins
  int default_material_ = -1;
  std::vector<int> texcoord_sets_;  // per glTF material: the TEXCOORD_n its base-colour texture reads
};

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
  out.positions = accessors_.read_vec3(pos_acc, path, "POSITION");
  const size_t nverts = out.positions.size();
  auto check_count = [&](int acc, size_t count, const std::string& what) {
    if (count != nverts) {
      fail(element("accessors", static_cast<size_t>(acc)) + " (" + path + " " + what + "): " +
           str(count) + " elements, but POSITION has " + str(nverts));
    }
  };
  if (const int acc = attr(prim.attributes, "NORMAL"); acc >= 0) {
    out.normals = accessors_.read_vec3(acc, path, "NORMAL");
    check_count(acc, out.normals.size(), "NORMAL");
  }
  // The set that the material's base-colour texture reads (textureInfo.texCoord, or the
  // KHR_texture_transform override); a primitive without it gets uv (0, 0), as without TEXCOORD_0.
  const size_t material = static_cast<size_t>(prim.material);
  const int set = prim.material >= 0 && material < texcoord_sets_.size() ? texcoord_sets_[material] : 0;
  const std::string texcoord = "TEXCOORD_" + str(set);
  if (const int acc = attr(prim.attributes, texcoord.c_str()); acc >= 0) {
    out.uvs = accessors_.read_texcoords(acc, path, texcoord);
    check_count(acc, out.uvs.size(), texcoord);
  }

  // Morph targets.
  out.target_positions.resize(prim.targets.size());
  out.target_normals.resize(prim.targets.size());
  for (size_t k = 0; k < prim.targets.size(); ++k) {
    const std::string tname = element("targets", k);
    if (const int acc = attr(prim.targets[k], "POSITION"); acc >= 0) {
      out.target_positions[k] = accessors_.read_vec3(acc, path, (tname + ".POSITION").c_str());
      check_count(acc, out.target_positions[k].size(), tname + ".POSITION");
    }
    if (const int acc = attr(prim.targets[k], "NORMAL"); acc >= 0 && !out.normals.empty()) {
      out.target_normals[k] = accessors_.read_vec3(acc, path, (tname + ".NORMAL").c_str());
      check_count(acc, out.target_normals[k].size(), tname + ".NORMAL");
    }
  }

  // Skinning attributes (set 0; further sets are ignored with a warning).
  const int joints_acc = attr(prim.attributes, "JOINTS_0");
  const int weights_acc = attr(prim.attributes, "WEIGHTS_0");
  if (joints_acc >= 0 && weights_acc >= 0) {
    const tinygltf::Accessor& ja = accessors_.accessor(joints_acc, path);
    if (ja.type != TINYGLTF_TYPE_VEC4 ||
        (ja.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE &&
         ja.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT) ||
        ja.normalized) {
      fail(element("accessors", static_cast<size_t>(joints_acc)) + " (" + path +
           " JOINTS_0): " + type_name(ja.type) + " of " + component_name(ja.componentType) +
           ", expected VEC4 of UNSIGNED_BYTE or UNSIGNED_SHORT");
    }
    const tinygltf::Accessor& wa = accessors_.accessor(weights_acc, path);
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
    const std::vector<double> j = accessors_.read_accessor(joints_acc, path + " JOINTS_0");
    const std::vector<double> w = accessors_.read_accessor(weights_acc, path + " WEIGHTS_0");
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
    indices = accessors_.read_indices(prim.indices, path);
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
        accessors_.read_accessor(src.inverseBindMatrices, sname + ".inverseBindMatrices", true);
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
    const uint8_t* bytes = accessors_.view_bytes(image.bufferView, 0, 1, length, length, iname);
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

// KHR_texture_transform on a textureInfo as its matrix (identity without the extension); its
// texCoord, when given, replaces `texcoord_set`.
glm::mat3 GltfReader::texture_transform(const tinygltf::TextureInfo& info, const std::string& name,
                                        int& texcoord_set) const {
  const auto it = info.extensions.find("KHR_texture_transform");
  if (it == info.extensions.end()) return glm::mat3(1.0f);
  const std::string where = name + ".extensions.KHR_texture_transform";
  const tinygltf::Value& ext = it->second;
  if (!ext.IsObject()) fail(where + " is not a JSON object");
  auto vec2_or = [&](const char* key, glm::vec2 fallback) {
    if (!ext.Has(key)) return fallback;
    const tinygltf::Value& v = ext.Get(key);
    glm::vec2 value(std::numeric_limits<float>::quiet_NaN());
    if (v.IsArray() && v.ArrayLen() == 2 && v.Get(0).IsNumber() && v.Get(1).IsNumber()) {
      value = glm::vec2(static_cast<float>(v.Get(0).GetNumberAsDouble()), static_cast<float>(v.Get(1).GetNumberAsDouble()));
    }
    if (!std::isfinite(value.x) || !std::isfinite(value.y)) fail(where + "." + key + " must be an array of 2 finite numbers");
    return value;
  };
  const glm::vec2 offset = vec2_or("offset", glm::vec2(0.0f));
  const glm::vec2 scale = vec2_or("scale", glm::vec2(1.0f));
  float rotation = 0.0f;
  if (ext.Has("rotation")) {
    const tinygltf::Value& v = ext.Get("rotation");
    rotation = v.IsNumber() ? static_cast<float>(v.GetNumberAsDouble()) : std::numeric_limits<float>::quiet_NaN();
    if (!std::isfinite(rotation)) fail(where + ".rotation must be a finite number (radians)");
  }
  if (ext.Has("texCoord")) {
    const tinygltf::Value& v = ext.Get("texCoord");
    const double set = v.IsNumber() ? v.GetNumberAsDouble() : -1.0;
    if (!(set >= 0.0 && set <= 65535.0 && std::floor(set) == set)) {
      fail(where + ".texCoord must be a TEXCOORD set index (an integer, at least 0)");
    }
    texcoord_set = static_cast<int>(set);
  }
  return texture_transform_matrix(offset, rotation, scale);
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
    int set = 0;
    if (pbr.baseColorTexture.index >= 0) {
      const std::string info = name + ".pbrMetallicRoughness.baseColorTexture";
      set = pbr.baseColorTexture.texCoord;
      if (set < 0) fail(info + ".texCoord is " + str(set) + ": a TEXCOORD set index is at least 0");
      m.texture_transform = texture_transform(pbr.baseColorTexture, info, set);
      m.texture = texture_for(pbr.baseColorTexture.index, name + ".baseColorTexture");
    }
    texcoord_sets_.push_back(set);
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
  read_animations(accessors_, options.animation, animated, *rig_);

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
  validate_scene(scene_);  // the texture coordinates and material ids too, which posing leaves as they are
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
                                           "KHR_materials_ior", "KHR_mesh_quantization",
                                           "KHR_texture_transform"};
  for (size_t i = 0; i < model.extensionsRequired.size(); ++i) {
    const std::string& name = model.extensionsRequired[i];
    if (std::find(std::begin(kSupported), std::end(kSupported), name) == std::end(kSupported)) {
      throw input_error(path, "extensionsRequired[" + std::to_string(i) + "]: extension '" + name +
                                  "' is not supported (mobirt reads KHR_lights_punctual, "
                                  "KHR_materials_transmission, KHR_materials_ior, KHR_mesh_quantization, "
                                  "KHR_texture_transform)");
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
