// Pose and skinning: the rig at time t (keyframes sampled, node transforms composed, joint matrices)
// and the scene's world-space vertices, lights and camera from it.
#include <glm/gtc/matrix_inverse.hpp>
#include <glm/gtc/matrix_transform.hpp>

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>

#include "core/error.h"
#include "scene/gltf_names.h"
#include "scene/gltf_rig.h"
#include "scene/validate.h"

namespace mobirt::gltf {

namespace {

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

// A posed corner without a normal: posing leaves it zero (none in the file, a zero one, or a
// singular transform), and the triangle's flat normal takes its place.
bool no_normal(const glm::vec3& n) { return n.x == 0.0f && n.y == 0.0f && n.z == 0.0f; }

}  // namespace

void GltfRig::fail_at(double t, const std::string& message) const {
  throw input_error(file, message + (channels.empty() ? std::string()
                                                      : " (at t = " + std::to_string(t) + " s)"));
}

void pose(const GltfRig& rig, double t, Pose& p) {
  const size_t nnodes = rig.rest_local.size();
  p.translation = rig.rest_translation;
  p.rotation = rig.rest_rotation;
  p.scale = rig.rest_scale;
  p.weights = rig.rest_weights;
  double v[4];
  for (const AnimChannel& ch : rig.channels) {
    const KeyframeTrack& s = rig.samplers[ch.sampler];
    switch (ch.path) {
      case ChannelPath::Translation:
        sample_keyframes(s, t, false, v);
        p.translation[ch.node] = glm::dvec3(v[0], v[1], v[2]);
        break;
      case ChannelPath::Rotation: {
        sample_keyframes(s, t, true, v);
        const glm::dquat q(v[3], v[0], v[1], v[2]);
        const double len = glm::length(q);
        p.rotation[ch.node] = len > 0.0 ? q / len : glm::dquat(1.0, 0.0, 0.0, 0.0);
        break;
      }
      case ChannelPath::Scale:
        sample_keyframes(s, t, false, v);
        p.scale[ch.node] = glm::dvec3(v[0], v[1], v[2]);
        break;
      case ChannelPath::Weights:
        sample_keyframes(s, t, false, &p.weights[rig.weight_offset[ch.node]]);
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
        // The flat normal only for a triangle with a corner that has none (no normals in the file,
        // a zero one, or a singular transform): a mesh with normals rarely needs it. Measured
        // (callgrind of GltfRig::evaluate over 10 toaster frames): 53.2M -> 47.7M instructions.
        // Where it is not computed, no corner reads the zero that stands in for it.
        const bool flat_needed =
            no_normal(nrm[vi[0]]) || no_normal(nrm[vi[1]]) || no_normal(nrm[vi[2]]);
        const glm::vec3 flat =
            flat_needed ? geometric_normal(pos[vi[0]], pos[vi[1]], pos[vi[2]]) : glm::vec3(0.0f);
        for (int k = 0; k < 3; ++k) {
          mesh.positions[corner] = pos[vi[k]];
          const glm::vec3& n = nrm[vi[k]];
          mesh.normals[corner] = no_normal(n) ? flat : n;
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
  // The loader validates the first pose in full (gltf_loader.cpp); a later one changes only what
  // validate_posed() checks.
  validate_posed(out);
}

}  // namespace mobirt::gltf
