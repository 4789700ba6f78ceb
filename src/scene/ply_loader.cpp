// PLY (Stanford polygon file format), ASCII and binary little- and big-endian: a small reader
// with every read bounds-checked. Debian packages no PLY library (tinyply, happly and miniply are
// not in bookworm; assimp reads PLY but would bring a whole import framework for one format).

#include <algorithm>
#include <bit>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "core/error.h"
#include "scene/loader.h"
#include "scene/tessellate.h"
#include "scene/validate.h"

namespace mobirt {

namespace {

constexpr size_t kMaxTriangles = (size_t(1) << 24) - 1;  // the 24-bit hit index
constexpr double kMaxFaceVertices = 1 << 16;
constexpr size_t kMaxVertices = size_t(1) << 31;

enum class Type { I8, U8, I16, U16, I32, U32, F32, F64 };

size_t type_size(Type t) {
  switch (t) {
    case Type::I8: case Type::U8: return 1;
    case Type::I16: case Type::U16: return 2;
    case Type::I32: case Type::U32: case Type::F32: return 4;
    case Type::F64: return 8;
  }
  return 0;
}

// The largest value of an integer type (colours are scaled by it); 1 for floats.
double type_max(Type t) {
  switch (t) {
    case Type::I8: return 127.0;
    case Type::U8: return 255.0;
    case Type::I16: return 32767.0;
    case Type::U16: return 65535.0;
    case Type::I32: return 2147483647.0;
    case Type::U32: return 4294967295.0;
    default: return 1.0;
  }
}

// A value in a message: integers without decimals.
std::string text_of(double v) {
  std::ostringstream out;
  out << v;
  return out.str();
}

bool is_integer(Type t) { return t != Type::F32 && t != Type::F64; }

bool parse_type(const std::string& word, Type& out) {
  static const std::map<std::string, Type> names = {
      {"char", Type::I8},    {"int8", Type::I8},     {"uchar", Type::U8},   {"uint8", Type::U8},
      {"short", Type::I16},  {"int16", Type::I16},   {"ushort", Type::U16}, {"uint16", Type::U16},
      {"int", Type::I32},    {"int32", Type::I32},   {"uint", Type::U32},   {"uint32", Type::U32},
      {"float", Type::F32},  {"float32", Type::F32}, {"double", Type::F64}, {"float64", Type::F64}};
  const auto it = names.find(word);
  if (it == names.end()) return false;
  out = it->second;
  return true;
}

struct Property {
  std::string name;
  Type type = Type::F32;
  bool list = false;
  Type count_type = Type::U8;
};

struct Element {
  std::string name;
  size_t count = 0;
  std::vector<Property> properties;
};

enum class Format { Ascii, BinaryLittle, BinaryBig };

// Slots of the vertex properties mobirt reads.
enum Slot { X, Y, Z, NX, NY, NZ, U, V, R, G, B, kSlots };

int vertex_slot(const std::string& name) {
  static const std::map<std::string, int> slots = {
      {"x", X},  {"y", Y},  {"z", Z},  {"nx", NX}, {"ny", NY}, {"nz", NZ},
      {"u", U},  {"v", V},  {"s", U},  {"t", V},   {"texture_u", U}, {"texture_v", V},
      {"texture_s", U}, {"texture_t", V}, {"red", R}, {"green", G}, {"blue", B},
      {"diffuse_red", R}, {"diffuse_green", G}, {"diffuse_blue", B}};
  const auto it = slots.find(name);
  return it == slots.end() ? -1 : it->second;
}

class PlyReader {
 public:
  PlyReader(const std::string& path, std::string bytes) : path_(path), data_(std::move(bytes)) {}

  Scene read() {
    scene_.source = path_;
    header();
    bool have_vertices = false;
    for (const Element& e : elements_) {
      if (e.name == "vertex") {
        // A second vertex element would replace the vertices the faces were checked against.
        if (have_vertices) fail("element 'vertex' appears twice: a PLY file has one vertex list");
        have_vertices = true;
        vertices(e);
      } else if (e.name == "face") {
        faces(e);
      } else {
        // An element without properties takes no bytes, whatever its count.
        for (size_t i = 0; !e.properties.empty() && i < e.count; ++i) skip_record(e, i);
      }
    }
    build();
    validate_scene(scene_);
    return std::move(scene_);
  }

 private:
  [[noreturn]] void fail(const std::string& message) const { throw input_error(path_, message); }

  std::string where(const Element& e, size_t record, const Property& p) const {
    return "element '" + e.name + "' " + std::to_string(record) + " property '" + p.name + "'";
  }

