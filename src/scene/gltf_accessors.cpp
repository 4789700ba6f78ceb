#include "scene/gltf_accessors.h"

#include <algorithm>
#include <cstring>
#include <limits>
#include <type_traits>

#include "scene/validate.h"

namespace mobirt::gltf {

namespace {

constexpr size_t kMaxUnbackedCount = size_t(1) << 26;  // accessors without a bufferView

// One component of type T at p; normalised integers map to [0, 1] or [-1, 1] (glTF 2.0, 3.11).
template <class T>
double read_as(const uint8_t* p, bool normalized) {
  T v;
  std::memcpy(&v, p, sizeof(T));
  if constexpr (std::is_integral_v<T>) {
    if (normalized) {
      const double v_max = static_cast<double>(std::numeric_limits<T>::max());
      return std::is_signed_v<T> ? std::max(v / v_max, -1.0) : v / v_max;
    }
  }
  return v;
}

double read_component(const uint8_t* p, int ct, bool normalized) {
  switch (ct) {
    case TINYGLTF_COMPONENT_TYPE_BYTE: return read_as<int8_t>(p, normalized);
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: return read_as<uint8_t>(p, normalized);
    case TINYGLTF_COMPONENT_TYPE_SHORT: return read_as<int16_t>(p, normalized);
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: return read_as<uint16_t>(p, normalized);
    case TINYGLTF_COMPONENT_TYPE_INT: return read_as<int32_t>(p, normalized);
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: return read_as<uint32_t>(p, normalized);
    case TINYGLTF_COMPONENT_TYPE_FLOAT: return read_as<float>(p, false);
    default: return 0.0;
  }
}

}  // namespace

AccessorReader::AccessorReader(const std::string& file, const tinygltf::Model& model)
    : file_(file), model_(model) {
  const auto& used = model.extensionsUsed;
  quantized_ = std::find(used.begin(), used.end(), "KHR_mesh_quantization") != used.end();
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

const tinygltf::Accessor& AccessorReader::accessor(int index, const std::string& user) const {
  if (index < 0 || static_cast<size_t>(index) >= model_.accessors.size()) {
    fail(user + ": accessor " + str(index) + " does not exist (the file has " +
         str(model_.accessors.size()) + " accessors)");
  }
  return model_.accessors[static_cast<size_t>(index)];
}

const uint8_t* AccessorReader::view_bytes(int view_index, size_t offset, size_t count, size_t elem,
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

std::vector<double> AccessorReader::read_accessor(int index, const std::string& user,
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

std::vector<glm::vec3> AccessorReader::read_vec3(int index, const std::string& user,
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

std::vector<glm::vec2> AccessorReader::read_texcoords(int index, const std::string& user,
                                                      const std::string& attribute) const {
  const tinygltf::Accessor& a = accessor(index, user);
  const std::string name = element("accessors", static_cast<size_t>(index));
  if (a.type != TINYGLTF_TYPE_VEC2) {
    fail(name + " (" + user + " " + attribute + "): type " + type_name(a.type) + ", expected VEC2");
  }
  const int ct = a.componentType;
  const bool ok = ct == TINYGLTF_COMPONENT_TYPE_FLOAT ||
                  ((ct == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE ||
                    ct == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT) &&
                   (a.normalized || quantized_)) ||
                  ((ct == TINYGLTF_COMPONENT_TYPE_BYTE || ct == TINYGLTF_COMPONENT_TYPE_SHORT) &&
                   quantized_);
  if (!ok) {
    fail(name + " (" + user + " " + attribute + "): component type " + component_name(ct) +
         (a.normalized ? "" : " (not normalized)") +
         ", expected FLOAT or normalized UNSIGNED_BYTE / UNSIGNED_SHORT");
  }
  const std::vector<double> v = read_accessor(index, user + " " + attribute);
  std::vector<glm::vec2> out(a.count);
  for (size_t i = 0; i < a.count; ++i) {
    out[i] = glm::vec2(static_cast<float>(v[2 * i]), static_cast<float>(v[2 * i + 1]));
  }
  return out;
}

std::vector<uint32_t> AccessorReader::read_indices(int index, const std::string& user) const {
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

}  // namespace mobirt::gltf
