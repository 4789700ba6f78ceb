// Wavefront OBJ + MTL through tinyobjloader (v2 ObjReader API).

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wshadow"
#include <tiny_obj_loader.h>
#pragma GCC diagnostic pop

#include <algorithm>
#include <atomic>
#include <exception>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <map>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "core/error.h"
#include "scene/animation.h"
#include "scene/loader.h"
#include "scene/validate.h"

namespace mobirt {

namespace {


glm::vec3 vec3_of(const tinyobj::real_t* v) {
  return glm::vec3(static_cast<float>(v[0]), static_cast<float>(v[1]), static_cast<float>(v[2]));
}

float max3(const glm::vec3& v) { return std::max(v.x, std::max(v.y, v.z)); }

// MTL -> Phong; the table is docs/materials.md.
Material convert(const tinyobj::material_t& src) {
  Material m;
  m.name = src.name;
  m.diffuse = glm::clamp(vec3_of(src.diffuse), 0.0f, 1.0f);
  m.specular = glm::clamp(vec3_of(src.specular), 0.0f, 1.0f);
  m.shininess = std::isfinite(src.shininess)
                    ? std::clamp(static_cast<float>(src.shininess), 1.0f, 1024.0f)
                    : 32.0f;
  const bool mirror_illum = src.illum == 3 || src.illum == 5 || src.illum == 7;
  if (mirror_illum || !src.reflection_texname.empty()) m.reflectance = max3(m.specular);
  const float dissolve = static_cast<float>(src.dissolve);  // tinyobjloader folds Tr into d
  if (std::isfinite(dissolve) && dissolve < 1.0f) {
    m.transmittance = std::clamp(1.0f - dissolve, 0.0f, 1.0f);
  } else if (src.illum == 6 || src.illum == 7) {
    m.transmittance = std::clamp(max3(vec3_of(src.transmittance)), 0.0f, 1.0f);  // Tf
  }
  const float ior = static_cast<float>(src.ior);
  m.ior = std::isfinite(ior) && ior >= 1.0f ? ior : 1.0f;
  return m;
}

// Reads the .mtl given in LoadOptions::mtl for every `mtllib` of the OBJ, once.
class OverrideMtlReader : public tinyobj::MaterialReader {
 public:
  explicit OverrideMtlReader(const std::string& path) : path_(path) {}
  bool operator()(const std::string&, std::vector<tinyobj::material_t>* materials,
                  std::map<std::string, int>* material_map, std::string* warn,
                  std::string* err) override {
    if (loaded_) return true;
    loaded_ = true;
    std::ifstream in(path_);
    if (!in) throw input_error(path_, "cannot be opened for reading");
    tinyobj::LoadMtl(material_map, materials, &in, warn, err);
    return true;
  }

