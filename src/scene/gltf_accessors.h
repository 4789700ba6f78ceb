// The bounds-checked reader of glTF accessors: every byte read from a buffer is checked against
// its buffer view and the view against its buffer, so that a broken file ends in a BadInput error
// naming the accessor, never a crash. The one place that reads buffer data.
#pragma once

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wshadow"
#pragma GCC diagnostic ignored "-Wunused-parameter"
#pragma GCC diagnostic ignored "-Wunused-function"
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"
// The same in every file that includes tinygltf: gltf_loader.cpp adds TINYGLTF_IMPLEMENTATION.
#define TINYGLTF_NO_STB_IMAGE
#define TINYGLTF_NO_STB_IMAGE_WRITE
#define TINYGLTF_NO_EXTERNAL_IMAGE
#include <tiny_gltf.h>
#pragma GCC diagnostic pop

#include <glm/glm.hpp>

#include <cstdint>
#include <string>
#include <vector>

#include "core/error.h"
#include "scene/gltf_names.h"

namespace mobirt::gltf {

std::string component_name(int component_type);  // "UNSIGNED_SHORT (5123)"
std::string type_name(int type);                  // "VEC3"

class AccessorReader {
 public:
  AccessorReader(const std::string& file, const tinygltf::Model& model);

  const std::string& file() const { return file_; }
  const tinygltf::Model& model() const { return model_; }
  [[noreturn]] void fail(const std::string& message) const { throw input_error(file_, message); }

  // accessors[index], or an error naming `user` (the element that refers to it).
  const tinygltf::Accessor& accessor(int index, const std::string& user) const;
  // Bytes of `count` elements of `elem` bytes, `stride` apart, starting `offset` bytes into buffer
  // view `view_index`: every range checked against the view and the view against its buffer.
  const uint8_t* view_bytes(int view_index, size_t offset, size_t count, size_t elem,
                            size_t stride, const std::string& who) const;
  // All components of an accessor as doubles (normalised integers mapped to [0, 1] or [-1, 1]),
  // sparse substitution applied. `matrix4`: MAT4 of FLOAT expected; otherwise SCALAR to VEC4.
  std::vector<double> read_accessor(int index, const std::string& user,
                                    bool matrix4 = false) const;
  // Vertex attributes, with the component types glTF allows (KHR_mesh_quantization widens them).
  std::vector<glm::vec3> read_vec3(int index, const std::string& user, const char* attribute) const;
  // `attribute` ("TEXCOORD_1") names the set in messages.
  std::vector<glm::vec2> read_texcoords(int index, const std::string& user,
                                        const std::string& attribute = "TEXCOORD_0") const;
  std::vector<uint32_t> read_indices(int index, const std::string& user) const;

 private:
  const std::string& file_;
  const tinygltf::Model& model_;
  bool quantized_ = false;
};

}  // namespace mobirt::gltf