  void header() {
    size_t line_no = 0;
    auto next_line = [&](std::string& line) {
      if (pos_ >= data_.size()) fail("header line " + std::to_string(line_no + 1) + ": unexpected end of file before end_header");
      size_t end = data_.find('\n', pos_);
      const bool last = end == std::string::npos;
      if (last) end = data_.size();
      line.assign(data_, pos_, end - pos_);
      if (!line.empty() && line.back() == '\r') line.pop_back();
      // A header cut off mid-line: say so rather than report the fragment as a keyword.
      if (last && line != "end_header") {
        fail("header line " + std::to_string(line_no + 1) + ": unexpected end of file before end_header");
      }
      pos_ = std::min(end + 1, data_.size());
      ++line_no;
    };
    std::string line;
    if (data_.compare(0, 3, "ply") != 0) fail("not a PLY file: it does not begin with 'ply'");
    next_line(line);
    if (line != "ply") fail("not a PLY file: the first line is not 'ply'");
    bool have_format = false;
    while (true) {
      next_line(line);
      std::istringstream words(line);
      std::string key;
      words >> key;
      const std::string at = "header line " + std::to_string(line_no) + ": ";
      if (key == "end_header") break;
      if (key.empty() || key == "comment" || key == "obj_info") continue;
      if (key == "format") {
        std::string format, version;
        words >> format >> version;
        if (format == "ascii") {
          format_ = Format::Ascii;
        } else if (format == "binary_little_endian") {
          format_ = Format::BinaryLittle;
        } else if (format == "binary_big_endian") {
          format_ = Format::BinaryBig;
        } else {
          fail(at + "unknown format '" + format + "' (ascii, binary_little_endian or binary_big_endian)");
        }
        have_format = true;
      } else if (key == "element") {
        Element e;
        long long count = -1;
        if (!(words >> e.name >> count) || count < 0) fail(at + "expected 'element NAME COUNT'");
        e.count = size_t(count);
        elements_.push_back(e);
      } else if (key == "property") {
        if (elements_.empty()) fail(at + "a property before any element");
        Property p;
        std::string type;
        words >> type;
        if (type == "list") {
          std::string count_type, item_type;
          words >> count_type >> item_type >> p.name;
          p.list = true;
          if (!parse_type(count_type, p.count_type) || !parse_type(item_type, p.type) || p.name.empty() ||
              !is_integer(p.count_type)) {
            fail(at + "expected 'property list COUNT_TYPE ITEM_TYPE NAME' with an integer COUNT_TYPE");
          }
        } else if (!parse_type(type, p.type) || !(words >> p.name)) {
          fail(at + "expected 'property TYPE NAME' (TYPE: char, uchar, short, ushort, int, uint, float, double)");
        }
        elements_.back().properties.push_back(p);
      } else {
        fail(at + "unknown header keyword '" + key.substr(0, 40) + "'");
      }
    }
    if (!have_format) fail("the header has no 'format' line");
    // Each record takes at least this many bytes (ASCII: a digit and a separator per value), so a
    // count the file cannot hold is refused before anything is allocated.
    size_t need = 0;
    for (const Element& e : elements_) {
      size_t record = 0;
      for (const Property& p : e.properties) {
        record += format_ == Format::Ascii ? 2 : p.list ? type_size(p.count_type) : type_size(p.type);
      }
      if (record > 0 && e.count > (data_.size() - pos_ + 1) / record) {
        fail("element '" + e.name + "': " + std::to_string(e.count) + " records do not fit in the " +
             std::to_string(data_.size() - pos_) + " bytes after the header (truncated file?)");
      }
      need += e.count * record;
      if (need > data_.size() - pos_ + elements_.size()) {
        fail("the elements' " + std::to_string(need) + " bytes at least do not fit in the " +
             std::to_string(data_.size() - pos_) + " bytes after the header (truncated file?)");
      }
    }
  }

  double value(Type t, const Element& e, size_t record, const Property& p) {
    if (format_ == Format::Ascii) {
      while (pos_ < data_.size() && std::isspace(static_cast<unsigned char>(data_[pos_]))) ++pos_;
      const size_t start = pos_;
      while (pos_ < data_.size() && !std::isspace(static_cast<unsigned char>(data_[pos_]))) ++pos_;
      if (start == pos_) fail(where(e, record, p) + ": unexpected end of file (truncated?)");
      const std::string word(data_, start, std::min<size_t>(pos_ - start, 64));
      errno = 0;
      char* end = nullptr;
      const double v = std::strtod(word.c_str(), &end);
      if (end != word.c_str() + word.size() || pos_ - start > 64 || errno == ERANGE) {
        fail(where(e, record, p) + ": '" + word.substr(0, 40) + "' is not a number");
      }
      return v;
    }
    const size_t n = type_size(t);
    if (n > data_.size() - pos_) fail(where(e, record, p) + ": unexpected end of file (truncated?)");
    unsigned char b[8];
    std::memcpy(b, data_.data() + pos_, n);
    pos_ += n;
    const bool little = format_ == Format::BinaryLittle;
    if (little != (std::endian::native == std::endian::little)) std::reverse(b, b + n);
    auto as = [&](auto v) {
      std::memcpy(&v, b, sizeof(v));
      return double(v);
    };
    switch (t) {
      case Type::I8: return as(int8_t{});
      case Type::U8: return as(uint8_t{});
      case Type::I16: return as(int16_t{});
      case Type::U16: return as(uint16_t{});
      case Type::I32: return as(int32_t{});
      case Type::U32: return as(uint32_t{});
      case Type::F32: return as(float{});
      case Type::F64: return as(double{});
    }
    return 0.0;
  }