 private:
  std::string path_;
  bool loaded_ = false;
};

// True when a line of `text` is an mtllib statement.
bool has_mtllib(const std::string& text) {
  size_t pos = 0;
  while (pos < text.size()) {
    size_t i = pos;
    while (i < text.size() && (text[i] == ' ' || text[i] == '\t')) ++i;
    if (text.compare(i, 6, "mtllib") == 0 && i + 6 < text.size() &&
        (text[i + 6] == ' ' || text[i + 6] == '\t')) {
      return true;
    }
    const size_t end = text.find('\n', pos);
    if (end == std::string::npos) break;
    pos = end + 1;
  }
  return false;
}

// tinyobjloader reads a coordinate it cannot parse ("nan", "inf", "1,5") as 0 without a word, which
// silently moves the vertex. Each v/vn/vt line with characters other than those of plain numbers is
// checked field by field; a coordinate that is not a whole finite number is recorded (kind 0 = v,
// 1 = vn, 2 = vt; the element's index; the component) and set to NaN after parsing, so that
// validate_scene names the triangle that uses it. The character scan keeps ordinary files at one
// pass over the bytes.
struct BadCoordinate {
  int kind;
  size_t index;
  int component;
};

std::vector<BadCoordinate> bad_obj_coordinates(const std::string& text) {
  std::vector<BadCoordinate> bad;
  size_t counts[3] = {0, 0, 0};
  for (size_t pos = 0; pos < text.size();) {
    size_t end = text.find('\n', pos);
    if (end == std::string::npos) end = text.size();
    size_t i = pos;
    while (i < end && (text[i] == ' ' || text[i] == '\t')) ++i;
    int kind = -1;
    if (i + 1 < end && text[i] == 'v' && (text[i + 1] == ' ' || text[i + 1] == '\t')) {
      kind = 0;
    } else if (i + 2 < end && text[i] == 'v' && (text[i + 1] == 'n' || text[i + 1] == 't') &&
               (text[i + 2] == ' ' || text[i + 2] == '\t')) {
      kind = text[i + 1] == 'n' ? 1 : 2;
    }
    if (kind >= 0) {
      const size_t index = counts[kind]++;
      if (text.find_first_not_of("0123456789+-.eE \t\r", i + (kind == 0 ? 1 : 2)) < end) {
        std::istringstream fields(text.substr(i, end - i));
        std::string field;
        fields >> field;  // the keyword
        for (int c = 0; c < (kind == 2 ? 2 : 3) && fields >> field && field[0] != '#'; ++c) {
          char* stop = nullptr;
          const double v = std::strtod(field.c_str(), &stop);
          if (*stop != '\0' || !std::isfinite(v)) bad.push_back({kind, index, c});
        }
      }
    }
    pos = end + 1;
  }
  return bad;
}

// The OBJ parsed; `material_folder` gets the folder that map_Kd paths are relative to.
struct ParsedObj {
  tinyobj::attrib_t attrib;
  std::vector<tinyobj::shape_t> shapes;
  std::vector<tinyobj::material_t> materials;
  std::string warning;
  std::string error;
  std::string material_folder;
};

void parse_obj(const std::string& path, const std::string& mtl, ParsedObj& out) {
  const std::filesystem::path file(path);
  std::string folder = file.parent_path().string();
  if (folder.empty()) folder = ".";
  bool ok;
  std::vector<BadCoordinate> bad;
  {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw input_error(path, "cannot be opened for reading");
    bad = bad_obj_coordinates(std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>()));
  }
  if (mtl.empty()) {
    // What tinyobj::ObjReader::ParseFromFile does, without copying its results.
    ok = tinyobj::LoadObj(&out.attrib, &out.shapes, &out.materials, &out.warning, &out.error,
                          path.c_str(), folder.c_str(), /*triangulate=*/true,
                          /*default_vcols_fallback=*/false);
    out.material_folder = folder;
  } else {
    check_scene_file(mtl);
    std::ifstream in(path, std::ios::binary);
    if (!in) throw input_error(path, "cannot be opened for reading");
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    // An OBJ without mtllib resolves no usemtl; the replacement .mtl is read up front then.
    if (!has_mtllib(text)) text.insert(0, "mtllib replacement.mtl\n");
    std::istringstream stream(std::move(text));
    OverrideMtlReader reader(mtl);
    ok = tinyobj::LoadObj(&out.attrib, &out.shapes, &out.materials, &out.warning, &out.error,
                          &stream, &reader, true, false);
    std::string mfolder = std::filesystem::path(mtl).parent_path().string();
    out.material_folder = mfolder.empty() ? "." : mfolder;
  }
  if (!ok) {
    const std::string why = library_message(out.error);
    throw input_error(path, "not a valid OBJ file: " +
                                (why.empty() ? std::string("tinyobjloader could not parse it")
                                             : why));
  }
  for (const BadCoordinate& b : bad) {  // read as 0 by tinyobjloader: NaN, refused by validate_scene
    std::vector<tinyobj::real_t>& values =
        b.kind == 0 ? out.attrib.vertices : b.kind == 1 ? out.attrib.normals : out.attrib.texcoords;
    const size_t at = b.index * (b.kind == 2 ? 2 : 3) + size_t(b.component);
    if (at < values.size()) values[at] = std::numeric_limits<tinyobj::real_t>::quiet_NaN();
  }
}

}  // namespace

Scene load_obj(const std::string& path) { return load_obj(path, LoadOptions{}); }

Scene load_obj(const std::string& path, const LoadOptions& options) {
  return detail::load_obj_frame(path, options.mtl, true);
}

