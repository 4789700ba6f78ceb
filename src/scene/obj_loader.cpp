// Wavefront OBJ + MTL through tinyobjloader (v2 ObjReader API).

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wshadow"
#include <tiny_obj_loader.h>
#pragma GCC diagnostic pop

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "core/error.h"
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

}  // namespace

Scene load_obj(const std::string& path) {
  check_scene_file(path);
  const std::filesystem::path file(path);
  std::string folder = file.parent_path().string();
  if (folder.empty()) folder = ".";

  tinyobj::ObjReaderConfig config;
  config.triangulate = true;
  config.vertex_color = false;
  config.mtl_search_path = folder;
  tinyobj::ObjReader reader;
  const bool ok = reader.ParseFromFile(path, config);
  if (!ok || !reader.Valid()) {
    const std::string why = library_message(reader.Error());
    throw input_error(path, "not a valid OBJ file: " +
                                (why.empty() ? std::string("tinyobjloader could not parse it")
                                             : why));
  }
  if (!reader.Warning().empty()) scene_warning(path, library_message(reader.Warning()));
  if (!reader.Error().empty()) scene_warning(path, library_message(reader.Error()));

  const tinyobj::attrib_t& attrib = reader.GetAttrib();
  const std::vector<tinyobj::shape_t>& shapes = reader.GetShapes();
  const std::vector<tinyobj::material_t>& materials = reader.GetMaterials();

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
        if (!std::filesystem::exists(tex)) {
          scene_warning(path, "material '" + src.name + "': texture " + tex + " not found");
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

}  // namespace mobirt