  // A list's length: a whole number in [0, 65536].
  size_t list_count(const Element& e, size_t record, const Property& p) {
    const double c = value(p.count_type, e, record, p);
    if (!(c >= 0.0 && c <= kMaxFaceVertices) || c != std::floor(c)) {
      fail(where(e, record, p) + ": list length " + text_of(c) + " is not a whole number in [0, 65536]");
    }
    return size_t(c);
  }

  void skip_record(const Element& e, size_t record) {
    for (const Property& p : e.properties) {
      const size_t n = p.list ? list_count(e, record, p) : 1;
      for (size_t k = 0; k < n; ++k) value(p.type, e, record, p);
    }
  }

  void vertices(const Element& e) {
    if (e.count > kMaxVertices) fail("element 'vertex': " + std::to_string(e.count) + " vertices, more than 2^31");
    std::vector<int> slot(e.properties.size(), -1);
    for (size_t i = 0; i < e.properties.size(); ++i) {
      if (!e.properties[i].list) slot[i] = vertex_slot(e.properties[i].name);
      if (slot[i] >= 0) have_[slot[i]] = true;
      if (slot[i] >= R && slot[i] <= B) colour_scale_[slot[i] - R] = type_max(e.properties[i].type);
    }
    if (!have_[X] || !have_[Y] || !have_[Z]) fail("element 'vertex' lacks one of the properties x, y and z");
    normals_ = have_[NX] && have_[NY] && have_[NZ];
    texcoords_ = have_[U] && have_[V];
    vertex_colours_ = have_[R] && have_[G] && have_[B];
    verts_.resize(e.count * kSlots, 0.0f);
    for (size_t r = 0; r < e.count; ++r) {
      for (size_t i = 0; i < e.properties.size(); ++i) {
        const Property& p = e.properties[i];
        const size_t n = p.list ? list_count(e, r, p) : 1;
        for (size_t k = 0; k < n; ++k) {
          const double v = value(p.type, e, r, p);
          if (slot[i] >= 0) verts_[r * kSlots + size_t(slot[i])] = float(v);
        }
      }
    }
    vertex_count_ = e.count;
  }

  void faces(const Element& e) {
    int list = -1;
    int colour[3] = {-1, -1, -1};
    for (size_t i = 0; i < e.properties.size(); ++i) {
      const Property& p = e.properties[i];
      if (p.list && (p.name == "vertex_indices" || p.name == "vertex_index") && list < 0) list = int(i);
      for (int c = 0; c < 3; ++c) {
        static const char* const names[3] = {"red", "green", "blue"};
        if (!p.list && p.name == names[c]) colour[c] = int(i);
      }
    }
    if (list < 0) fail("element 'face' has no list property vertex_indices (or vertex_index)");
    const bool face_colours = colour[0] >= 0 && colour[1] >= 0 && colour[2] >= 0;
    for (size_t r = 0; r < e.count; ++r) {
      Face face;
      face.first = face_indices_.size();
      for (size_t i = 0; i < e.properties.size(); ++i) {
        const Property& p = e.properties[i];
        const size_t n = p.list ? list_count(e, r, p) : 1;
        for (size_t k = 0; k < n; ++k) {
          const double v = value(p.type, e, r, p);
          if (int(i) == list) {
            if (!(v >= 0.0 && v < double(vertex_count_)) || v != std::floor(v)) {
              fail("element 'face' " + std::to_string(r) + ": vertex index " + text_of(v) +
                   " is out of range: the file has " + std::to_string(vertex_count_) +
                   " vertices (before the faces)");
            }
            face_indices_.push_back(uint32_t(v));
          }
          for (int c = 0; c < 3; ++c) {
            if (int(i) == colour[c]) face.colour[c] = float(v / type_max(p.type));
          }
        }
      }
      face.count = face_indices_.size() - face.first;
      if (face.count > kMaxPolygonVertices) {
        fail("element 'face' " + std::to_string(r) + ": " + std::to_string(face.count) + " vertices, more than the " +
             std::to_string(kMaxPolygonVertices) + " a face may have");
      }
      face.coloured = face_colours;
      triangles_ += face.count >= 3 ? face.count - 2 : 0;
      if (triangles_ > kMaxTriangles) {
        fail("element 'face': the faces make more than " + std::to_string(kMaxTriangles) +
             " triangles, the most the 24-bit hit index holds");
      }
      faces_.push_back(face);
    }
  }