namespace detail {

Scene load_obj_frame(const std::string& path, const std::string& mtl, bool warnings) {
  check_scene_file(path);
  ParsedObj parsed;
  parse_obj(path, mtl, parsed);
  auto warn = [&](const std::string& message) {
    if (warnings) scene_warning(path, message);
  };
  if (!parsed.warning.empty()) warn(library_message(parsed.warning));
  if (!parsed.error.empty()) warn(library_message(parsed.error));
  const std::string& folder = parsed.material_folder;

  const tinyobj::attrib_t& attrib = parsed.attrib;
  const std::vector<tinyobj::shape_t>& shapes = parsed.shapes;
  const std::vector<tinyobj::material_t>& materials = parsed.materials;

  Scene scene;
  scene.source = path;
  std::map<std::string, int> texture_by_path;
  for (const tinyobj::material_t& src : materials) {
    Material m = convert(src);
    if (!src.diffuse_texname.empty()) {
      const std::string tex =
          (std::filesystem::path(folder) / src.diffuse_texname).lexically_normal().string();
      auto it = texture_by_path.find(tex);
      if (it == texture_by_path.end()) {
        TextureRef ref;
        ref.name = src.diffuse_texname;
        ref.path = tex;
        std::error_code ec;  // the non-throwing form: a name too long is just "not found"
        if (!std::filesystem::exists(tex, ec)) {
          warn("material '" + src.name + "': texture " + tex + " not found");
        }
        it = texture_by_path.emplace(tex, static_cast<int>(scene.textures.size())).first;
        scene.textures.push_back(std::move(ref));
      }
      m.texture = it->second;
    }
    scene.materials.push_back(m);
  }
  int default_material = -1;

  const size_t nv = attrib.vertices.size() / 3;
  const size_t nn = attrib.normals.size() / 3;
  const size_t nt = attrib.texcoords.size() / 2;
  const bool any_texcoords = nt > 0;
  TriangleMesh& mesh = scene.mesh;

  for (const tinyobj::shape_t& shape : shapes) {
    const tinyobj::mesh_t& sm = shape.mesh;
    size_t offset = 0;
    for (size_t f = 0; f < sm.num_face_vertices.size(); ++f) {
      const size_t fv = sm.num_face_vertices[f];
      if (offset + fv > sm.indices.size()) {
        throw input_error(path, "shape '" + shape.name + "': face " + std::to_string(f) +
                                    " runs past the index list");
      }
      if (fv != 3) {  // triangulate=true leaves only triangles; anything else is skipped
        offset += fv;
        continue;
      }
      glm::vec3 p[3];
      glm::vec3 n[3];
      glm::vec2 uv[3];
      bool has_normals = true;
      for (size_t k = 0; k < 3; ++k) {
        const tinyobj::index_t idx = sm.indices[offset + k];
        if (idx.vertex_index < 0 || static_cast<size_t>(idx.vertex_index) >= nv) {
          throw input_error(path, "shape '" + shape.name + "': face " + std::to_string(f) +
                                      " uses vertex " + std::to_string(idx.vertex_index + 1) +
                                      ", but the file has " + std::to_string(nv) + " vertices");
        }
        p[k] = vec3_of(&attrib.vertices[3 * static_cast<size_t>(idx.vertex_index)]);
        if (idx.normal_index >= 0 && static_cast<size_t>(idx.normal_index) < nn) {
          n[k] = vec3_of(&attrib.normals[3 * static_cast<size_t>(idx.normal_index)]);
        } else {
          has_normals = false;
        }
        uv[k] = glm::vec2(0.0f);
        if (idx.texcoord_index >= 0 && static_cast<size_t>(idx.texcoord_index) < nt) {
          const size_t t = 2 * static_cast<size_t>(idx.texcoord_index);
          // OBJ's v grows upwards; mobirt follows glTF, whose v grows downwards.
          uv[k] = glm::vec2(static_cast<float>(attrib.texcoords[t]),
                            1.0f - static_cast<float>(attrib.texcoords[t + 1]));
        }
      }
      const glm::vec3 flat = geometric_normal(p[0], p[1], p[2]);
      for (size_t k = 0; k < 3; ++k) {
        mesh.positions.push_back(p[k]);
        glm::vec3 nk = flat;
        if (has_normals) {
          const float len = glm::length(n[k]);
          if (!std::isfinite(len)) {
            nk = n[k];  // validation names the triangle
          } else if (len > 0.0f) {
            nk = n[k] / len;
          }
        }
        mesh.normals.push_back(nk);
        if (any_texcoords) mesh.texcoords.push_back(uv[k]);
      }
      const int mid = f < sm.material_ids.size() ? sm.material_ids[f] : -1;
      if (mid >= 0 && static_cast<size_t>(mid) < materials.size()) {
        mesh.material_ids.push_back(static_cast<uint32_t>(mid));
      } else {
        if (default_material < 0) {
          Material m;
          m.name = "default";
          default_material = static_cast<int>(scene.materials.size());
          scene.materials.push_back(m);
        }
        mesh.material_ids.push_back(static_cast<uint32_t>(default_material));
      }
      offset += fv;
    }
  }

  validate_scene(scene);
  return scene;
}


namespace {

// The frames of an OBJ sequence, all in memory: positions and normals per frame (the triangle
// soup of TriangleMesh), frame = floor(t * fps) clamped.
class ObjSequence : public detail::Animator {
 public:
  void evaluate(double t, Scene& out) const override {
    const size_t n = positions.size();
    // The small bias keeps t = k / fps on frame k despite rounding.
    const double f = std::floor(t * fps + 1e-9);
    const size_t frame = !(f > 0.0) ? 0 : f >= static_cast<double>(n - 1) ? n - 1
                                                                           : static_cast<size_t>(f);
    out.mesh.positions.assign(positions[frame].begin(), positions[frame].end());
    out.mesh.normals.assign(normals[frame].begin(), normals[frame].end());
    out.lights.clear();
    out.camera.reset();
    out.degenerate_triangles = degenerate[frame];
  }