  glm::vec3 vertex(size_t i, int slot) const {
    const float* v = &verts_[i * kSlots + size_t(slot)];
    return glm::vec3(v[0], v[1], v[2]);
  }

  // A face's colour group: 6 bits a channel of its colour.
  uint32_t group_of(const glm::vec3& colour) const {
    const glm::uvec3 q = glm::uvec3(glm::clamp(colour, 0.0f, 1.0f) * 63.0f + 0.5f);
    return (q.x << 12) | (q.y << 6) | q.z;
  }

  void build() {
    const bool colours = vertex_colours_ || (!faces_.empty() && faces_.front().coloured);
    std::map<uint32_t, uint32_t> material_of_group;  // group -> material
    std::vector<glm::dvec3> sums;                    // per material: colour sum, for the mean
    std::vector<size_t> counts;
    if (!colours) {
      scene_.materials.push_back(Material{});
      scene_.materials.back().name = "default";
    }
    TriangleMesh& mesh = scene_.mesh;
    std::vector<glm::vec3> polygon;
    for (const Face& f : faces_) {
      if (f.count < 3) continue;  // points and lines are not rendered
      polygon.clear();
      glm::vec3 mean(0.0f);
      for (size_t k = 0; k < f.count; ++k) {
        const uint32_t vi = face_indices_[f.first + k];
        polygon.push_back(vertex(vi, X));
        if (vertex_colours_) {
          mean += glm::vec3(vertex(vi, R)) / glm::vec3(colour_scale_[0], colour_scale_[1], colour_scale_[2]);
        }
      }
      uint32_t material = 0;
      if (colours) {
        const glm::vec3 colour = f.coloured ? glm::vec3(f.colour[0], f.colour[1], f.colour[2]) : mean / float(f.count);
        const auto [it, added] = material_of_group.emplace(group_of(colour), uint32_t(sums.size()));
        if (added) {
          sums.emplace_back(0.0);
          counts.push_back(0);
        }
        material = it->second;
        sums[material] += glm::dvec3(colour);
        ++counts[material];
      }
      std::vector<uint32_t> tris = triangulate_polygon(polygon);
      if (tris.empty()) tris = {0, 1, 2};  // no area: one degenerate triangle, counted
      const glm::vec3 flat = polygon_normal(polygon);
      for (size_t t = 0; t < tris.size(); t += 3) {
        for (size_t k = 0; k < 3; ++k) {
          const uint32_t vi = face_indices_[f.first + tris[t + k]];
          mesh.positions.push_back(vertex(vi, X));
          mesh.normals.push_back(normals_ ? vertex(vi, NX) : flat);
          if (texcoords_) {
            const float* uv = &verts_[vi * kSlots + U];
            mesh.texcoords.emplace_back(uv[0], 1.0f - uv[1]);
          }
        }
        mesh.material_ids.push_back(material);
      }
    }
    for (size_t m = 0; m < sums.size(); ++m) {
      Material mat;
      mat.diffuse = glm::clamp(glm::vec3(sums[m] / double(counts[m])), 0.0f, 1.0f);
      mat.name = "colour group " + std::to_string(m);
      scene_.materials.push_back(mat);
    }
  }

  struct Face {
    size_t first = 0, count = 0;
    bool coloured = false;
    float colour[3] = {0.0f, 0.0f, 0.0f};
  };

  std::string path_;
  std::string data_;
  size_t pos_ = 0;
  Format format_ = Format::Ascii;
  std::vector<Element> elements_;
  Scene scene_;
  bool have_[kSlots] = {};
  float colour_scale_[3] = {1.0f, 1.0f, 1.0f};
  bool normals_ = false, texcoords_ = false, vertex_colours_ = false;
  std::vector<float> verts_;  // kSlots floats per vertex
  size_t vertex_count_ = 0;
  std::vector<uint32_t> face_indices_;
  std::vector<Face> faces_;
  size_t triangles_ = 0;
};

}  // namespace

Scene load_ply(const std::string& path) {
  check_scene_file(path);
  std::ifstream in(path, std::ios::binary);
  if (!in) throw input_error(path, "cannot be opened for reading");
  std::ostringstream bytes;
  bytes << in.rdbuf();
  Scene scene = PlyReader(path, bytes.str()).read();
  return scene;
}

}  // namespace mobirt