  double fps = 24.0;
  std::vector<std::vector<glm::vec3>> positions;
  std::vector<std::vector<glm::vec3>> normals;
  std::vector<size_t> degenerate;
};

}  // namespace

AnimatedScene load_obj_sequence(const std::vector<std::string>& files, const std::string& source,
                                const LoadOptions& options) {
  if (files.empty()) throw input_error(source, "no frame files");
  const size_t n = files.size();
  // Frames load in parallel (one worker per core); only the first frame prints warnings.
  std::vector<Scene> frames(n);
  std::vector<std::exception_ptr> errors(n);
  std::atomic<size_t> next{0};
  auto work = [&] {
    for (size_t i = next++; i < n; i = next++) {
      try {
        frames[i] = load_obj_frame(files[i], options.mtl, i == 0);
      } catch (...) {
        errors[i] = std::current_exception();
      }
    }
  };
  const size_t workers =
      std::min<size_t>(n, std::max(1u, std::thread::hardware_concurrency()));
  std::vector<std::thread> threads;
  for (size_t w = 1; w < workers; ++w) threads.emplace_back(work);
  work();
  for (std::thread& th : threads) th.join();
  for (size_t i = 0; i < n; ++i) {
    if (errors[i]) std::rethrow_exception(errors[i]);
  }

  const Scene& first = frames[0];
  auto seq = std::make_shared<ObjSequence>();
  seq->fps = options.fps;
  for (size_t i = 0; i < n; ++i) {
    Scene& frame = frames[i];
    if (i > 0) {
      const std::string why = "the frames of a sequence need the same topology as the first, " +
                              files[0];
      if (frame.mesh.triangle_count() != first.mesh.triangle_count()) {
        throw input_error(files[i], "frame " + std::to_string(i) + " has " +
                                        std::to_string(frame.mesh.triangle_count()) +
                                        " triangles, the first frame " +
                                        std::to_string(first.mesh.triangle_count()) + ": " + why);
      }
      for (size_t t = 0; t < frame.mesh.material_ids.size(); ++t) {
        const Material& a = frame.materials[frame.mesh.material_ids[t]];
        const Material& b = first.materials[first.mesh.material_ids[t]];
        if (a.name != b.name) {
          throw input_error(files[i], "frame " + std::to_string(i) + ": triangle " +
                                          std::to_string(t) + " has material '" + a.name +
                                          "', in the first frame '" + b.name + "': " + why);
        }
      }
      if (frame.mesh.texcoords.empty() != first.mesh.texcoords.empty()) {
        throw input_error(files[i], "frame " + std::to_string(i) +
                                        (frame.mesh.texcoords.empty() ? " lacks" : " has") +
                                        " texture coordinates, unlike the first frame: " + why);
      }
    }
    seq->positions.push_back(std::move(frame.mesh.positions));
    seq->normals.push_back(std::move(frame.mesh.normals));
    seq->degenerate.push_back(frame.degenerate_triangles);
  }
  Scene rest = std::move(frames[0]);
  rest.source = source;
  rest.mesh.positions = seq->positions[0];
  rest.mesh.normals = seq->normals[0];
  const double duration = static_cast<double>(n) / options.fps;
  std::shared_ptr<const Animator> animator;
  if (n > 1) animator = std::move(seq);
  return AnimatedScene(std::move(rest), std::move(animator), duration, options.fps, n);
}

}  // namespace detail

}  // namespace mobirt
